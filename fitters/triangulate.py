"""Triangulation of a single view to a tolerance: 2.5-D Delaunay refined by greedy point insertion.

The scan is seen as a height field: every point gets plane coordinates (range image: its pixel (col, row);
unstructured view: its coordinates in the best-fit plane) and a depth along the viewing direction (the
plane's normal for unstructured views).  Starting from the convex hull and a coarse lattice of vertices,
every round

1. triangulates the vertices with `scipy.spatial.Delaunay` in the plane,
2. locates the points inside the triangles that are new this round (range images: every new triangle
   is rasterised over the pixel lattice with exact integer edge functions; unstructured views:
   `find_simplex`, all points at once) and measures their error, the depth difference to the triangle
   interpolated barycentrically, i.e. the distance in 3-D along the viewing direction; triangles that
   survive a round keep their verdict,
3. inserts, into every triangle that is over the tolerance or illegal, its worst point,

until no triangle needs a point (Garland & Heckbert, "Fast polygonal approximation of terrains and height
fields", 1995: greedy insertion; many points per round as in their multi-pass variant).  A triangle is
illegal if it spans a depth discontinuity or an invalid pixel: its vertices or the points inside it
belong to different pieces of the surface (connected components of the pixel grid whose links are not
steeper than `disc_slope`), it covers an invalid pixel, or one of its edges is steeper than `disc_slope`.
Illegal triangles are refined like the others and dropped from the result when nothing is left to insert.
Every valid input point therefore ends up a vertex or inside a kept triangle within `tol` of it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
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
    pixels, slivers of surface steeper than the discontinuity limit); rounds of insertion."""

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_index: np.ndarray
    max_error: float
    rms_error: float
    n_points: int
    uncovered: int
    rounds: int
    tol: float

    def report(self) -> dict:
        return {"vertices": len(self.vertices), "triangles": len(self.triangles), "points": self.n_points,
                "tol": self.tol, "max_error": self.max_error, "rms_error": self.rms_error,
                "uncovered_points": self.uncovered, "rounds": self.rounds}


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
    pid (k,) grid value (-1 = invalid pixel), lam (k, 3) barycentric coordinates) per chunk. Edge
    functions in exact integer arithmetic (Pineda 1988; int32 suffices below 2^15 pixels a side): a pixel
    on an edge is in both triangles."""
    c = corners.astype(np.int64)
    lo = c.min(axis=1)
    w = c[:, :, 0].max(axis=1) - lo[:, 0] + 1
    h = c[:, :, 1].max(axis=1) - lo[:, 1] + 1
    area = ((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
            - (c[:, 1, 1] - c[:, 0, 1]) * (c[:, 2, 0] - c[:, 0, 0]))
    sg = np.sign(area)
    small = np.int32 if max(grid.shape) < 2 ** 15 else np.int64
    coef = []                                  # edge k (opposite vertex k): E = e0 + ea * ox + eb * oy
    for k in range(3):
        a, b = c[:, (k + 1) % 3], c[:, (k + 2) % 3]
        ea, eb = -(b[:, 1] - a[:, 1]) * sg, (b[:, 0] - a[:, 0]) * sg
        e0 = ea * (lo[:, 0] - a[:, 0]) + eb * (lo[:, 1] - a[:, 1])
        coef.append((e0.astype(small), ea.astype(small), eb.astype(small)))
    w32, lo32 = w.astype(small), lo.astype(small)
    count = np.where(area != 0, w * h, 0)
    ends = np.cumsum(count)
    start = 0
    while start < len(c):
        stop = max(int(np.searchsorted(ends, (ends[start - 1] if start else 0) + chunk, side="right")), start + 1)
        idx = np.arange(start, min(stop, len(c)), dtype=small)
        cnt = count[idx]
        t = np.repeat(idx, cnt)
        off = np.arange(len(t), dtype=small) - np.repeat((np.cumsum(cnt) - cnt).astype(small), cnt)
        wt = w32[t]
        oy = off // wt
        ox = off - oy * wt
        e = [e0[t] + ea[t] * ox + eb[t] * oy for e0, ea, eb in coef]
        inside = (e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)
        t, ox, oy = t[inside], ox[inside], oy[inside]
        lam = np.column_stack([x[inside] for x in e]) / np.abs(area[t])[:, None]
        yield t, grid[lo32[t, 1] + oy, lo32[t, 0] + ox], lam
        start = stop


def _locate(scan, uv, tri, simp, which, is_vertex):
    """Points inside the triangles `which` (indices into simp): (t, pid, lam) with pid -1 for invalid
    pixels, and the valid points that no triangle contains (numerically outside the hull). Vertices are
    left out: their error is 0."""
    if scan.grid is not None:
        parts = [(which[t], pid, lam) for t, pid, lam in _raster(scan.grid, uv[simp[which]])]
        if not parts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64)
        t, pid, lam = (np.concatenate(x) for x in zip(*parts))
        keep = (pid < 0) | ~is_vertex[np.maximum(pid, 0)]
        return t[keep], pid[keep], lam[keep], np.zeros(0, np.int64)
    pid = np.flatnonzero(~is_vertex)
    t = tri.find_simplex(uv[pid])
    lost = pid[t < 0]
    pid, t = pid[t >= 0], t[t >= 0]
    mine = np.zeros(len(simp), bool)
    mine[which] = True
    pid, t = pid[mine[t]], t[mine[t]]
    b = np.einsum("nij,nj->ni", tri.transform[t, :2], uv[pid] - tri.transform[t, 2])
    return t, pid, np.column_stack([b, 1 - b.sum(axis=1)]), lost


def triangulate(scan: Scan, tol: float, *, disc_slope: float = 6.0, n_cells: int = 8,
                max_rounds: int = 200) -> Triangulation:
    """Triangulate a single view until every valid point lies within `tol` (file units, along the viewing
    direction) of the mesh; see the module docstring. disc_slope: depth change per unit of lateral
    distance above which two points are on different sides of a discontinuity (6 ~ 80 degrees)."""
    if not tol > 0:
        raise ScanError(f"{scan.source}: the tolerance must be positive, got {tol}")
    if scan.n < 3:
        raise ScanError(f"{scan.source}: at least 3 points are needed to triangulate, got {scan.n}")
    uv, ab, d, toward_sensor = _frame(scan)
    labels = _labels(scan, ab, d, disc_slope)
    n = scan.n
    is_vertex = np.zeros(n, bool)
    try:
        is_vertex[_initial_vertices(uv, n_cells, scan.grid)] = True
    except QhullError:
        raise ScanError(f"{scan.source}: the points are collinear in the projection plane") from None
    prev_keys, prev_legal = np.zeros(0, np.int64), np.zeros(0, bool)
    rounds = 0
    while True:
        rounds += 1
        tri = Delaunay(uv[is_vertex])
        simp = np.flatnonzero(is_vertex)[tri.simplices]              # (m, 3) point ids
        ss = np.sort(simp, axis=1)
        keys = (ss[:, 0] * n + ss[:, 1]) * n + ss[:, 2]
        # a triangle that survives a round keeps its verdict; only new ones are examined
        if scan.grid is not None and len(prev_keys):
            order = np.argsort(prev_keys)
            pos = np.minimum(np.searchsorted(prev_keys[order], keys), len(prev_keys) - 1)
            old = order[pos]
            survived = prev_keys[old] == keys
        else:
            old, survived = np.zeros(len(keys), np.int64), np.zeros(len(keys), bool)
        legal = np.where(survived, prev_legal[old] if len(prev_legal) else False, False)
        new = np.flatnonzero(~survived)
        t, pid, lam, lost = _locate(scan, uv, tri, simp, new, is_vertex)
        vl = labels[simp[new]]
        ok = (vl[:, 0] == vl[:, 1]) & (vl[:, 1] == vl[:, 2])
        for i, j in ((0, 1), (1, 2), (2, 0)):
            pa, pb = simp[new, i], simp[new, j]
            ok &= np.abs(d[pa] - d[pb]) <= disc_slope * np.linalg.norm(ab[pa] - ab[pb], axis=1)
        legal[new] = ok
        valid = pid >= 0
        pv = np.maximum(pid, 0)
        err = np.where(valid, np.abs(d[pv] - np.einsum("ni,ni->n", lam, d[simp[t]])), -np.inf)
        foreign = labels[pv] != labels[simp[t, 0]]
        mismatch = ~valid | foreign
        legal[t[mismatch]] = False                                   # covers an invalid pixel or another piece
        score = np.where(valid & foreign, np.inf, err)               # foreign valid points go in first
        worst = np.full(len(keys), -np.inf)
        np.maximum.at(worst, t, score)
        bad = ~legal | (worst > tol)
        want = bad[t] & (score == worst[t]) & (score > -np.inf)
        _, first = np.unique(t[want], return_index=True)
        insert = np.unique(np.concatenate([pid[want][first], lost]))
        prev_keys, prev_legal = keys, legal
        if not len(insert) or rounds >= max_rounds:
            break
        is_vertex[insert] = True
    return _result(scan, uv, d, tri, simp, legal, is_vertex, toward_sensor, rounds, tol)


def _result(scan, uv, d, tri, simp, legal, is_vertex, toward_sensor, rounds, tol) -> Triangulation:
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
    t, pid, lam, _ = _locate(scan, uv, tri, simp, np.flatnonzero(legal), is_vertex)
    valid = pid >= 0
    e = np.abs(d[pid[valid]] - np.einsum("ni,ni->n", lam[valid], d[simp[t[valid]]]))
    np.minimum.at(best, pid[valid], e)
    covered = np.isfinite(best)
    used = np.unique(kept)
    remap = np.full(n, -1)
    remap[used] = np.arange(len(used))
    e = best[covered]
    return Triangulation(p[used], remap[kept], used, float(e.max()) if len(e) else 0.0,
                         float(np.sqrt((e ** 2).mean())) if len(e) else 0.0, n, int((~covered).sum()), rounds, tol)
