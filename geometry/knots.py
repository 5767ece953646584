"""Knot vectors and the shape-preserving operations on them.

The operations work on homogeneous control points `pw (n, k)`: rows are control points, the k
columns any number of coordinates (for a curve (w*P, w), k = d+1; for a surface direction, a whole
row of the net flattened, k = n_other * 4). The same code therefore serves curves and both
directions of surfaces, and because the maps are linear in `pw` they are exact for rational
geometry.

- `refine_knots`    knot insertion and refinement (Piegl & Tiller A5.1/A5.4; A5.3/A5.5 for surfaces).
- `split_knots`     splitting at a parameter by inserting it to full multiplicity.
- `elevate_degree`  degree elevation (Bezier decomposition, eq. 5.36, least-squares knot removal).
- `rescale_knots`   affine reparameterisation.
- `clamped_knots`, `uniform_knots`, `multiplicity`: knot-vector helpers.
"""
from __future__ import annotations

from math import comb

import numpy as np

from rgm.errors import GeometryError

from .basis import find_spans

__all__ = ["clamped_knots", "uniform_knots", "multiplicity", "refine_knots", "split_knots",
           "elevate_degree", "rescale_knots", "clamp", "is_clamped", "insert_knot_once"]


def clamped_knots(degree: int, interior=(), domain=(0.0, 1.0)) -> np.ndarray:
    """Clamped knot vector: p+1 copies of each end of `domain` around the sorted `interior` knots."""
    interior = np.sort(np.asarray(interior, dtype=float))
    lo, hi = map(float, domain)
    if interior.size and (interior[0] <= lo or interior[-1] >= hi):
        raise GeometryError(f"interior knots must lie strictly inside ({lo:g}, {hi:g})")
    return np.concatenate([np.full(degree + 1, lo), interior, np.full(degree + 1, hi)])


def uniform_knots(degree: int, count: int, domain=(0.0, 1.0)) -> np.ndarray:
    """Clamped knot vector with uniformly spaced interior knots for `count` control points."""
    if count < degree + 1:
        raise GeometryError(f"degree {degree} needs at least {degree + 1} control points, got {count}")
    interior = np.linspace(*domain, count - degree + 1)[1:-1]
    return clamped_knots(degree, interior, domain)


def multiplicity(knots: np.ndarray, u: float) -> int:
    """How many times the value u occurs in the knot vector."""
    return int(np.searchsorted(knots, u, side="right") - np.searchsorted(knots, u, side="left"))


def rescale_knots(knots: np.ndarray, degree: int, u0: float, u1: float) -> np.ndarray:
    """Knots mapped affinely so that the domain [knots[p], knots[n]] becomes [u0, u1]."""
    if not np.isfinite(u0) or not np.isfinite(u1) or not u0 < u1:
        raise GeometryError(f"new domain must satisfy u0 < u1, got [{u0}, {u1}]")
    n = len(knots) - degree - 1
    a, b = knots[degree], knots[n]
    out = u0 + (knots - a) * ((u1 - u0) / (b - a))
    out[knots == a], out[knots == b] = u0, u1    # every copy of an end knot exactly (no rounding below it)
    return out


