"""Model objects lowered to OpenCASCADE topology: analytic revolutions, B-spline faces, pcurve-trimmed
faces, sewn shells and solids, all valid by BRepCheck_Analyzer; CadQuery objects users can keep editing."""
import numpy as np
import pytest

pytest.importorskip("OCP")
pytestmark = pytest.mark.occ

from rgm.backends import occ  # noqa: E402
from rgm.errors import BackendError  # noqa: E402
from rgm.geometry import NurbsCurve, NurbsSurface  # noqa: E402
from rgm.model import (  # noqa: E402
    BSplineCurve, BSplineSurface, Circle, CircularArc, Line, Loop, Model, Plane, Polyline, Revolution, Shell,
    TrimmedFace,
)


def volume(shape):
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return props.Mass()


def types(shape):
    return [occ.surface_type(f) for f in occ.faces_of(shape)]


Y = ([0, 0, 0], [0, 1, 0])


@pytest.mark.parametrize("profile, expected", [
    (Line([10, 0, 0], [10, 50, 0]), ["Cylinder"]),
    (Line([10, 0, 0], [5, 50, 0]), ["Cone"]),
    (Line([2, 0, 0], [10, 0, 0]), ["Plane"]),
    (CircularArc([0, 0, 0], [0, 0, 1], 10, [0, -10, 0], [0, 10, 0]), ["Sphere"]),
    (BSplineCurve(NurbsCurve(2, [0, 0, 0, 1, 1, 1], [[5, 0, 0], [9, 5, 0], [6, 10, 0]])), ["SurfaceOfRevolution"]),
])
def test_revolution_keeps_analytic_kinds(profile, expected):
    shape = occ.to_shape(Revolution(profile, *Y))
    assert types(shape) == expected
    assert occ.is_valid(shape)


def test_pin_is_a_solid_with_exact_volume():
    pts = np.array([[0, 0, 0], [25.95, 0, 0], [27.15, 1.2, 0], [27.15, 128.68, 0], [25.95, 129.88, 0], [0, 129.88, 0]])
    shape = occ.to_shape(Revolution(Polyline(pts), *Y, name="pin"))
    assert shape.ShapeType().name == "TopAbs_SOLID"
    assert types(shape) == ["Plane", "Cone", "Cylinder", "Cone", "Plane"]
    x0, x1, dy = pts[:-1, 0], pts[1:, 0], np.diff(pts[:, 1])
    exact = abs(np.sum(np.pi * dy * (x0 * x0 + x0 * x1 + x1 * x1) / 3))
    assert volume(shape) == pytest.approx(exact, rel=1e-9)


def test_partial_revolution_has_its_angle_range():
    rev = Revolution(Line([10, 0, 0], [10, 20, 0]), *Y, start=np.pi / 4, end=np.pi)
    face = occ.faces_of(occ.to_shape(rev))[0]
    from OCP.BRepTools import BRepTools

    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    assert u1 - u0 == pytest.approx(3 * np.pi / 4)


def bicubic(seed=0, n=5, rational=False):
    rng = np.random.default_rng(seed)
    k = np.concatenate([np.zeros(4), np.sort(rng.uniform(0.2, 0.8, n - 4)), np.ones(4)])
    g = np.linspace(0, 10, n)
    ctrl = np.stack(list(np.meshgrid(g, g, indexing="ij")) + [rng.uniform(-2, 2, (n, n))], axis=-1)
    return NurbsSurface(3, 3, k, k, ctrl, rng.uniform(0.5, 2, (n, n)) if rational else None)


def test_bspline_face_has_the_same_poles_and_points():
    nurbs = bicubic(1, rational=True)
    face = occ.faces_of(occ.to_shape(BSplineSurface(nurbs)))[0]
    from OCP.BRep import BRep_Tool

    surf = BRep_Tool.Surface_s(face)
    u, v = np.random.default_rng(2).uniform(0, 1, (2, 50))
    ours = nurbs.evaluate(u, v)
    theirs = np.array([[surf.Value(a, b).X(), surf.Value(a, b).Y(), surf.Value(a, b).Z()] for a, b in zip(u, v)])
    assert np.abs(ours - theirs).max() < 1e-12


