"""Planar profiles: lines, circular arcs and B-spline stretches in the (r, z) half plane.

`fit_conic_profile` turns a noisy 2-D point set (a surface of revolution's meridian section) into a chain
of pieces from axis to axis:

1. Conic pieces (lines and circular arcs) by sequential RANSAC with a lack-of-fit test; whatever no
   conic explains is free-form data (`rgm.fitters.profile_pieces`).
2. Free-form stretches surrounded by them drop pieces that are only the local shape of a smooth curve
   (`_absorb_into_stretches`: short beside the stretch, or left smoothly on both sides and not an
   axis-aligned face); then a stretch that one line or arc explains within noise on its own points is
   that conic (`_conic_stretches`): where a conic and a spline both fit to the noise level, the simpler
   model wins.
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

from rgm.errors import GeometryError
from rgm.fitters.profile_pieces import (Piece, along, conic_over, extract_pieces, intersections, is_tangent,
                                        refit_tangent_arc, tangency)
from rgm.fitters.profile_spline import fit_spline_stretch, spline_closest

__all__ = ["Segment", "Profile", "fit_conic_profile"]


@dataclass(frozen=True, eq=False)
class Segment:
    """One piece of a profile, points (2,) in (r, z): a line from p0 to p1 (center None); a circular arc
    (center, radius) from p0 to p1 through `through`; or a cubic B-spline (ctrl (n, 2), knots (n + 4,),
    p0 = ctrl[0], p1 = ctrl[-1]).  support: how many points the line or arc was fitted to (0 for a
    spline, a bridging line, or a segment not fitted to data), for the uncertainty of dimensions."""

    p0: np.ndarray
    p1: np.ndarray
    center: np.ndarray | None = None
    radius: float | None = None
    through: np.ndarray | None = None
    ctrl: np.ndarray | None = None
    knots: np.ndarray | None = None
    support: int = 0

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


# ------------------------------------------------------------------------------ chaining
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
    ccw = (along(piece, piece.mid[None])[0] <= along(piece, piece.ends[1][None])[0])
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
            out[-1] = Piece("line", point, prev.dir, None, ends, np.r_[prev.run, piece.run], (prev.mid + piece.mid) / 2)
            continue
        out.append(piece)
        gaps.append(stretch[k])
    return out, gaps


def _axis_piece(z):
    return Piece("line", np.array([0.0, z]), np.array([0.0, 1.0]), None, np.zeros((2, 2)), np.zeros(0, int),
                  np.zeros(2))


def _segment(piece, p0, p1):
    if piece.kind == "line":
        return Segment(p0, p1, support=piece.support)
    v = (p0 + p1) / 2 - piece.point
    v = v if v @ v > 1e-24 else piece.mid - piece.point
    through = piece.point + v / np.linalg.norm(v) * piece.radius
    if np.linalg.norm(through - piece.mid) > np.linalg.norm(2 * piece.point - through - piece.mid):
        through = 2 * piece.point - through                       # the arc is the side the data are on
    return Segment(p0, p1, piece.point.copy(), float(piece.radius), through, support=piece.support)


def _density(count, a, b, r):
    """Points per unit area of surface (up to 2 pi) of a profile stretch from a to b at mean radius r."""
    return count / max(np.linalg.norm(b - a) * r, 1e-300)


def _stretches(chain, q, free, z_mid, min_support):
    """Indices into q (k,) of the free points between each pair of neighbouring pieces (by angle about
    (0, z_mid)), or None where fewer than `min_support` lie there or their density on the surface is
    under a fifth of the pieces' median (scattered outliers, not a stretch of surface)."""
    ang = _star(q[free], z_mid)
    typical = np.median([_density(p.support, *p.ends, np.mean(q[p.run, 0])) for p in chain])
    out = []
    for a, b in zip(chain, chain[1:]):
        lo, hi = _star(a.ends[1], z_mid), _star(b.ends[0], z_mid)
        idx = free[(ang > lo) & (ang < hi)]
        dense = len(idx) >= min_support and _density(len(idx), a.ends[1], b.ends[0], np.mean(q[idx, 0])) > 0.2 * typical
        out.append(idx if dense else None)
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
                      and _smooth_departure(piece.ends[0], -_tangent(piece, 0), q[before], near)
                      and _smooth_departure(piece.ends[1], _tangent(piece, 1), q[after], near))
            if (smooth and not aligned) or own < (0.1 if aligned else 0.25) * (own + around):
                free = np.r_[free, piece.run]
                chain = chain[:k] + chain[k + 1:]
                break
        else:
            return chain, free, stretch


