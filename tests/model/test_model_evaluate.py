"""The evaluator: examples, -D overrides, unit conversion to model units, angles in radians, user
fns, arithmetic and members, and runtime errors as diagnostics on the offending call."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import rgm
from rgm.compiler.diagnostics import CompileError
from rgm.model import CircularArc, IntersectionCurve, Point, Revolution, TrimmedFace, Vector

EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "examples").glob("*.rgm"))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_every_example_evaluates(path):
    model = rgm.load(path)
    assert model.exported(), "something to emit"
    assert not any(d.is_error for d in model.diagnostics)
    for obj in model.exported():
        assert obj.name is not None and obj.span is not None and obj.span.file == str(path)


def _radii(rev: Revolution) -> np.ndarray:
    s = rev.nurbs()
    (u0, u1), (v0, v1) = s.domain
    pts = s.evaluate_grid(np.linspace(u0, u1, 33), np.linspace(v0, v1, 33)).reshape(-1, 3)
    rel = pts - rev.axis_point
    return np.linalg.norm(rel - np.outer(rel @ rev.axis_dir, rev.axis_dir), axis=1)


def test_define_changes_the_revolution():
    pin = Path(__file__).resolve().parents[2] / "examples" / "pin.rgm"
    if not pin.exists():
        pytest.skip("examples/pin.rgm not written yet")
    base, wide = rgm.load(pin), rgm.load(pin, params={"radius": 30})
    assert wide.params["radius"] == 30 and base.params["radius"] == pytest.approx(27.15)
    assert _radii(wide["pin"]).max() == pytest.approx(30.0, abs=1e-9)
    assert _radii(base["pin"]).max() == pytest.approx(27.15, abs=1e-9)
    inches = rgm.load(pin, params={"radius": "1in"})
    assert _radii(inches["pin"]).max() == pytest.approx(25.4, abs=1e-9)


def test_units_are_converted_to_the_model_units():
    model = rgm.loads("units cm;\ntolerance 0.5mm;\np := pt(1in, 20mm, 3);\nd := 2m;\n")
    assert np.allclose(model["p"].xyz, [2.54, 2.0, 3.0])
    assert model["d"] == pytest.approx(200.0) and model.tolerance == pytest.approx(0.05) and model.units == "cm"


def test_angles_are_radians_and_transforms_keep_kinds():
    text = """
units mm;
axis := line(pt(0, 0, 0), pt(0, 0, 1));
quarter := revolve(line(pt(5, 0, 0), pt(5, 0, 10)), axis, from: 0deg, to: 90deg);
turned := rotate(quarter, vec(0, 0, 1), 90deg);
fn lift(g: surface, h: length) := translate(g, vec(0, 0, h));
up := lift(turned, 1cm);
a := arc(pt(1, 0, 0), pt(0, 1, 0), pt(-1, 0, 0));
"""
    model = rgm.loads(text)
    quarter, up = model["quarter"], model["up"]
    assert quarter.end == pytest.approx(math.pi / 2) and quarter.start == 0.0
    assert isinstance(up, Revolution) and up.name == "up"
    (u0, u1), (v0, v1) = up.domain
    pts = up.nurbs().evaluate_grid(np.linspace(u0, u1, 21), np.linspace(v0, v1, 21)).reshape(-1, 3)
    # the quarter cylinder r = 5, z in [0, 10], angles [0, 90deg] turned by 90deg and lifted by 1 cm
    assert np.allclose(np.hypot(pts[:, 0], pts[:, 1]), 5.0)
    assert pts[:, 2].min() == pytest.approx(10.0) and pts[:, 2].max() == pytest.approx(20.0)
    angles = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
    assert angles.min() == pytest.approx(90.0) and angles.max() == pytest.approx(180.0)
    arc = model["a"]
    assert isinstance(arc, CircularArc) and arc.radius == pytest.approx(1.0) and arc.sweep == pytest.approx(math.pi)
    assert np.allclose(arc.center, 0.0, atol=1e-12)


def test_arithmetic_members_and_intersections():
    text = """
units mm;
tolerance 0.02;
a := pt(1, 2, 3);
b := pt(4, 6, 3);
d := b - a;
m := a + d / 2;
len := d.length;
s := extrude(line(pt(0, 0, 0), pt(10, 0, 0)), vec(0, 10, 0));
c := intersect(s, plane(pt(0, 0, 0), vec(1, 0, 0)));
f := trim(s, outer: loop(uvline(uv(0, 0), uv(1, 0)), uvline(uv(1, 0), uv(1, 1)), uvline(uv(1, 1), uv(0, 1)),
                         uvline(uv(0, 1), uv(0, 0))));
"""
    model = rgm.loads(text)
    assert isinstance(model["d"], Vector) and np.allclose(model["d"].xyz, [3, 4, 0])
    assert isinstance(model["m"], Point) and np.allclose(model["m"].xyz, [2.5, 4, 3])
    assert model["len"] == pytest.approx(5.0)
    assert isinstance(model["c"], IntersectionCurve) and model["c"].tolerance == pytest.approx(0.02)
    assert isinstance(model["f"], TrimmedFace) and not model["f"].outer.is_lazy


def test_runtime_failure_is_a_diagnostic_on_the_call():
    text = "units mm;\nparam k := 2;\nbad := arc(pt(0, 0, 0), pt(1, 0, 0), pt(k, 0, 0));\n"
    with pytest.raises(CompileError) as info:
        rgm.loads(text, filename="bad.rgm")
    diag = next(d for d in info.value.diagnostics if d.is_error)
    assert diag.span is not None and diag.span.line == 3
    assert "collinear" in diag.message
