"""Planar profiles: lines, circular arcs and B-spline stretches in the (r, z) half plane.

`fit_conic_profile` turns a noisy 2-D point set (a surface of revolution's meridian section) into a chain
of pieces from axis to axis:

1. Conic pieces by sequential RANSAC (Fischler & Bolles 1981).  Hypotheses come from random pairs (lines)
   and triples (circles), half of them local (a random anchor and partners among its nearest neighbours
   at log-uniform ranks, as in NAPSAC, so that a small fillet is proposed as readily as a long face);
   least-squares refinement (total least squares for lines; the geometric circle fit, Chernov 2010
   ch. 4, for arcs); only the largest contiguous run of inliers is kept.  Lines within `angle_tol` of the
   axis directions, or whose ends would move by less than 2 thr, become exactly axis-parallel or
   perpendicular (a designer's intent: a cylinder is r = R).
2. A conic holds only if its run is one piece of surface (at least half of 50 equal bins along it hold
   points) and its residuals show no systematic pattern (a lack-of-fit test): over the central 90 % of
   the run, the median signed residual of each of 3-12 equal-count bins is within
   max(5 sigma / sqrt(bin count), thr / 8) (about 4 standard errors of a median; thr / 8 leaves room
   for a real part's form error), sigma the noise estimated from consecutive residual differences
   (`profile_spline.noise_sigma`).  A hypothesis that fails is replaced by the best of the other kind;
   when both fail, its run is free-form data.  Faces found first take the points near their joints
   whose noise leans towards them, so an arc is refitted on the central 70 % of its run.
3. Chaining: the pieces in the order the profile runs from the axis at its lowest z outwards and back
   (angle about the axis point at the median z).  Free-form data between two neighbouring pieces (at
   least `min_support` points, their median distance to the fitted spline within thr) becomes a cubic
   B-spline refined by knot insertion to the tolerance (`rgm.fitters.profile_spline`, the paper's
   Figure 6), tangent to a neighbour where the data leave it within 20 deg.  Other neighbours meet where
   they are tangent (a line and an arc, or two arcs, off tangency by less than max(2 thr, r (1 - cos
   5 deg))) at the tangent point, each such arc refitted first with its tangencies as constraints (a
   fillet between two lines keeps one free parameter, its radius); else at their intersection.
   Collinear neighbouring lines (a face seen in two views) are joined.

`Profile.distance` is the exact Euclidean distance of points to the chain: for a full surface of
revolution the closest surface point lies in the point's own meridian half plane, so this is the exact
closest-point distance to the surface.  All lengths are in model units (mm).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from rgm.errors import GeometryError
from rgm.fitters.profile_spline import fit_spline_stretch, noise_sigma, spline_closest

__all__ = ["Segment", "Profile", "fit_conic_profile"]


@dataclass(frozen=True, eq=False)
class Segment:
    """One piece of a profile, points (2,) in (r, z): a line from p0 to p1 (center None); a circular arc
    (center, radius) from p0 to p1 through `through`; or a cubic B-spline (ctrl (n, 2), knots (n + 4,),
    p0 = ctrl[0], p1 = ctrl[-1])."""

    p0: np.ndarray
    p1: np.ndarray
    center: np.ndarray | None = None
    radius: float | None = None
    through: np.ndarray | None = None
    ctrl: np.ndarray | None = None
    knots: np.ndarray | None = None

    @property
    def kind(self) -> str:
        return "bspline" if self.ctrl is not None else "line" if self.center is None else "arc"

    def _sweep(self):
        """Arc: start angle a0 and signed sweep (radians, positive counter-clockwise) through `through`."""
        a0, a1, am = (np.arctan2(*(p - self.center)[::-1]) for p in (self.p0, self.p1, self.through))
        span = (a1 - a0) % (2 * np.pi)
        return a0, span if (am - a0) % (2 * np.pi) <= span else span - 2 * np.pi

    def distance(self, q) -> np.ndarray:
        """(m,) distance of points q (m, 2) to this segment."""
        if self.kind == "bspline":
            return np.abs(spline_closest(self.ctrl, self.knots, q)[1])
        if self.kind == "line":
            d = self.p1 - self.p0
            t = np.clip((q - self.p0) @ d / max(d @ d, 1e-300), 0.0, 1.0)
            return np.linalg.norm(q - (self.p0 + t[:, None] * d), axis=1)
        v = q - self.center
        a0, sweep = self._sweep()
        rel = (np.sign(sweep) * (np.arctan2(v[:, 1], v[:, 0]) - a0)) % (2 * np.pi)
        on_arc = np.abs(np.linalg.norm(v, axis=1) - self.radius)
        ends = np.minimum(np.linalg.norm(q - self.p0, axis=1), np.linalg.norm(q - self.p1, axis=1))
        return np.where(rel <= abs(sweep), on_arc, ends)

    def sample(self, spacing: float) -> np.ndarray:
        """(k, 2) points along the segment, about `spacing` apart, both ends included."""
        if self.kind == "line":
            k = max(2, int(np.linalg.norm(self.p1 - self.p0) / spacing) + 1)
            return self.p0 + np.linspace(0, 1, k)[:, None] * (self.p1 - self.p0)
        if self.kind == "arc":
            a0, sweep = self._sweep()
            ang = a0 + np.linspace(0, 1, max(3, int(abs(sweep) * self.radius / spacing) + 1)) * sweep
            return self.center + self.radius * np.column_stack([np.cos(ang), np.sin(ang)])
        from scipy.interpolate import BSpline

        spline = BSpline(self.knots, self.ctrl, len(self.knots) - len(self.ctrl) - 1)
        length = np.sum(np.linalg.norm(np.diff(self.ctrl, axis=0), axis=1))   # the polygon bounds the arc length
        return spline(np.linspace(0, 1, max(4, int(length / spacing) + 1)))

    def shifted(self, offset) -> Segment:
        """The segment moved by `offset` (2,)."""
        def move(p):
            return None if p is None else p + offset

        return replace(self, p0=self.p0 + offset, p1=self.p1 + offset, center=move(self.center),
                       through=move(self.through), ctrl=move(self.ctrl))


@dataclass(frozen=True)
class Profile:
    """An open chain of segments in (r, z), p1 of each segment = p0 of the next."""

    segments: tuple

    @property
    def vertices(self) -> np.ndarray:
        """(k + 1, 2) the chain's vertices."""
        return np.array([self.segments[0].p0] + [s.p1 for s in self.segments])

    def distance(self, q) -> np.ndarray:
        """(m,) Euclidean distance of (r, z) points q (m, 2) to the chain."""
        q = np.asarray(q, float)
        return np.min([s.distance(q) for s in self.segments], axis=0)


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
class _Piece:
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
    """A _Piece from its run: ends at the 0.5 and 99.5 percentiles along it, projected onto it."""
    lo, hi = np.percentile(trun, [0.5, 99.5])
    ends = q[run][[np.argmin(np.abs(trun - lo)), np.argmin(np.abs(trun - hi))]]
    mid = np.median(q[run], axis=0)
    if kind == "line":
        ends = params[0] + np.outer(((ends - params[0]) @ params[1]), params[1])
        return _Piece("line", params[0], params[1], None, ends, run, mid)
    ends = params[0] + (ends - params[0]) / np.linalg.norm(ends - params[0], axis=1, keepdims=True) * params[1]
    return _Piece("arc", params[0], None, params[1], ends, run, mid)


