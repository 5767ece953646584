"""Curves on surfaces for the IGES back end: the model-space image of a parameter-space curve (S∘B)
and the parameter-space image of a model-space curve, both as B-splines within a tolerance.

An IGES 142 carries both curves; only one of them is exact in the model, so the other is
approximated here, at the file's tolerance. On a plane both maps are affine and the results are
exact (the control points are mapped). Elsewhere the curve is sampled on each knot span of its
source, interpolated by a cubic spline (scipy `make_interp_spline`, not-a-knot) with the parameter
of the source's IGES entity as its own (a 100 arc's is its angle, so arcs are fitted even on a
plane), and the samples are doubled until the chordal deviation at the midpoints of the samples is
within the tolerance. Both curves of a 142 then share one parameter, which receivers that keep both
(OpenCASCADE with PREF = 2) need: otherwise they re-approximate one of them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.errors import BackendError
from rgm.geometry import NurbsCurve
from rgm.model import Circle, CircularArc, Plane, Polyline


#: parameter tolerance (relative to the domain) of the foot points of a curve lying off its surface
_OFF_SURFACE_UV = 1e-8


def fit_parametric(func, breaks, tol: float, continuity=None, max_level: int = 9) -> NurbsCurve:
    """Cubic B-spline interpolant of `func` (params (m,) -> points (m, d)) with the parameter of its
    source, within `tol`. `breaks` (k,) are the source's knots and the parameters where its image may
    lose smoothness, `continuity` (k,) the order of continuity there (default 0): a break that is C0 or
    C1 becomes a knot of multiplicity 3 or 2 (the fit is as smooth as the source, so receivers that
    split curves at C0 knots, OpenCASCADE, split it where they split the source), smoother breaks none.
    Each interval between breaks gets uniform simple knots, the spline interpolates at the Greville
    abscissae, and intervals whose deviation at the midpoints exceeds `tol` get twice the knots."""
    from scipy.interpolate import make_interp_spline

    order = np.argsort(breaks, kind="stable")
    breaks = np.asarray(breaks, dtype=float)[order]
    cont = (np.zeros(len(breaks), int) if continuity is None else np.asarray(continuity, int))[order]
    a, b = breaks[0], breaks[-1]
    eps = 1e-12 * (b - a)   # a crossing found at a knot break is that break
    keep = (breaks - a > eps) & (b - breaks > eps) & (cont < 2)
    inner, joins = breaks[keep], cont[keep]
    if inner.size:  # near-duplicates: one break, the least continuity
        group = np.concatenate([[0], np.cumsum(np.diff(inner) > eps)])
        inner = inner[np.concatenate([[True], np.diff(group) > 0])]
        joins = np.minimum.reduceat(joins, np.flatnonzero(np.concatenate([[True], np.diff(group) > 0])))
    edges = np.concatenate([[a], inner, [b]])
    levels = np.zeros(len(edges) - 1, int)
    while True:
        parts = [np.full(4, a)]
        for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
            parts.append(np.linspace(lo, hi, (4 << levels[i]) + 1)[1:-1])
            parts.append(np.full(3 - joins[i] if i < len(joins) else 4, hi))
        knots = np.concatenate(parts)
        x = np.clip((knots[1:-3] + knots[2:-2] + knots[3:-1]) / 3.0, a, b)   # Greville abscissae
        spl = make_interp_spline(x, func(x), k=3, t=knots)
        mid = 0.5 * (x[:-1] + x[1:])
        err = np.linalg.norm(spl(mid) - func(mid), axis=1)
        bad = np.unique(np.clip(np.searchsorted(edges, mid[err > tol], side="right") - 1, 0, len(levels) - 1))
        if bad.size == 0:
            return NurbsCurve(3, knots, spl.c, None)
        if levels[bad].max() >= max_level:
            raise BackendError(f"could not approximate a curve on a surface within {tol:g} (best {err.max():.3g})")
        levels[bad] += 1


def _crossings(func, domain, surface, count: int = 512):
    """(params (k,), continuity (k,)) where the parameter-space curve `func` (t (m,) -> (m, 2)) crosses an
    interior knot line of `surface`'s NURBS form, and the surface's continuity across that line (located
    by sampling, then 50 bisection steps for all crossings at once)."""
    if isinstance(surface, Plane):
        return np.zeros(0), np.zeros(0, int)
    nurbs = surface.nurbs()
    t = np.linspace(*domain, count)
    p = func(t)
    out, cont = [], []
    for axis, (knots, degree, n) in enumerate(((nurbs.knots_u, nurbs.degree_u, nurbs.nu),
                                               (nurbs.knots_v, nurbs.degree_v, nurbs.nv))):
        lines, mult = np.unique(knots[degree + 1:n], return_counts=True)
        if lines.size == 0:
            continue
        span = np.searchsorted(lines, p[:, axis], side="right")
        i = np.flatnonzero(np.diff(span))
        if i.size == 0:
            continue
        line = np.minimum(span[i], span[i + 1])
        lo, hi, target = t[i], t[i + 1], lines[line]
        below = p[i, axis] < target
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            same = (func(mid)[:, axis] < target) == below
            lo, hi = np.where(same, mid, lo), np.where(same, hi, mid)
        out.append(0.5 * (lo + hi))
        cont.append(degree - mult[line])
    return (np.concatenate(out), np.concatenate(cont)) if out else (np.zeros(0), np.zeros(0, int))


def surface_points(surface, u, v) -> np.ndarray:
    """Points (m, 3) of a model surface at parameters u, v (m,) (plane coordinates for a Plane)."""
    if isinstance(surface, Plane):
        return surface.origin + np.outer(u, surface.x_dir) + np.outer(v, surface.y_dir)
    return surface.nurbs().evaluate(u, v)


def _knot_breaks(curve: NurbsCurve):
    """(distinct knots (k,) in the domain, the curve's continuity there (degree - multiplicity))."""
    u0, u1 = curve.domain
    k, mult = np.unique(curve.knots, return_counts=True)
    inside = (k >= u0) & (k <= u1)
    return k[inside], curve.degree - mult[inside]


@dataclass
class ArcPlacement:
    """How a circle or arc is written as a 100: its parameters (ZT, centre, start, end in the definition
    plane), the 3x4 matrix of the 124 that places the definition space (None: it is model space), and the
    100's own parameter, the counter-clockwise angle `theta` (t0, t1) in the definition plane."""

    params: list
    matrix: np.ndarray | None
    theta: tuple

    def evaluate(self, t) -> np.ndarray:
        """Model-space points (m, 3) at angles t (m,) of the 100's parametrisation."""
        zt, cx, cy, sx, sy = self.params[:5]
        r = float(np.hypot(sx - cx, sy - cy))
        t = np.asarray(t, float)
        local = np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t), np.full(t.shape, zt)])
        return local if self.matrix is None else local @ self.matrix[:, :3].T + self.matrix[:, 3]


