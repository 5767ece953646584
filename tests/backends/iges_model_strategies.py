"""Hypothesis strategies for random models of every entity kind, and a structural model comparison,
shared by the IGES and Alpha_1 round-trip tests.

Kinds: every curve and surface of the model, lazy intersections (a B-spline surface cut by a plane or
by another B-spline surface), trimmed faces whose loops are parameter-space lines, polylines, arcs,
circles and B-splines, or model-space curves on the surface (iso-parameter B-splines of a B-spline
surface, lines, circles and arcs in a plane), with no outer loop or up to three holes, shells, and
any of these moved by a random similarity (rotation, uniform scale, mirror, translation), which the
model holds baked (as the compiler's `translate/rotate/scale/mirror` leave it).
"""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from rgm.geometry import NurbsCurve, NurbsSurface
from rgm.geometry.knots import uniform_knots
from rgm.model import (
    BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, IntersectionCurve, Line, Loop,
    Model, Plane, Polyline, Revolution, RuledSurface, Shell, TrimmedFace,
)

KINDS = ("line", "polyline", "arc", "circle", "bspline", "composite", "bsurface", "plane", "revolution",
         "extrusion", "ruled", "trimmed", "shell", "intersection", "transformed")


def _unit(rng, n=3):
    v = rng.normal(size=n)
    return v / np.linalg.norm(v)


def _bspline(rng, dim=3, rational=None, degree=None):
    p = int(degree or rng.integers(1, 4))
    n = int(rng.integers(p + 1, p + 5))
    ctrl = rng.uniform(-10, 10, (n, dim))
    rational = bool(rng.integers(0, 2)) if rational is None else rational
    w = rng.uniform(0.5, 2.0, n) if rational else None
    return NurbsCurve(p, uniform_knots(p, n), ctrl, w)


def _bsurface(rng):
    pu, pv = (int(rng.integers(1, 4)) for _ in range(2))
    nu, nv = int(rng.integers(pu + 1, pu + 4)), int(rng.integers(pv + 1, pv + 4))
    ctrl = np.zeros((nu, nv, 3))
    ctrl[..., 0] = np.linspace(0, 10, nu)[:, None]
    ctrl[..., 1] = np.linspace(0, 10, nv)[None, :]
    ctrl[..., 2] = rng.uniform(-2, 2, (nu, nv))
    w = rng.uniform(0.5, 2.0, (nu, nv)) if rng.integers(0, 2) else None
    return NurbsSurface(pu, pv, uniform_knots(pu, nu), uniform_knots(pv, nv), ctrl, w)


def _graph(rng, axes, span=(0.0, 10.0)):
    """A gentle biquadratic patch: coordinate axes[2] = 5 +- 1 over axes[0], axes[1] in `span`."""
    ctrl = np.zeros((3, 3, 3))
    ctrl[..., axes[0]] = np.linspace(*span, 3)[:, None]
    ctrl[..., axes[1]] = np.linspace(*span, 3)[None, :]
    ctrl[..., axes[2]] = 5 + rng.uniform(-1, 1, (3, 3))
    w = rng.uniform(0.7, 1.5, (3, 3)) if rng.integers(0, 2) else None
    return BSplineSurface(NurbsSurface(2, 2, uniform_knots(2, 3), uniform_knots(2, 3), ctrl, w))


def intersection(rng, name, tol):
    """A lazy intersection with one branch: a patch z ~ 5 cut by a plane x ~ 5 or a wall patch x ~ 5."""
    a = _graph(rng, (0, 1, 2))
    b = _graph(rng, (1, 2, 0), (-1.0, 11.0)) if rng.integers(0, 2) else \
        Plane([rng.uniform(4, 6), 5, 5], [1.0, *rng.uniform(-0.3, 0.3, 2)])
    return IntersectionCurve(*((a, b) if rng.integers(0, 2) else (b, a)), tol, name=name)


def similarity(rng, scale: bool = True) -> np.ndarray:
    """A random 4x4 similarity: rotation about a random axis, uniform scale (unless not `scale`), a
    mirror half the time, then a translation."""
    k = _unit(rng)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    angle = rng.uniform(0, 2 * np.pi)
    r = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
    m = np.eye(4)
    m[:3, :3] = r * (rng.uniform(0.5, 2.0) if scale else 1.0) @ np.diag([-1.0 if rng.integers(0, 2) else 1.0, 1.0, 1.0])
    m[:3, 3] = rng.uniform(-10, 10, 3)
    return m


