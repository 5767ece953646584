"""Model → IGES → model: rgm's reader gives back the same model, and OpenCASCADE's IGESControl_Reader
reads every file with all roots transferred, no fail message, and geometry matching rgm's evaluation."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from iges_model_strategies import KINDS, assert_same_model, make_object, models
from rgm.backends.iges import iges_text, write_iges
from rgm.backends.iges_read import read_iges
from rgm.model import Model, Plane, Revolution, Surface, TrimmedFace

SETTINGS = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(models())
def test_model_iges_model_is_identical(model):
    text = iges_text(model)
    back = read_iges(text)
    assert back.ok, back.messages()
    assert_same_model(model, back.model)
    for name, obj in model.objects.items():  # nested named pieces come back as bindings too
        assert name in back.model.objects


@SETTINGS
@given(models())
def test_output_is_deterministic_and_80_columns(model):
    import os

    os.environ["SOURCE_DATE_EPOCH"] = "1700000000"
    try:
        a, b = iges_text(model), iges_text(model)
    finally:
        del os.environ["SOURCE_DATE_EPOCH"]
    assert a == b
    assert "20231114.221320" in a
    assert all(len(line) == 80 for line in a.splitlines())


@SETTINGS
@given(models(kinds=[k for k in KINDS if k not in ("composite", "plane", "trimmed", "shell")]))
def test_nurbs_only_writes_126_and_128_with_the_same_geometry(model):
    from rgm.backends.iges_parse import parse_iges
    from rgm.backends.iges_verify import sample_object

    text = iges_text(model, nurbs_only=True)
    types = {e.type for e in parse_iges(text).entries.values()}
    assert types <= {126, 128, 102, 142, 144, 402, 406}, types
    back = read_iges(text).model
    for name in model.exports:
        a, b = sample_object(model.objects[name], 1e-3), sample_object(back.objects[name], 1e-3)
        assert np.abs(a - b).max() <= 1e-12 * 100


def _occ_distance_to_model(points, objs):
    """Distance (k,) of points to the nearest exported rgm surface or curve (rgm's own inversion)."""
    best = np.full(len(points), np.inf)
    for obj in objs:
        faces = obj.faces if hasattr(obj, "faces") else [obj]
        for f in faces:
            s = f.surface if isinstance(f, TrimmedFace) else f
            if isinstance(s, Plane):
                d = np.abs(s.signed_distance(points))
            elif isinstance(s, Surface):
                d = s.nurbs().closest_point(points)[3]
            elif hasattr(s, "pieces"):
                d = np.min([p.nurbs().closest_point(points)[2] for p in s.pieces], axis=0)
            else:
                d = s.nurbs().closest_point(points)[2]
            best = np.minimum(best, d)
    return best


@pytest.mark.occ
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
def test_opencascade_reads_every_file(tmp_path_factory, model):
    """Every kind; PREF = 2 so that OpenCASCADE's edges are the file's model-space curves (with
    PREF = 1 it rebuilds them from the pcurves itself, to ~1e-7 of the size: see docs/backends.md)."""
    pytest.importorskip("OCP")
    from rgm.backends.iges_occ_check import occ_read_iges

    path = tmp_path_factory.mktemp("iges") / "m.igs"
    write_iges(model, path, pcurve_preference="3d")
    occ = occ_read_iges(path)
    assert occ.fails == [] and occ.roots == occ.transferred == len(model.exports)
    size = 30.0
    mm = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}[model.units]  # OpenCASCADE works in mm
    for kind, wires, pts, _uv in occ.faces:
        assert _occ_distance_to_model(pts / mm, model.exported()).max() <= 1e-9 * size, kind
    for pts in occ.edges:
        assert _occ_distance_to_model(pts / mm, model.exported()).max() <= 1e-9 * size


@pytest.mark.occ
def test_revolution_arrives_as_surface_of_revolution_and_trim_keeps_its_hole(tmp_path):
    pytest.importorskip("OCP")
    from rgm.backends.iges_occ_check import occ_read_iges

    rng = np.random.default_rng(7)
    rev = make_object("revolution", rng, "pin")
    face = make_object("trimmed", rng, "hand")
    model = Model("mm", 1e-3, {"pin": rev, "hand": face}, ("pin", "hand"))
    path = tmp_path / "m.igs"
    write_iges(model, path, verify=True)
    occ = occ_read_iges(path)
    kinds = [(k, w) for k, w, _p, _uv in occ.faces]
    assert kinds[0] == ("SurfaceOfRevolution", 1)
    assert kinds[1][1] == 2  # outer wire and the hole
    assert isinstance(read_iges(path.read_text()).model.objects["pin"], Revolution)


@pytest.mark.occ
def test_verify_fails_and_keeps_no_file_when_the_reader_disagrees(tmp_path, monkeypatch):
    pytest.importorskip("OCP")
    import rgm.backends.iges_verify as V
    from rgm.errors import BackendError

    model = Model("mm", 1e-3, {"s": make_object("bsurface", np.random.default_rng(1), "s")}, ("s",))
    real = V.sample_object
    calls = {"n": 0}

    def shifted(obj, tol, count=9):  # the read-back object (second call) moves by 1 mm
        calls["n"] += 1
        return real(obj, tol, count) + (1.0 if calls["n"] % 2 == 0 else 0.0)

    monkeypatch.setattr(V, "sample_object", shifted)
    with pytest.raises(BackendError, match="deviates"):
        write_iges(model, tmp_path / "bad.igs", verify=True)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.occ
@pytest.mark.parametrize("seed", [0, 2])
def test_opencascade_trimmed_face_edges_with_model_space_preference(tmp_path, seed):
    """With PREF = 2 OpenCASCADE takes the 142's model-space curves (fitted to 1e-10 x size): edges exact."""
    pytest.importorskip("OCP")
    from rgm.backends.iges_occ_check import occ_read_iges

    face = make_object("trimmed", np.random.default_rng(seed), "hand")
    model = Model("mm", 1e-3, {"hand": face}, ("hand",))
    write_iges(model, tmp_path / "t.igs", pcurve_preference="3d")
    occ = occ_read_iges(tmp_path / "t.igs")
    assert occ.fails == [] and occ.roots == occ.transferred == 1
    assert occ.faces[0][1] == 2
    for pts in [f[2] for f in occ.faces] + occ.edges:
        assert _occ_distance_to_model(pts, [face]).max() <= 1e-9 * 30