def _grow(kind, params, q, pool, thr, gap, angle_tol, min_support):
    """A hypothesis refined on its inliers (inliers -> least squares, until the inliers no longer change,
    at most 8 times) and cut to its largest contiguous run: a _Piece, or None when fewer than
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


def _along(piece, q):
    """Positions (m,) of points along a piece: arc length along a line, angle about an arc's centre from
    its first end (unwrapped in the direction of its second end)."""
    if piece.kind == "line":
        return (q - piece.point) @ piece.dir
    v, e = q - piece.point, piece.ends - piece.point
    a0 = np.arctan2(e[0, 1], e[0, 0])
    return (np.arctan2(v[:, 1], v[:, 0]) - a0) % (2 * np.pi)


def _holds(piece, q, thr) -> bool:
    """The lack-of-fit test of the module docstring (step 2), after an occupancy test: at least half of 50
    equal bins along the run hold a point (a run stitched together from scattered points is no face)."""
    pts = q[piece.run]
    t = _positions(piece.kind, _params(piece), pts)
    occupied = np.unique(np.minimum((50 * (t - t.min()) / max(np.ptp(t), 1e-300)).astype(int), 49))
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


def _extract_pieces(q, thr, gap, angle_tol, min_support, rng):
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


# ------------------------------------------------------------------------------ chaining
def _intersections(a: _Piece, b: _Piece):
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


def _tangency(a: _Piece, b: _Piece):
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


def _is_tangent(a, b, thr):
    gap, _ = _tangency(a, b)
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
        if not _is_tangent(piece, other, thr):
            continue
        point = _tangency(piece, other)[1]
        close_to_end = np.min(np.linalg.norm(piece.ends - point, axis=1)) < 0.5 * piece.radius + 2 * thr
        on_other = np.min(np.linalg.norm(other.ends - point, axis=1)) < 0.5 * piece.radius + 2 * thr
        if close_to_end and on_other:
            near.append(other)
    return _refit_tangent_arc(piece, near, q) if near else piece


def _refit_tangent_arc(arc: _Piece, neighbours, q):
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
                target = r + nb.radius if abs(d - (r + nb.radius)) <= abs(d - abs(r - nb.radius)) else abs(r - nb.radius)
                out.append([weight * (d - target)])
        return np.concatenate(out)

    x = least_squares(residuals, np.r_[arc.point, arc.radius]).x
    ends = x[:2] + (arc.ends - x[:2]) / np.linalg.norm(arc.ends - x[:2], axis=1, keepdims=True) * x[2]
    return replace(arc, point=x[:2], radius=float(x[2]), ends=ends)


def _order(pieces, z_mid):
    """Chain the pieces as the profile runs from the axis at its lowest z outwards and back to the axis at
    its highest z: by the angle atan2(z - z_mid, r) of each piece's median point, seen from the axis
    point (0, z_mid) (exact for profiles star-shaped about that point, as turned parts nearly always
    are).  Each piece's ends are oriented the same way."""
    chain = []
    for piece in sorted(pieces, key=lambda pc: _star(pc.mid, z_mid)):
        if _star(piece.ends[0], z_mid) > _star(piece.ends[1], z_mid):
            piece = replace(piece, ends=piece.ends[::-1])
        chain.append(piece)
    return chain


