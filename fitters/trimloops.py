"""Trimming loops: where the data is, in a surface's parameter space.

A range image's valid-pixel mask (or a rasterised cover of scattered parameters) is contoured by marching
squares at the half-way level between valid and invalid cells, giving closed polygons in (u, v). Each is
classified as an outer boundary (counter-clockwise) or a hole (clockwise, inside an outer one) and fitted
by closed 2-D B-spline pieces (split at corners) refined by knot insertion until they stay within the
loop tolerance, so the trimmed
surface is valid only where data was.

The loops are valid trimming loops (`check_loops`: each simple, the holes inside the outer boundary and
apart from it and from each other, on dense samples; `crossing_pairs`, a vectorised sweep). Where a region
is a cell or two wide (a neck, a spike, a thin wall before a hole), contour vertices snapped to their
nearest data points may land on or past each other, and a fit at the tolerance may cut across: such
snaps are held back, and pieces whose fit would cross are fitted closer (as a last resort, as the contour
polyline itself). A piece of data touching the face only at a cell corner (a pinch) is another component,
left outside the trim. `TrimLoops.notes` says what was done.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from rgm.errors import GeometryError
from rgm.fitters.freeform import CurveFit, design_matrix, fit_curve

# Marching-squares segments per case; corners are bit 1 = (i, j), 2 = (i, j+1), 4 = (i+1, j+1),
# 8 = (i+1, j); edges 0 = top (i, j..j+1), 1 = right, 2 = bottom, 3 = left. Segments run with the
# inside on their left, so outer boundaries come out counter-clockwise in (row, col) = (u, v).
_SEGMENTS = {
    1: [(3, 0)], 2: [(0, 1)], 3: [(3, 1)], 4: [(1, 2)], 5: [(3, 0), (1, 2)], 6: [(0, 2)], 7: [(3, 2)],
    8: [(2, 3)], 9: [(2, 0)], 10: [(0, 1), (2, 3)], 11: [(2, 1)], 12: [(1, 3)], 13: [(1, 0)], 14: [(0, 3)],
}
_EDGE_OFFSET = np.array([[0.0, 0.5], [0.5, 1.0], [1.0, 0.5], [0.5, 0.0]])  # (di, dj) of each edge midpoint


def mask_contours(mask: np.ndarray) -> list[np.ndarray]:
    """Closed polygons (k, 2) in (row, col) pixel coordinates around the True regions of `mask`.

    Outer boundaries run one way and holes the other (checked by signed area downstream)."""
    m = np.pad(np.asarray(mask, bool), 1)
    case = (m[:-1, :-1] * 1 + m[:-1, 1:] * 2 + m[1:, 1:] * 4 + m[1:, :-1] * 8).astype(np.int8)
    seg_a, seg_b = [], []
    for c, segs in _SEGMENTS.items():  # 14 cases, each vectorised over all cells
        ii, jj = np.nonzero(case == c)
        base = np.stack([ii, jj], axis=1).astype(float) - 1.0  # undo the padding
        for ea, eb in segs:
            seg_a.append(base + _EDGE_OFFSET[ea])
            seg_b.append(base + _EDGE_OFFSET[eb])
    if not seg_a:
        return []
    a, b = np.concatenate(seg_a), np.concatenate(seg_b)
    key = lambda p: (int(round(p[0] * 2)), int(round(p[1] * 2)))  # noqa: E731 (half-pixel lattice)
    nxt = {key(p): i for i, p in enumerate(a)}
    used = np.zeros(len(a), bool)
    loops = []
    for start in range(len(a)):  # linking is O(boundary length), not per pixel
        if used[start]:
            continue
        chain, i = [], start
        while not used[i]:
            used[i] = True
            chain.append(a[i])
            i = nxt.get(key(b[i]))
            if i is None:
                break
        if len(chain) >= 4:
            loops.append(np.array(chain))
    return loops


def signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def corner_indices(poly: np.ndarray, window: int = 3, angle: float = np.deg2rad(50),
                   min_gap: int = 12) -> np.ndarray:
    """Vertices of a closed polygon (k, 2) where the boundary turns by more than `angle` (radians),
    judged over `window` vertices on each side so that a pixel staircase does not count as corners."""
    k = len(poly)
    if k < 2 * window + 2:
        return np.zeros(0, int)
    a = poly - np.roll(poly, window, axis=0)
    b = np.roll(poly, -window, axis=0) - poly
    cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
    turn = np.arccos(np.clip(cos, -1, 1))
    left = np.max([np.roll(turn, s) for s in range(1, window + 1)], axis=0)
    right = np.max([np.roll(turn, -s) for s in range(1, window + 1)], axis=0)
    peak = (turn > left) & (turn >= right)  # one vertex per corner, even on a plateau
    idx = np.nonzero(peak & (turn > angle))[0]
    if len(idx) < 2:
        return idx
    min_gap = max(3, min(min_gap, k // 10))
    keep = [idx[0]]          # corners closer than `min_gap` vertices: keep the sharper (a ragged edge)
    for i in idx[1:]:
        if i - keep[-1] < min_gap:
            if turn[i] > turn[keep[-1]]:
                keep[-1] = i
        else:
            keep.append(i)
    if len(keep) > 1 and keep[0] + k - keep[-1] < min_gap:
        keep.pop(0 if turn[keep[0]] < turn[keep[-1]] else -1)
    return np.array(keep)


def _densify(poly: np.ndarray, per_edge: int = 4) -> np.ndarray:
    """An open polyline (k, 2) with `per_edge` evenly spaced points on every edge, and on an edge over twice
    the median length (a jump across a stretch with no samples, as where a loop is rebuilt between shared
    edges) as many as its length holds median edges times `per_edge`, so that a least-squares fit has data
    in every knot span it may create and cannot swing away between its points."""
    a, b = poly[:-1], poly[1:]
    length = np.linalg.norm(b - a, axis=1)
    typical = float(np.median(length)) if len(length) else 0.0
    long = length > 2 * typical if typical > 0 else np.zeros(len(length), bool)   # (most edges of zero length)
    n = np.full(len(length), per_edge)
    n[long] = np.ceil(per_edge * length[long] / typical).astype(int)
    first = np.repeat(np.cumsum(n) - n, n)                        # each point's edge's first point
    t = (np.arange(n.sum()) - first) / np.repeat(n, n)            # j / n on every edge, without a loop
    pts = np.repeat(a, n, axis=0) + t[:, None] * np.repeat(b - a, n, axis=0)
    return np.vstack([pts, poly[-1:]])


def _fit_segments(poly: np.ndarray, cuts, tol_uv: float, degree: int, band=None) -> tuple[CurveFit, ...]:
    """B-spline pieces through the stretches poly[a:b + 1] of an open polyline between consecutive `cuts`
    (vertex indices), each refined by knot insertion to `tol_uv` with its ends fixed on the vertices; a
    stretch along an end of `band` (`_on_band`) is the straight line between its ends."""
    pieces = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        seg = poly[a:b + 1]
        if _band_line(seg, band):
            pieces.append(_polyline_piece(seg[[0, -1]], tol_uv))
        else:
            pieces.append(fit_curve(_densify(seg), tol_uv, degree=min(degree, len(seg) - 1), fix_ends=True))
    return tuple(pieces)


def _band_clipped(poly: np.ndarray, band) -> np.ndarray:
    """A closed polygon (k, 2) with u clipped to `band` (u0, u1), each run of vertices on an end reduced to
    its first and last (the run is a straight piece: a contour that went past the end and came back
    would otherwise double back along it)."""
    p = _distinct(np.c_[np.clip(poly[:, 0], *band), poly[:, 1]])
    u = p[:, 0]
    inner = np.isin(u, band) & (u == np.roll(u, 1)) & (u == np.roll(u, -1))
    return p if inner.all() else p[~inner]


def _band_line(seg: np.ndarray, band) -> bool:
    """Whether every vertex of the polyline `seg` lies on an end of `band` (u0, u1): a straight piece."""
    return band is not None and bool(np.isin(seg[:, 0], band).all())


def _on_band(uv: np.ndarray, band, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """The polyline uv (k, 2) with vertices within 1e-9 of u = u0 or u1 of `band` put exactly on it, and
    the indices where a run of such vertices starts or ends (the cuts that make a run one straight piece)."""
    uv = np.array(uv, float)
    for end in band:
        uv[np.abs(uv[:, 0] - end) <= 1e-9, 0] = end
    on = np.isin(uv[:, 0], band)
    before, after = np.roll(on, 1), np.roll(on, -1)
    if not closed:
        before[0] = after[-1] = False
    return uv, np.flatnonzero(on & ~(before & after)) if not on.all() else np.zeros(0, int)


def fit_closed_loop(uv: np.ndarray, tol_uv: float, degree: int = 3) -> tuple[CurveFit, ...]:
    """Closed polygon (k, 2) -> consecutive B-spline pieces, split at corners (C0 there, smooth between),
    each refined by knot insertion to `tol_uv`; the pieces share their end points, so the loop closes."""
    corners = corner_indices(uv)
    if len(corners) == 0:
        return (fit_curve(_densify(np.vstack([uv, uv[:1]])), tol_uv, degree=degree, fix_ends=True),)
    rolled = np.vstack([np.roll(uv, -corners[0], axis=0), uv[corners[0]]])
    return _fit_segments(rolled, np.r_[corners - corners[0], len(uv)], tol_uv, degree)


def fit_open_chain(uv: np.ndarray, tol_uv: float, degree: int = 3, band=None) -> tuple[CurveFit, ...]:
    """Open polyline (k, 2), k >= 2 -> consecutive B-spline pieces from its first vertex to its last
    (which they keep exactly: the chain joins what lies beyond its ends), split at its corners as a
    closed loop is (`corner_indices`, judged away from the ends) and each refined to `tol_uv`. With
    `band` (u0, u1), its runs along u = u0 or u1 stay straight pieces on them (`fit_trim_loops`)."""
    uv = np.asarray(uv, float)
    w = 3
    inner = corner_indices(uv, window=w) if len(uv) >= 2 * w + 2 else np.zeros(0, int)
    inner = inner[(inner >= w) & (inner <= len(uv) - 1 - w)]   # a closed polygon's wrap-around is no corner
    if band is not None:
        uv, runs = _on_band(uv, band, closed=False)
        inner = np.union1d(inner, runs[(runs > 0) & (runs < len(uv) - 1)])
    return _fit_segments(uv, np.r_[0, inner, len(uv) - 1], tol_uv, degree, band)


def loop_stats_max(loop: tuple[CurveFit, ...]) -> float:
    return max(piece.stats.max for piece in loop)


# ------------------------------------------------------------------------------- validity of loops
def _orient(p, q, r, eps):
    """Sign (-1, 0, 1) of the turn p -> q -> r, 0 within `eps` (a cross product's scale)."""
    c = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    return np.where(np.abs(c) <= eps, 0, np.sign(c))


def crossing_pairs(loops, chunk: int = 1 << 21) -> np.ndarray:
    """Pairs of edges of closed polygons `loops` (each (k, 2), the last vertex joined to the first) that
    cross or touch, other than consecutive edges of one polygon (which share their vertex): (m, 4) rows
    (loop a, edge a, loop b, edge b); edge e of a loop runs from its vertex e to vertex e + 1. A vectorised
    sweep: edges sorted by their smallest x, each tested against those whose x-range starts within its
    own, then by y-range and the four orientations (collinear overlaps and touching vertices count)."""
    loops = [np.asarray(p, float) for p in loops]
    if not loops:
        return np.zeros((0, 4), int)
    a = np.vstack(loops)
    b = np.vstack([np.roll(p, -1, axis=0) for p in loops])
    lid = np.concatenate([np.full(len(p), k) for k, p in enumerate(loops)])
    sid = np.concatenate([np.arange(len(p)) for p in loops])
    size = np.array([len(p) for p in loops])[lid]
    scale = max(float(np.ptp(a, axis=0).max()), 1e-300)
    eps = 1e-12 * scale * scale
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.argsort(lo[:, 0], kind="stable")
    stop = np.searchsorted(lo[order, 0], hi[order, 0], side="right")   # sorted edges i+1 .. stop-1
    count = np.maximum(stop - np.arange(len(a)) - 1, 0)
    out = []
    first = 0
    while first < len(a):   # rows of sorted edges whose candidate pairs fit in one chunk
        last = first + max(1, int(np.searchsorted(np.cumsum(count[first:]), chunk, side="right")))
        rows = np.arange(first, min(last, len(a)))
        first = rows[-1] + 1
        n = count[rows]
        if n.sum() == 0:
            continue
        i = np.repeat(rows, n)
        j = i + 1 + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        p, q = order[i], order[j]
        keep = (lo[p, 1] <= hi[q, 1]) & (lo[q, 1] <= hi[p, 1])
        gap = np.abs(sid[p] - sid[q])
        keep &= ~((lid[p] == lid[q]) & ((gap == 1) | (gap == size[p] - 1)))
        p, q = p[keep], q[keep]
        hit = ((_orient(a[p], b[p], a[q], eps) * _orient(a[p], b[p], b[q], eps) <= 0)
               & (_orient(a[q], b[q], a[p], eps) * _orient(a[q], b[q], b[p], eps) <= 0))
        out.append(np.c_[lid[p][hit], sid[p][hit], lid[q][hit], sid[q][hit]])
    return np.vstack(out) if out else np.zeros((0, 4), int)


def is_simple(poly: np.ndarray) -> bool:
    """Whether a closed polygon (k, 2) neither crosses nor touches itself."""
    return len(crossing_pairs([_distinct(poly)])) == 0


def crosses_itself(chain: np.ndarray) -> bool:
    """Whether an open polyline (k, 2) crosses or touches itself (repeated consecutive vertices aside)."""
    chain = np.asarray(chain, float)
    chain = chain[np.r_[True, np.any(np.diff(chain, axis=0) != 0, axis=1)]]
    pairs = crossing_pairs([chain])     # closed: the edge from the last vertex back to the first is not its own
    return bool(np.any((pairs[:, [1, 3]] < len(chain) - 1).all(axis=1)))


def _inside(point: np.ndarray, poly: np.ndarray) -> bool:
    """Whether `point` (2,) lies inside the closed polygon (k, 2) (even-odd rule)."""
    x, y = point
    a, b = poly, np.roll(poly, -1, axis=0)
    up = (a[:, 1] > y) != (b[:, 1] > y)
    t = (y - a[up, 1]) / (b[up, 1] - a[up, 1])
    return bool(np.sum(a[up, 0] + t * (b[up, 0] - a[up, 0]) > x) % 2)


def _distinct(poly: np.ndarray) -> np.ndarray:
    """A closed polygon without repeated consecutive vertices (nor a last vertex repeating the first)."""
    poly = np.asarray(poly, float)
    keep = np.any(poly != np.roll(poly, 1, axis=0), axis=1)
    return poly[keep] if keep.any() else poly[:1]


def _loop_problems(polys) -> tuple[list[tuple[int, int]], list[str]]:
    """What makes closed polygons polys[0] (the outer boundary) and polys[1:] (its holes) invalid trimming
    loops: (loop, edge) pairs involved in a crossing or touch, and what is wrong, in words. Valid: both
    empty. A hole must lie inside the outer boundary and outside the other holes."""
    bad, why = [], []
    pairs = crossing_pairs(polys)
    if len(pairs):
        bad += [(int(la), int(ea)) for la, ea, _, _ in pairs] + [(int(lb), int(eb)) for _, _, lb, eb in pairs]
        own = pairs[:, 0] == pairs[:, 2]
        if own.any():
            why.append(f"{int(own.sum())} crossings of loops with themselves")
        if (~own).any():
            why.append(f"{int((~own).sum())} crossings between loops")
    for k, hole in enumerate(polys[1:], 1):
        if len(pairs) and np.any((pairs[:, 0] == k) | (pairs[:, 2] == k)):
            continue   # crossing: already said
        if not _inside(hole[0], polys[0]) or any(_inside(hole[0], other) for m, other in enumerate(polys[1:], 1)
                                                 if m != k):
            bad += [(k, e) for e in range(len(hole))]
            why.append(f"hole {k} outside the outer boundary or inside another hole")
    return bad, why


def loop_samples(loop: tuple[CurveFit, ...], per_ctrl: int = 16, min_per_piece: int = 64):
    """Dense samples of a closed loop of pieces: points (m, 2) (each piece's last point, the next one's
    first, given once; no point repeating the one before) and the piece each sample's outgoing edge
    belongs to (m,). Each piece's first and last sample spans are subdivided geometrically (halved 8
    times): at a sharp corner two pieces leave nearly along each other, and may cross just by it."""
    pts, owner = [], []
    for k, piece in enumerate(loop):
        m = max(min_per_piece, per_ctrl * len(piece.ctrl))
        end = 0.5 ** np.arange(8, 0, -1) / (m - 1)
        t = np.unique(np.r_[np.linspace(0.0, 1.0, m), end, 1.0 - end])
        pts.append((design_matrix(t, piece.knots, piece.degree) @ piece.ctrl)[:-1])
        owner.append(np.full(len(t) - 1, k))
    pts, owner = np.vstack(pts), np.concatenate(owner)
    keep = np.any(pts != np.roll(pts, 1, axis=0), axis=1)   # no zero-length edges (a clamped piece)
    return (pts[keep], owner[keep]) if keep.any() else (pts[:1], owner[:1])


def polygon_problems(polys) -> list[str]:
    """What is wrong with closed polygons polys[0] (the outer boundary) and polys[1:] (its holes) as
    trimming loops (`_loop_problems`, in words). Empty: valid."""
    return _loop_problems(polys)[1]


def check_loops(outer: tuple[CurveFit, ...], holes=()) -> list[str]:
    """What is wrong with fitted trimming loops (dense samples of each): a loop crossing or touching
    itself, two loops crossing, a hole outside the outer boundary or inside another. Empty: valid."""
    return _loop_problems([loop_samples(loop)[0] for loop in (outer, *holes)])[1]


@dataclass(frozen=True)
class TrimLoops:
    """Closed loops of 2-D B-spline pieces in the surface's (u, v) domain: one outer boundary
    (counter-clockwise) and its holes (clockwise); simple, holes inside the outer boundary and apart."""

    outer: tuple[CurveFit, ...]
    holes: tuple[tuple[CurveFit, ...], ...]
    dropped: int  # further outer components (separate pieces of data) not covered by this face
    notes: tuple = ()   # what was done to keep the loops valid (said in the fit's notes)
    band: tuple | None = None   # (u0, u1): the loops run straight along these iso-lines (`fit_trim_loops`)


#: how far (in pixels) the loops run beyond a grid's outermost rows and columns, where the contour (half a
#: pixel out) meets the image border: the data there stay inside the trim, the loops inside the domain
BORDER_REACH = 0.25


def _along(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Parameters at fractional pixel positions x along one grid direction with parameters t (n,)
    (increasing): linear between pixels, extended by the end steps up to BORDER_REACH beyond the ends."""
    n = len(t)
    x = np.clip(x, -BORDER_REACH, n - 1 + BORDER_REACH)
    y = np.interp(x, np.arange(n), t)
    if n > 1:
        y = np.where(x < 0, t[0] + x * (t[1] - t[0]), y)
        y = np.where(x > n - 1, t[-1] + (x - (n - 1)) * (t[-1] - t[-2]), y)
    return y


def _to_uv(poly_px, u_of_row, v_of_col):
    return np.c_[_along(poly_px[:, 0], u_of_row), _along(poly_px[:, 1], v_of_col)]


def _snapped(raw: list[np.ndarray], tree, rounds: int = 200) -> tuple[list[np.ndarray], int]:
    """The polygons `raw` (the contours in (u, v), jointly valid) with each vertex moved to its nearest data
    point, except where that makes the loops cross or touch (in a region a cell or two wide, vertices of
    both sides may snap to the same point, or past each other): for each crossing or touching pair of
    edges, the one of their vertices that moved farthest goes half-way back to its contour position (all
    the way the second time), until none is left. Returns the polygons and how many vertices were held
    back."""
    near = [tree.data[tree.query(p)[1]] for p in raw]
    moved = [np.linalg.norm(s - p, axis=1) for p, s in zip(raw, near)]
    snap = [np.ones(len(p)) for p in raw]     # how far each vertex goes towards its data point
    for _ in range(rounds):
        polys, index = [], []
        for p, s, flag in zip(raw, near, snap):
            q = p + flag[:, None] * (s - p)
            keep = np.any(q != np.roll(q, 1, axis=0), axis=1)
            keep = keep if keep.any() else np.r_[True, np.zeros(len(q) - 1, bool)]
            polys.append(q[keep])
            index.append(np.nonzero(keep)[0])
        pairs = crossing_pairs(polys)
        if not len(pairs):
            pairs = np.array([(k, e, k, e) for k, e in _loop_problems(polys)[0]]).reshape(-1, 4)
        if not len(pairs):
            return polys, int(sum((s < 1).sum() for s in snap))
        reverted = set()
        for la, ea, lb, eb in pairs:   # the raw vertices behind each edge's ends (merged ones included)
            cand = []
            for loop, edge in ((la, ea), (lb, eb)):
                idx, n = index[loop], len(raw[loop])
                a, b = idx[edge], idx[(edge + 1) % len(idx)]
                span = np.arange(a, a + (b - a) % n + 1) % n if len(idx) > 1 else np.arange(n)
                span = np.unique(np.r_[span, (a - 1) % n])     # a vertex merged into the edge's start
                cand += [(snap[loop][v] * moved[loop][v], loop, v) for v in span if snap[loop][v] > 0]
            if cand and not reverted.intersection((c[1], c[2]) for c in cand):
                _, loop, v = max(cand)
                snap[loop][v] = 0.5 if snap[loop][v] == 1 else 0.0
                reverted.add((loop, v))
        if not reverted:
            break
    return [_distinct(p) for p in raw], int(sum(len(p) for p in raw))


def _stretches(uv: np.ndarray, band=None) -> list[np.ndarray]:
    """A closed polygon (k, 2) cut at its corners (`corner_indices`) into open polylines, each from a
    corner to the next (the last vertex of one the first of the next); one closed stretch if no corner.
    With `band` (u0, u1), also cut where a run of vertices on u = u0 or u = u1 starts and ends."""
    corners = corner_indices(uv)
    if band is not None:
        corners = np.union1d(corners, _on_band(uv, band, closed=True)[1])
    if len(corners) == 0:
        return [np.vstack([uv, uv[:1]])]
    rolled = np.vstack([np.roll(uv, -corners[0], axis=0), uv[corners[0]]])
    cuts = np.r_[corners - corners[0], len(uv)]
    return [rolled[a:b + 1] for a, b in zip(cuts[:-1], cuts[1:])]


def _polyline_piece(seg: np.ndarray, tol_uv: float) -> CurveFit:
    """The stretch itself as a degree-1 B-spline (exact: residual 0)."""
    from rgm.fitters.freeform import fit_stats

    t = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(seg, axis=0), axis=1))]
    t = t / t[-1]
    return CurveFit(1, np.r_[0.0, t, 1.0], seg.copy(), fit_stats(np.zeros(len(seg)), tol_uv, "max"))


def _fit_stretch(seg: np.ndarray, tol_uv: float, degree: int, lo, hi, exact: bool = False) -> CurveFit:
    if exact or len(seg) < 3:
        piece = _polyline_piece(seg, tol_uv)
    else:
        piece = fit_curve(_densify(seg), tol_uv, degree=min(degree, len(seg) - 1), fix_ends=True)
    # the control polygon is clamped into the domain, so (convex hull) the loop stays inside it
    return replace(piece, ctrl=np.clip(piece.ctrl, lo, hi))


def _fit_valid(polys: list[np.ndarray], tol_uv: float, degree: int, lo, hi, rounds: int = 5, band=None):
    """Loops of B-spline pieces through the jointly valid polygons `polys` (outer first), each piece within
    `tol_uv`; where the fitted loops cross or touch (a fit cutting across a narrow neck or corner, a hole's
    loop meeting the outer one) the pieces involved are fitted again to half the tolerance, up to `rounds`
    times, and failing that are the polygon's stretch itself (degree 1), which cannot cross. A stretch
    along an end of `band` (u0, u1) is the straight line from its first vertex to its last, exactly on it.
    Returns the loops and the number of pieces tightened and of pieces made polylines."""
    stretches = [_stretches(p, band) for p in polys]
    stretches = [[s[[0, -1]] if _band_line(s, band) else s for s in ss] for ss in stretches]
    tols = [np.full(len(s), tol_uv) for s in stretches]
    loops = [[_fit_stretch(s, tol_uv, degree, lo, hi) for s in ss] for ss in stretches]
    tightened, exact = set(), set()
    for attempt in range(rounds + 1):
        samples = [loop_samples(tuple(lp)) for lp in loops]
        bad, _ = _loop_problems([pts for pts, _ in samples])
        if not bad:
            break
        for loop, piece in {(lp, int(samples[lp][1][e])) for lp, e in bad}:
            if attempt < rounds:
                tols[loop][piece] /= 2
                tightened.add((loop, piece))
                loops[loop][piece] = _fit_stretch(stretches[loop][piece], tols[loop][piece], degree, lo, hi)
            else:
                exact.add((loop, piece))
                loops[loop][piece] = _fit_stretch(stretches[loop][piece], tol_uv, degree, lo, hi, exact=True)
    return [tuple(lp) for lp in loops], len(tightened - exact), len(exact)


def fit_trim_loops(mask: np.ndarray, u_of_row, v_of_col, tol_uv: float, *, min_pixels: int = 20,
                   degree: int = 3, snap_to=None, domain=None, band=None) -> TrimLoops:
    """Fit the boundary of `mask` (rows, cols) with closed B-spline loops in (u, v).

    u_of_row (rows,), v_of_col (cols,): the parameters of the grid rows and columns.
    tol_uv: the loops' tolerance in parameter units (a model tolerance divided by the surface's speed).
    Components smaller than `min_pixels` (speckle) are ignored; the largest component is the face (cells
    touching it only at a cell corner are another component: pinched off, outside its trim, and said so).
    snap_to: optional data parameters (k, 2); each contour vertex then moves to its nearest data point,
    so a rasterised boundary follows the data rather than the raster's staircase (except where that would
    make the loops cross or touch).
    domain: optional ((u0, u1), (v0, v1)), the surface's: the loops stay in it. Where the contour meets
    the grid's border they run BORDER_REACH pixels beyond the outermost rows and columns (within the domain).
    band: optional (u0, u1): the loops stay within u0 <= u <= u1, and where the contour reaches past either
    they run exactly along it (straight pieces on the iso-parameter lines, not snapped to the data): a face
    cut from a closed wrap along those lines (`rgm.fitters.wrap`), whose neighbour is the same surface past them.

    The loops are valid (`check_loops`): each simple, the holes inside the outer boundary and apart from it
    and each other. Pieces whose fit would cross are fitted tighter (or as the contour itself); `notes` say so.
    """
    mask = np.asarray(mask, bool)
    lab, count = ndimage.label(mask)
    if count == 0:
        raise GeometryError("the mask has no valid cells: nothing to trim to")
    sizes = np.bincount(lab.ravel())[1:]
    keep = 1 + int(np.argmax(sizes))
    component = lab == keep
    polys = [p for p in mask_contours(component) if abs(signed_area(p)) >= min_pixels / 4]
    if not polys:
        raise GeometryError("the data region is too small to trim to")
    areas = np.array([signed_area(p) for p in polys])
    outer_i = int(np.argmax(np.abs(areas)))
    outer_sign = np.sign(areas[outer_i])
    notes = []
    corner = ndimage.label(mask, structure=np.ones((3, 3)))[0]    # 8-connected: pinches join
    pinched = np.setdiff1d(np.unique(lab[(corner == corner[component][0]) & ~component]), [0])
    if len(pinched):
        notes.append(f"{len(pinched)} piece(s) of data ({int(np.isin(lab, pinched).sum())} cells) touching the "
                     f"face only at a cell corner (a pinch) are left outside its trim")

    u_of_row, v_of_col = np.asarray(u_of_row, float), np.asarray(v_of_col, float)
    corners = np.array([[-BORDER_REACH] * 2, [len(u_of_row) - 1 + BORDER_REACH, len(v_of_col) - 1 + BORDER_REACH]])
    lo, hi = _to_uv(corners, u_of_row, v_of_col)
    if domain is not None:
        lo, hi = np.maximum(lo, np.asarray(domain, float)[:, 0]), np.minimum(hi, np.asarray(domain, float)[:, 1])
    chosen = [polys[outer_i]] + [p for i, p in enumerate(polys) if i != outer_i and np.sign(areas[i]) != outer_sign]
    raw = [_distinct(_to_uv(p, u_of_row, v_of_col)) for p in chosen]
    if band is not None:
        raw = [_band_clipped(p, band) for p in raw]
    if snap_to is not None:
        from scipy.spatial import cKDTree

        snap_to = np.asarray(snap_to, float)
        if band is not None:   # the vertices on the band's ends are their own nearest points: they stay
            snap_to = np.vstack([snap_to] + [p[np.isin(p[:, 0], band)] for p in raw])
        raw, kept = _snapped(raw, cKDTree(snap_to))
        if kept:
            notes.append(f"{kept} contour vertices held back from their nearest data point (the loops would "
                         f"cross or touch there: a region a cell or two wide)")
    uv = [p if (signed_area(p) > 0) == (k == 0) else p[::-1] for k, p in enumerate(raw)]
    loops, tightened, exact = _fit_valid(uv, tol_uv, degree, lo, hi, band=band)
    if tightened or exact:
        notes.append(f"{tightened + exact} trimming-loop piece(s) would cross a loop at the tolerance (a narrow "
                     f"neck or sharp corner): fitted closer to the data boundary"
                     + (f", {exact} of them as its contour polyline" if exact else ""))
    problems = check_loops(loops[0], loops[1:])
    if problems:
        raise GeometryError(f"the trimming loops are not valid: {'; '.join(problems)}")
    return TrimLoops(loops[0], tuple(loops[1:]), int(np.sum(sizes >= min_pixels)) - 1, tuple(notes),
                     None if band is None else tuple(map(float, band)))
