"""Hypothesis strategies for random models of every entity kind, and a structural model comparison,
shared by the IGES and Alpha_1 round-trip tests."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from rgm.geometry import NurbsCurve, NurbsSurface
from rgm.geometry.knots import uniform_knots
from rgm.model import (
    IntersectionCurve, BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, Line, Loop, Model, Plane,
    Polyline, Revolution, RuledSurface, Shell, TrimmedFace,
)

KINDS = ("line", "polyline", "arc", "circle", "bspline", "composite", "bsurface", "plane", "revolution",
         "extrusion", "ruled", "trimmed", "shell")


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


def make_object(kind: str, rng, name: str):
    """A random model object of `kind`, bound to `name` (nested pieces get names of their own)."""
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
        surface = BSplineSurface(_bsurface(rng), name=f"{name}_surface") if rng.integers(0, 2) else \
            Plane(rng.uniform(-5, 5, 3), _unit(rng), name=f"{name}_plane")
        (u0, u1), (v0, v1) = ((0.0, 1.0), (0.0, 1.0)) if not isinstance(surface, Plane) else ((-4, 4), (-4, 4))
        a, b = u0 + 0.1 * (u1 - u0), u0 + 0.9 * (u1 - u0)
        c, d = v0 + 0.1 * (v1 - v0), v0 + 0.9 * (v1 - v0)
        corners = [(a, c), (b, c), (b, d), (a, d), (a, c)]
        outer = Loop(tuple(Line(p, q) for p, q in zip(corners, corners[1:])), name=f"{name}_outer")
        mid = np.array([(a + b) / 2, (c + d) / 2])
        r = 0.2 * (b - a)
        hole = Loop((Circle(mid, [0, 0, -1], r),))
        arc_hole = Loop((CircularArc(mid + [0, (d - c) / 4], [0, 0, 1], r / 2, mid + [r / 2, (d - c) / 4],
                                     mid + [-r / 2, (d - c) / 4]),
                         Line(mid + [-r / 2, (d - c) / 4], mid + [r / 2, (d - c) / 4])))
        return TrimmedFace(surface, outer, (hole,) if rng.integers(0, 2) else (arc_hole,), name=name)
    if kind == "shell":
        faces = (make_object("bsurface", rng, f"{name}_a"), make_object("trimmed", rng, f"{name}_b"))
        return Shell(faces, name=name)
    raise ValueError(kind)


@st.composite
def models(draw, kinds=KINDS, units=("mm", "in", "cm", "m")):
    """A Model of 1-4 exported objects of random kinds (seeded numpy generator drawn by hypothesis)."""
    seed = draw(st.integers(0, 2**32 - 1))
    chosen = draw(st.lists(st.sampled_from(kinds), min_size=1, max_size=4))
    rng = np.random.default_rng(seed)
    objects = {f"{k}_{i}": make_object(k, rng, f"{k}_{i}") for i, k in enumerate(chosen)}
    return Model(draw(st.sampled_from(units)), float(draw(st.sampled_from([1e-3, 1e-4, 0.01]))), objects,
                 tuple(objects))


#: kinds IGES has no entity for: written as the 128 of their exact NURBS form, read back as BSplineSurface
LOWERED = (Extrusion, RuledSurface)


def assert_same(a, b, size: float = 100.0, path: str = "", lowered=LOWERED):
    """Structural equality: kinds and names; NURBS data (degrees, knots, control points, weights) and
    line/polyline points bit-identical; analytic frames (arc centres, axis directions, planes) within
    1e-12 x size (IGES stores them as points, so the last bit can move)."""
    where = path or getattr(a, "name", "") or type(a).__name__
    if isinstance(a, lowered):
        assert isinstance(b, BSplineSurface), f"{where}: {type(b).__name__}"
        return _same_nurbs_surface(a.nurbs(), b.nurbs(), where)
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
        ca, cb = a.curve, b.curve
        assert ca.degree == cb.degree and np.array_equal(ca.knots, cb.knots), where
        assert np.array_equal(ca.ctrl, cb.ctrl), where
        assert (ca.weights is None and cb.weights is None) or np.array_equal(ca.weights, cb.weights), where
    elif isinstance(a, CompositeCurve):
        assert len(a.pieces) == len(b.pieces), where
        for i, (p, q) in enumerate(zip(a.pieces, b.pieces)):
            assert_same(p, q, size, f"{where}.pieces[{i}]", lowered)
    elif isinstance(a, BSplineSurface):
        _same_nurbs_surface(a.surface, b.surface, where)
    elif isinstance(a, Plane):
        for f in ("origin", "normal", "x_dir"):
            assert np.allclose(getattr(a, f), getattr(b, f), **close), f"{where}.{f}"
    elif isinstance(a, Revolution):
        assert_same(a.profile, b.profile, size, f"{where}.profile", lowered)
        assert np.allclose(a.axis_point, b.axis_point, **close), where
        assert np.allclose(a.axis_dir, b.axis_dir, **close), where
        assert abs(a.start - b.start) <= 1e-15 * 8 and abs(a.end - b.end) <= 1e-15 * 8, where
    elif isinstance(a, Extrusion):
        assert_same(a.profile, b.profile, size, f"{where}.profile", lowered)
        assert np.array_equal(a.direction, b.direction), where
    elif isinstance(a, RuledSurface):
        assert_same(a.a, b.a, size, f"{where}.a", lowered)
        assert_same(a.b, b.b, size, f"{where}.b", lowered)
    elif isinstance(a, IntersectionCurve):
        assert a.tolerance == b.tolerance, where
        assert_same(a.a, b.a, size, f"{where}.a", lowered)
        assert_same(a.b, b.b, size, f"{where}.b", lowered)
    elif isinstance(a, Loop):
        assert len(a.pieces) == len(b.pieces), where
        for i, (p, q) in enumerate(zip(a.pieces, b.pieces)):
            assert_same(p, q, size, f"{where}.pieces[{i}]", lowered)
    elif isinstance(a, TrimmedFace):
        assert_same(a.surface, b.surface, size, f"{where}.surface", lowered)
        assert (a.outer is None) == (b.outer is None), where
        if a.outer is not None:
            assert_same(a.outer, b.outer, size, f"{where}.outer", lowered)
        assert len(a.holes) == len(b.holes), where
        for i, (p, q) in enumerate(zip(a.holes, b.holes)):
            assert_same(p, q, size, f"{where}.holes[{i}]", lowered)
    elif isinstance(a, Shell):
        assert len(a.faces) == len(b.faces), where
        for i, (p, q) in enumerate(zip(a.faces, b.faces)):
            assert_same(p, q, size, f"{where}.faces[{i}]", lowered)
    else:
        raise AssertionError(f"{where}: no comparison for {type(a).__name__}")


def _same_nurbs_surface(sa, sb, where):
    assert (sa.degree_u, sa.degree_v) == (sb.degree_u, sb.degree_v), where
    assert np.array_equal(sa.knots_u, sb.knots_u) and np.array_equal(sa.knots_v, sb.knots_v), where
    assert np.array_equal(sa.ctrl, sb.ctrl), where
    assert (sa.weights is None and sb.weights is None) or np.array_equal(sa.weights, sb.weights), where


def assert_same_model(a: Model, b: Model, lowered=LOWERED):
    assert a.units == b.units and a.tolerance == b.tolerance
    assert list(a.exports) == list(b.exports)
    for name in a.exports:
        assert_same(a.objects[name], b.objects[name], 100.0, name, lowered)