def _star(p, z_mid):
    return np.arctan2(p[..., 1] - z_mid, p[..., 0])


def _tangent(piece, which):
    """Unit tangent (2,) at piece.ends[which], in the direction of travel (ends[0] -> ends[1])."""
    if piece.kind == "line":
        d = piece.ends[1] - piece.ends[0]
        return d / np.linalg.norm(d) if d @ d > 0 else piece.dir
    v = piece.ends[which] - piece.point
    ccw = (_along(piece, piece.mid[None])[0] <= _along(piece, piece.ends[1][None])[0])
    t = np.array([-v[1], v[0]]) if ccw else np.array([v[1], -v[0]])
    return t / np.linalg.norm(t)


def _smooth_departure(end, tangent, pts, radius):
    """True when the points near `end` (within `radius`) leave it within 20 deg of `tangent`."""
    near = pts[np.linalg.norm(pts - end, axis=1) < radius]
    if len(near) < 10:
        return False
    d = np.mean(near - end, axis=0)
    return bool(d @ tangent > np.cos(np.radians(20.0)) * np.linalg.norm(d))


def _merge_collinear(chain, stretch, thr, angle_tol):
    """Join neighbouring lines of the chain that are one line (same direction within angle_tol, offset
    within thr) and have no free-form stretch between them: a face seen in two views with a gap between
    them.  stretch[k] holds the free points between chain[k] and chain[k + 1] (or None)."""
    out, gaps = [chain[0]], []
    for k, piece in enumerate(chain[1:]):
        prev = out[-1]
        if (stretch[k] is None and piece.kind == prev.kind == "line" and abs(piece.dir @ prev.dir) > np.cos(angle_tol)
                and abs((piece.point - prev.point) @ np.array([-prev.dir[1], prev.dir[0]])) < thr):
            w = prev.support / (prev.support + piece.support)
            point = w * prev.point + (1 - w) * (piece.point - ((piece.point - prev.point) @ prev.dir) * prev.dir)
            ends = point + np.outer((np.array([prev.ends[0], piece.ends[1]]) - point) @ prev.dir, prev.dir)
            out[-1] = _Piece("line", point, prev.dir, None, ends, np.r_[prev.run, piece.run], (prev.mid + piece.mid) / 2)
            continue
        out.append(piece)
        gaps.append(stretch[k])
    return out, gaps


def _axis_piece(z):
    return _Piece("line", np.array([0.0, z]), np.array([0.0, 1.0]), None, np.zeros((2, 2)), np.zeros(0, int),
                  np.zeros(2))


def _segment(piece, p0, p1):
    if piece.kind == "line":
        return Segment(p0, p1)
    v = (p0 + p1) / 2 - piece.point
    v = v if v @ v > 1e-24 else piece.mid - piece.point
    through = piece.point + v / np.linalg.norm(v) * piece.radius
    if np.linalg.norm(through - piece.mid) > np.linalg.norm(2 * piece.point - through - piece.mid):
        through = 2 * piece.point - through                       # the arc is the side the data are on
    return Segment(p0, p1, piece.point.copy(), float(piece.radius), through)


