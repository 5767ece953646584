"""Curves on surfaces for the IGES back end: the model-space image of a parameter-space curve (S∘B)
and the parameter-space image of a model-space curve, both as B-splines within a tolerance.

An IGES 142 carries both curves; only one of them is exact in the model, so the other is
approximated here, at the file's tolerance. On a plane both maps are affine and the results are
exact (the control points are mapped). Elsewhere the curve is sampled on each knot span of its
source, interpolated by a cubic spline (scipy `make_interp_spline`, not-a-knot) with the source's
parameter as its own, and the samples are doubled until the chordal deviation at the midpoints of
the samples is within the tolerance.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import BackendError
from rgm.geometry import NurbsCurve
from rgm.model import Plane


def _fit_span(func, a: float, b: float, tol: float, max_level: int):
    """(knots, coefficients) of a clamped cubic interpolant of func on [a, b] within tol."""
    from scipy.interpolate import make_interp_spline

    err = np.inf
    for level in range(max_level + 1):
        t = np.linspace(a, b, (4 << level) + 1)
        spl = make_interp_spline(t, func(t), k=3)
        mid = 0.5 * (t[:-1] + t[1:])
        err = float(np.linalg.norm(spl(mid) - func(mid), axis=1).max())
        if err <= tol:
            return spl.t, spl.c
    raise BackendError(f"could not approximate a curve on a surface within {tol:g} (best {err:.3g})")


def fit_parametric(func, breaks, tol: float, max_level: int = 9) -> NurbsCurve:
    """Cubic B-spline interpolant of `func` (params (m,) -> points (m, d)) with the parameter of its
    source: each interval between the sorted `breaks` (k,) (the source's knots and the parameters
    where it crosses the surface's knot lines, where the image may have a kink) is interpolated on
    its own, doubling the samples until within `tol` at their midpoints, and the pieces are joined
    with knots of multiplicity 3 (C0) at the breaks."""
    breaks = np.unique(np.asarray(breaks, dtype=float))
    knots, coef = [], []
    for a, b in zip(breaks[:-1], breaks[1:]):
        t, c = _fit_span(func, a, b, tol, max_level)
        if knots:
            knots[-1] = knots[-1][:-1]
            t, c = t[4:], c[1:]
        knots.append(t)
        coef.append(c)
    return NurbsCurve(3, np.concatenate(knots), np.concatenate(coef), None)


def _crossings(uv: NurbsCurve, surface, count: int = 512) -> np.ndarray:
    """Parameters (k,) where the 2-D curve `uv` crosses an interior knot line of `surface`'s NURBS form
    (located by sampling, then 50 vectorised bisection steps)."""
    nurbs = surface.nurbs()
    lines = [np.unique(nurbs.knots_u[nurbs.degree_u + 1:nurbs.nu]), np.unique(nurbs.knots_v[nurbs.degree_v + 1:nurbs.nv])]
    t = np.linspace(*uv.domain, count)
    p = uv.evaluate(t)
    out = []
    for axis, knots in enumerate(lines):
        if knots.size == 0:
            continue
        span = np.searchsorted(knots, p[:, axis], side="right")
        for i in np.flatnonzero(np.diff(span)):
            lo, hi = t[i], t[i + 1]
            target = knots[min(span[i], span[i + 1])]
            below = p[i, axis] < target
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                if (uv.evaluate([mid])[0, axis] < target) == below:
                    lo = mid
                else:
                    hi = mid
            out.append(0.5 * (lo + hi))
    return np.array(out)


def surface_points(surface, u, v) -> np.ndarray:
    """Points (m, 3) of a model surface at parameters u, v (m,) (plane coordinates for a Plane)."""
    if isinstance(surface, Plane):
        return surface.origin + np.outer(u, surface.x_dir) + np.outer(v, surface.y_dir)
    return surface.nurbs().evaluate(u, v)


def _knot_breaks(curve: NurbsCurve) -> np.ndarray:
    u0, u1 = curve.domain
    k = np.unique(curve.knots)
    return k[(k >= u0) & (k <= u1)]


def model_curve(surface, uv: NurbsCurve, tol: float) -> NurbsCurve:
    """The 3-D curve S(B(t)) of the 2-D curve `uv` on `surface` (exact on a plane)."""
    if isinstance(surface, Plane):
        ctrl = surface_points(surface, uv.ctrl[:, 0], uv.ctrl[:, 1])
        return NurbsCurve(uv.degree, uv.knots, ctrl, uv.weights)

    def func(t):
        p = uv.evaluate(t)
        return surface_points(surface, p[:, 0], p[:, 1])

    return fit_parametric(func, np.concatenate([_knot_breaks(uv), _crossings(uv, surface)]), tol)


def parameter_curve(surface, curve: NurbsCurve, tol: float) -> NurbsCurve:
    """The 2-D image in `surface`'s parameter space of a 3-D `curve` lying on it (exact on a plane)."""
    if isinstance(surface, Plane):
        return NurbsCurve(curve.degree, curve.knots, surface.coordinates(curve.ctrl), curve.weights)
    nurbs = surface.nurbs()
    (u0, u1), (v0, v1) = nurbs.domain
    # parameter tolerance from the surface's extent: a deviation tol in space is about tol/size in (u, v)
    size = float(np.ptp(nurbs.bbox(), axis=0).max()) or 1.0
    scale = max(u1 - u0, v1 - v0)

    def func(t):
        u, v, _pts, _dist = nurbs.closest_point(curve.evaluate(t))
        return np.column_stack([u, v])

    return fit_parametric(func, _knot_breaks(curve), tol * scale / size)
