"""Scattered points split into patches at their creases (sharp edges), the first step of
`rgm.fitters.patches`.

A point is a crease point when at least two of its 2k nearest neighbours have normals more than
`angle_deg` away from its own (robust PCA normals, unoriented: |n_i . n_j| is compared). Crease points
are set aside, the rest joined by a k-nearest graph (8 neighbours within a few point spacings, normals
agreeing) into components; small components are dropped and each crease point then joins the patch on
whose local tangent plane it lies, so neighbouring patches meet at the crease itself.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from rgm.errors import GeometryError
from rgm.fitters.normals import pca_normals

__all__ = ["checked_points", "median_spacing", "linked_components", "crease_mask", "split_scattered", "unit_rows"]


def checked_points(points) -> np.ndarray:
    """Points (n, 3) as floats; fewer than 16, or any not finite, are refused with a message."""
    p = np.asarray(points, float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 16:
        raise GeometryError(f"need at least 16 points (n, 3), got an array of shape {p.shape}")
    if not np.isfinite(p).all():
        raise GeometryError("points contain NaN or infinite coordinates")
    return p


def median_spacing(tree: cKDTree) -> float:
    """Median nearest-neighbour distance of the tree's points (model units)."""
    return float(np.median(tree.query(tree.data, k=2, workers=-1)[0][:, 1]))


def linked_components(points, normals, radius: float, angle_deg: float) -> np.ndarray:
    """Connected-component labels (n,) of the graph linking each point to its 8 nearest within `radius`
    whose normals agree within `angle_deg` (normals None: no normal test)."""
    # k as a list: (n, k) arrays even for a single point
    d, nb = cKDTree(points).query(points, k=list(range(1, min(9, len(points)) + 1)),
                                  distance_upper_bound=radius, workers=-1)
    linked = np.isfinite(d[:, 1:])
    pairs = np.c_[np.repeat(np.arange(len(points)), linked.sum(axis=1)), nb[:, 1:][linked]]
    if normals is not None:
        cos = np.abs(np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]))
        pairs = pairs[cos >= np.cos(np.radians(angle_deg))]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points), len(points)))
    return connected_components(graph, directed=False)[1]


def crease_mask(points, normals=None, *, angle_deg: float = 35.0, k: int = 16, tree=None) -> np.ndarray:
    """(n,) bool: points whose neighbourhood (2k nearest) holds at least two unit normals more than
    `angle_deg` away from the point's own, or whose k nearest are mostly such points (no stray smooth
    point inside a band). Normals (n, 3) may be unoriented; by default robust PCA normals."""
    points = checked_points(points)
    tree = tree or cKDTree(points)
    normals = pca_normals(points, k, tree=tree)[0] if normals is None else np.asarray(normals, float)
    _, idx = tree.query(points, k=int(min(2 * k, len(points))), workers=-1)
    cos = np.abs(np.einsum("nkd,nd->nk", normals[idx], normals))
    crease = np.sort(cos, axis=1)[:, 1] < np.cos(np.radians(angle_deg))
    return crease | (crease[idx[:, :k]].mean(axis=1) >= 0.5)


def split_scattered(points, normals=None, *, angle_deg: float = 35.0, k: int = 16, radius: float | None = None,
                    min_points: int | None = None) -> list[np.ndarray]:
    """Split scattered points (n, 3) at their creases: index arrays, one a patch, largest first.

    The graph links each smooth point to its 8 nearest smooth points within `radius` (default 5 x the
    median point spacing) whose normals agree within `angle_deg`: a k-nearest graph follows the sampling
    density, which varies between overlapping and single views. Components smaller than `min_points`
    (default 0.25 % of the points, at least 30) are dropped; crease points then join the patch on whose
    tangent plane they lie, and those with no patch near stay out."""
    points = checked_points(points)
    tree = cKDTree(points)
    radius = radius or 5 * median_spacing(tree)
    min_points = min_points or max(30, len(points) // 400)
    normals = pca_normals(points, k, tree=tree)[0] if normals is None else unit_rows(np.asarray(normals, float))
    crease = crease_mask(points, normals, angle_deg=angle_deg, k=k, tree=tree)
    keep = np.nonzero(~crease)[0]
    if len(keep) == 0:
        raise GeometryError("every point lies on a crease: lower the crease angle or check the normals")
    comp = linked_components(points[keep], normals[keep], radius, angle_deg)
    sizes = np.bincount(comp)
    big = np.nonzero(sizes >= min_points)[0]
    big = big[np.argsort(-sizes[big], kind="stable")]
    if len(big) == 0:
        raise GeometryError(f"no patch of at least {min_points} points between the creases")
    rank = np.full(len(sizes), -1)
    rank[big] = np.arange(len(big))
    label = np.full(len(points), -1)
    label[keep] = rank[comp]
    # each crease point joins the patch on whose local tangent plane it lies: the plane fitted to the 24
    # smooth points of the patch nearest to its nearest one (within 4 radius; near a corner that may be 8
    # point spacings away, where one point's normal averaged over its 8 neighbours tilted enough to send a
    # point 0.09 mm off one face but 0.5 mm off the other to the other), so neighbouring patches meet at the
    # crease and no point of one face is pulled into the other
    loose = np.nonzero(label < 0)[0]
    best = np.full(len(loose), np.inf)
    for r in range(len(big)):
        own = np.nonzero(label == r)[0]
        tree = cKDTree(points[own])
        d, j = tree.query(points[loose], distance_upper_bound=4 * radius, workers=-1)
        ok = np.isfinite(d)
        k = min(24, len(own))
        around = own[tree.query(points[own[j[ok]]], k=k, workers=-1)[1].reshape(-1, k)]
        off = np.full(len(loose), np.inf)
        off[ok] = plane_offsets(points[loose[ok]], points[around])
        better = off < best
        best[better] = off[better]
        label[loose[better]] = r
    return [np.nonzero(label == r)[0] for r in range(len(big))]


def plane_offsets(query, around):
    """Distances (m,) of points `query` (m, 3) from the least-squares planes of their neighbourhoods
    `around` (m, k, 3): the plane through each neighbourhood's centroid normal to its least variance."""
    centre = around.mean(axis=1)
    _, _, vt = np.linalg.svd(around - centre[:, None], full_matrices=False)
    return np.abs(np.einsum("md,md->m", query - centre, vt[:, -1]))


def unit_rows(a):
    return a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-300)