# --- trimmed faces --------------------------------------------------------------------------------

def _iso_patch(s: NurbsSurface, a, b, c, d) -> NurbsSurface:
    """The sub-patch [a, b] x [c, d] of `s` (exact splits): its boundary rows are iso-curves of `s`."""
    s = s.split("u", a)[1].split("u", b)[0]
    return s.split("v", c)[1].split("v", d)[0]


def _row(s: NurbsSurface, index, along: str) -> NurbsCurve:
    """Boundary curve of a patch: the control row at `index` in the other direction, as a 3-D NURBS."""
    if along == "u":
        ctrl, w, p, k = s.ctrl[:, index], s.weights[:, index] if s.is_rational else None, s.degree_u, s.knots_u
    else:
        ctrl, w, p, k = s.ctrl[index], s.weights[index] if s.is_rational else None, s.degree_v, s.knots_v
    return NurbsCurve(p, k, ctrl, w)


class _FaceFrame:
    """A trimmed face's surface and how to draw loops on it in parameter space or in model space."""

    def __init__(self, surface):
        self.surface = surface
        self.plane = isinstance(surface, Plane)

    def lift(self, uv):
        """Model-space point of parameter-space points (plane only)."""
        uv = np.asarray(uv, float)
        s = self.surface
        return s.origin + uv[..., :1] * s.x_dir + uv[..., 1:] * s.y_dir

    def rectangle(self, rng, a, b, c, d, space: int) -> Loop:
        """A closed loop around [a, b] x [c, d]: parameter-space pieces (space 2; lines, a polyline, a
        B-spline edge) or model-space pieces (space 3; iso-curves of a B-spline surface, lines in a plane)."""
        corners = [(a, c), (b, c), (b, d), (a, d), (a, c)]
        if space == 3 and not self.plane:
            s = _iso_patch(self.surface.nurbs(), a, b, c, d)
            rows = [_row(s, 0, "u"), _row(s, -1, "v"), _row(s, -1, "u").reverse(), _row(s, 0, "v").reverse()]
            return Loop(tuple(BSplineCurve(r) for r in rows))
        if space == 3:
            return Loop(tuple(Line(self.lift(p), self.lift(q)) for p, q in zip(corners, corners[1:])))
        wiggle = np.column_stack([np.linspace(a, b, 5), c + rng.uniform(-0.04, 0.04, 5) * (d - c)])
        wiggle[[0, -1], 1] = c
        bottom = BSplineCurve(NurbsCurve(3, uniform_knots(3, 5), wiggle,
                                         rng.uniform(0.5, 2, 5) if rng.integers(0, 2) else None))
        return Loop((bottom, Line(corners[1], corners[2]), Polyline(np.array(corners[2:]))))

    def hole(self, rng, centre, r, space: int) -> Loop:
        """A hole of radius ~r around `centre` (2,): a circle, an arc closed by a line, a closed B-spline,
        a triangle, or (space 3) an iso-curve rectangle / a model-space circle or arc in a plane."""
        centre = np.asarray(centre, float)
        style = int(rng.integers(0, 4))
        if space == 3 and not self.plane:
            return self.rectangle(rng, centre[0] - r, centre[0] + r, centre[1] - r, centre[1] + r, 3)
        if space == 3:
            normal = self.surface.normal * (1.0 if rng.integers(0, 2) else -1.0)
            if style < 2:
                return Loop((Circle(self.lift(centre), normal, r),))
            c3 = self.lift(centre)
            s3, e3 = c3 + r * self.surface.x_dir, c3 - r * self.surface.x_dir
            arc = CircularArc(c3, normal, r, s3, e3)
            return Loop((arc, Line(e3, s3)))
        if style == 0:
            return Loop((Circle(centre, [0, 0, float(rng.choice([-1, 1]))], r),))
        if style == 1:
            s, e = centre + [r, 0], centre - [r, 0]
            return Loop((CircularArc(centre, [0, 0, 1], r, s, e), Line(e, s)))
        if style == 2:
            t = np.linspace(0, 2 * np.pi, 7)[:-1]
            ring = centre + r * np.column_stack([np.cos(t), np.sin(t)]) * rng.uniform(0.6, 1.0, (6, 1))
            ring = np.vstack([ring, ring[:1]])
            return Loop((BSplineCurve(NurbsCurve(3, uniform_knots(3, 7), ring, None)),))
        tri = centre + r * np.array([[1.0, 0.0], [-0.5, 0.8], [-0.5, -0.8], [1.0, 0.0]])
        return Loop((Polyline(tri),))


