"""Constrained Delaunay triangulation of a face's parameter domain: boundary loops plus free points.

`constrained_delaunay(points, segments, loops)` returns the triangles of the region inside the loops
(even-odd) such that every segment is an edge, whatever the free points do near the boundary:

1. Qhull (`scipy.spatial.Delaunay`) triangulates all points, with four far ghost corners so that no
   real point is on the convex hull (Qhull may drop collinear hull points). Zero-area triangles that
   Qhull's triangulated output can leave between collinear points are removed by splitting their
   neighbour across the long edge.
2. Each segment missing from the result is recovered: the triangles it crosses form a cavity whose
   two halves (left and right of the segment) are re-triangulated by the Delaunay-optimal vertex
   choice (Anglada, "An improved incremental algorithm for constructing restricted Delaunay
   triangulations", Computers & Graphics 21(2), 1997).
3. Triangles are grouped into regions that no segment separates (connected components across
   unconstrained edges); a region is kept when one interior point of it is inside the loops.

Only the few missing segments cost Python-level work; everything else is vectorised.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import BackendError


class OnSegment(BackendError):
    """Free points lie on a boundary segment (within rounding): the caller drops them and retries."""

    def __init__(self, ids):
        super().__init__(f"{len(ids)} point(s) lie on a boundary segment")
        self.ids = np.asarray(sorted(ids), np.int64)


def _orient(a, b, c):
    """Twice the signed area of triangles (a, b, c) (broadcast over leading axes of (..., 2))."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _incircle(a, b, c, d) -> bool:
    """True when d lies strictly inside the circumcircle of triangle (a, b, c), either orientation."""
    m = np.array([a - d, b - d, c - d])
    det = np.linalg.det(np.column_stack([m, (m * m).sum(axis=1)]))
    return bool(det * _orient(a, b, c) > 0)


def _edge_keys(tri, n):
    """Undirected edge keys (t, 3) of triangles (t, 3): edge k joins corners k and k + 1."""
    a, b = tri, np.roll(tri, -1, axis=1)
    return np.minimum(a, b) * n + np.maximum(a, b)


def _pair_keys(seg, n):
    """Undirected keys of index pairs (s, 2)."""
    return np.minimum(seg[:, 0], seg[:, 1]) * n + np.maximum(seg[:, 0], seg[:, 1])


def _member(keys, sorted_keys) -> np.ndarray:
    """Mask of `keys` found in the sorted array `sorted_keys` (binary search; cheaper than np.isin
    for a few keys against many)."""
    if len(sorted_keys) == 0:
        return np.zeros(np.shape(keys), bool)
    i = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
    return sorted_keys[i] == keys


def _ccw(p, tri):
    flip = _orient(p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]) < 0
    tri[flip] = tri[flip][:, ::-1]
    return tri


def _remove_flat(p, tri, scale):
    """Replace each zero-area triangle (x, m, y), m between x and y, and its neighbour (y, x, q) across
    the long edge by (x, m, q) and (m, y, q)."""
    n = len(p)
    for _ in range(64):
        area = np.abs(_orient(p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]))
        flat = np.flatnonzero(area <= 1e-13 * scale * scale)
        if len(flat) == 0:
            return tri
        keys = _edge_keys(tri, n)
        drop, add = set(), []
        for t in flat:
            if t in drop:
                continue
            v = tri[t]
            length = np.linalg.norm(p[np.roll(v, -1)] - p[v], axis=1)
            k = int(np.argmax(length))                 # the long edge: corners k, k + 1
            x, y, m = v[k], v[(k + 1) % 3], v[(k + 2) % 3]
            other = np.flatnonzero((keys == keys[t, k]).any(axis=1))
            other = [o for o in other if o != t and o not in drop]
            drop.add(t)
            if other:
                q = int(np.setdiff1d(tri[other[0]], [x, y])[0])
                drop.add(other[0])
                add += [(x, m, q), (m, y, q)]
        keep = np.setdiff1d(np.arange(len(tri)), list(drop))
        tri = _ccw(p, np.concatenate([tri[keep], np.array(add, np.int64).reshape(-1, 3)]))
    raise BackendError("degenerate triangles remain in a face's parameter domain")