def test_trimmed_face_with_hole_and_3d_edges():
    nurbs = bicubic(3)
    outer = Loop((Polyline([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.1, 0.1]]),))
    hole = Loop((Circle([0.5, 0.5], [0, 0, -1], 0.2),))
    shape = occ.to_shape(TrimmedFace(BSplineSurface(nurbs), outer, (hole,)))
    assert occ.is_valid(shape)
    assert len(occ._wires_of(shape)) == 2
    # every edge has a 3-D curve (built from its pcurve) and a pcurve on the face
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    face = occ.faces_of(shape)[0]
    exp = TopExp_Explorer(shape, TopAbs_EDGE)
    while exp.More():
        edge = TopoDS.Edge_s(exp.Current())
        assert BRep_Tool.Curve_s(edge, 0.0, 1.0) is not None
        assert BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 1.0) is not None
        exp.Next()


def test_trimmed_plane_has_its_area():
    plane = Plane([0, 0, 0], [0, 0, 1], [1, 0, 0])
    square = TrimmedFace(plane, Loop((Polyline([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0], [0, 0, 0]]),)))
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(occ.to_shape(square), props)
    assert props.Mass() == pytest.approx(12.0, rel=1e-12)


def cut_skin():
    """A bicubic bump with x = 50 u exactly (control x at the Greville abscissae) and its lazy
    intersection with the plane x = 25 (the line u = 0.5 in its parameters)."""
    from rgm.model import IntersectionCurve

    n, p = 8, 3
    k = np.concatenate([np.zeros(p + 1), np.arange(1, n - p) / (n - p), np.ones(p + 1)])
    greville = np.array([k[i + 1:i + p + 1].mean() for i in range(n)])
    x, y = np.meshgrid(50 * greville, 50 * greville, indexing="ij")
    skin = BSplineSurface(NurbsSurface(p, p, k, k, np.stack([x, y, 6 * np.sin(x / 9) * np.cos(y / 13)], axis=-1)))
    cut = IntersectionCurve(skin, Plane([25, 0, 0], [1, 0, 0]), 0.01)
    return skin, cut