def trimmed(rng, name):
    """A trimmed B-spline surface or plane: an outer loop (or none) and up to three holes, each loop
    wholly in parameter space or wholly in model space."""
    if rng.integers(0, 2):
        frame = _FaceFrame(BSplineSurface(_bsurface(rng), name=f"{name}_surface"))
        u0, u1, v0, v1 = 0.0, 1.0, 0.0, 1.0
    else:
        frame = _FaceFrame(Plane(rng.uniform(-5, 5, 3), _unit(rng), name=f"{name}_plane"))
        u0, u1, v0, v1 = -4.0, 4.0, -4.0, 4.0
    a, b = u0 + 0.1 * (u1 - u0), u0 + 0.9 * (u1 - u0)
    c, d = v0 + 0.1 * (v1 - v0), v0 + 0.9 * (v1 - v0)
    outer = None if rng.integers(0, 5) == 0 else frame.rectangle(rng, a, b, c, d, int(rng.choice([2, 3])))
    count = int(rng.integers(1 if outer is None else 0, 4))
    width = (b - a) / max(count, 1)
    r = 0.3 * min(width, d - c) / 2
    holes = tuple(frame.hole(rng, (a + (i + 0.5) * width, (c + d) / 2), r, int(rng.choice([2, 3])))
                  for i in range(count))
    if outer is not None and rng.integers(0, 2):
        outer = outer.named(f"{name}_outer")
    return TrimmedFace(frame.surface, outer, holes, name=name)


# --- objects and models ---------------------------------------------------------------------------

def make_object(kind: str, rng, name: str, tol: float = 1e-3, bases=KINDS):
    """A random model object of `kind`, bound to `name` (nested pieces get names of their own);
    `tol` is the tolerance of lazy intersections, `bases` the kinds a "transformed" object may have."""
    if kind == "line":
        return Line(rng.uniform(-10, 10, 3), rng.uniform(-10, 10, 3), name=name)
    if kind == "polyline":
        return Polyline(rng.uniform(-10, 10, (int(rng.integers(2, 7)), 3)), name=name)
    if kind in ("arc", "circle"):
        n = _unit(rng) if rng.integers(0, 3) else np.array([0.0, 0.0, float(rng.choice([-1, 1]))])
        c, r = rng.uniform(-5, 5, 3), float(rng.uniform(0.5, 5))
        if kind == "circle":
            return Circle(c, n, r, name=name)
        x = np.cross(n, _unit(rng))
        x /= np.linalg.norm(x)
        y = np.cross(n, x)
        a = float(rng.uniform(0.3, 6.0))
        return CircularArc(c, n, r, c + r * x, c + r * (np.cos(a) * x + np.sin(a) * y), name=name)
    if kind == "bspline":
        return BSplineCurve(_bspline(rng), name=name)
    if kind == "composite":
        b = _bspline(rng)
        line = Line(b.end, b.end + rng.uniform(-3, 3, 3), name=f"{name}_leg")
        return CompositeCurve((BSplineCurve(b), line), name=name)
    if kind == "bsurface":
        return BSplineSurface(_bsurface(rng), name=name)
    if kind == "plane":
        return Plane(rng.uniform(-5, 5, 3), _unit(rng), name=name)
    if kind == "revolution":
        pts = np.column_stack([rng.uniform(1, 5, 4), np.zeros(4), np.sort(rng.uniform(0, 10, 4))])
        profile = Polyline(pts, name=f"{name}_profile") if rng.integers(0, 2) else \
            BSplineCurve(NurbsCurve(3, uniform_knots(3, 4), pts), name=f"{name}_profile")
        start = float(rng.uniform(0, 3))
        end = float(rng.uniform(start + 0.5, 2 * np.pi))
        return Revolution(profile, rng.uniform(-1, 1, 3) * [0, 0, 1], [0, 0, 1], start, end, name=name)
    if kind == "extrusion":
        return Extrusion(BSplineCurve(_bspline(rng)), rng.uniform(-5, 5, 3), name=name)
    if kind == "ruled":
        a = _bspline(rng, degree=2, rational=False)
        b = NurbsCurve(2, a.knots, a.ctrl + rng.uniform(1, 3, 3), None)
        return RuledSurface(BSplineCurve(a), BSplineCurve(b), name=name)
    if kind == "trimmed":
        return trimmed(rng, name)
    if kind == "shell":
        faces = (make_object("bsurface", rng, f"{name}_a"), trimmed(rng, f"{name}_b"))
        return Shell(faces, name=name)
    if kind == "intersection":
        return intersection(rng, name, tol)
    if kind == "transformed":
        base = str(rng.choice([k for k in bases if k != "transformed"]))
        return make_object(base, rng, name, tol).transform(similarity(rng))
    raise ValueError(kind)


