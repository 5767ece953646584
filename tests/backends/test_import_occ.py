"""`rgmc import` of IGES files written by OpenCASCADE (IGESControl_Writer, Faces mode) from CadQuery
shapes: the .rgm text compiles back to the same geometry within 1e-9 x the part's size."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("cadquery")
pytestmark = pytest.mark.occ


def _shapes():
    import cadquery as cq

    return {
        "box": cq.Workplane().box(10, 20, 30).val(),
        "cylinder": cq.Workplane().cylinder(20, 5).val(),
        "fillet": cq.Workplane().box(10, 10, 10).edges("|Z").fillet(2).val(),
        "loft": cq.Workplane().circle(5).workplane(offset=10).rect(6, 6).loft().val(),
    }


def _surfaces(model):
    out = []
    for obj in model.exported():
        for f in getattr(obj, "faces", [obj]):
            out.append(getattr(f, "surface", f))
    return out


def _distance(points, surfaces):
    from rgm.model import Plane

    best = np.full(len(points), np.inf)
    for s in surfaces:
        d = np.abs(s.signed_distance(points)) if isinstance(s, Plane) else s.nurbs().closest_point(points)[3]
        best = np.minimum(best, d)
    return best


def _loop_curves(model, size):
    """3-D NurbsCurves of every loop piece (parameter-space pieces mapped through their surface)."""
    from rgm.backends.iges_curves import model_curve

    out = []
    for obj in model.exported():
        for f in getattr(obj, "faces", [obj]):
            for loop in f.loops():
                for p in loop.pieces:
                    for q in getattr(p, "pieces", [p]):
                        c = q.nurbs()
                        out.append(c if c.dim == 3 else model_curve(f.surface, c, 1e-11 * size))
    return out


@pytest.mark.parametrize("name", ["box", "cylinder", "fillet", "loft"])
def test_import_of_opencascade_iges_compiles_to_the_same_geometry(tmp_path, capsys, name):
    import rgm
    from rgm.backends.iges_occ_check import occ_write_iges, sample_shape
    from rgm.cli import main

    shape = _shapes()[name]
    igs = tmp_path / f"{name}.igs"
    occ_write_iges([shape.wrapped], igs)
    out = tmp_path / f"{name}.rgm"
    assert main(["import", str(igs), "-o", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err
    model = rgm.load(out)
    occ_faces, occ_edges = sample_shape(shape.wrapped, 6)  # the original shape, not a read-back
    bb = shape.BoundingBox()
    size = max(bb.xlen, bb.ylen, bb.zlen)
    faces = shape.Faces()
    assert len(occ_faces) == len(faces) == sum(len(getattr(o, "faces", [o])) for o in model.exported())
    surfaces = _surfaces(model)
    for kind, _wires, pts, _uv in occ_faces:
        assert _distance(pts, surfaces).max() <= 1e-9 * size, kind
    curves = _loop_curves(model, size)
    for pts in occ_edges:
        d = np.min([c.closest_point(pts)[2] for c in curves], axis=0)
        assert d.max() <= 1e-9 * size
