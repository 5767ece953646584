"""Planar profiles made of conic sections: lines and circular arcs in the (r, z) half plane.

`fit_conic_profile` segments a noisy 2-D point set (a surface of revolution's meridian section) into
straight lines and circular arcs by sequential RANSAC (Fischler & Bolles 1981) with least-squares
refinement (total least squares for lines; the geometric circle fit, Chernov 2010 ch. 4, for arcs), keeps
for every primitive only its largest contiguous run of inliers, snaps lines within `angle_tol` of the
axis directions (or whose ends would move by less than 2 thr) to exact axis-parallel/perpendicular lines (a designer's intent: a cylinder is r = R), and
chains the pieces from axis to axis, each vertex the intersection of neighbouring primitives (so
dimensions come from whole faces, not from noisy corner points).

`Profile.distance` is the exact Euclidean distance of points to the chain: for a full surface of
revolution the closest surface point lies in the point's own meridian half plane, so this is the exact
closest-point distance to the surface.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from rgm.errors import GeometryError

__all__ = ["Segment", "Profile", "fit_conic_profile"]


@dataclass(frozen=True)
class Segment:
    """A line (center None) or a circular arc from p0 to p1 through `through`; points are (2,) (r, z)."""

    p0: np.ndarray
    p1: np.ndarray
    center: np.ndarray | None = None
    radius: float | None = None
    through: np.ndarray | None = None

    @property
    def kind(self) -> str:
        return "line" if self.center is None else "arc"

    def distance(self, q) -> np.ndarray:
        """(m,) distance of points q (m, 2) to this segment."""
        if self.center is None:
            d = self.p1 - self.p0
            t = np.clip((q - self.p0) @ d / max(d @ d, 1e-300), 0.0, 1.0)
            return np.linalg.norm(q - (self.p0 + t[:, None] * d), axis=1)
        v = q - self.center
        ang = np.arctan2(v[:, 1], v[:, 0])
        a0, a1, am = (np.arctan2(*(p - self.center)[::-1]) for p in (self.p0, self.p1, self.through))
        span = (a1 - a0) % (2 * np.pi)
        ccw = (am - a0) % (2 * np.pi) <= span
        rel = (ang - a0) % (2 * np.pi) if ccw else (a0 - ang) % (2 * np.pi)
        width = span if ccw else 2 * np.pi - span
        on_arc = np.abs(np.linalg.norm(v, axis=1) - self.radius)
        ends = np.minimum(np.linalg.norm(q - self.p0, axis=1), np.linalg.norm(q - self.p1, axis=1))
        return np.where(rel <= width, on_arc, ends)


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


def _circle_fit(q, center0, radius0):
    sol = least_squares(lambda p: np.linalg.norm(q - p[:2], axis=1) - p[2], np.r_[center0, radius0])
    return sol.x[:2], abs(sol.x[2])


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
    point: np.ndarray      # line: a point; arc: centre
    dir: np.ndarray | None  # line: unit direction
    radius: float | None
    ends: np.ndarray        # (2, 2) extreme inliers along the primitive (0.5 and 99.5 percentiles)
    support: int
    mid: np.ndarray         # (2,) median of the inliers


def _residual(piece_kind, params, q):
    if piece_kind == "line":
        p, d = params
        return np.abs((q - p) @ np.array([-d[1], d[0]]))
    c, r = params
    return np.abs(np.linalg.norm(q - c, axis=1) - r)


def _largest_run(t, gap):
    order = np.argsort(t)
    breaks = np.flatnonzero(np.diff(t[order]) > gap)
    starts, stops = np.r_[0, breaks + 1], np.r_[breaks + 1, len(t)]
    k = int(np.argmax(stops - starts))
    return order[starts[k]:stops[k]]


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


def _best_hypothesis(q, sample, thr, extent, rng, hyp):
    i, j = rng.integers(0, len(sample), (2, hyp))
    a, b = sample[i], sample[j]
    d = b - a
    ok = np.linalg.norm(d, axis=1) > 3 * thr
    a, d = a[ok], d[ok] / np.linalg.norm(d[ok], axis=1, keepdims=True)
    n = np.column_stack([-d[:, 1], d[:, 0]])
    line_count = (np.abs((sample @ n.T) - np.sum(a * n, axis=1)) < thr).sum(axis=0)
    k = rng.integers(0, len(sample), (3, hyp))
    centre, rad = _circumcircles(sample[k[0]], sample[k[1]], sample[k[2]])
    ok = np.isfinite(rad) & (rad > 5 * thr) & (rad < 2 * extent)
    centre, rad = centre[ok], rad[ok]
    dist = np.linalg.norm(sample[:, None, :] - centre[None], axis=2)
    circle_count = (np.abs(dist - rad) < thr).sum(axis=0) if len(rad) else np.zeros(0, int)
    best_line = int(np.argmax(line_count)) if len(line_count) else None
    best_circle = int(np.argmax(circle_count)) if len(circle_count) else None
    lc = line_count[best_line] if best_line is not None else 0
    cc = circle_count[best_circle] if best_circle is not None else 0
    if lc >= 0.85 * cc and best_line is not None:  # Occam: a line unless an arc explains clearly more
        return "line", (a[best_line], d[best_line])
    if best_circle is None:
        return None, None
    return "arc", (centre[best_circle], rad[best_circle])


def _extract_pieces(q, thr, gap, angle_tol, min_support, rng):
    extent = float(np.ptp(q, axis=0).max())
    pool = np.arange(len(q))
    pieces = []
    while len(pool) >= min_support and len(pieces) < 40:
        sample = q[pool[rng.choice(len(pool), min(len(pool), 2500), replace=False)]]
        kind, params = _best_hypothesis(q[pool], sample, thr, extent, rng, 300)
        if kind is None:
            break
        for _ in range(3):  # inliers -> least squares -> inliers
            inl = pool[_residual(kind, params, q[pool]) < thr]
            if len(inl) < 3:
                break
            if kind == "line":
                params = _snap(*_line_tls(q[inl]), q[inl], angle_tol, thr)
            else:
                params = _circle_fit(q[inl], *params)
        if len(inl) < min_support:
            break
        if kind == "line":
            t = (q[inl] - params[0]) @ params[1]
        else:
            v = q[inl] - params[0]
            ang = np.arctan2(v[:, 1], v[:, 0])
            shift = ang[np.argmax(np.diff(np.sort(ang), append=np.sort(ang)[0] + 2 * np.pi))]
            t = ((ang - shift) % (2 * np.pi)) * params[1]
        local = _largest_run(t, gap)
        run, trun = inl[local], t[local]
        if len(run) < min_support:
            break
        lo, hi = np.percentile(trun, [0.5, 99.5])
        ends = q[run][[np.argmin(np.abs(trun - lo)), np.argmin(np.abs(trun - hi))]]
        mid = np.median(q[run], axis=0)
        if kind == "arc":  # an arc whose sagitta over its run is within the threshold is a line
            half = np.linalg.norm(ends[1] - ends[0]) / 2
            if params[1] - np.sqrt(max(params[1] ** 2 - half ** 2, 0.0)) < 2 * thr and np.ptp(trun) < params[1] * np.pi:
                kind, params = "line", _snap(*_line_tls(q[run]), q[run], angle_tol, thr)
                t = (q[run] - params[0]) @ params[1]
                lo, hi = np.percentile(t, [0.5, 99.5])
                ends = q[run][[np.argmin(np.abs(t - lo)), np.argmin(np.abs(t - hi))]]
        if kind == "line":
            ends = params[0] + np.outer(((ends - params[0]) @ params[1]), params[1])
            pieces.append(_Piece("line", params[0], params[1], None, ends, len(run), mid))
        else:
            ends = params[0] + (ends - params[0]) / np.linalg.norm(ends - params[0], axis=1, keepdims=True) * params[1]
            pieces.append(_Piece("arc", params[0], None, params[1], ends, len(run), mid))
        pool = np.setdiff1d(pool, run, assume_unique=True)
    return pieces


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
        if disc < 0:
            s = np.array([-bq / 2])  # tangent-ish: nearest point of the line to the circle
        else:
            s = (-bq + np.array([-1, 1]) * np.sqrt(disc)) / 2
        return a.point + s[:, None] * a.dir
    d = np.linalg.norm(b.point - a.point)
    if d < 1e-12 or d > a.radius + b.radius or d < abs(a.radius - b.radius):
        return np.zeros((0, 2))
    x = (d * d + a.radius ** 2 - b.radius ** 2) / (2 * d)
    h = np.sqrt(max(a.radius ** 2 - x * x, 0.0))
    u = (b.point - a.point) / d
    base = a.point + x * u
    return base + np.outer([-h, h], [-u[1], u[0]])


def _order(pieces, z_mid):
    """Chain the pieces as the profile runs from the axis at its lowest z outwards and back to the axis at
    its highest z: by the angle atan2(z - z_mid, r) of each piece's median point, seen from the axis
    point (0, z_mid) (exact for profiles star-shaped about that point, as turned parts nearly always
    are).  Each piece's ends are oriented the same way."""
    def angle(p):
        return np.arctan2(p[..., 1] - z_mid, p[..., 0])

    chain = []
    for piece in sorted(pieces, key=lambda pc: angle(pc.mid)):
        ends = piece.ends if angle(piece.ends[0]) <= angle(piece.ends[1]) else piece.ends[::-1]
        chain.append((piece, ends))
    return chain