@st.composite
def models(draw, kinds=KINDS, units=("mm", "in", "cm", "m")):
    """A Model of 1-4 exported objects of random kinds (seeded numpy generator drawn by hypothesis)."""
    seed = draw(st.integers(0, 2**32 - 1))
    chosen = draw(st.lists(st.sampled_from(kinds), min_size=1, max_size=4))
    tol = float(draw(st.sampled_from([1e-3, 1e-4, 0.01])))
    rng = np.random.default_rng(seed)
    objects = {f"{k}_{i}": make_object(k, rng, f"{k}_{i}", tol, kinds) for i, k in enumerate(chosen)}
    return Model(draw(st.sampled_from(units)), tol, objects, tuple(objects))


# --- structural comparison ------------------------------------------------------------------------

#: kinds IGES has no entity for: written as the 128 of their exact NURBS form, read back as BSplineSurface
LOWERED = (Extrusion, RuledSurface)


def _distance_to(surface, pts) -> np.ndarray:
    if isinstance(surface, Plane):
        return np.abs(surface.signed_distance(pts))
    return surface.nurbs().closest_point(pts)[3]


def assert_same_approximation(a: IntersectionCurve, b, tol: float, where: str):
    """`b` is the file's curve of the lazy intersection `a`: its approximation at `tol` (bit-identical
    NURBS data; in model space, or, as a loop piece read from its pcurve, in an operand's (u, v)) and
    within `tol` of both operand surfaces (65 points measured by rgm's inversion)."""
    assert isinstance(b, BSplineCurve), f"{where}: {type(b).__name__}"
    t = np.linspace(*b.curve.domain, 65)
    if b.dim == 3:
        _same_nurbs_curve(a.nurbs(tol), b.curve, where)
        pts = b.curve.evaluate(t)
    else:
        on = [s for s in (a.a, a.b) if np.array_equal(a.uv_curves(s, tol)[0].ctrl, b.curve.ctrl)]
        assert on, f"{where}: not the approximation in either operand's parameters"
        _same_nurbs_curve(a.uv_curves(on[0], tol)[0], b.curve, where)
        from rgm.backends.iges_curves import surface_points

        uv = b.curve.evaluate(t)
        pts = surface_points(on[0], uv[:, 0], uv[:, 1])
    for s in (a.a, a.b):
        assert _distance_to(s, pts).max() <= tol, f"{where}: off an operand surface"


