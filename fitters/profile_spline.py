"""B-spline stretches of planar profiles, refined by knot insertion to a tolerance (the paper's Figure 6).

Where no line or circular arc explains a stretch of a meridian profile (a vase's bulge, say), the stretch
becomes a cubic B-spline from the end of the piece before it to the start of the piece after it:

1. Start with one Bezier span (4 control points: few knots, as in Figure 6, left).
2. Solve for the control points by weighted linear least squares with the end conditions as linear
   constraints: the end points are the neighbouring pieces' ends (G0), and where the part is smooth the
   second (last but one) control point lies on the neighbour's tangent (G1: P1 = P0 + alpha t0, alpha
   the only unknown of that end).  A small second-difference term (relative weight `smoothing`) keeps
   spans with little data well posed (Piegl & Tiller §9.4 for the least-squares set-up).
3. Correct the parameters by projecting every point onto the current curve (closest point: nearest of a
   dense sample, then Newton steps on (C(t) - q) . C'(t) = 0; Hoschek's intrinsic parameterisation), so
   that the residuals are Euclidean distances, the figure the certificate measures.  Two rounds per knot
   vector.
4. Per knot span, the certificate's statistic (max, p99 or p95) of the distances of the span's inliers
   (points within max(3 thr, 3 robust sigmas) of the curve; the rest are outliers and given weight 0).
   A knot is inserted at the middle of every span whose statistic exceeds the tolerance (Figure 6,
   right), or whose error is systematic beyond a quarter of it (the mean signed distance over a half
   span above max(tol / 4, 4 sigma / sqrt(count))): a curve whose noise-free error eats most of the
   tolerance is a poor model even where noise is low.  Then back to 2, until no span needs a knot.

Never chasing noise: a span is not split when the median of its distances is within 25 % of what noise
alone gives (0.6745 sigma; sigma estimated from differences of consecutive residuals along the curve,
which cancel any smooth systematic error: 1.4826 median |diff| / sqrt 2, `noise_sigma`), so neither
noise nor the few outliers left by filtering drive refinement; nor when it holds fewer than 4 (degree + 1)
points; the number of control points is capped (`max_ctrl`).  All lengths are in model units (mm).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline
from scipy.spatial import cKDTree

from rgm.errors import GeometryError

__all__ = ["SplineStretch", "fit_spline_stretch", "spline_closest", "noise_sigma"]

DEGREE = 3
_QUANTILE = {"max": 1.0, "p99": 0.99, "p95": 0.95}


@dataclass(frozen=True)
class SplineStretch:
    """ctrl (n, 2) control points, knots (n + 4,) clamped on [0, 1]; history: (control points, worst span
    statistic) after each knot vector (Figure 6's refinement); stopped: why refinement ended."""

    ctrl: np.ndarray
    knots: np.ndarray
    history: tuple
    stopped: str


def noise_sigma(*sequences) -> float:
    """Noise sigma (model units) of residuals (m,) ordered along a curve, pooled over the sequences given:
    1.4826 median |consecutive difference| / sqrt 2 (smooth systematic errors cancel in the differences)."""
    d = np.concatenate([np.diff(np.asarray(s, float)) for s in sequences])
    return float(1.4826 * np.median(np.abs(d)) / np.sqrt(2.0)) if len(d) else 0.0


def spline_closest(ctrl, knots, q, *, newton: int = 4):
    """Closest points of q (m, 2) on the B-spline (ctrl (n, 2), knots (n + degree + 1,)): returns (t (m,) in the knot
    domain, signed distance (m,) in model units, positive on the left of the direction of travel).
    Nearest of 24 samples a span, then Newton steps on f(t) = (C(t) - q) . C'(t), t kept in the domain
    (points beyond an end get the end point)."""
    degree = len(knots) - len(ctrl) - 1
    spline = BSpline(knots, ctrl, degree)
    d1, d2 = spline.derivative(1), spline.derivative(2)
    breaks = np.unique(knots)
    s = np.unique((breaks[:-1, None] + np.diff(breaks)[:, None] * np.linspace(0, 1, 25)[None]).ravel())
    _, nearest = cKDTree(spline(s)).query(q)
    t = s[nearest]
    lo, hi = knots[degree], knots[-degree - 1]
    for _ in range(newton):
        c, c1, c2 = spline(t) - q, d1(t), d2(t)
        f, df = np.sum(c * c1, axis=1), np.sum(c1 * c1, axis=1) + np.sum(c * c2, axis=1)
        t = np.clip(t - np.where(df > 1e-300, f / np.where(df > 1e-300, df, 1.0), 0.0), lo, hi)
    v, tangent = q - spline(t), d1(t)
    side = np.sign(tangent[:, 0] * v[:, 1] - tangent[:, 1] * v[:, 0])
    return t, np.where(side == 0, 1.0, side) * np.linalg.norm(v, axis=1)


def _constraint_map(n, start, end, t0, t1):
    """vec(P) = c + M x for control points P (n, 2) flattened row-major: the end points fixed, the
    second and last-but-one points on the end tangents (G1, one unknown each) when t0 / t1 are given,
    free otherwise; the interior points free."""
    cols, fixed = [], np.zeros(2 * n)
    fixed[:2], fixed[-2:] = start, end

    def free(i):
        for k in range(2):
            col = np.zeros(2 * n)
            col[2 * i + k] = 1.0
            cols.append(col)

    for i in range(1, n - 1):
        if i == 1 and t0 is not None:
            col = np.zeros(2 * n)
            fixed[2:4], col[2:4] = start, t0
            cols.append(col)
        elif i == n - 2 and t1 is not None:
            col = np.zeros(2 * n)
            fixed[2 * i:2 * i + 2], col[2 * i:2 * i + 2] = end, -t1
            cols.append(col)
        else:
            free(i)
    return fixed, np.column_stack(cols)


def _solve(t, q, w, knots, start, end, t0, t1, smoothing):
    n = len(knots) - DEGREE - 1
    b = BSpline.design_matrix(t, knots, DEGREE).tocsr()
    bw = b.multiply(w[:, None]).tocsr()
    g = (b.T @ bw).toarray()
    h = bw.T @ q
    dd = np.diff(np.eye(n), 2, axis=0)
    g = g + smoothing * (np.trace(g) / n) * (dd.T @ dd)
    fixed, m = _constraint_map(n, start, end, t0, t1)
    big = np.kron(g, np.eye(2))
    lhs = m.T @ big @ m
    rhs = m.T @ ((h - g @ fixed.reshape(n, 2)).ravel())
    x = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    return (fixed + m @ x).reshape(n, 2)


def _span_stats(t, signed, inl, breaks, quantile):
    """Per span (len(breaks) - 1,) of the inliers: the quantile and the median of their distances, their
    count, and the larger |mean signed distance| of the span's two halves with its half's count."""
    k = len(breaks) - 1
    span = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, k - 1)[inl]
    half = 2 * span + (t[inl] > 0.5 * (breaks[span] + breaks[span + 1]))
    s = signed[inl]
    order = np.lexsort((np.abs(s), span))
    idx, d = span[order], np.abs(s)[order]
    count = np.bincount(idx, minlength=k)
    first = np.r_[0, np.cumsum(count)[:-1]]
    last = max(len(d) - 1, 0)
    pick = np.minimum(first + np.floor(quantile * np.maximum(count - 1, 0) + 0.5).astype(int), last)
    stat = np.where(count > 0, d[pick] if len(d) else 0.0, 0.0)
    median = np.where(count > 0, d[np.minimum(first + (count - 1) // 2, last)] if len(d) else 0.0, 0.0)
    hc = np.bincount(half, minlength=2 * k).reshape(k, 2)
    hmean = np.abs(np.bincount(half, s, minlength=2 * k).reshape(k, 2)) / np.maximum(hc, 1)
    worst = np.argmax(hmean, axis=1)
    return stat, median, count, hmean[np.arange(k), worst], hc[np.arange(k), worst]


def fit_spline_stretch(q, start, end, *, tol: float, thr: float, statistic: str = "p95", t0=None, t1=None,
                       max_ctrl: int = 40, smoothing: float = 1e-6) -> SplineStretch:
    """Cubic B-spline from `start` to `end` ((2,) each) through the noisy stretch points q (m, 2) (module
    docstring).  t0, t1: unit tangents (2,) at the start and end, in the direction of travel, for G1 ends
    (None: G0).  tol: the bound on the certificate's `statistic` ("max", "p99", "p95") per span; thr:
    the profile's inlier distance (about 3 noise sigmas).  Returns the spline and its refinement history.
    """
    q = np.asarray(q, float)
    start, end = np.asarray(start, float), np.asarray(end, float)
    chord = end - start
    if len(q) < 4 * (DEGREE + 1) or chord @ chord <= 0:
        raise GeometryError(f"a spline stretch needs at least {4 * (DEGREE + 1)} points and distinct ends")
    quantile = _QUANTILE[statistic]
    t = np.clip((q - start) @ chord / (chord @ chord), 0.0, 1.0)
    knots = np.r_[np.zeros(DEGREE + 1), np.ones(DEGREE + 1)]
    w = np.ones(len(q))
    history = []
    while True:
        for _ in range(2):
            ctrl = _solve(t, q, w, knots, start, end, t0, t1, smoothing)
            t, signed = spline_closest(ctrl, knots, q)
            dist = np.abs(signed)
            trim = max(3.0 * thr, 3.0 * 1.4826 * np.median(dist))
            w = (dist <= trim).astype(float)
        inl = w > 0
        along = np.argsort(t)
        sigma = noise_sigma(signed[along][inl[along]])
        breaks = np.unique(knots)
        stat, median, count, bias, bias_count = _span_stats(t, signed, inl, breaks, quantile)
        history.append((len(ctrl), float(stat.max())))
        over = (stat > tol) & (median > 1.25 * 0.6745 * sigma)
        biased = bias > np.maximum(tol / 4, 4 * sigma / np.sqrt(np.maximum(bias_count, 1)))
        split = (over | biased) & (count >= 4 * (DEGREE + 1))
        if not split.any():
            reason = "" if (stat <= tol).all() else "the remaining error is noise or too few points a span"
            return SplineStretch(ctrl, knots, tuple(history), reason)
        if len(ctrl) + int(split.sum()) > max_ctrl:
            return SplineStretch(ctrl, knots, tuple(history), f"control-point limit {max_ctrl} reached")
        knots = np.sort(np.r_[knots, 0.5 * (breaks[:-1] + breaks[1:])[split]])
