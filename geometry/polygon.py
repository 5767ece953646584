"""Point-in-region tests for plane polygons: the trimming loops of faces in their parameter planes.

`inside_polygons(points, polygons)` is the even-odd rule (inside an outer loop, outside its holes) for
many points against loops of many vertices, as the mesher's trimmed faces (grid points against loops of
thousands of samples) and the fitters' trimmed surfaces (data parameters against their loops) need it.
Crossings of the ray from each point towards +x are counted edge by edge, but each edge meets only the
points whose y lies in its half-open span [min y, max y): with the points sorted by y those are one
block, so the work is the number of (edge, point) pairs a horizontal line actually brings together,
a few per point for a simple loop, not points x edges.
"""
from __future__ import annotations

import numpy as np

#: (edge, point) pairs handled at once (memory: a few arrays of this length)
_CHUNK = 4_000_000


def inside_polygons(points, polygons) -> np.ndarray:
    """(k,) bool: points (k, 2) inside the region of closed polygons (each (m, 2), last vertex not
    repeated) by the even-odd rule. A point on a horizontal edge's line or exactly on an edge falls on
    whichever side the half-open rule puts it (consistently: a tiling of polygons counts it once)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    out = np.zeros(len(pts), bool)
    if not len(pts) or not polygons:
        return out
    a = np.vstack(polygons)
    b = np.vstack([np.roll(p, -1, axis=0) for p in polygons])
    order = np.argsort(pts[:, 1], kind="stable")
    ys = pts[order, 1]
    start = np.searchsorted(ys, np.minimum(a[:, 1], b[:, 1]), side="left")
    count = np.searchsorted(ys, np.maximum(a[:, 1], b[:, 1]), side="left") - start
    total = np.cumsum(count)
    first = 0
    while first < len(a):   # edges in chunks of about _CHUNK pairs
        last = max(first + 1, int(np.searchsorted(total, (total[first - 1] if first else 0) + _CHUNK, side="right")))
        c = count[first:last]
        edge = np.repeat(np.arange(first, last), c)
        k = order[np.arange(len(edge)) - np.repeat(np.cumsum(c) - c, c) + np.repeat(start[first:last], c)]
        y = pts[k, 1]
        cross_x = a[edge, 0] + (y - a[edge, 1]) * (b[edge, 0] - a[edge, 0]) / (b[edge, 1] - a[edge, 1])
        out ^= (np.bincount(k[pts[k, 0] < cross_x], minlength=len(pts)) % 2).astype(bool)
        first = last
    return out