def _same_lazy_loop(surface, a: Loop, b: Loop, tol: float, where: str, same):
    """A loop whose intersection pieces became their approximation at `tol`: a piece between two curves
    as the loop takes it, its branch's stretch between them (`loop_stretches`, bit-identical NURBS data
    in model space or in the face's (u, v), and on both operands); the other pieces as `assert_same`."""
    from rgm.model.validate import loop_stretches

    assert len(a.pieces) == len(b.pieces), where
    stretches = loop_stretches(a, surface, tol)
    for i, (p, q) in enumerate(zip(a.pieces, b.pieces)):
        if i not in stretches:
            same(p, q, f".pieces[{i}]")
            continue
        assert isinstance(q, BSplineCurve), f"{where}.pieces[{i}]: {type(q).__name__}"
        uv, curve = stretches[i]
        _same_nurbs_curve(curve if q.dim == 3 else uv, q.curve, f"{where}.pieces[{i}]")
        pts = curve.evaluate(np.linspace(*curve.domain, 65))
        for s in (p.a, p.b):
            assert _distance_to(s, pts).max() <= tol, f"{where}.pieces[{i}]: off an operand surface"


def assert_same(a, b, size: float = 100.0, path: str = "", lowered=LOWERED, approximated: float | None = None):
    """Structural equality: kinds and names; NURBS data (degrees, knots, control points, weights) and
    line/polyline points bit-identical; analytic frames (arc centres, axis directions, planes) within
    1e-12 x size (IGES stores them as points, so the last bit can move). With `approximated` (the IGES
    file's tolerance), a lazy intersection must have become its approximation at that tolerance."""
    where = path or getattr(a, "name", "") or type(a).__name__
    same = lambda p, q, sub: assert_same(p, q, size, f"{where}{sub}", lowered, approximated)  # noqa: E731
    if isinstance(a, lowered):
        assert isinstance(b, BSplineSurface), f"{where}: {type(b).__name__}"
        return _same_nurbs_surface(a.nurbs(), b.nurbs(), where)
    if isinstance(a, IntersectionCurve) and approximated is not None:
        return assert_same_approximation(a, b, approximated, where)
    assert type(a) is type(b), f"{where}: {type(a).__name__} became {type(b).__name__}"
    assert getattr(a, "name", None) == getattr(b, "name", None), f"{where}: name {a.name!r} -> {b.name!r}"
    close = dict(rtol=0, atol=1e-12 * size)
    if isinstance(a, Line):
        assert np.array_equal(a.p0, b.p0) and np.array_equal(a.p1, b.p1), where
    elif isinstance(a, Polyline):
        assert np.array_equal(a.points, b.points), where
    elif isinstance(a, (Circle, CircularArc)):
        assert np.allclose(a.center, b.center, **close) and np.allclose(a.normal, b.normal, **close), where
        assert abs(a.radius - b.radius) <= 1e-12 * size, where
        if isinstance(a, CircularArc):
            assert np.allclose(a.start_point, b.start_point, **close), where
            assert np.allclose(a.end_point, b.end_point, **close), where
    elif isinstance(a, BSplineCurve):
        _same_nurbs_curve(a.curve, b.curve, where)
    elif isinstance(a, BSplineSurface):
        _same_nurbs_surface(a.surface, b.surface, where)
    elif isinstance(a, Plane):
        for f in ("origin", "normal", "x_dir"):
            assert np.allclose(getattr(a, f), getattr(b, f), **close), f"{where}.{f}"
    elif isinstance(a, Revolution):
        same(a.profile, b.profile, ".profile")
        assert np.allclose(a.axis_point, b.axis_point, **close), where
        assert np.allclose(a.axis_dir, b.axis_dir, **close), where
        assert abs(a.start - b.start) <= 1e-15 * 8 and abs(a.end - b.end) <= 1e-15 * 8, where
    elif isinstance(a, Extrusion):
        same(a.profile, b.profile, ".profile")
        assert np.array_equal(a.direction, b.direction), where
    elif isinstance(a, (RuledSurface, IntersectionCurve)):
        if isinstance(a, IntersectionCurve):
            assert a.tolerance == b.tolerance, where
        same(a.a, b.a, ".a")
        same(a.b, b.b, ".b")
    elif isinstance(a, (CompositeCurve, Loop)):
        assert len(a.pieces) == len(b.pieces), where
        for i, (p, q) in enumerate(zip(a.pieces, b.pieces)):
            same(p, q, f".pieces[{i}]")
    elif isinstance(a, TrimmedFace):
        same(a.surface, b.surface, ".surface")
        assert (a.outer is None) == (b.outer is None), where
        loops = ([(a.outer, b.outer, ".outer")] if a.outer is not None else []) + \
            [(p, q, f".holes[{i}]") for i, (p, q) in enumerate(zip(a.holes, b.holes))]
        assert len(a.holes) == len(b.holes), where
        for p, q, sub in loops:
            if approximated is None:
                same(p, q, sub)
            else:
                _same_lazy_loop(a.surface, p, q, approximated, f"{where}{sub}",
                                lambda x, y, piece, sub=sub: same(x, y, f"{sub}{piece}"))
    elif isinstance(a, Shell):
        assert len(a.faces) == len(b.faces), where
        for i, (p, q) in enumerate(zip(a.faces, b.faces)):
            same(p, q, f".faces[{i}]")
    else:
        raise AssertionError(f"{where}: no comparison for {type(a).__name__}")