def _conic_stretches(chain, q, free, stretch, z_mid, thr, gap, angle_tol, min_support, rng):
    """Stretches that one line or arc explains within noise become that conic
    (`profile_pieces.conic_over`): where both a conic and a B-spline fit the data to the noise level the
    simpler model wins, so a short face that extraction missed among the whole profile's points (a
    chamfer seen by a few hundred of them) is not bridged by a spline.  Returns (chain, free, stretches)."""
    extent = float(np.ptp(q, axis=0).max())
    while True:
        for k, idx in enumerate(stretch):
            piece = None if idx is None else conic_over(idx, q, chain, thr, gap, angle_tol, min_support, extent, rng)
            if piece is not None:
                chain = _order(chain[:k + 1] + [piece] + chain[k + 1:], z_mid)
                free = np.setdiff1d(free, piece.run)
                stretch = _stretches(chain, q, free, z_mid, min_support)
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
    `close_to_axis` a chain end within 5 % of the extent from r = 0, an end face, or an arc end within a
    fifth of its radius of where its circle meets the axis (a dome's pole, where data thin out) is
    extended to the axis.
    """
    rz = np.asarray(rz, float)
    if len(rz) < 20:
        raise GeometryError(f"a profile needs at least 20 points, got {len(rz)}")
    tol = 4 * thr if tol is None else tol
    extent = float(np.ptp(rz, axis=0).max())
    min_support = max(20, len(rz) // 400)
    pieces, free = extract_pieces(rz, thr, 0.04 * extent, angle_tol, min_support, np.random.default_rng(seed))
    if not pieces:
        raise GeometryError("no line or arc explains the profile points")
    z_mid = float(np.median(rz[:, 1]))
    near = max(10 * thr, 0.02 * extent)
    chain, free, stretch = _absorb_into_stretches(_order(pieces, z_mid), rz, free, z_mid, min_support, near)
    chain, free, stretch = _conic_stretches(chain, rz, free, stretch, z_mid, thr, 0.04 * extent, angle_tol,
                                            min_support, np.random.default_rng(seed + 1))
    chain, stretch = _merge_collinear(chain, stretch, thr, angle_tol)
    tangent = [s is None and is_tangent(a, b, thr) for a, b, s in zip(chain, chain[1:], stretch)]
    for k in sorted((k for k, p in enumerate(chain) if p.kind == "arc"), key=lambda k: -chain[k].support):
        nbs = [chain[j] for j, flag in ((k - 1, k > 0 and tangent[k - 1]), (k + 1, k < len(tangent) and tangent[k]))
               if flag]
        if nbs:
            chain[k] = refit_tangent_arc(chain[k], nbs, rz)
    joints = []   # per neighbouring pair: (end of the first, connecting Segment or None, start of the second)
    for k, (a, b) in enumerate(zip(chain, chain[1:])):
        bridge = None if stretch[k] is None else _spline_joint(a, b, rz[stretch[k]], rz, thr, tol, statistic, near)
        ref = (a.ends[1] + b.ends[0]) / 2
        cand = intersections(a, b)
        if bridge is not None:
            joints.append((bridge.p0, bridge, bridge.p1))
        elif tangent[k]:
            p = tangency(a, b)[1]
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
            hit = intersections(piece, _axis_piece(end[1]))
            if not len(hit):
                continue
            hit = hit[np.argmin(np.linalg.norm(hit - end, axis=1))]
            flat_end = piece.kind == "line" and abs(piece.dir[1]) < 1e-12   # an end face across the axis
            pole = (piece.kind == "arc" and abs(np.linalg.norm(hit - piece.point) - piece.radius) < thr
                    and np.linalg.norm(hit - end) < 0.2 * piece.radius)     # a dome: data thin out at its pole
            if end[0] < 0.05 * extent or flat_end or pole:
                first, last = (hit, last) if which == 0 else (first, hit)
    segments, cur = [], first
    for k, piece in enumerate(chain):
        end, bridge, nxt = joints[k] if k < len(joints) else (last, None, None)
        segments.append(_segment(piece, cur, end))
        if bridge is not None:
            segments.append(bridge)
        cur = nxt
    return Profile(tuple(s for s in segments if np.linalg.norm(s.p1 - s.p0) > 1e-9))