def _merge_collinear(chain, thr, angle_tol):
    """Join neighbouring lines of the chain that are one line (same direction within angle_tol, offset
    within thr): a face seen in two views with a gap between them."""
    out = [chain[0]]
    for piece, ends in chain[1:]:
        prev, pends = out[-1]
        if piece.kind == prev.kind == "line" and abs(piece.dir @ prev.dir) > np.cos(angle_tol):
            normal = np.array([-prev.dir[1], prev.dir[0]])
            if abs((piece.point - prev.point) @ normal) < thr:
                w = prev.support / (prev.support + piece.support)
                point = w * prev.point + (1 - w) * (piece.point - ((piece.point - prev.point) @ prev.dir) * prev.dir)
                new_ends = np.array([pends[0], ends[1]])
                new_ends = point + np.outer((new_ends - point) @ prev.dir, prev.dir)
                out[-1] = (_Piece("line", point, prev.dir, None, new_ends, prev.support + piece.support,
                                  (prev.mid + piece.mid) / 2), new_ends)
                continue
        out.append((piece, ends))
    return out


def _axis_piece(z):
    return _Piece("line", np.array([0.0, z]), np.array([0.0, 1.0]), None, np.zeros((2, 2)), 0, np.zeros(2))


def _segment(piece, p0, p1, ends):
    if piece.kind == "line":
        return Segment(p0, p1)
    mid_data = (ends[0] + ends[1]) / 2 - piece.point
    through = piece.point + mid_data / max(np.linalg.norm(mid_data), 1e-300) * piece.radius
    return Segment(p0, p1, piece.point.copy(), float(piece.radius), through)