def arc_placement(arc) -> ArcPlacement:
    """The 100 (+ 124) of a Circle or CircularArc: arcs with normal +z as they are, normal -z through a
    half-turn about x (coordinates negated exactly), other planes through the arc's frame; circles
    always through a frame at their centre (x = `perpendicular(normal)`), so centre and radius are exact."""
    from rgm.geometry.conics import perpendicular

    n = np.asarray(arc.normal, float)
    c = _as3(arc.center)
    if isinstance(arc, Circle):
        x = perpendicular(n)
        r = arc.radius
        return ArcPlacement([0.0, 0.0, 0.0, r, 0.0, r, 0.0], np.column_stack([x, np.cross(n, x), n, c]),
                            (0.0, 2 * np.pi))
    s, e = _as3(arc.start_point), _as3(arc.end_point)
    if n[2] == 1.0:
        params, matrix = [c[2], c[0], c[1], s[0], s[1], e[0], e[1]], None
    elif n[2] == -1.0:
        params, matrix = [-c[2], c[0], -c[1], s[0], -s[1], e[0], -e[1]], np.column_stack([np.diag([1.0, -1.0, -1.0]),
                                                                                          np.zeros(3)])
    else:
        x, y = arc.frame
        ls, le = (np.array([x @ (p - c), y @ (p - c)]) for p in (s, e))
        params, matrix = [0.0, 0.0, 0.0, *ls, *le], np.column_stack([x, y, n, c])
    t0 = float(np.arctan2(params[4] - params[2], params[3] - params[1]))
    return ArcPlacement(params, matrix, (t0, t0 + arc.sweep))


def _as3(p) -> np.ndarray:
    p = np.asarray(p, float)
    return np.concatenate([p, np.zeros(3 - p.shape[-1])]) if p.shape[-1] < 3 else p


def _nurbs(piece) -> NurbsCurve:
    return piece if isinstance(piece, NurbsCurve) else piece.nurbs()


def parametrisation(piece):
    """(func t (m,) -> points (m, dim), breaks, continuity there) of a curve as its IGES entity is
    parametrised (a 100 arc by its angle, a 106 polyline by its arc length, as OpenCASCADE reads it,
    anything else by its NURBS form), so that a partner curve fitted to it has the parameter a receiver
    sees on the exact curve."""
    if isinstance(piece, (Circle, CircularArc)):
        placement = arc_placement(piece)
        return (lambda t: placement.evaluate(t)[:, :piece.dim]), np.array(placement.theta), np.zeros(2, int)
    if isinstance(piece, Polyline):
        pts = np.asarray(piece.points, float)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        return (lambda t: np.column_stack([np.interp(t, s, x) for x in pts.T])), s, np.zeros(len(s), int)
    curve = _nurbs(piece)
    return (curve.evaluate, *_knot_breaks(curve))


