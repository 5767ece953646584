"""The lattice part of a face's triangulation: unit cells of the initial grid, split along a diagonal.

The mesher triangulates each face in a plane where its initial grid's cells are unit squares
(`rgm.backends.mesh._FaceMesher.scaled`), so most of a large face's points sit on the integer lattice.
A cell whose four corners are points, with no other point in it (edges included) and no segment
entering it, needs no Delaunay search: its two triangles are known (a square's four corners are
cocircular, so either diagonal is Delaunay). `split_lattice` finds those *full* cells; the constrained
Delaunay step (`rgm.backends.mesh_cdt.constrained_delaunay`) then triangulates only the band between
the trimming loops and the full cells' outline, which it keeps as segments. On a fitted free-form face
meshed to 0.01 mm (46,000 points, 600 boundary samples) Qhull's triangulation of every point took
0.46 s; the band is a few thousand.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.geometry.polygon import inside_polygons

#: a point within this (cell units) of the integer lattice is a lattice node
_ON = 1e-9
#: cells are blocked by points and segments this near (cell units): conservative against round-off
_NEAR = 1e-9
#: the lattice is used when at least this many nodes would be left out of the Delaunay search
_WORTH = 256


@dataclass
class Lattice:
    """Full cells of a point set: their triangles (2c, 3) (indices into the points, counter-clockwise),
    `inner` (n,) the points whose four cells are all full (left out of the band), `outline` (e, 2) the
    full cells' edges that border no other full cell (segments of the band), and `full` (nx, ny) with
    `origin` (2,) to look a cell up."""

    triangles: np.ndarray
    inner: np.ndarray
    outline: np.ndarray
    full: np.ndarray
    origin: np.ndarray

    def in_full_cell(self, pts) -> np.ndarray:
        """(k,) bool: points (k, 2) in a full cell (by the cell their coordinates floor to)."""
        ij = np.floor(pts).astype(np.int64) - self.origin
        ok = (ij >= 0).all(axis=1) & (ij < np.array(self.full.shape)).all(axis=1)
        out = np.zeros(len(pts), bool)
        out[ok] = self.full[ij[ok, 0], ij[ok, 1]]
        return out


def split_lattice(p, seg, polygons) -> Lattice | None:
    """The full cells of points p (n, 2) with segments seg (s, 2) (index pairs) inside the region of
    `polygons` (even-odd), or None when fewer than _WORTH nodes would be left out (or the lattice is too
    sparse to be worth a grid). A cell no segment enters and no point lies in is wholly inside the region
    or wholly outside it (a notch or a hole whose corners are loop samples on the lattice): its centre says
    which."""
    on = (np.abs(p - np.rint(p)) <= _ON).all(axis=1)
    if on.sum() < _WORTH:
        return None
    ij = np.rint(p[on]).astype(np.int64)
    origin = ij.min(axis=0)
    shape = ij.max(axis=0) - origin + 1
    if shape[0] * shape[1] > 8 * len(p):
        return None
    node = np.full(shape, -1, np.int64)
    node[tuple((ij - origin).T)] = np.flatnonzero(on)
    full = (node[:-1, :-1] >= 0) & (node[1:, :-1] >= 0) & (node[1:, 1:] >= 0) & (node[:-1, 1:] >= 0)
    _block_points(full, p[~on] - origin)
    if not _block_segments(full, p[seg[:, 0]] - origin, p[seg[:, 1]] - origin):
        return None
    ci, cj = np.nonzero(full)
    full[ci, cj] = inside_polygons(np.column_stack([ci, cj]) + origin + 0.5, polygons)
    # nodes all four of whose cells are full: the band leaves them out
    padded = np.pad(full, 1)
    inner_node = padded[:-1, :-1] & padded[1:, :-1] & padded[:-1, 1:] & padded[1:, 1:]
    if inner_node.sum() < _WORTH:
        return None
    inner = np.zeros(len(p), bool)
    inner[node[inner_node]] = True
    ci, cj = np.nonzero(full)
    c00, c10, c11, c01 = node[ci, cj], node[ci + 1, cj], node[ci + 1, cj + 1], node[ci, cj + 1]
    triangles = np.concatenate([np.column_stack([c00, c10, c11]), np.column_stack([c00, c11, c01])])
    # outline: a full cell's side whose neighbour across it is not full
    left = ~padded[:-2, 1:-1][full]          # the cell at i - 1
    right = ~padded[2:, 1:-1][full]
    below = ~padded[1:-1, :-2][full]
    above = ~padded[1:-1, 2:][full]
    outline = np.concatenate([np.column_stack([c00, c01])[left], np.column_stack([c10, c11])[right],
                              np.column_stack([c00, c10])[below], np.column_stack([c01, c11])[above]])
    return Lattice(triangles, inner, outline, full, origin)


def _block_points(full, q):
    """Clear the cells of `full` whose closed square (grown by _NEAR) holds a point of q (k, 2)."""
    for dx in (-_NEAR, _NEAR):
        for dy in (-_NEAR, _NEAR):
            ij = np.floor(q + [dx, dy]).astype(np.int64)
            ok = (ij >= 0).all(axis=1) & (ij < np.array(full.shape)).all(axis=1)
            full[ij[ok, 0], ij[ok, 1]] = False


def _block_segments(full, a, b, most: int = 64) -> bool:
    """Clear the cells of `full` that segments [a, b] (s, 2) enter (their interior grown by _NEAR; a
    segment along a cell's side does not enter it). False when a segment spans more than `most` cells
    in a direction (not a face's boundary sample spacing: leave the lattice alone)."""
    lo = np.floor(np.minimum(a, b) - _NEAR).astype(np.int64)
    hi = np.floor(np.maximum(a, b) + _NEAR).astype(np.int64)
    span = hi - lo + 1
    if len(a) and span.max() > most:
        return False
    count = span[:, 0] * span[:, 1]
    s = np.repeat(np.arange(len(a)), count)
    k = np.arange(len(s)) - np.repeat(np.cumsum(count) - count, count)
    i = lo[s, 0] + k // span[s, 1]
    j = lo[s, 1] + k % span[s, 1]
    # the segment's bounding box meets the open cell (grown) in both directions, and the cell's corners
    # are not all on one side of its line (the separating axes of a segment and a square)
    lo_s, hi_s = np.minimum(a, b)[s], np.maximum(a, b)[s]
    overlap = (lo_s[:, 0] < i + 1 + _NEAR) & (hi_s[:, 0] > i - _NEAR) & \
              (lo_s[:, 1] < j + 1 + _NEAR) & (hi_s[:, 1] > j - _NEAR)
    d = b[s] - a[s]
    side = [d[:, 0] * (j + y - a[s, 1]) - d[:, 1] * (i + x - a[s, 0]) for x, y in ((0, 0), (1, 0), (1, 1), (0, 1))]
    tol = _NEAR * np.linalg.norm(d, axis=1)
    one_side = np.all([v > tol for v in side], axis=0) | np.all([v < -tol for v in side], axis=0)
    along = (np.abs(d[:, 0]) <= _NEAR) & ((np.abs(a[s, 0] - i) <= _NEAR) | (np.abs(a[s, 0] - i - 1) <= _NEAR)) | \
            (np.abs(d[:, 1]) <= _NEAR) & ((np.abs(a[s, 1] - j) <= _NEAR) | (np.abs(a[s, 1] - j - 1) <= _NEAR))
    enter = overlap & ~one_side & ~along
    ok = enter & (i >= 0) & (i < full.shape[0]) & (j >= 0) & (j < full.shape[1])
    full[i[ok], j[ok]] = False
    return True
