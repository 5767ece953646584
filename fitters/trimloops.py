"""Trimming loops: where the data is, in a surface's parameter space.

A range image's valid-pixel mask (or a rasterised cover of scattered parameters) is contoured by marching
squares at the half-way level between valid and invalid cells, giving closed polygons in (u, v). Each is
classified as an outer boundary (counter-clockwise) or a hole (clockwise, inside an outer one) and fitted
by closed 2-D B-spline pieces (split at corners) refined by knot insertion until they stay within the
loop tolerance, so the trimmed
surface is valid only where data was.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from rgm.errors import GeometryError
from rgm.fitters.freeform import CurveFit, fit_curve

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
    """An open polyline (k, 2) with `per_edge` evenly spaced points on every edge (k-1) * per_edge + 1,
    so that a least-squares fit has data in every knot span it may create."""
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)
    a, b = poly[:-1], poly[1:]
    pts = (a[:, None, :] + (b - a)[:, None, :] * t[None, :, None]).reshape(-1, 2)
    return np.vstack([pts, poly[-1:]])


def _fit_segments(poly: np.ndarray, cuts, tol_uv: float, degree: int) -> tuple[CurveFit, ...]:
    """B-spline pieces through the stretches poly[a:b + 1] of an open polyline between consecutive `cuts`
    (vertex indices), each refined by knot insertion to `tol_uv` with its ends fixed on the vertices."""
    pieces = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        seg = poly[a:b + 1]
        pieces.append(fit_curve(_densify(seg), tol_uv, degree=min(degree, len(seg) - 1), fix_ends=True))
    return tuple(pieces)


def fit_closed_loop(uv: np.ndarray, tol_uv: float, degree: int = 3) -> tuple[CurveFit, ...]:
    """Closed polygon (k, 2) -> consecutive B-spline pieces, split at corners (C0 there, smooth between),
    each refined by knot insertion to `tol_uv`; the pieces share their end points, so the loop closes."""
    corners = corner_indices(uv)
    if len(corners) == 0:
        return (fit_curve(_densify(np.vstack([uv, uv[:1]])), tol_uv, degree=degree, fix_ends=True),)
    rolled = np.vstack([np.roll(uv, -corners[0], axis=0), uv[corners[0]]])
    return _fit_segments(rolled, np.r_[corners - corners[0], len(uv)], tol_uv, degree)


def fit_open_chain(uv: np.ndarray, tol_uv: float, degree: int = 3) -> tuple[CurveFit, ...]:
    """Open polyline (k, 2), k >= 2 -> consecutive B-spline pieces from its first vertex to its last
    (which they keep exactly: the chain joins what lies beyond its ends), split at its corners as a
    closed loop is (`corner_indices`, judged away from the ends) and each refined to `tol_uv`."""
    uv = np.asarray(uv, float)
    w = 3
    inner = corner_indices(uv, window=w) if len(uv) >= 2 * w + 2 else np.zeros(0, int)
    inner = inner[(inner >= w) & (inner <= len(uv) - 1 - w)]   # a closed polygon's wrap-around is no corner
    return _fit_segments(uv, np.r_[0, inner, len(uv) - 1], tol_uv, degree)


def loop_stats_max(loop: tuple[CurveFit, ...]) -> float:
    return max(piece.stats.max for piece in loop)


@dataclass(frozen=True)
class TrimLoops:
    """Closed loops of 2-D B-spline pieces in the surface's (u, v) domain: one outer boundary
    (counter-clockwise) and its holes (clockwise)."""

    outer: tuple[CurveFit, ...]
    holes: tuple[tuple[CurveFit, ...], ...]
    dropped: int  # further outer components (separate pieces of data) not covered by this face


def _to_uv(poly_px, u_of_row, v_of_col):
    rows, cols = len(u_of_row), len(v_of_col)
    r = np.clip(poly_px[:, 0], 0, rows - 1)
    c = np.clip(poly_px[:, 1], 0, cols - 1)
    return np.c_[np.interp(r, np.arange(rows), u_of_row), np.interp(c, np.arange(cols), v_of_col)]


def fit_trim_loops(mask: np.ndarray, u_of_row, v_of_col, tol_uv: float, *, min_pixels: int = 20,
                   degree: int = 3, snap_to=None) -> TrimLoops:
    """Fit the boundary of `mask` (rows, cols) with closed B-spline loops in (u, v).

    u_of_row (rows,), v_of_col (cols,): the parameters of the grid rows and columns.
    tol_uv: the loops' tolerance in parameter units (a model tolerance divided by the surface's speed).
    Components smaller than `min_pixels` (speckle) are ignored; the largest component is the face.
    snap_to: optional data parameters (k, 2); each contour vertex then moves to its nearest data point,
    so a rasterised boundary follows the data rather than the raster's staircase.
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

    lo = np.array([np.min(u_of_row), np.min(v_of_col)])
    hi = np.array([np.max(u_of_row), np.max(v_of_col)])
    tree = None
    if snap_to is not None:
        from scipy.spatial import cKDTree

        tree = cKDTree(np.asarray(snap_to, float))

    def fit(poly, want_ccw):
        uv = _to_uv(poly, np.asarray(u_of_row, float), np.asarray(v_of_col, float))
        if tree is not None:
            uv = tree.data[tree.query(uv)[1]]
            uv = uv[np.r_[True, np.any(np.diff(uv, axis=0) != 0, axis=1)]]  # drop repeated vertices
        if (signed_area(uv) > 0) != want_ccw:
            uv = uv[::-1]
        # the control polygon is clamped into the domain, so (convex hull) the loop stays inside it
        return tuple(replace(piece, ctrl=np.clip(piece.ctrl, lo, hi)) for piece in fit_closed_loop(uv, tol_uv, degree))

    outer = fit(polys[outer_i], True)
    holes = tuple(fit(p, False) for i, p in enumerate(polys)
                  if i != outer_i and np.sign(areas[i]) != outer_sign)
    return TrimLoops(outer, holes, int(np.sum(sizes >= min_pixels)) - 1)