def model_curve(surface, piece, tol: float) -> NurbsCurve:
    """The 3-D curve S(B(t)) of the parameter-space curve `piece` (model object or NurbsCurve) on
    `surface`, with the parameter of B's IGES entity (exact on a plane when B is a NURBS: the control
    points are mapped); C0/C1 where B is or where B crosses a C0/C1 knot line of S."""
    if isinstance(surface, Plane) and not isinstance(piece, (Circle, CircularArc, Polyline)):
        uv = _nurbs(piece)
        return NurbsCurve(uv.degree, uv.knots, surface_points(surface, uv.ctrl[:, 0], uv.ctrl[:, 1]), uv.weights)
    curve, breaks, cont = parametrisation(piece)

    def func(t):
        p = curve(t)
        return surface_points(surface, p[:, 0], p[:, 1])

    crossings, crossing_cont = _crossings(curve, breaks[[0, -1]], surface)
    return fit_parametric(func, np.concatenate([breaks, crossings]), tol, np.concatenate([cont, crossing_cont]))


def parameter_curve(surface, piece, tol: float, near=None) -> NurbsCurve:
    """The 2-D image in `surface`'s parameter space of the model-space curve `piece` (a model object
    written as a NURBS entity, or a NurbsCurve) lying on it, with the same parameter (exact on a plane).
    On a surface closed in u or v (a full revolution, to within `tol`), points on the seam take the side of the curve's
    neighbouring points, or, for a piece along the seam, the side of `near` (the (u, v) where the
    previous loop piece ended), so that the image is continuous and the loop's images join."""
    curve = _nurbs(piece)
    if isinstance(surface, Plane):
        return NurbsCurve(curve.degree, curve.knots, surface.coordinates(curve.ctrl), curve.weights)
    nurbs = surface.nurbs()
    (u0, u1), (v0, v1) = nurbs.domain
    # parameter tolerance from the surface's extent: a deviation tol in space is about tol/size in (u, v)
    size = float(np.ptp(nurbs.bbox(), axis=0).max()) or 1.0
    scale = max(u1 - u0, v1 - v0)
    closed = [np.abs(nurbs.ctrl[0] - nurbs.ctrl[-1]).max() <= tol,        # (to within the fit's tolerance:
              np.abs(nurbs.ctrl[:, 0] - nurbs.ctrl[:, -1]).max() <= tol]   # other writers round 2 pi)

    def func(t):
        u, v, _pts, _dist = nurbs.closest_point(curve.evaluate(t))
        uv = np.column_stack([u, v])
        for axis, (lo, hi) in enumerate(nurbs.domain):
            if closed[axis]:
                uv[:, axis] = _seam_side(uv[:, axis], lo, hi, None if near is None else near[axis])
        return uv

    breaks, cont = _knot_breaks(curve)
    tol_uv = tol * scale / size
    if nurbs.closest_point(curve.evaluate(np.linspace(*curve.domain, 33)))[3].max() > 1e-9 * size:
        # a curve off the surface (a fitted seam curve between two patches): its foot points lose one
        # order of smoothness where they cross a knot line of the surface, which becomes a break, and
        # are found to about 1e-10 of the domain (a closest point off the surface is a flat minimum)
        crossings, crossing_cont = _crossings(func, curve.domain, surface)
        breaks = np.concatenate([breaks, crossings])
        cont = np.concatenate([cont, np.maximum(crossing_cont - 1, 0)])
        tol_uv = max(tol_uv, _OFF_SURFACE_UV * scale)
    return fit_parametric(func, breaks, tol_uv, cont)


def _seam_side(x, lo: float, hi: float, hint) -> np.ndarray:
    """Parameters (m,) along a curve (in order) with the seam values (lo or hi, either is the same point)
    set to the side of the nearest preceding (else following) off-seam sample, or of `hint` when all
    lie on the seam."""
    eps = 1e-9 * (hi - lo)
    seam = (x - lo < eps) | (hi - x < eps)
    if not seam.any():
        return x
    if seam.all():
        return np.full_like(x, hi if hint is not None and abs(hint - hi) < abs(hint - lo) else lo)
    idx = np.arange(len(x))
    before = np.maximum.accumulate(np.where(seam, -1, idx))
    after = np.minimum.accumulate(np.where(seam, len(x), idx)[::-1])[::-1]
    ref = x[np.where(before >= 0, before, after)]
    return np.where(seam, np.where(ref > 0.5 * (lo + hi), hi, lo), x)
