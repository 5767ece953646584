"""Triangulation of a single view to a tolerance: 2.5-D Delaunay refined by greedy point insertion, then
thinned by vertex removal.

The scan is seen as a height field: every point gets plane coordinates (range image: its pixel (col, row);
unstructured view: its coordinates in the best-fit plane) and a depth along the viewing direction (the
plane's normal for unstructured views).  Starting from the convex hull and a coarse lattice of vertices,
every round

1. triangulates the vertices with `scipy.spatial.Delaunay` in the plane,
2. locates the points inside the triangles not seen before (range images: every triangle is rasterised
   over the pixel lattice by scanlines bounded with exact integer edge functions; unstructured views:
   `find_simplex`, all points at once) and measures their error, the depth difference to the triangle
   interpolated barycentrically, i.e. the distance in 3-D along the viewing direction; a triangle's
   verdict is kept by its corner ids, so a triangle that comes back is not measured again,
3. inserts, into every triangle that is over the tolerance or illegal, its worst point,

until no triangle needs a point (Garland & Heckbert, "Fast polygonal approximation of terrains and height
fields", 1995: greedy insertion; many points per round as in their multi-pass variant).  Greedy insertion
leaves early vertices that later ones made redundant, so passes of vertex removal follow: an independent
set of vertices (no two adjacent; none on the hull or at an illegal triangle) is taken out, the triangles
Delaunay puts in their holes are measured, and every vertex whose hole misses the tolerance is put back
(a Delaunay triangle stays Delaunay when other points go, so its old star returns); any triangle still
out of tolerance gets points as in step 3.  Passes stop when one removes under 1 % of the vertices.
A triangle is illegal if it spans a depth discontinuity or an invalid pixel: its vertices or the points
inside it belong to different pieces of the surface (connected components of the pixel grid whose links
are not steeper than `disc_slope`), it covers an invalid pixel, or one of its edges is steeper than
`disc_slope`.  Illegal triangles are refined like the others and dropped from the result when nothing is
left to insert.  Every valid input point therefore ends up a vertex or inside a kept triangle within `tol`
of it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, Delaunay, QhullError

from rgm.fitters.filters import view_axis
from rgm.fitters.io import Scan, ScanError

__all__ = ["Triangulation", "triangulate"]


@dataclass(frozen=True, eq=False)
class Triangulation:
    """vertices (k, 3) in the scan's frame; triangles (m, 3) indices into vertices, facing the sensor;
    vertex_index (k,) indices into scan.points; max_error / rms_error over all covered input points
    (file units, along the viewing direction); uncovered: valid points in no kept triangle (isolated
    pixels, slivers of surface steeper than the discontinuity limit); rounds: Delaunay triangulations
    measured for insertion; passes: vertex-removal passes."""

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_index: np.ndarray
    max_error: float
    rms_error: float
    n_points: int
    uncovered: int
    rounds: int
    passes: int
    tol: float

    def report(self) -> dict:
        return {"vertices": len(self.vertices), "triangles": len(self.triangles), "points": self.n_points,
                "tol": self.tol, "max_error": self.max_error, "rms_error": self.rms_error,
                "uncovered_points": self.uncovered, "rounds": self.rounds, "removal_passes": self.passes}


def _frame(scan: Scan):
    """Plane coordinates uv (n, 2) (pixel (col, row) for range images), metric lateral coordinates
    ab (n, 2), depth d (n,) along the viewing direction, and the unit vector towards the sensor."""
    if scan.grid is not None:
        v = view_axis(scan)
        a_ax = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(v, a_ax)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(v, e1)
        pos = np.argwhere(scan.grid >= 0)
        uv = np.empty((scan.n, 2))
        uv[scan.grid[pos[:, 0], pos[:, 1]]] = pos[:, ::-1]
        return uv, np.column_stack([scan.points @ e1, scan.points @ e2]), scan.points @ -v, -v
    centred = scan.points - scan.points.mean(axis=0)
    axes = np.linalg.svd(centred[:: max(1, len(centred) // 20000)], full_matrices=False)[2]
    towards = scan.sensor_directions()
    n = axes[2] if towards is None or towards.mean(axis=0) @ axes[2] >= 0 else -axes[2]
    uv = np.column_stack([centred @ axes[0], centred @ axes[1]])
    return uv, uv, centred @ n, n


def _labels(scan: Scan, ab, d, disc_slope):
    """(n,) connected component of every valid point; grid links steeper than disc_slope are cut."""
    if scan.grid is None:
        return np.zeros(scan.n, np.int64)
    g = scan.grid
    valid = g >= 0
    gi = np.maximum(g, 0)
    A, B, D = ab[gi, 0], ab[gi, 1], d[gi]
    rows, cols, cut = [], [], 0
    for axis in (0, 1):
        both = valid[1:] & valid[:-1] if axis == 0 else valid[:, 1:] & valid[:, :-1]
        dd, da, db = (np.diff(x, axis=axis) for x in (D, A, B))
        keep = both & (dd * dd <= disc_slope ** 2 * (da * da + db * db))
        cut += int((both & ~keep).sum())
        p_ = g[:-1][keep] if axis == 0 else g[:, :-1][keep]
        q_ = g[1:][keep] if axis == 0 else g[:, 1:][keep]
        rows.append(p_)
        cols.append(q_)
    if cut == 0 and valid.all():
        return np.zeros(scan.n, np.int64)          # a complete image with no cut link: one piece
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r)), (r, c)), shape=(scan.n, scan.n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def _initial_vertices(uv, n_cells, grid=None):
    """Convex-hull points plus one point per cell of a coarse lattice (about n_cells^2 points). For a range
    image the hull is taken over the first and last valid pixel of every row."""
    candidates = np.arange(len(uv))
    if grid is not None:
        rows = np.flatnonzero((grid >= 0).any(axis=1))
        valid = grid[rows] >= 0
        first = valid.argmax(axis=1)
        last = grid.shape[1] - 1 - valid[:, ::-1].argmax(axis=1)
        candidates = np.concatenate([grid[rows, first], grid[rows, last]])
    hull = candidates[ConvexHull(uv[candidates]).vertices]
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    cell = max((hi - lo).max() / n_cells, 1e-300)
    key = np.floor((uv - lo) / cell).astype(np.int64)
    _, first = np.unique(key[:, 0] * (n_cells + 2) + key[:, 1], return_index=True)
    return np.unique(np.concatenate([hull, first]))


def _raster(grid, corners, chunk=1_000_000):
    """Pixels inside lattice triangles. corners (m, 3, 2) integer (col, row). Yields (t (k,) triangle,
    pid (k,) grid value (-1 = invalid pixel), lam (k, 3) barycentric coordinates) per chunk of about
    `chunk` pixels.  Scanlines: on every row of a triangle the three edge functions (Pineda 1988), exact
    integers, bound the run of inside pixels by an integer floor/ceil division, so only inside pixels are
    generated; a pixel on an edge is in both triangles.  int32 suffices below 2^15 pixels a side."""
    c = corners.astype(np.int64)
    area = ((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
            - (c[:, 1, 1] - c[:, 0, 1]) * (c[:, 2, 0] - c[:, 0, 0]))
    sg = np.sign(area)[:, None]
    a, b = c[:, [1, 2, 0]], c[:, [2, 0, 1]]                 # edge k runs a -> b, opposite vertex k
    ea, eb = -(b[..., 1] - a[..., 1]) * sg, (b[..., 0] - a[..., 0]) * sg    # E_k = ea x + eb y + e0
    e0 = -(ea * a[..., 0] + eb * a[..., 1])
    y0 = c[:, :, 1].min(axis=1)
    h = np.where(area != 0, c[:, :, 1].max(axis=1) - y0 + 1, 0)
    rt = np.repeat(np.arange(len(c)), h)                                    # one entry per triangle row
    ry = np.repeat(y0, h) + np.arange(len(rt)) - np.repeat(np.cumsum(h) - h, h)
    A, cst = ea[rt], eb[rt] * ry[:, None] + e0[rt]                         # E_k = A x + cst on the row
    pos, neg = A > 0, A < 0
    lo = np.where(pos, -(cst // np.where(pos, A, 1)), np.iinfo(np.int64).min).max(axis=1)
    hi = np.where(neg, cst // np.where(neg, -A, 1), np.iinfo(np.int64).max).min(axis=1)
    lo = np.maximum(lo, c[rt, :, 0].min(axis=1))
    hi = np.minimum(hi, c[rt, :, 0].max(axis=1))
    cnt = np.where(((A == 0) & (cst < 0)).any(axis=1), 0, np.maximum(hi - lo + 1, 0))
    small = np.int32 if max(grid.shape) < 2 ** 15 else np.int64
    ends = np.cumsum(cnt)
    start = 0
    while start < len(rt):
        stop = max(int(np.searchsorted(ends, (ends[start - 1] if start else 0) + chunk, side="right")), start + 1)
        rows = np.arange(start, min(stop, len(rt)))
        k = cnt[rows]
        t = np.repeat(rt[rows].astype(small), k)
        y = np.repeat(ry[rows].astype(small), k)
        x = np.repeat(lo[rows].astype(small), k) + (np.arange(int(k.sum()), dtype=small)
                                                    - np.repeat((np.cumsum(k) - k).astype(small), k))
        lam = np.column_stack([ea[t, j].astype(small) * x + eb[t, j].astype(small) * y + e0[t, j].astype(small)
                               for j in range(3)]) / np.abs(area[t])[:, None]
        yield t, grid[y, x], lam
        start = stop


def _locate(scan, uv, tri, simp, which):
    """Points inside the triangles `which` (indices into simp): (k, pid, lam) with k the position in
    `which`, non-decreasing (a triangle's points are consecutive), pid the point (-1 for invalid pixels;
    vertices included) and lam (n, 3) its barycentric coordinates; and the valid points that no triangle
    contains (numerically outside the hull)."""
    if scan.grid is not None:
        parts = list(_raster(scan.grid, uv[simp[which]]))
        if not parts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64)
        k, pid, lam = (np.concatenate(x) for x in zip(*parts))
        return k, pid, lam, np.zeros(0, np.int64)
    pid = np.arange(scan.n)
    t = tri.find_simplex(uv)
    lost = pid[t < 0]
    pos = np.full(len(simp), -1)
    pos[which] = np.arange(len(which))
    k = np.where(t >= 0, pos[t], -1)
    order = np.argsort(k, kind="stable")
    order = order[k[order] >= 0]
    pid, t, k = pid[order], t[order], k[order]
    b = np.einsum("nij,nj->ni", tri.transform[t, :2], uv[pid] - tri.transform[t, 2])
    return k, pid, np.column_stack([b, 1 - b.sum(axis=1)]), lost


def _examine(scan, uv, ab, d, labels, tri, simp, which, is_vertex, disc_slope):
    """Verdicts on the triangles `which` (indices into simp): legal (k,) (no depth discontinuity, invalid
    pixel or other piece inside or along an edge), worst (k,) the largest error of a point inside that is
    not a vertex (inf for a point of another piece, -inf if none), wpid (k,) that point (-1 if none), and
    the valid points outside every triangle (numerically outside the hull).  Per-triangle reductions run
    over the consecutive runs of `_locate` (reduceat), not by scattering."""
    k, pid, lam, lost = _locate(scan, uv, tri, simp, which)
    sw = simp[which]
    vl = labels[sw]
    legal = (vl[:, 0] == vl[:, 1]) & (vl[:, 1] == vl[:, 2])
    for i, j in ((0, 1), (1, 2), (2, 0)):
        pa, pb = sw[:, i], sw[:, j]
        legal &= np.abs(d[pa] - d[pb]) <= disc_slope * np.linalg.norm(ab[pa] - ab[pb], axis=1)
    worst = np.full(len(which), -np.inf)
    wpid = np.full(len(which), -1)
    if not len(k):
        return legal, worst, wpid, lost
    valid = pid >= 0
    pv = np.maximum(pid, 0)
    score = np.abs(d[pv] - np.einsum("ni,ni->n", lam, d[sw[k]]))
    trouble = ~valid
    if labels.any():                                                 # several pieces: check membership
        foreign = valid & (labels[pv] != vl[k, 0])
        trouble |= foreign
        score[foreign] = np.inf                                      # foreign valid points go in first
    score[~valid | is_vertex[pv]] = -np.inf
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    runs = k[starts]
    legal[runs] &= ~np.logical_or.reduceat(trouble, starts)          # covers an invalid pixel or another piece
    worst[runs] = np.maximum.reduceat(score, starts)
    top = np.flatnonzero((score == worst[k]) & (score > -np.inf))
    lead = np.ones(len(top), bool)
    lead[1:] = k[top][1:] != k[top][:-1]
    first = top[lead]                                                # the first worst point of each run
    wpid[k[first]] = pid[first]
    return legal, worst, wpid, lost


class _Verdicts:
    """The verdict (legal, worst error, its point) of every triangle examined so far, by triangle key
    (sorted vertex ids).  A triangle's verdict depends only on its corners and the points inside it, so
    a triangle that comes back in a later triangulation is not examined again."""

    def __init__(self, scan, uv, ab, d, labels, disc_slope):
        self.args = (scan, uv, ab, d, labels)
        self.disc_slope = disc_slope
        self.keys = np.zeros(0, np.int64)
        self.legal, self.worst, self.wpid = np.zeros(0, bool), np.zeros(0), np.zeros(0, np.int64)

    def of(self, is_vertex):
        """Delaunay triangulation of the vertices and the verdicts of its triangles:
        (tri, simp (m, 3) point ids, legal (m,), worst (m,), wpid (m,), lost points)."""
        scan, uv, ab, d, labels = self.args
        n = len(is_vertex)
        tri = Delaunay(uv[is_vertex])
        simp = np.flatnonzero(is_vertex)[tri.simplices]
        ss = np.sort(simp, axis=1)
        keys = (ss[:, 0] * n + ss[:, 1]) * n + ss[:, 2]
        at = np.minimum(np.searchsorted(self.keys, keys), max(len(self.keys) - 1, 0))
        known = self.keys[at] == keys if len(self.keys) else np.zeros(len(keys), bool)
        new = np.flatnonzero(~known)
        lg, wo, wp, lost = _examine(scan, uv, ab, d, labels, tri, simp, new, is_vertex, self.disc_slope)
        legal, worst, wpid = np.empty(len(keys), bool), np.empty(len(keys)), np.empty(len(keys), np.int64)
        legal[known], worst[known], wpid[known] = self.legal[at[known]], self.worst[at[known]], self.wpid[at[known]]
        legal[new], worst[new], wpid[new] = lg, wo, wp
        order = np.argsort(np.concatenate([self.keys, keys[new]]), kind="stable")
        self.keys = np.concatenate([self.keys, keys[new]])[order]
        self.legal = np.concatenate([self.legal, lg])[order]
        self.worst = np.concatenate([self.worst, wo])[order]
        self.wpid = np.concatenate([self.wpid, wp])[order]
        return tri, simp, legal, worst, wpid, lost


def _independent_removals(tri, simp, legal, is_vertex, rng):
    """(n,) bool: vertices to try removing, no two adjacent (Luby 1986: a vertex goes if its random
    priority is below all its neighbours'), none on the hull or at a dropped (illegal) triangle."""
    n = len(is_vertex)
    blocked = ~is_vertex
    blocked[simp[~legal].ravel()] = True
    blocked[np.flatnonzero(is_vertex)[tri.convex_hull.ravel()]] = True
    prio = rng.random(n)
    edges = simp[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    lowest = np.full(n, np.inf)
    np.minimum.at(lowest, edges[:, 0], prio[edges[:, 1]])
    np.minimum.at(lowest, edges[:, 1], prio[edges[:, 0]])
    return ~blocked & (prio < lowest)


def _owners(simp, gone, failed):
    """The removed vertices (gone (n,) bool) to put back for the new triangles failed (k, 3): a removed
    vertex's hole is filled from its old neighbours, so a failed triangle's owner is the removed vertex
    next to all three of its corners in the old triangulation simp; a triangle spanning two holes (whose
    stars shared an edge) puts back every removed neighbour of its corners."""
    n = len(gone)
    edges = np.concatenate([simp[:, [0, 1]], simp[:, [1, 2]], simp[:, [2, 0]]])
    edges = np.concatenate([edges, edges[:, ::-1]])
    edges = edges[gone[edges[:, 1]]]
    G = csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    Ga, Gb, Gc = G[failed[:, 0]], G[failed[:, 1]], G[failed[:, 2]]
    rows, owners = Ga.multiply(Gb).multiply(Gc).nonzero()
    spanning = np.setdiff1d(np.arange(len(failed)), rows)
    around = (Ga[spanning] + Gb[spanning] + Gc[spanning]).nonzero()[1]
    return np.unique(np.concatenate([owners, around]))


def triangulate(scan: Scan, tol: float, *, disc_slope: float = 6.0, n_cells: int = 8,
                max_rounds: int = 200, thin_passes: int = 8, seed: int = 0) -> Triangulation:
    """Triangulate a single view until every valid point lies within `tol` (file units, along the viewing
    direction) of the mesh; see the module docstring. disc_slope: depth change per unit of lateral
    distance above which two points are on different sides of a discontinuity (6 ~ 80 degrees);
    thin_passes: at most this many vertex-removal passes after the insertion (seeded by `seed`)."""
    if not tol > 0:
        raise ScanError(f"{scan.source}: the tolerance must be positive, got {tol}")
    if scan.n < 3:
        raise ScanError(f"{scan.source}: at least 3 points are needed to triangulate, got {scan.n}")
    uv, ab, d, toward_sensor = _frame(scan)
    labels = _labels(scan, ab, d, disc_slope)
    is_vertex = np.zeros(scan.n, bool)
    try:
        is_vertex[_initial_vertices(uv, n_cells, scan.grid)] = True
    except QhullError:
        raise ScanError(f"{scan.source}: the points are collinear in the projection plane") from None
    verdicts = _Verdicts(scan, uv, ab, d, labels, disc_slope)
    rng = np.random.default_rng(seed)
    rounds = passes = 0
    thinning = thin_passes > 0
    while True:
        rounds += 1
        tri, simp, legal, worst, wpid, lost = verdicts.of(is_vertex)
        bad = ~legal | (worst > tol)
        insert = np.unique(np.concatenate([wpid[bad & (wpid >= 0)], lost]))
        if len(insert) and rounds < max_rounds:
            is_vertex[insert] = True
            continue
        if not thinning or rounds >= max_rounds:
            break
        passes += 1                      # every point is within tol: try removing an independent set
        gone = _independent_removals(tri, simp, legal, is_vertex, rng)
        trial = is_vertex & ~gone
        tri2, simp2, legal2, worst2, _, lost2 = verdicts.of(trial)
        back = _owners(simp, gone, simp2[~legal2 | (worst2 > tol)])
        trial[back] = True
        trial[lost2] = True
        thinning = passes < thin_passes and gone.sum() - len(back) >= 0.01 * is_vertex.sum()  # worth more?
        is_vertex = trial
    return _result(scan, uv, d, tri, simp, legal, is_vertex, toward_sensor, rounds, passes, tol)


def _result(scan, uv, d, tri, simp, legal, is_vertex, toward_sensor, rounds, passes, tol) -> Triangulation:
    """Keep the legal triangles, face them to the sensor, and measure every valid point against them."""
    p = scan.points
    kept = simp[legal]
    normal = np.cross(p[kept[:, 1]] - p[kept[:, 0]], p[kept[:, 2]] - p[kept[:, 0]])
    area = np.linalg.norm(normal, axis=1)
    kept, normal = kept[area > 0], normal[area > 0]
    flip = normal @ toward_sensor < 0
    kept[flip] = kept[flip][:, ::-1]
    n = scan.n
    best = np.full(n, np.inf)                                        # error of each point, over kept triangles
    best[kept.ravel()] = 0.0
    which = np.flatnonzero(legal)
    k, pid, lam, _ = _locate(scan, uv, tri, simp, which)
    valid = pid >= 0
    e = np.abs(d[pid[valid]] - np.einsum("ni,ni->n", lam[valid], d[simp[which[k[valid]]]]))
    np.minimum.at(best, pid[valid], e)
    covered = np.isfinite(best)
    used = np.unique(kept)
    remap = np.full(n, -1)
    remap[used] = np.arange(len(used))
    e = best[covered]
    return Triangulation(p[used], remap[kept], used, float(e.max()) if len(e) else 0.0,
                         float(np.sqrt((e ** 2).mean())) if len(e) else 0.0, n, int((~covered).sum()), rounds,
                         passes, tol)
