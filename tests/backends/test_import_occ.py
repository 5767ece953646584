"""`rgmc import` of IGES files written by OpenCASCADE (IGESControl_Writer, Faces mode) from CadQuery
shapes, then `rgmc compile -t iges` and `-t step` of the imported `.rgm`: the files read back (by
OpenCASCADE, and the IGES also by rgm) are the original geometry within 1e-9 x the part's size, in both
directions (points of the original on the result, points of the result on the original)."""
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
        # a through hole: its rims are full circles, one loop each on the plate's faces, and pieces of
        # the hole's loop beside its seam line (OpenCASCADE starts them at the seam)
        "bracket": cq.Workplane().box(40, 20, 5).faces(">Z").workplane().hole(6).edges("|Z").fillet(3).val(),
    }


def _loop_points(model, count: int = 9) -> np.ndarray:
    """rgm's own evaluation of every trimming curve of a model's faces: C(t) for model-space pieces,
    S(B(t)) for parameter-space ones."""
    from rgm.backends.iges_curves import surface_points

    out = []
    for obj in model.exported():
        for face in getattr(obj, "faces", [obj]):
            for piece in (p for loop in face.loops() for p in loop.pieces):
                c = piece.nurbs()
                p = c.evaluate(np.linspace(*c.domain, count))
                out.append(p if c.dim == 3 else surface_points(face.surface, p[:, 0], p[:, 1]))
    return np.concatenate(out)


def _pcurve_gap(shape, count: int = 9) -> float:
    """How far a shape's edges (3-D curves) are from their pcurves on its faces (max over samples)."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve

    from rgm.backends.iges_occ_compare import _edges, _explore, _xyz

    gap = 0.0
    for face in _explore(shape, "face"):
        for edge in _edges(face):
            on, c3 = BRepAdaptor_Curve(edge, face), BRepAdaptor_Curve(edge)
            t = np.linspace(on.FirstParameter(), on.LastParameter(), count)
            gap = max(gap, float(np.linalg.norm(_xyz(on.Value(x) for x in t) - _xyz(c3.Value(x) for x in t),
                                                axis=1).max()))
    return gap


CASES = [(n, t) for n in ("box", "cylinder", "fillet", "loft", "bracket") for t in ("iges", "step")]


@pytest.mark.parametrize("name, target", CASES)
def test_import_compile_and_read_back_gives_the_original_geometry(tmp_path, capsys, name, target):
    from rgm.backends.iges_occ_check import occ_read_iges, occ_write_iges, shape_points
    from rgm.backends.iges_read import read_iges_file
    from rgm.backends.occ import distances_to_shape, faces_of, read_step
    from rgm.cli import main

    original = _shapes()[name]
    bb = original.BoundingBox()
    size = max(bb.xlen, bb.ylen, bb.zlen)
    igs, rgm_file = tmp_path / f"{name}.igs", tmp_path / f"{name}.rgm"
    occ_write_iges([original.wrapped], igs)
    assert main(["import", str(igs), "-o", str(rgm_file)]) == 0
    assert "warning" not in capsys.readouterr().err
    out = tmp_path / f"back.{target}"
    assert main(["compile", str(rgm_file), "-t", target, "-o", str(out)]) == 0, capsys.readouterr().err
    if target == "iges":
        occ = occ_read_iges(out)
        assert occ.fails == [] and occ.roots == occ.transferred
        result = occ.shape
        ours = read_iges_file(out)
        assert ours.ok, ours.messages()
        # the trimming curves in OpenCASCADE's file are its pcurves, which on lofted B-spline faces lie up to
        # 1.8e-8 mm (within its edge tolerance 1e-7) from its own 3-D edges: the original is no tighter
        limit = max(1e-9 * size, _pcurve_gap(original.wrapped))
        assert distances_to_shape(_loop_points(ours.model), original.wrapped).max() <= limit
    else:
        result = read_step(out)
    assert len(faces_of(result)) == len(original.Faces())
    there = distances_to_shape(shape_points(original.wrapped, 5), result).max()
    back = distances_to_shape(shape_points(result, 5), original.wrapped).max()
    assert max(there, back) <= 1e-9 * size, (there, back)


def test_imported_holed_bracket_meshes_watertight(tmp_path):
    """The bracket's faces share their edges in the imported model, full-circle rims included (each
    starts where the hole's seam meets it, on the plate's faces as on the hole's): its mesh is closed,
    and its volume is within tol x area of the exact one (box less hole less four corner fillets)."""
    from rgm.backends.iges_occ_check import occ_write_iges
    from rgm.backends.mesh import signed_volume, tessellate
    from rgm.cli import main
    import rgm

    igs, rgm_file = tmp_path / "bracket.igs", tmp_path / "bracket.rgm"
    occ_write_iges([_shapes()["bracket"].wrapped], igs)
    assert main(["import", str(igs), "-o", str(rgm_file)]) == 0
    tol = 0.05
    v, t = tessellate(rgm.load(rgm_file), tol)
    e = np.sort(t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, uses = np.unique(e[:, 0] * len(v) + e[:, 1], return_counts=True)
    assert (uses == 2).all()
    exact = 40 * 20 * 5 - np.pi * 3 ** 2 * 5 - 4 * (3 ** 2 - np.pi * 3 ** 2 / 4) * 5
    area = 2 * (40 * 20 - np.pi * 9 - 4 * (9 - np.pi * 9 / 4)) + 5 * (2 * (34 + 14) + 2 * np.pi * 3 + 2 * np.pi * 3)
    assert abs(signed_volume(v, t) - exact) <= tol * area