def _pseudo_polygon(p, a, b, chain, out):
    """Triangulate the polygon a, chain..., b (chain on one side of ab) with edge ab, appending to out."""
    if not chain:
        return
    c = 0
    for i in range(1, len(chain)):
        if _incircle(p[a], p[b], p[chain[c]], p[chain[i]]):
            c = i
    _pseudo_polygon(p, a, chain[c], chain[:c], out)
    _pseudo_polygon(p, chain[c], b, chain[c + 1:], out)
    out.append((a, b, chain[c]))


def _insert_segment(p, tri, a, b, constrained, n_fixed):
    """Make (a, b) an edge of `tri` by re-triangulating the cavity of the triangles it crosses."""
    n = len(p)
    pa, pb = p[a], p[b]
    ab = pb - pa
    length2 = float(ab @ ab)
    # vertices on the open segment: free ones are dropped by the caller, fixed ones are an error
    rel = p - pa
    t = rel @ ab / length2
    off = np.abs(rel[:, 0] * ab[1] - rel[:, 1] * ab[0]) / length2
    on = np.flatnonzero((t > 1e-12) & (t < 1 - 1e-12) & (off < 1e-11))
    on = on[(on != a) & (on != b)]
    if len(on):
        if (on >= n_fixed).all():
            raise OnSegment(on)
        raise BackendError("two trimming loops touch or overlap (a boundary point lies on another "
                           "loop's segment)")
    c, d = tri, np.roll(tri, -1, axis=1)
    oc, od = _orient(pa, pb, p[c]), _orient(pa, pb, p[d])
    oa, ob = _orient(p[c], p[d], pa), _orient(p[c], p[d], pb)
    crossing = (oc * od < 0) & (oa * ob < 0)
    if _member(_edge_keys(tri, n)[crossing], constrained).any():
        raise BackendError("trimming loops cross each other (or a loop crosses itself)")
    cavity = crossing.any(axis=1)
    if not cavity.any():
        return tri
    ct = tri[cavity]
    directed = np.stack([ct, np.roll(ct, -1, axis=1)], axis=-1).reshape(-1, 2)
    dkey = directed[:, 0] * n + directed[:, 1]
    border = directed[~np.isin(dkey, directed[:, 1] * n + directed[:, 0])]
    succ = dict(zip(border[:, 0].tolist(), border[:, 1].tolist()))
    if len(succ) != len(border):
        raise BackendError("a trimming segment's cavity is not a simple polygon")
    chains = ([], [])
    for side, (start, end) in enumerate(((a, b), (b, a))):   # counter-clockwise: right of ab, then left
        v = succ.get(start)
        while v != end:
            if v is None or len(chains[side]) > len(border):
                raise BackendError("a trimming segment's cavity is not a simple polygon")
            chains[side].append(v)
            v = succ.get(v)
    new = []
    _pseudo_polygon(p, a, b, chains[0], new)
    _pseudo_polygon(p, b, a, chains[1], new)
    return _ccw(p, np.concatenate([tri[~cavity], np.array(new, np.int64).reshape(-1, 3)]))