def test_intersection_trim_is_cut_by_opencascade_on_the_plane():
    """A bump surface with x = 50 u exactly (control x at the Greville abscissae), trimmed by a loop whose
    one side is the lazy intersection with the plane x = 25: OpenCASCADE's own intersector computes that
    side (no computation by rgm), its edge lies on the plane to the file precision, and the face has the
    area of the half surface u <= 0.5."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_EDGE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    skin, cut = cut_skin()
    loop = Loop((Line([0, 0], [0.5, 0]), cut, Line([0.5, 1], [0, 1]), Line([0, 1], [0, 0])))
    shape = occ.to_shape(TrimmedFace(skin, loop))
    assert cut.computed == ()                      # rgm's marcher never ran: OpenCASCADE cut it

    def area(s):   # adaptive integration to 1e-10 (the default Gauss rule is only good to ~1e-6)
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(s, props, 1e-10)
        return props.Mass()

    half = BRepBuilderAPI_MakeFace(occ.surface_geom(skin), 0.0, 0.5, 0.0, 1.0, occ.PRECISION).Face()
    assert area(shape) == pytest.approx(area(half), rel=1e-7)
    on_plane = 0
    exp = TopExp_Explorer(shape, TopAbs_EDGE)
    while exp.More():
        edge = TopoDS.Edge_s(exp.Current())
        curve, (t0, t1) = BRep_Tool.Curve_s(edge, 0.0, 1.0), BRep_Tool.Range_s(edge)
        xs = np.array([curve.Value(t).X() for t in np.linspace(t0, t1, 50)])
        if np.ptp(xs) < 1e-6:
            on_plane += np.abs(xs - 25).max() <= 1e-6
        exp.Next()
    assert on_plane >= 1


def test_loop_pieces_that_miss_the_intersection_are_a_clear_error():
    skin, cut = cut_skin()
    loop = Loop((Line([0, 0], [0.4, 0]), cut, Line([0.5, 1], [0, 1]), Line([0, 1], [0, 0])))
    with pytest.raises(BackendError, match="must meet"):
        occ.to_shape(TrimmedFace(skin, loop))


def test_shell_of_six_patches_is_sewn_into_a_unit_cube():
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    k = [0, 0, 1, 1]
    faces = [BSplineSurface(NurbsSurface(1, 1, k, k, np.array([[c[a], c[b]], [c[d], c[e]]]))) for a, b, e, d in quads]
    solid = occ.to_shape(Shell(faces))
    assert solid.ShapeType().name == "TopAbs_SOLID"
    assert volume(solid) == pytest.approx(1.0, rel=1e-9)


def test_to_cadquery_objects_can_be_filleted_and_cut():
    import cadquery as cq

    pin = Revolution(Polyline([[0, 0, 0], [10, 0, 0], [10, 40, 0], [0, 40, 0]]), *Y, name="pin")
    model = Model("mm", 0.01, {"pin": pin}, ("pin",))
    solid = occ.to_shape(pin)
    obj = occ.to_cadquery(model)
    assert isinstance(obj, cq.Shape) and obj.isValid()
    rounded = obj.fillet(1.0, obj.Edges())
    assert rounded.isValid() and rounded.Volume() < obj.Volume()
    cut = obj.cut(cq.Solid.makeBox(5, 5, 5, cq.Vector(-2.5, 10, 8)))
    assert cut.isValid() and cut.Volume() < volume(solid)


def test_unlowerable_objects_are_clear_errors():
    with pytest.raises(BackendError, match="infinite plane"):
        occ.to_shape(Plane([0, 0, 0], [0, 0, 1]))
    with pytest.raises(BackendError, match="parameter-space"):
        occ.to_shape(Line([0, 0], [1, 1]))


def test_loop_joins_off_by_round_off_are_made_exact_and_real_gaps_are_left():
    """`_snapped_joins`: pcurve pieces whose joins miss by round-off (a projected 3-D piece meets its
    neighbours to about 1e-9 in (u, v), over the wire's precision on a part a few hundred mm across)
    are made to meet exactly, a B-spline's end pole or a segment moved; a gap of 1e-3 is not hidden."""
    from OCP.GCE2d import GCE2d_MakeSegment
    from OCP.Geom2d import Geom2d_BSplineCurve
    from OCP.gp import gp_Pnt2d

    from rgm.backends.occ import _geom2d_pieces, _snapped_joins

    def segment(a, b):
        c = GCE2d_MakeSegment(gp_Pnt2d(*a), gp_Pnt2d(*b)).Value()
        return c, c.FirstParameter(), c.LastParameter()

    arc = _geom2d_pieces(BSplineCurve(NurbsCurve(3, [0, 0, 0, 0, 1, 1, 1, 1],
                                                 [[1, 0], [1.2, 0.4], [0.8, 0.8], [1, 1 + 3e-9]])))
    assert isinstance(arc[0][0], Geom2d_BSplineCurve)
    loop = [segment((0, 0), (1, 0)), *arc, segment((1, 1), (0, 1)), segment((0, 1), (0, 2e-9))]
    out = _snapped_joins(loop)
    for (c, _, t1), (d, t0, _) in zip(out, out[1:] + out[:1]):
        assert c.Value(t1).Distance(d.Value(t0)) == 0.0
    apart = [segment((0, 0), (1, 0)), segment((1, 1e-3), (0, 1)), segment((0, 1), (0, 0))]
    out = _snapped_joins(apart)
    assert out[0][0].Value(out[0][2]).Distance(out[1][0].Value(out[1][1])) == pytest.approx(1e-3)