def _same_nurbs_curve(ca, cb, where):
    assert ca.degree == cb.degree and np.array_equal(ca.knots, cb.knots), where
    assert np.array_equal(ca.ctrl, cb.ctrl), where
    assert (ca.weights is None and cb.weights is None) or np.array_equal(ca.weights, cb.weights), where


def _same_nurbs_surface(sa, sb, where):
    assert (sa.degree_u, sa.degree_v) == (sb.degree_u, sb.degree_v), where
    assert np.array_equal(sa.knots_u, sb.knots_u) and np.array_equal(sa.knots_v, sb.knots_v), where
    assert np.array_equal(sa.ctrl, sb.ctrl), where
    assert (sa.weights is None and sb.weights is None) or np.array_equal(sa.weights, sb.weights), where


def assert_same_model(a: Model, b: Model, lowered=LOWERED, approximated: float | None = None):
    """Units, tolerance, exports in order, and every export structurally the same (`assert_same`)."""
    assert a.units == b.units and a.tolerance == b.tolerance
    assert list(a.exports) == list(b.exports)
    for name in a.exports:
        assert_same(a.objects[name], b.objects[name], 100.0, name, lowered, approximated)


# --- the independent reader -----------------------------------------------------------------------

def assert_opencascade_reads(model: Model, path, *, nurbs_only: bool = False, pcurve_preference: str = "auto",
                             limit: float = 1e-9):
    """OpenCASCADE's IGESControl_Reader reads `path` with no fail message and every root transferred,
    one shape per export; every face and edge matches rgm's own evaluation within `limit` x the model's
    size (`rgm.backends.iges_occ_compare.measure`: same parameters where the file keeps them, edges
    against the trimming curves both ways). OCC's 3-D edge curves must match as closely where it takes
    them from the file (no 142, or PREF = 2); where it rebuilds them from the pcurves (PREF = 1 or 3) they
    must lie within the tolerance OCC gives the edge. A revolution arrives as a surface of revolution
    (unless `nurbs_only`), a trimmed face as one face with a wire per loop (plus the natural boundary
    when it has no outer loop), a shell as its faces. Returns the measurements."""
    from rgm.backends.iges_occ_check import occ_read_iges
    from rgm.backends.iges_occ_compare import measure, model_size

    occ = occ_read_iges(path)
    exported = model.exported()
    assert occ.fails == [], occ.fails
    assert occ.roots == occ.transferred == len(occ.shapes) == len(exported), (occ.roots, occ.transferred)
    size = model_size(model)
    measured = measure(model, occ.shapes, pcurve_preference=pcurve_preference)
    for obj, m in zip(exported, measured):
        assert m.worst <= limit * size, m
        faces = obj.faces if isinstance(obj, Shell) else [obj]
        if isinstance(obj, (Shell, TrimmedFace)):
            assert len(m.faces) == len(faces), m
        for face, (kind, wires, edges_3d) in zip(faces, m.faces):
            if isinstance(face, TrimmedFace):
                assert wires == len(face.holes) + 1, (m, face.name)
                model_space = all(p.dim == 3 for loop in face.loops() for p in loop.pieces)
                from_file = pcurve_preference == "3d" or (pcurve_preference == "auto" and model_space)
            else:
                from_file = True
                if isinstance(face, Revolution) and not nurbs_only:
                    assert kind == "SurfaceOfRevolution", m
            assert edges_3d <= (limit * size if from_file else max(limit * size, m.edge_tolerance)), m
    return measured
