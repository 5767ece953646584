"""Conic pieces of a planar profile: sequential RANSAC for lines and circular arcs, with a lack-of-fit
test, and the pieces' geometry (intersections, tangency, tangent-constrained arc refits).

1. Hypotheses come from random pairs (lines) and triples (circles) of the (r, z) points, half of them
   local (a random anchor and partners among its nearest neighbours at log-uniform ranks, as in NAPSAC,
   so that a small fillet is proposed as readily as a long face) (Fischler & Bolles 1981).  Each is
   refined by least squares on its inliers (total least squares for lines; the geometric circle fit,
   Chernov 2010 ch. 4, for arcs) and cut to its largest contiguous run of inliers.  Lines within
   `angle_tol` of the axis directions, or whose ends would move by less than 2 thr, become exactly
   axis-parallel or perpendicular (a designer's intent: a cylinder is r = R).  Faces found first take
   the points near their joints whose noise leans towards them, so an arc is refitted on the central
   70 % of its run, and tangent to the faces it touches (`refit_tangent_arc`).
2. A conic holds only if its run is one piece of surface (at least half of 50 equal bins along it hold
   points) and its residuals show no systematic pattern (a lack-of-fit test): over the central 90 % of
   the run, the median signed residual of each of 3-12 equal-count bins is within
   max(5 sigma / sqrt(bin count), thr / 8) (about 4 standard errors of a median; thr / 8 leaves room
   for a real part's form error), sigma the noise estimated from consecutive residual differences
   (`profile_spline.noise_sigma`).  A hypothesis that fails is replaced by the best of the other kind,
   then looked for again within the failed run (a fillet under a chord); when all fail, the run is
   free-form data.  At the end each piece takes back the free points that are its inliers next to it.
   `conic_over` gives the free stretches left between pieces a second chance on their own points.

All lengths are in model units (mm).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from rgm.fitters.profile_spline import noise_sigma

__all__ = ["Piece", "extract_pieces", "conic_over", "intersections", "tangency", "is_tangent", "refit_tangent_arc",
           "along"]


# ------------------------------------------------------------------------------ primitive fits
def _line_tls(q):
    c = q.mean(axis=0)
    _, _, vt = np.linalg.svd(q - c, full_matrices=False)
    return c, vt[0]                                    # point, unit direction


def _circle_fit(q, center0, radius0, iterations: int = 20):
    """Geometric circle fit (Chernov 2010 ch. 4): Gauss-Newton on |q - c| - r from (center0, radius0)."""
    x = np.r_[center0, radius0].astype(float)
    for _ in range(iterations):
        v = q - x[:2]
        d = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
        jac = np.column_stack([-v / d[:, None], -np.ones(len(q))])
        step = np.linalg.lstsq(jac.T @ jac, -(jac.T @ (d - x[2])), rcond=None)[0]   # normal equations, 3 x 3
        x += step
        if np.linalg.norm(step) <= 1e-12 * max(abs(x[2]), 1.0):
            break
    return x[:2], abs(x[2])


def _circumcircles(a, b, c):
    """Centres (h, 2) and radii (h,) of triangles (h, 2) each; NaN where collinear."""
    d = 2 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        sa, sb, sc = (np.sum(p * p, axis=1) for p in (a, b, c))
        ux = (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d
        uy = (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d
    centre = np.column_stack([ux, uy])
    return centre, np.linalg.norm(a - centre, axis=1)


@dataclass
class Piece:
    kind: str
    point: np.ndarray       # line: a point; arc: centre
    dir: np.ndarray | None  # line: unit direction
    radius: float | None
    ends: np.ndarray        # (2, 2) extreme inliers along the primitive (0.5 and 99.5 percentiles)
    run: np.ndarray         # indices of its points
    mid: np.ndarray         # (2,) median of the inliers

    @property
    def support(self) -> int:
        return len(self.run)


def _signed(kind, params, q):
    """Signed residuals (m,) of points q (m, 2): offset from the line, or distance from the centre - r."""
    if kind == "line":
        p, d = params
        return (q - p) @ np.array([-d[1], d[0]])
    c, r = params
    return np.linalg.norm(q - c, axis=1) - r


def _snap(p, d, inl, angle_tol, thr):
    """Axis-parallel (r = const) or perpendicular (z = const) lines become exact when within angle_tol
    or when their ends would move by less than 2 thr (short faces: a groove's wall seen by few points)."""
    length = np.ptp(inl @ d)
    for axis in (0, 1):
        if abs(d[axis]) < np.sin(angle_tol) or abs(d[axis]) * length < 2 * thr:
            d = np.eye(2)[1 - axis]
            p = np.where(np.arange(2) == axis, inl[:, axis].mean(), inl.mean(axis=0))
            return p, d
    return p, d


def _hypotheses(sample, thr, extent, rng, hyp):
    """The best line and the best circle of `hyp` random hypotheses each (module docstring, step 1), as
    [(kind, params, inlier count)], the preferred first: a line unless a circle explains clearly more."""
    m = len(sample)
    pairs, triples = rng.integers(0, m, (2, hyp)), rng.integers(0, m, (3, hyp))
    k = min(m - 1, 256)
    if k >= 8:  # local half: anchor and neighbours at log-uniform ranks
        g = hyp // 2
        anchor = rng.integers(0, m, hyp - g)
        _, nb = cKDTree(sample).query(sample[anchor], k=k + 1)
        far = np.exp(rng.uniform(np.log(4), np.log(k), hyp - g)).astype(int)
        rows = np.arange(hyp - g)
        pairs[:, g:] = anchor, nb[rows, far]
        triples[:, g:] = anchor, nb[rows, far // 2], nb[rows, far]
    a, d = sample[pairs[0]], sample[pairs[1]] - sample[pairs[0]]
    ok = np.linalg.norm(d, axis=1) > 3 * thr
    a, d = a[ok], d[ok] / np.linalg.norm(d[ok], axis=1, keepdims=True)
    n = np.column_stack([-d[:, 1], d[:, 0]])
    line_count = (np.abs((sample @ n.T) - np.sum(a * n, axis=1)) < thr).sum(axis=0)
    centre, rad = _circumcircles(*(sample[i] for i in triples))
    ok = np.isfinite(rad) & (rad > 5 * thr) & (rad < 2 * extent)
    centre, rad = centre[ok], rad[ok]
    sq = np.sum(sample ** 2, axis=1)[:, None] - 2 * sample @ centre.T + np.sum(centre ** 2, axis=1)
    circle_count = (np.abs(np.sqrt(np.maximum(sq, 0.0)) - rad) < thr).sum(axis=0)
    out = []
    if len(line_count):
        i = int(np.argmax(line_count))
        out.append(("line", (a[i], d[i]), int(line_count[i])))
    if len(circle_count):
        i = int(np.argmax(circle_count))
        out.append(("arc", (centre[i], rad[i]), int(circle_count[i])))
    if len(out) == 2 and out[0][2] < 0.85 * out[1][2]:  # Occam: a line unless an arc explains clearly more
        out.reverse()
    return out


def _positions(kind, params, pts):
    """Positions (m,) of points (m, 2) along a primitive (mm): along a line's direction; arc length about
    an arc's centre, counted from the end of the points' widest angular gap."""
    if kind == "line":
        return (pts - params[0]) @ params[1]
    v = pts - params[0]
    ang = np.arctan2(v[:, 1], v[:, 0])
    srt = np.sort(ang)
    shift = srt[(np.argmax(np.diff(srt, append=srt[0] + 2 * np.pi)) + 1) % len(srt)]
    return ((ang - shift) % (2 * np.pi)) * params[1]


def _run(kind, params, q, inl, gap, keep=None):
    """The contiguous run (no gap along the primitive longer than `gap`, or than half an arc's radius) of
    the inliers `inl` that is the largest or, given `keep`, holds most of `keep`: (indices, positions)."""
    gap = gap if kind == "line" else min(gap, 0.5 * params[1])
    t = _positions(kind, params, q[inl])
    order = np.argsort(t)
    cuts = np.r_[0, np.flatnonzero(np.diff(t[order]) > gap) + 1, len(t)]
    label = np.repeat(np.arange(len(cuts) - 1), np.diff(cuts))
    weight = np.ones(len(t)) if keep is None else np.isin(inl[order], keep).astype(float)
    best = int(np.argmax(np.bincount(label, weight)))
    local = order[label == best]
    return inl[local], t[local]


def _make_piece(kind, params, q, run, trun):
    """A Piece from its run: ends at the 0.5 and 99.5 percentiles along it, projected onto it."""
    lo, hi = np.percentile(trun, [0.5, 99.5])
    ends = q[run][[np.argmin(np.abs(trun - lo)), np.argmin(np.abs(trun - hi))]]
    mid = np.median(q[run], axis=0)
    if kind == "line":
        ends = params[0] + np.outer(((ends - params[0]) @ params[1]), params[1])
        return Piece("line", params[0], params[1], None, ends, run, mid)
    ends = params[0] + (ends - params[0]) / np.linalg.norm(ends - params[0], axis=1, keepdims=True) * params[1]
    return Piece("arc", params[0], None, params[1], ends, run, mid)


def _grow(kind, params, q, pool, thr, gap, angle_tol, min_support):
    """A hypothesis refined on its inliers (inliers -> least squares, until the inliers no longer change,
    at most 8 times) and cut to its largest contiguous run: a Piece, or None when fewer than
    `min_support` points support it.  An arc whose sagitta over its run is within 2 thr is a line."""
    res = np.abs(_signed(kind, params, q[pool]))
    band, inl = pool[res < 4 * thr], pool[res < thr]   # the refinement moves the primitive by less than 3 thr
    for _ in range(8):
        if len(inl) < max(3, min_support):
            return None
        params = _snap(*_line_tls(q[inl]), q[inl], angle_tol, thr) if kind == "line" else _circle_fit(q[inl], *params)
        prev, inl = inl, band[np.abs(_signed(kind, params, q[band])) < thr]
        if len(inl) == len(prev) and np.array_equal(inl, prev):
            break
    inl = pool[np.abs(_signed(kind, params, q[pool])) < thr]
    if len(inl) < min_support:
        return None
    run, trun = _run(kind, params, q, inl, gap)
    if kind == "arc" and len(run) >= min_support:
        # faces found before took the points near the joints whose noise leans towards them, which biases
        # the radius: refit on the central 70 % of the run and take the run again, unless that loses over
        # 5 % of the points (no true arc then: the lack-of-fit test judges the whole-run fit)
        lo, hi = np.percentile(trun, [15, 85])
        central = _circle_fit(q[run[(trun >= lo) & (trun <= hi)]], *params)
        again = _run(kind, central, q, pool[np.abs(_signed(kind, central, q[pool])) < thr], gap)
        if len(again[0]) >= 0.95 * len(run):
            params, (run, trun) = central, again
    if len(run) < min_support:
        return None
    if kind == "arc":
        half = np.linalg.norm(np.subtract(*q[run][[np.argmin(trun), np.argmax(trun)]])) / 2
        if params[1] - np.sqrt(max(params[1] ** 2 - half ** 2, 0.0)) < 2 * thr and np.ptp(trun) < params[1] * np.pi:
            kind, params = "line", _snap(*_line_tls(q[run]), q[run], angle_tol, thr)
            trun = _positions(kind, params, q[run])
    return _make_piece(kind, params, q, run, trun)


def _regrow(piece, q, free, thr, gap):
    """The piece with the free points that are its inliers and contiguous with its run (points of a
    rejected hypothesis that belong to an accepted face)."""
    params = _params(piece)
    cand = np.r_[piece.run, free]
    run, trun = _run(piece.kind, params, q, cand[np.abs(_signed(piece.kind, params, q[cand])) < thr], gap,
                     keep=piece.run)
    return _make_piece(piece.kind, params, q, run, trun)


def _params(piece):
    return (piece.point, piece.dir) if piece.kind == "line" else (piece.point, piece.radius)


def along(piece, q):
    """Positions (m,) of points along a piece: arc length along a line, angle about an arc's centre from
    its first end (unwrapped in the direction of its second end)."""
    if piece.kind == "line":
        return (q - piece.point) @ piece.dir
    v, e = q - piece.point, piece.ends - piece.point
    a0 = np.arctan2(e[0, 1], e[0, 0])
    return (np.arctan2(v[:, 1], v[:, 0]) - a0) % (2 * np.pi)


def _holds(piece, q, thr) -> bool:
    """The lack-of-fit test of the module docstring (step 2), after an occupancy test: at least half of 50
    equal bins between the piece's ends (the run's 0.5 and 99.5 percentiles, as `_make_piece` places
    them) hold a point (a run stitched together from scattered points is no face; a stray inlier a few mm
    along the line beyond a short face is not part of it, and must not spread the bins)."""
    pts = q[piece.run]
    t = _positions(piece.kind, _params(piece), pts)
    lo, hi = np.percentile(t, [0.5, 99.5])
    inside = t[(t >= lo) & (t <= hi)]
    occupied = np.unique(np.minimum((50 * (inside - lo) / max(hi - lo, 1e-300)).astype(int), 49))
    if len(occupied) < 25:
        return False
    order = np.argsort(t)
    cut = len(order) // 20
    s = _signed(piece.kind, _params(piece), pts[order[cut:len(order) - cut]])
    if len(s) < 30:
        return True
    sigma = noise_sigma(s)
    bins = int(np.clip(len(s) // 60, 3, 12))
    medians = np.array([np.median(b) for b in np.array_split(s, bins)])   # robust to the few outliers left
    return bool(np.all(np.abs(medians) <= max(5 * sigma / np.sqrt(len(s) // bins), thr / 8)))


def _proposals(where, pool, q, found, thr, gap, angle_tol, min_support, extent, rng):
    """The best line and circle hypotheses drawn from the points `where`, grown over `pool` (arcs made
    tangent to the faces `found` they touch), preferred first."""
    sample = q[where[rng.choice(len(where), min(len(where), 1500), replace=False)]]
    grown = [_grow(kind, params, q, pool, thr, gap, angle_tol, min_support)
             for kind, params, _ in _hypotheses(sample, thr, extent, rng, 300)]
    return [_tangent_to_faces(g, found, q, thr) for g in grown if g is not None]


def conic_over(where, q, found, thr, gap, angle_tol, min_support, extent, rng):
    """The line or arc that alone explains the points `where` (indices into q; a stretch that extraction
    left to free form): grown over them only, holding the lack-of-fit test, and leaving fewer than
    max(min_support, 10 %) of them outside its run; else None."""
    for piece in _proposals(where, where, q, found, thr, gap, angle_tol, min_support, extent, rng):
        if len(where) - piece.support < max(min_support, 0.1 * len(where)) and _holds(piece, q, thr):
            return piece
    return None


def extract_pieces(q, thr, gap, angle_tol, min_support, rng):
    """Sequential RANSAC with the lack-of-fit test: (pieces, indices of free-form points)."""
    extent = float(np.ptp(q, axis=0).max())
    pool = np.arange(len(q))
    pieces, free, misses = [], [], 0
    for _ in range(80):
        if len(pool) < min_support or misses == 4:  # four rounds of hypotheses in a row found nothing
            break
        grown = _proposals(pool, pool, q, pieces, thr, gap, angle_tol, min_support, extent, rng)
        misses = 0 if grown else misses + 1
        if not grown:
            continue
        piece = next((g for g in grown if _holds(g, q, thr)), None)
        for _ in range(2 if piece is None else 0):  # look again within the failed run: a fillet under a chord
            piece = next((g for g in _proposals(grown[0].run, pool, q, pieces, thr, gap, angle_tol, min_support,
                                                extent, rng) if _holds(g, q, thr)), None)
            if piece is not None:
                break
        taken = grown[0].run if piece is None else piece.run
        if piece is None:
            free.append(taken)
        else:
            pieces.append(piece)
        pool = np.setdiff1d(pool, taken, assume_unique=True)
    free = np.concatenate(free + [pool]).astype(int)
    for k in np.argsort([-p.support for p in pieces]):
        pieces[k] = _regrow(pieces[k], q, free, thr, gap)
        free = np.setdiff1d(free, pieces[k].run)
    return pieces, free


# ------------------------------------------------------------------------------ piece geometry
def intersections(a: Piece, b: Piece):
    """Candidate intersection points (k, 2) of two primitives (k = 0, 1 or 2)."""
    if a.kind == "arc" and b.kind == "line":
        a, b = b, a
    if a.kind == "line" and b.kind == "line":
        m = np.column_stack([a.dir, -b.dir])
        if abs(np.linalg.det(m)) < 1e-9:
            return np.zeros((0, 2))
        s = np.linalg.solve(m, b.point - a.point)
        return (a.point + s[0] * a.dir)[None]
    if a.kind == "line":  # line a, circle b
        f = a.point - b.point
        bq, cq = 2 * f @ a.dir, f @ f - b.radius ** 2
        disc = bq * bq - 4 * cq
        s = np.array([-bq / 2]) if disc < 0 else (-bq + np.array([-1, 1]) * np.sqrt(disc)) / 2
        return a.point + s[:, None] * a.dir
    d = np.linalg.norm(b.point - a.point)
    if d < 1e-12 or d > a.radius + b.radius or d < abs(a.radius - b.radius):
        return np.zeros((0, 2))
    x = (d * d + a.radius ** 2 - b.radius ** 2) / (2 * d)
    h = np.sqrt(max(a.radius ** 2 - x * x, 0.0))
    u = (b.point - a.point) / d
    return a.point + x * u + np.outer([-h, h], [-u[1], u[0]])


def tangency(a: Piece, b: Piece):
    """How far two pieces are from tangency (model units; inf for two lines) and the tangent point."""
    if a.kind == "line" and b.kind == "line":
        return np.inf, None
    if a.kind == "arc" and b.kind == "line":
        a, b = b, a
    if a.kind == "line":
        n = np.array([-a.dir[1], a.dir[0]])
        off = (b.point - a.point) @ n
        return abs(abs(off) - b.radius), b.point - off * n
    v = b.point - a.point
    d = np.linalg.norm(v)
    outer, inner = abs(d - (a.radius + b.radius)), abs(d - abs(a.radius - b.radius))
    u = v / max(d, 1e-300)
    if outer <= inner:
        return outer, a.point + a.radius * u
    big, small = (a, b) if a.radius >= b.radius else (b, a)
    return inner, big.point + big.radius * (small.point - big.point) / max(d, 1e-300)


def is_tangent(a, b, thr):
    gap, _ = tangency(a, b)
    r = min(p.radius for p in (a, b) if p.kind == "arc") if np.isfinite(gap) else 0.0
    return gap < max(2 * thr, r * (1 - np.cos(np.radians(5.0))))


def _tangent_to_faces(piece, found, q, thr):
    """An arc refitted tangent to the pieces already found that it nearly touches tangentially near one of
    its ends (a fillet between two faces keeps one free parameter, its radius; this removes the bias the
    faces' claim on the joint points leaves in a free circle fit); other pieces unchanged."""
    if piece.kind != "arc":
        return piece
    near = []
    for other in found:
        if not is_tangent(piece, other, thr):
            continue
        point = tangency(piece, other)[1]
        close_to_end = np.min(np.linalg.norm(piece.ends - point, axis=1)) < 0.5 * piece.radius + 2 * thr
        on_other = np.min(np.linalg.norm(other.ends - point, axis=1)) < 0.5 * piece.radius + 2 * thr
        if close_to_end and on_other:
            near.append(other)
    return refit_tangent_arc(piece, near, q) if near else piece


def refit_tangent_arc(arc: Piece, neighbours, q):
    """Refit an arc's centre and radius to its run with tangency to each neighbour as a (heavily
    weighted) constraint; its ends are projected onto the new circle."""
    pts = q[arc.run]
    weight = 100.0 * np.sqrt(len(pts))

    def residuals(x):
        c, r = x[:2], x[2]
        out = [np.linalg.norm(pts - c, axis=1) - r]
        for nb in neighbours:
            if nb.kind == "line":
                n = np.array([-nb.dir[1], nb.dir[0]])
                out.append([weight * (abs((c - nb.point) @ n) - r)])
            else:
                d = np.linalg.norm(c - nb.point)
                outer, inner = r + nb.radius, abs(r - nb.radius)          # external or internal tangency
                out.append([weight * (d - (outer if abs(d - outer) <= abs(d - inner) else inner))])
        return np.concatenate(out)

    x = least_squares(residuals, np.r_[arc.point, arc.radius]).x
    ends = x[:2] + (arc.ends - x[:2]) / np.linalg.norm(arc.ends - x[:2], axis=1, keepdims=True) * x[2]
    return replace(arc, point=x[:2], radius=float(x[2]), ends=ends)
