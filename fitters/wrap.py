"""A full wrap as one surface closed round its axis, cut into two faces that share their seams exactly.

A patch whose points go all the way round a cylinder-like base (`rgm.fitters.patch_base.base_parameters`: no
gap in its angle) is no clamped surface over that angle: the two ends of its parameter range are the same
points. Fitted as two halves apart, the halves meet only as nearly as their extrapolations happen to (YCB
mustard bottle, views with seed 3: 2.82 mm at a 1 mm tolerance), tangentially, where no intersection
can share their edge. Here the wrap is fitted once, u its angle over 2 pi and v its height, the control net
closed C1 across u = 0 / u = 1 (`rgm.fitters.freeform.closure_u`, an exact linear constraint in the least
squares, kept by every knot insertion), refined to the tolerance as any patch (`fit_surface`). It is then
cut into two faces at u = 0 and u = 1/2: each is the closed surface from a margin before one seam to a
margin past the other (`arc`, by knot insertion: the same surface, not an approximation), trimmed to its
half of the data with its two seams as straight iso-parameter pieces of its loop
(`rgm.fitters.trimloops.fit_trim_loops`, `band`). Along a seam both faces' edges are the same 3-D curve (to
round-off), and each surface runs on past the seam as its neighbour does, so G0 holds by construction
and the measured gap (`rgm.fitters.patches.g0_gaps`) is round-off. The margin is the patches' usual reach
past their data (5 point spacings), so a neighbour's intersection with either face runs past the seam.
"""
from __future__ import annotations

import time

import numpy as np

from rgm.errors import GeometryError
from rgm.fitters.freeform import SurfaceFit, fit_stats, statistic_value
from rgm.fitters.patch_base import reach_margins
from rgm.geometry.knots import rescale_knots, split_knots

__all__ = ["arc", "fit_wrap", "seam_margin"]

_TRIES = 3   # fits of the closed surface, each aiming 15 % lower, until both halves meet the tolerance


def _piece(knots, pw, p, a, b):
    """The part of a clamped curve (knots, pw (n, k)) over [a, b] within its domain [0, 1]."""
    if a > knots[p]:
        knots, pw = split_knots(knots, p, pw, a)[1]
    if b < knots[-1]:
        knots, pw = split_knots(knots, p, pw, b)[0]
    return knots, pw


