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


def fit_parametric(func, breaks, tol: float, max_level: int = 8) -> NurbsCurve:
    """Cubic B-spline interpolant of `func` (params (m,) -> points (m, d)) over the sorted `breaks`
    (k,), the knots of the source curve, refined until within `tol` at the sample midpoints."""
    breaks = np.unique(np.asarray(breaks, dtype=float))
    err = np.inf
    for level in range(max_level + 1):
        per = 4 << level
        t = np.unique(np.concatenate([np.linspace(a, b, per + 1) for a, b in zip(breaks[:-1], breaks[1:])]))
        from scipy.interpolate import make_interp_spline

        spl = make_interp_spline(t, func(t), k=3)
        mid = 0.5 * (t[:-1] + t[1:])
        err = float(np.linalg.norm(spl(mid) - func(mid), axis=1).max())
        if err <= tol:
            return NurbsCurve(3, spl.t, spl.c, None)
    raise BackendError(f"could not approximate a curve on a surface within {tol:g} (best {err:.3g})")


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

    return fit_parametric(func, _knot_breaks(uv), tol)


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