def fit_conic_profile(rz, *, thr: float, angle_tol: float = np.radians(1.0), close_to_axis: bool = True,
                      seed: int = 0) -> Profile:
    """Lines and circular arcs through noisy profile points rz (n, 2) = (r, z).

    thr : inlier distance (model units), about 3 noise sigmas.  Pieces need a contiguous run of at least
    max(20, 0.25 %) of the points; gaps longer than 4 % of the profile's extent end a run.  With
    `close_to_axis` a chain end within 5 % of the extent from r = 0 is extended to the axis.
    """
    rz = np.asarray(rz, float)
    if len(rz) < 20:
        raise GeometryError(f"a profile needs at least 20 points, got {len(rz)}")
    extent = float(np.ptp(rz, axis=0).max())
    rng = np.random.default_rng(seed)
    pieces = _extract_pieces(rz, thr, 0.04 * extent, angle_tol, max(20, len(rz) // 400), rng)
    if not pieces:
        raise GeometryError("no line or arc explains the profile points")
    chain = _merge_collinear(_order(pieces, float(np.median(rz[:, 1]))), thr, angle_tol)
    pts = []
    for (a, ea), (b, eb) in zip(chain, chain[1:]):
        cand = _intersections(a, b)
        ref = (ea[1] + eb[0]) / 2
        if len(cand) and np.min(np.linalg.norm(cand - ref, axis=1)) < 0.1 * extent:
            pts.append([cand[np.argmin(np.linalg.norm(cand - ref, axis=1))]])
        else:  # no nearby intersection: bridge the gap with a straight piece
            pts.append([ea[1], eb[0]])
    first, last = chain[0][1][0], chain[-1][1][1]
    if close_to_axis:
        for end, piece, which in ((first, chain[0][0], 0), (last, chain[-1][0], 1)):
            flat_end = piece.kind == "line" and abs(piece.dir[1]) < 1e-12   # an end face across the axis
            if end[0] < 0.05 * extent or flat_end:
                hit = _intersections(piece, _axis_piece(end[1]))
                if len(hit):
                    hit = hit[np.argmin(np.linalg.norm(hit - end, axis=1))]
                    if which == 0:
                        first = hit
                    else:
                        last = hit
    segments, cur = [], first
    for k, (piece, ends) in enumerate(chain):
        joint = pts[k] if k < len(pts) else [last]
        segments.append(_segment(piece, cur, joint[0], ends))
        if len(joint) == 2:
            segments.append(Segment(joint[0], joint[1]))
        cur = joint[-1]
    return Profile(tuple(s for s in segments if np.linalg.norm(s.p1 - s.p0) > 1e-9))