def refine_knots(knots: np.ndarray, degree: int, pw: np.ndarray, new_knots) -> tuple[np.ndarray, np.ndarray]:
    """Insert all of `new_knots` (any order, repeats allowed) at once (Piegl & Tiller A5.4).

    knots : (n+p+1,);  pw : (n, k) homogeneous control points.
    Returns (knots (n+r+p+1,), pw (n+r, k)). The new knots must lie strictly inside the domain and
    no interior knot may end up with multiplicity above the degree.
    """
    p = degree
    x = np.sort(np.atleast_1d(np.asarray(new_knots, dtype=float)))
    if x.size == 0:
        return np.array(knots, dtype=float), np.array(pw, dtype=float)
    n = pw.shape[0]
    lo, hi = knots[p], knots[n]
    if not np.all(np.isfinite(x)) or x[0] <= lo or x[-1] >= hi:
        raise GeometryError(f"inserted knots must lie strictly inside the domain ({lo:g}, {hi:g}), "
                            f"got [{x[0]:g}, {x[-1]:g}]")
    values, counts = np.unique(np.concatenate([knots, x]), return_counts=True)
    counts = counts[(values > lo) & (values < hi)]
    if counts.max() > p:
        raise GeometryError(f"knot insertion would repeat an interior knot {counts.max()} times "
                            f"(degree {p} allows {p})")
    r = x.size
    a = int(find_spans(knots, p, x[:1])[0])
    b = int(np.searchsorted(knots, x[-1], side="right") - 1) + 1
    m = n + p                      # index of the last knot
    qw = np.empty((n + r,) + pw.shape[1:])
    ubar = np.empty(m + r + 1)
    qw[:a - p + 1] = pw[:a - p + 1]
    qw[b - 1 + r:] = pw[b - 1:]
    ubar[:a + 1] = knots[:a + 1]
    ubar[b + p + r:] = knots[b + p:]
    i, k = b + p - 1, b + p + r - 1
    for j in range(r - 1, -1, -1):
        while x[j] <= knots[i] and i > a:
            qw[k - p - 1] = pw[i - p - 1]
            ubar[k] = knots[i]
            k -= 1
            i -= 1
        qw[k - p - 1] = qw[k - p]
        for l in range(1, p + 1):
            ind = k - p + l
            alpha = ubar[k + l] - x[j]
            if alpha == 0.0:
                qw[ind - 1] = qw[ind]
            else:
                alpha /= ubar[k + l] - knots[i - p + l]
                qw[ind - 1] = alpha * qw[ind - 1] + (1.0 - alpha) * qw[ind]
        ubar[k] = x[j]
        k -= 1
    return ubar, qw


def insert_knot_once(knots: np.ndarray, degree: int, pw: np.ndarray, u: float):
    """Insert u once by Boehm's rule (Piegl & Tiller A5.1), for any u in [knots[p], knots[n]].

    Unlike `refine_knots` this accepts the domain ends, which is what clamping needs. At the
    right end the span to the left of u is used. Returns (knots (len+1,), pw (n+1, k)).
    """
    p = degree
    n = pw.shape[0]
    side = "left" if u == knots[n] else "right"
    k = int(np.searchsorted(knots, u, side=side)) - 1
    i = np.arange(k - p + 1, k + 1)
    alpha = ((u - knots[i]) / (knots[i + p] - knots[i])).reshape((-1,) + (1,) * (pw.ndim - 1))
    middle = alpha * pw[i] + (1.0 - alpha) * pw[i - 1]
    return np.insert(knots, k + 1, u), np.concatenate([pw[:k - p + 1], middle, pw[k:]])


def _cut(knots: np.ndarray, degree: int, pw: np.ndarray, u: float):
    """Split where u already has multiplicity p or p+1: the control point(s) there interpolate
    the curve. Returns ((knots_left, pw_left), (knots_right, pw_right))."""
    p = degree
    first = int(np.searchsorted(knots, u, side="left"))
    last = int(np.searchsorted(knots, u, side="right")) - 1
    ends = np.full(p + 1, u)
    return ((np.concatenate([knots[:first], ends]), pw[:first]),
            (np.concatenate([ends, knots[last + 1:]]), pw[last - p:]))


def split_knots(knots: np.ndarray, degree: int, pw: np.ndarray, u: float):
    """Split at parameter u strictly inside the domain.

    The knot u is first raised to multiplicity p (A5.1), which makes the control point there
    interpolate C(u). Returns ((knots_left, pw_left), (knots_right, pw_right)) on [u0, u] and [u, u1].
    """
    p = degree
    n = pw.shape[0]
    if not knots[p] < u < knots[n]:
        raise GeometryError(f"split parameter {u:g} must lie strictly inside the domain "
                            f"({knots[p]:g}, {knots[n]:g})")
    s = multiplicity(knots, u)
    if s < p:
        knots, pw = refine_knots(knots, p, pw, np.full(p - s, u))
    return _cut(knots, p, pw, u)