def arc(knots_u, ctrl, degree_u: int, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """The surface of a net closed across u = 0 / u = 1 (`ctrl` (nu, nv, 3) on the clamped `knots_u` of
    [0, 1], P_0 = P_{nu-1}) from u = a to u = b going forwards, 0 <= a < 1, a < b < a + 1 (b past 1 wraps
    round through u = 0), as a clamped net on [0, 1]: (knots (m + p + 1,), ctrl (m, nv, 3)). Cut by knot
    insertion, so the same surface; where it passes u = 0 the two pieces join at their common control
    column, a knot of multiplicity p (the closure makes the join C1 all the same)."""
    p, (nu, nv) = degree_u, ctrl.shape[:2]
    pw = ctrl.reshape(nu, -1)
    if b <= 1.0:
        knots, pw = _piece(knots_u, pw, p, a, b)
    else:
        k1, c1 = _piece(knots_u, pw, p, a, 1.0)
        k2, c2 = _piece(knots_u, pw, p, 0.0, b - 1.0)
        knots, pw = np.r_[k1[:-1], k2[p + 1:] + 1.0], np.r_[c1[:-1], c2]
    return rescale_knots(knots, p, 0.0, 1.0), pw.reshape(-1, nv, 3)


def seam_margin(points, u, v, reach: float) -> float:
    """How far past each seam a face of the wrap reaches, as a share of the turn: `reach` (model units)
    over the speed along u (`rgm.fitters.patch_base.reach_margins`), within [0.001, 0.1]."""

    return float(np.clip(reach_margins(points, u, v, reach)[0], 1e-3, 0.1)) if reach > 0 else 1e-3


def fit_wrap(points, u, v, tol: float, *, statistic: str = "p95", max_ctrl: int = 4000, reach: float = 0.0,
             anchors=None, sides=None):
    """The two faces of a full wrap of `points` (n, 3) at parameters u (its angle over 2 pi, in [0, 1))
    and v (its height, in [0, 1]): [(data indices (k,), FreeformShape, seconds, (s, t) its data's
    parameters)], one per half (u < 1/2, u >= 1/2), both from one closed surface (module docstring) that
    reaches `reach` (model units) past the data along v and past each seam. Each face's certificate is
    its half's residuals. `anchors` (`rgm.fitters.freeform.Anchors` at the closed surface's parameters:
    u, and v as its faces have it, past the margin): points the closed surface is pulled through.
    `sides` (n,): labels of points on each of which the statistic must hold on its own (`fit_surface`).
    Raises GeometryError when a half misses `tol` (`statistic`)."""
    from rgm.fitters.freeform_part import fit_freeform
    from rgm.fitters.freeform_surface import fit_surface

    t0 = time.perf_counter()
    points, u, v = np.asarray(points, float), np.asarray(u, float), np.asarray(v, float)
    margin = reach_margins(points, u, v, reach)[1] if reach > 0 else 0.0
    delta = seam_margin(points, u, v, reach)     # past each seam, as a share of the full turn
    v = margin + (1 - 2 * margin) * v
    halves, target = [], tol
    for _ in range(_TRIES):   # the certificate is the whole wrap's: a half may miss it, then aim lower
        fit = fit_surface(points, target, params=(u, v), statistic=statistic, max_ctrl=max_ctrl, closed_u=True,
                          anchors=anchors, sides=sides)
        halves = [_half(fit, u, start, delta, tol, statistic) for start in (0.0, 0.5)]
        missed = [(start, h) for start, h in zip((0.0, 0.5), halves) if not h[1].stats.holds]
        if not missed or fit.stopped:
            break
        target *= 0.85
    if missed:
        start, (own, _) = missed[0]
        raise GeometryError(f"its closed surface misses the tolerance on the half from {360 * start:.0f} degrees "
                            f"({statistic} {statistic_value(fit.residuals[own], statistic):.3g} over {tol:g}"
                            + (f"; {fit.stopped})" if fit.stopped else ")"))
    seconds = (time.perf_counter() - t0) / 2
    width = 0.5 + 2 * delta
    band = (delta / width, (0.5 + delta) / width)    # the two seams in a face's own u
    faces = []
    for start, (own, half) in zip((0.0, 0.5), halves):
        s = np.mod(u - start + delta, 1.0) / width      # every point's u in this face's parameters
        past = np.setdiff1d(np.flatnonzero(s <= 1.0), own)   # the other half's data within the margin
        params = (s[own], v[own])
        t1 = time.perf_counter()
        shape = fit_freeform(points[own], tol, statistic=statistic, cuts=False, params=params, surface=half,
                             band=band, cover=np.c_[s[past], v[past]])
        faces.append((own, shape, seconds + time.perf_counter() - t1, params))
    return faces


def _half(fit, u, start: float, delta: float, tol: float, statistic: str):
    """(data indices, SurfaceFit) of the face of the closed `fit` over the half from u = start, reaching
    `delta` past both seams; its certificate is its own data's residuals."""
    own = np.flatnonzero((u >= start) & (u < start + 0.5))
    a = (start - delta) % 1.0
    ku, ctrl = arc(fit.knots_u, fit.ctrl, fit.degree_u, a, a + 0.5 + 2 * delta)
    res = fit.residuals[own]
    stats = fit_stats(res, tol, statistic)
    return own, SurfaceFit(fit.degree_u, fit.degree_v, ku, fit.knots_v, ctrl, stats, res, fit.history,
                           "" if stats.holds else fit.stopped)
