"""Model → Alpha_1-style text → model gives back the same model; the text has the paper's Figure 7 style."""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from iges_model_strategies import assert_same_model, make_object, models
from rgm.backends.alpha1 import Alpha1Error, alpha1_text, read_alpha1, write_alpha1
from rgm.model import IntersectionCurve, Loop, Model, Plane, TrimmedFace

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(models())
def test_model_alpha1_model_is_identical(model):
    text = alpha1_text(model)
    back = read_alpha1(text)
    assert_same_model(model, back, lowered=())
    for name in model.objects:
        assert name in back.objects


def test_figure7_style_statements(tmp_path):
    rng = np.random.default_rng(3)
    model = Model("mm", 0.01, {"skin": make_object("bsurface", rng, "skin"),
                               "pin": make_object("revolution", rng, "pin")}, ("skin", "pin"), {"radius": 27.15})
    path = write_alpha1(model, tmp_path / "m.a1")
    text = path.read_text()
    lines = text.splitlines()
    assert all(line.startswith("#") or line.endswith(";") for line in lines)  # one statement a line
    assert re.search(r"^skin_1_p1 := (projPt\(\S+, \S+, \S+, \S+\)|pt\(\S+, \S+, \S+\));$", text, re.M)
    assert re.search(r"^skin := surface\(parminfo\((linear|quadratic|cubic), ec_open, knots\(", text, re.M)
    assert re.search(r"^pin := surfRev\(pin_profile, pt\(", text, re.M)
    assert "radius := param(27.15);" in text and lines[-1] == "export(skin, pin);"


def test_lazy_intersection_stays_lazy_and_shares_its_operands():
    rng = np.random.default_rng(5)
    skin = make_object("bsurface", rng, "skin")
    cut_plane = Plane([0, 0, 0.5], [0, 0, 1], name="cutter")
    cut = IntersectionCurve(skin, cut_plane, 1e-3, name="cut")
    face = TrimmedFace(skin, Loop((cut,)), name="hand")
    model = Model("mm", 1e-3, {"skin": skin, "cutter": cut_plane, "cut": cut, "hand": face}, ("hand",))
    back = read_alpha1(alpha1_text(model))
    piece = back.objects["hand"].outer.pieces[0]
    assert isinstance(piece, IntersectionCurve) and piece.computed == ()
    assert piece.a is back.objects["hand"].surface and piece.tolerance == 1e-3


@pytest.mark.parametrize("text, message", [
    ('units := "mm";\ntolerance := 0.1;\nc := spline(1);\n', "line 3: `spline` is not part"),
    ('tolerance := 0.1;\nc := line(pt(0, 0, 0), q);\n', "line 2: `q` is not defined"),
    ('tolerance := 0.1;\nc := line(pt(0, 0, 0) pt(1, 1, 1));\n', "line 2: expected `,`"),
    ('tolerance := 0.1;\nc := line(pt(0, 0, 0), pt(0, 0, 0), pt(1, 1, 1));\n', "line 2: wrong arguments"),
    ('tolerance := 0.1;\nc := curve(parminfo(cubic, ec_open, knots(0, 1)), list(pt(0, 0, 0)));\n', "line 2: curve"),
    ('tolerance := 0.1;\n$\n', "line 2: unexpected"),
])
def test_text_outside_the_subset_names_the_line(text, message):
    with pytest.raises(Alpha1Error, match=message):
        read_alpha1(text)


EXAMPLES = sorted((__import__("pathlib").Path(__file__).parents[2] / "examples").glob("*.rgm"))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_rgm_alpha1_model_for_the_examples(path, tmp_path):
    """.rgm → model → Alpha_1 text (via `rgmc compile -t alpha1`) → model: the same model."""
    import rgm
    from rgm.cli import main

    model = rgm.load(path)
    out = tmp_path / "m.a1"
    assert main(["compile", str(path), "-t", "alpha1", "-o", str(out)]) == 0
    back = read_alpha1(out.read_text())
    assert_same_model(model, back, lowered=())
    assert back.params == model.params
    for name, value in model.objects.items():
        if isinstance(value, float):
            assert back.objects[name] == value


def test_transform_values_are_baked_not_written():
    """A `transform` binding is not geometry: the Alpha_1 text holds what `place` made of it (the placed
    circle, bit-identical), and no statement for the transform itself."""
    import rgm

    source = ("units mm;\nt := rotation(vec(0, 0, 1), 90deg) * translation(vec(10mm, 0, 0));\n"
              "ring := circle(pt(40mm, 0, 0), 5mm);\nplaced := place(ring, t);\nexport placed;\n")
    model = rgm.loads(source)
    text = alpha1_text(model)
    assert not re.search(r"^t :=", text, re.M)
    back = read_alpha1(text)
    assert "t" not in back.objects
    np.testing.assert_array_equal(back.objects["placed"].center, model.objects["placed"].center)
    assert back.objects["placed"].radius == model.objects["placed"].radius