def inside_loops(pts, polygons) -> np.ndarray:
    """Even-odd test of points (k, 2) against closed polygons (list of (m, 2), first point not
    repeated), in chunks of about 4M point-edge pairs."""
    out = np.zeros(len(pts), bool)
    for poly in polygons:
        a, b = poly, np.roll(poly, -1, axis=0)
        step = max(1, 4_000_000 // max(len(poly), 1))
        for s in range(0, len(pts), step):
            x, y = pts[s:s + step, 0:1], pts[s:s + step, 1:2]
            cond = (a[:, 1] > y) != (b[:, 1] > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
            out[s:s + step] ^= (np.count_nonzero(cond & (x < xi), axis=1) % 2).astype(bool)
    return out


def _regions_inside(p, tri, constrained, n_real, polygons):
    """Mask of the triangles in regions (not separated by a segment) that lie inside the loops."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = len(p)
    keys = _edge_keys(tri, n).ravel()
    owner = np.repeat(np.arange(len(tri)), 3)
    order = np.argsort(keys, kind="stable")
    k, o = keys[order], owner[order]
    pair = np.flatnonzero((k[1:] == k[:-1]) & ~_member(k[1:], constrained))
    graph = coo_matrix((np.ones(len(pair)), (o[pair], o[pair + 1])), shape=(len(tri), len(tri)))
    ncomp, label = connected_components(graph, directed=False)
    ghost = np.zeros(ncomp, bool)
    ghost[label[(tri >= n_real).any(axis=1)]] = True
    first = np.unique(label, return_index=True)[1]
    centroid = p[tri[first]].mean(axis=1)
    keep = ~ghost & inside_loops(centroid, polygons)
    return keep[label]


class Incremental:
    """Qhull's triangulation kept between calls of `constrained_delaunay` on a growing point set: a call
    whose points extend the previous call's (same prefix, inside the same bounding box) adds only the
    new points to it (Qhull's incremental mode) instead of triangulating from scratch. `reset()` when
    the points change otherwise."""

    def __init__(self):
        self.reset()

    def reset(self):
        self.dt, self.n, self.box = None, 0, None


def _qhull(p, n_fixed, state):
    """(points with the four ghost corners first (n + 4, 2), Qhull's simplices in those indices)."""
    from scipy.spatial import Delaunay

    n = len(p)
    lo, hi = p.min(axis=0), p.max(axis=0)
    if state is not None and state.dt is not None and state.n <= n and \
            (lo >= state.box[0]).all() and (hi <= state.box[1]).all():
        if n > state.n:
            state.dt.add_points(p[state.n:])
        dt, ghosts = state.dt, state.ghosts
    else:
        scale = float(np.max(hi - lo)) or 1.0
        pad = 4 * scale
        ghosts = np.array([[lo[0] - pad, lo[1] - pad], [hi[0] + pad, lo[1] - pad],
                           [hi[0] + pad, hi[1] + pad], [lo[0] - pad, hi[1] + pad]])
        dt = Delaunay(np.concatenate([ghosts, p]), incremental=state is not None)
        if state is not None:
            state.dt, state.box, state.ghosts = dt, (lo, hi), ghosts
    if state is not None:
        state.n = n
    if len(dt.coplanar):
        dropped = np.unique(dt.coplanar[:, 0]) - 4
        if state is not None:
            state.reset()
        if (dropped >= n_fixed).all():
            raise OnSegment(dropped)
        raise BackendError("coincident boundary points in a face's parameter domain")
    return ghosts, dt.simplices


def constrained_delaunay(points, segments, loops, n_fixed=None, state: Incremental | None = None) -> np.ndarray:
    """Triangles (t, 3) int64, counter-clockwise, of the region inside `loops` (even-odd), with every
    segment as an edge.

    points : (n, 2) distinct points; the first `n_fixed` (default all) are the boundary, the rest free
             points that may be dropped. segments : (s, 2) point indices that must be edges.
    loops : list of (m,) index arrays, each a closed loop of points (first not repeated).
    Raises `OnSegment` (with the free points' indices) when free points lie on a segment, and
    BackendError when loops cross or touch. `state` (an `Incremental`) keeps Qhull's triangulation for
    the next call on these points plus more.
    """
    p = np.asarray(points, float)
    n = len(p)
    n_fixed = n if n_fixed is None else n_fixed
    ghosts, simplices = _qhull(p, n_fixed, state)
    scale = float(np.max(p.max(axis=0) - p.min(axis=0))) or 1.0
    allp = np.concatenate([p, ghosts])
    simplices = simplices.astype(np.int64) - 4          # Qhull's order: ghosts first; here: ghosts last
    simplices[simplices < 0] += n + 4
    tri = _remove_flat(allp, _ccw(allp, simplices), scale)
    seg = np.asarray(segments, np.int64)
    m = len(allp)
    constrained = np.unique(_pair_keys(seg, m))
    # a recovery removes only unconstrained edges, so segments recovered earlier stay
    for a, b in seg[~_member(_pair_keys(seg, m), np.sort(_edge_keys(tri, m).ravel()))]:
        if not _member(np.array([min(a, b) * m + max(a, b)]), np.sort(_edge_keys(tri, m).ravel()))[0]:
            tri = _insert_segment(allp, tri, int(a), int(b), constrained, n_fixed)
    if not _member(constrained, np.sort(_edge_keys(tri, m).ravel())).all():
        raise BackendError("a boundary segment could not be kept in a face's triangulation")
    polygons = [p[np.asarray(loop)] for loop in loops]
    return tri[_regions_inside(allp, tri, constrained, n, polygons)]

