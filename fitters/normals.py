"""Surface normals of scans by robust local PCA, oriented towards the sensor.

For every point, the k nearest neighbours (cKDTree, all cores) give a covariance whose smallest
eigenvector is the plane normal (Hoppe et al., "Surface reconstruction from unorganized points", 1992).
One reweighting step with Tukey's biweight on the distances to that plane (scale from the median
absolute deviation) keeps neighbours from across an edge or outliers from tilting the plane.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rgm.fitters.io import Scan

__all__ = ["pca_normals", "estimate_normals", "orient_normals"]


def _weighted_plane(nb, w):
    """nb (n, k, 3), w (n, k) -> normals (n, 3), centroids (n, 3) of the weighted PCA plane."""
    ws = np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    c = (nb * w[..., None]).sum(axis=1) / ws
    d = nb - c[:, None, :]
    cov = np.einsum("nk,nki,nkj->nij", w, d, d)
    return np.linalg.eigh(cov)[1][:, :, 0], c


def pca_normals(points, k: int = 16, *, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented robust PCA normals.

    points : (n, 3). Returns normals (n, 3) unit and sigma (n,), the robust RMS distance of the inlying
    neighbours to the local plane (a local noise level, in the points' units).
    """
    points = np.asarray(points, float)
    k = int(min(k, len(points)))
    tree = tree or cKDTree(points)
    _, idx = tree.query(points, k=k, workers=-1)
    normals = np.empty_like(points)
    sigma = np.empty(len(points))
    for s in range(0, len(points), 100_000):  # bounded memory: (chunk, k, 3)
        nb = points[idx[s:s + 100_000]]
        n0, c = _weighted_plane(nb, np.ones(nb.shape[:2]))
        r = np.einsum("nki,ni->nk", nb - c[:, None, :], n0)
        mad = 1.4826 * np.median(np.abs(r - np.median(r, axis=1, keepdims=True)), axis=1)
        scale = 4.685 * np.maximum(mad, 1e-12 * (1 + np.abs(nb).max()))
        w = np.clip(1 - (r / scale[:, None]) ** 2, 0, None) ** 2                # Tukey biweight
        n1, c1 = _weighted_plane(nb, w)
        r1 = np.einsum("nki,ni->nk", nb - c1[:, None, :], n1)
        normals[s:s + 100_000] = n1
        sigma[s:s + 100_000] = np.sqrt((w * r1 ** 2).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300))
    return normals, sigma


def orient_normals(normals, points, scan: Scan | None = None) -> np.ndarray:
    """Flip normals (n, 3) to face the scan's sensor (origin or view direction); with no sensor known,
    away from the centroid of the points."""
    towards = None if scan is None else scan.sensor_directions()
    if towards is None:
        towards = points - points.mean(axis=0)
    flip = np.einsum("ij,ij->i", normals, towards) < 0
    return np.where(flip[:, None], -normals, normals)


def estimate_normals(scan: Scan, k: int = 16) -> np.ndarray:
    """(n, 3) robust PCA normals of `scan.points`, in the scan's frame, oriented towards the sensor."""
    normals, _ = pca_normals(scan.points, k)
    return orient_normals(normals, scan.points, scan)