def _density(count, a, b, r):
    """Points per unit area of surface (up to 2 pi) of a profile stretch from a to b at mean radius r."""
    return count / max(np.linalg.norm(b - a) * r, 1e-300)


def _stretches(chain, q, free, z_mid, min_support):
    """Free points (k, 2) between each pair of neighbouring pieces (by angle about (0, z_mid)), or None
    where fewer than `min_support` lie there or their density on the surface is under a fifth of the
    pieces' median (scattered outliers, not a stretch of surface)."""
    ang = _star(q[free], z_mid)
    typical = np.median([_density(p.support, *p.ends, np.mean(q[p.run, 0])) for p in chain])
    out = []
    for a, b in zip(chain, chain[1:]):
        lo, hi = _star(a.ends[1], z_mid), _star(b.ends[0], z_mid)
        pts = q[free[(ang > lo) & (ang < hi)]]
        dense = len(pts) >= min_support and _density(len(pts), a.ends[1], b.ends[0], np.mean(pts[:, 0])) > 0.2 * typical
        out.append(pts if dense else None)
    return out


def _absorb_into_stretches(chain, q, free, z_mid, min_support, near):
    """Drop conic pieces that a free-form stretch surrounds: a smooth curve is locally a line or an arc,
    and such a piece is that, not a face.  A piece goes when it borders a stretch and its chord is under a
    quarter of its own and its neighbouring stretches' chords together (a tenth for a line parallel or
    perpendicular to the axis: a cylinder or a shoulder is a designer's face), or when stretches on both
    sides leave it smoothly (within 20 deg, `_smooth_departure` within `near` mm) and it is no such
    axis-aligned line.  Returns (chain, free, stretches)."""
    def chord(a, b):
        return float(np.linalg.norm(b - a))

    while True:
        stretch = _stretches(chain, q, free, z_mid, min_support)
        for k in range(1, len(chain) - 1):
            piece, before, after = chain[k], stretch[k - 1], stretch[k]
            if before is None and after is None:
                continue
            own = chord(*piece.ends)
            around = ((chord(chain[k - 1].ends[1], piece.ends[0]) if before is not None else 0.0)
                      + (chord(piece.ends[1], chain[k + 1].ends[0]) if after is not None else 0.0))
            aligned = piece.kind == "line" and np.min(np.abs(piece.dir)) < 1e-12
            smooth = (before is not None and after is not None
                      and _smooth_departure(piece.ends[0], -_tangent(piece, 0), before, near)
                      and _smooth_departure(piece.ends[1], _tangent(piece, 1), after, near))
            if (smooth and not aligned) or own < (0.1 if aligned else 0.25) * (own + around):
                free = np.r_[free, piece.run]
                chain = chain[:k] + chain[k + 1:]
                break
        else:
            return chain, free, stretch


def _cut_back(piece, which, length, q):
    """A point `length` (mm) inside the piece from its end `which` (0: start, 1: end), and the piece's run
    points (k, 2) beyond it."""
    t = _tangent(piece, which)
    sign = -1.0 if which == 1 else 1.0
    p = piece.ends[which] + sign * length * t
    if piece.kind == "arc":
        p = piece.point + (p - piece.point) / np.linalg.norm(p - piece.point) * piece.radius
    pts = q[piece.run]
    return p, pts[sign * ((pts - p) @ t) < 0]


def _spline_joint(a, b, pts, q, thr, tol, statistic, near):
    """The B-spline Segment bridging piece a to piece b through the stretch points `pts` (k, 2), or None
    when they do not form a stretch (median distance above thr: scattered outliers).  At an end where the
    data leave the piece smoothly the spline is tangent to it and takes over a little earlier (a fifth of
    the piece, at most a quarter of the stretch): where a face blends into a free-form curve the data
    cannot tell the joint within thr, so the spline gets the blend and the face keeps its straight part."""
    ta, tb = _tangent(a, 1), _tangent(b, 0)
    start, end = a.ends[1], b.ends[0]
    span = np.linalg.norm(end - start)
    t0 = ta if _smooth_departure(start, ta, pts, near) else None
    t1 = tb if _smooth_departure(end, -tb, pts, near) else None
    data = [pts]
    if t0 is not None:
        start, extra = _cut_back(a, 1, min(0.2 * np.linalg.norm(np.subtract(*a.ends)), 0.25 * span), q)
        data.append(extra)
    if t1 is not None:
        end, extra = _cut_back(b, 0, min(0.2 * np.linalg.norm(np.subtract(*b.ends)), 0.25 * span), q)
        data.append(extra)
    data = np.vstack(data)
    try:
        fit = fit_spline_stretch(data, start, end, tol=tol, thr=thr, statistic=statistic, t0=t0, t1=t1)
    except GeometryError:
        return None
    if np.median(np.abs(spline_closest(fit.ctrl, fit.knots, pts)[1])) > thr:
        return None
    return Segment(start.copy(), end.copy(), ctrl=fit.ctrl, knots=fit.knots)