def is_clamped(knots: np.ndarray, degree: int) -> bool:
    """True when both ends of the knot vector are repeated degree + 1 times."""
    return bool(knots[0] == knots[degree] and knots[-1] == knots[-degree - 1])


def clamp(knots: np.ndarray, degree: int, pw: np.ndarray):
    """The same curve on its domain with a clamped knot vector (end knots of multiplicity p+1):
    the parts outside the domain are cut off after raising the end knots to multiplicity p.
    Returns (knots, pw)."""
    p = degree
    lo, hi = knots[p], knots[pw.shape[0]]
    while multiplicity(knots, lo) < p:
        knots, pw = insert_knot_once(knots, p, pw, lo)
    knots, pw = _cut(knots, p, pw, lo)[1]
    while multiplicity(knots, hi) < p:
        knots, pw = insert_knot_once(knots, p, pw, hi)
    return _cut(knots, p, pw, hi)[0]


def bezier_elevation_matrix(degree: int, times: int) -> np.ndarray:
    """Coefficients (p+t+1, p+1) taking Bezier control points of degree p to degree p+t
    (Piegl & Tiller eq. 5.36): row i, column j is C(p, j) C(t, i-j) / C(p+t, i)."""
    p, t = degree, times
    out = np.zeros((p + t + 1, p + 1))
    for i in range(p + t + 1):
        for j in range(max(0, i - t), min(p, i) + 1):
            out[i, j] = comb(p, j) * comb(t, i - j) / comb(p + t, i)
    return out


def elevate_degree(knots: np.ndarray, degree: int, pw: np.ndarray, times: int):
    """Raise the degree from p to p + t with the shape unchanged; returns (knots, pw).

    Every distinct knot gains multiplicity t, as in Piegl & Tiller A5.9, but the knot-removal half
    of A5.9 (which divides by differences of nearby knots and loses accuracy when knots crowd) is
    replaced by a least-squares solve:

    1. decompose into Bezier segments by knot refinement (A5.6), and elevate each segment (eq. 5.36);
    2. the elevated curve Q on the target knot vector, refined to the same Bezier knots, must
       reproduce those segments: R Q = E, where R is the knot-insertion matrix (A5.4 applied to
       the identity). E lies in the range of R, so the least-squares solution is exact up to
       rounding, and its accuracy depends on the B-spline condition number, not on knot spacing.

    Knot vectors that are not clamped are clamped first.
    """
    p, t = degree, times
    knots = np.asarray(knots, dtype=float)
    if not is_clamped(knots, p):
        knots, pw = clamp(knots, p, pw)
    values, counts = np.unique(knots, return_counts=True)
    inner_values, inner_counts = values[1:-1], counts[1:-1]
    missing = np.repeat(inner_values, p - inner_counts)
    bez_knots, bez = refine_knots(knots, p, pw, missing)
    segments = values.size - 1
    rows = np.arange(segments)[:, None] * p + np.arange(p + 1)[None, :]
    elevated = np.einsum("ij,sj...->si...", bezier_elevation_matrix(p, t), bez[rows])
    target = np.repeat(values, np.r_[p + 1 + t, inner_counts + t, p + 1 + t])
    ph = p + t
    nq = target.size - ph - 1
    stacked = np.concatenate([elevated[:1, 0], elevated[:, 1:].reshape((-1,) + pw.shape[1:])])
    insertion = refine_knots(target, ph, np.eye(nq), missing)[1]
    flat = stacked.reshape(stacked.shape[0], -1)
    solution = np.linalg.lstsq(insertion, flat, rcond=None)[0]
    return target, solution.reshape((nq,) + pw.shape[1:])
