"""Trimming loops: where the data is, in a surface's parameter space.

A range image's valid-pixel mask (or a rasterised cover of scattered parameters) is contoured by marching
squares at the half-way level between valid and invalid cells, giving closed polygons in (u, v). Each is
classified as an outer boundary (counter-clockwise) or a hole (clockwise, inside an outer one) and fitted
by a closed 2-D B-spline refined by knot insertion until it stays within the loop tolerance, so the trimmed
surface is valid only where data was.
"""
from __future__ import annotations

from dataclasses import dataclass

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


@dataclass(frozen=True)
class TrimLoops:
    """Closed 2-D B-spline loops in the surface's (u, v) domain: one outer boundary and its holes."""

    outer: CurveFit
    holes: tuple[CurveFit, ...]
    dropped: int  # further outer components (separate pieces of data) not covered by this face


def _to_uv(poly_px, u_of_row, v_of_col):
    rows, cols = len(u_of_row), len(v_of_col)
    r = np.clip(poly_px[:, 0], 0, rows - 1)
    c = np.clip(poly_px[:, 1], 0, cols - 1)
    return np.c_[np.interp(r, np.arange(rows), u_of_row), np.interp(c, np.arange(cols), v_of_col)]


def fit_trim_loops(mask: np.ndarray, u_of_row, v_of_col, tol_uv: float, *, min_pixels: int = 20,
                   degree: int = 3) -> TrimLoops:
    """Fit the boundary of `mask` (rows, cols) with closed B-spline loops in (u, v).

    u_of_row (rows,), v_of_col (cols,): the parameters of the grid rows and columns.
    tol_uv: the loops' tolerance in parameter units (a model tolerance divided by the surface's speed).
    Components smaller than `min_pixels` (speckle) are ignored; the largest component is the face.
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

    def fit(poly, want_ccw):
        uv = _to_uv(poly, np.asarray(u_of_row, float), np.asarray(v_of_col, float))
        if (signed_area(uv) > 0) != want_ccw:
            uv = uv[::-1]
        uv = np.vstack([uv, uv[:1]])  # closed: the fit interpolates the common end point
        return fit_curve(uv, tol_uv, degree=degree, fix_ends=True)

    outer = fit(polys[outer_i], True)
    holes = tuple(fit(p, False) for i, p in enumerate(polys)
                  if i != outer_i and np.sign(areas[i]) != outer_sign)
    return TrimLoops(outer, holes, int(np.sum(sizes >= min_pixels)) - 1)