def fit_conic_profile(rz, *, thr: float, tol: float | None = None, statistic: str = "p95",
                      angle_tol: float = np.radians(1.0), close_to_axis: bool = True, seed: int = 0) -> Profile:
    """Lines, circular arcs and B-spline stretches through noisy profile points rz (n, 2) = (r, z).

    thr : inlier distance (model units), about 3 noise sigmas.  tol : the bound on `statistic` that
    B-spline stretches are refined to (default 4 thr).  Pieces need a contiguous run of at least
    max(20, 0.25 %) of the points; gaps longer than 4 % of the profile's extent end a run.  With
    `close_to_axis` a chain end within 5 % of the extent from r = 0 is extended to the axis.
    """
    rz = np.asarray(rz, float)
    if len(rz) < 20:
        raise GeometryError(f"a profile needs at least 20 points, got {len(rz)}")
    tol = 4 * thr if tol is None else tol
    extent = float(np.ptp(rz, axis=0).max())
    min_support = max(20, len(rz) // 400)
    pieces, free = _extract_pieces(rz, thr, 0.04 * extent, angle_tol, min_support, np.random.default_rng(seed))
    if not pieces:
        raise GeometryError("no line or arc explains the profile points")
    z_mid = float(np.median(rz[:, 1]))
    near = max(10 * thr, 0.02 * extent)
    chain, free, stretch = _absorb_into_stretches(_order(pieces, z_mid), rz, free, z_mid, min_support, near)
    chain, stretch = _merge_collinear(chain, stretch, thr, angle_tol)
    tangent = [s is None and _is_tangent(a, b, thr) for a, b, s in zip(chain, chain[1:], stretch)]
    for k in sorted((k for k, p in enumerate(chain) if p.kind == "arc"), key=lambda k: -chain[k].support):
        nbs = [chain[j] for j, flag in ((k - 1, k > 0 and tangent[k - 1]), (k + 1, k < len(tangent) and tangent[k]))
               if flag]
        if nbs:
            chain[k] = _refit_tangent_arc(chain[k], nbs, rz)
    joints = []   # per neighbouring pair: (end of the first, connecting Segment or None, start of the second)
    for k, (a, b) in enumerate(zip(chain, chain[1:])):
        bridge = None if stretch[k] is None else _spline_joint(a, b, stretch[k], rz, thr, tol, statistic, near)
        ref = (a.ends[1] + b.ends[0]) / 2
        cand = _intersections(a, b)
        if bridge is not None:
            joints.append((bridge.p0, bridge, bridge.p1))
        elif tangent[k]:
            p = _tangency(a, b)[1]
            joints.append((p, None, p))
        elif len(cand) and np.min(np.linalg.norm(cand - ref, axis=1)) < 0.1 * extent:
            p = cand[np.argmin(np.linalg.norm(cand - ref, axis=1))]
            joints.append((p, None, p))
        else:  # no nearby intersection: bridge the gap with a straight piece
            joints.append((a.ends[1], Segment(a.ends[1], b.ends[0]), b.ends[0]))
    first, last = chain[0].ends[0], chain[-1].ends[1]
    if close_to_axis:
        for which, piece in ((0, chain[0]), (1, chain[-1])):
            end = piece.ends[which]
            flat_end = piece.kind == "line" and abs(piece.dir[1]) < 1e-12   # an end face across the axis
            hit = _intersections(piece, _axis_piece(end[1])) if end[0] < 0.05 * extent or flat_end else []
            if len(hit):
                hit = hit[np.argmin(np.linalg.norm(hit - end, axis=1))]
                first, last = (hit, last) if which == 0 else (first, hit)
    segments, cur = [], first
    for k, piece in enumerate(chain):
        end, bridge, nxt = joints[k] if k < len(joints) else (last, None, None)
        segments.append(_segment(piece, cur, end))
        if bridge is not None:
            segments.append(bridge)
        cur = nxt
    return Profile(tuple(s for s in segments if np.linalg.norm(s.p1 - s.p0) > 1e-9))
