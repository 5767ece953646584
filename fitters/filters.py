"""Robust filtering of scans: the RLTS range-image filter and outlier removal for unstructured clouds.

RLTS filter (reweighted least trimmed squares; Rousseeuw & Leroy, *Robust Regression and Outlier
Detection*, 1987; the paper's filter [8]).  Overlapping w x w windows slide over the range image with a
stride.  In every window the depth along the viewing direction is modelled as a quadric of the two lateral
coordinates and fitted by LTS: FAST-LTS (Rousseeuw & Van Driessen, 2006) with random elemental plane
subsets and concentration steps (C-steps) on the quadric, all windows of a batch at once (numpy batched
solves, no per-window Python loop).  The LTS scale, corrected for consistency at the normal model,
selects the inliers; one least-squares refit on them (the "reweighting") gives the final fit and the
window's noise scale.

A pixel is an outlier only if it is far from the fit of *every* window containing it.  Near a step or a
corner some window lies wholly on the pixel's own surface, so edge pixels are kept and nothing is ever
averaged across a step: kept pixels are returned unchanged, rejected ones are dropped or replaced by the
depth of the fit of the window most centred on them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.spatial import cKDTree
from scipy.stats import norm

from rgm.fitters.io import Scan, ScanError

__all__ = ["FilterResult", "rlts_filter", "pixel_spacing", "statistical_outliers", "radius_outliers", "view_axis"]


@dataclass(frozen=True, eq=False)
class FilterResult:
    """scan: the filtered scan; rejected: (n,) bool over the *input* points; replaced: (n,) bool, rejected
    points that were moved onto the local fit (mode "replace") instead of dropped; score: (n,) smallest
    standardised residual over the windows holding each point (inf if no window could judge it);
    sigma: the median window noise scale (file units)."""

    scan: Scan
    rejected: np.ndarray
    replaced: np.ndarray
    score: np.ndarray
    sigma: float


def view_axis(scan: Scan) -> np.ndarray:
    """(3,) unit viewing direction of a scan: its `view_dir`, the mean ray from its sensor origin, or
    (unknown sensor) the normal of the best-fit plane, pointing away from the centroid's side it faces."""
    if scan.view_dir is not None:
        v = np.asarray(scan.view_dir, float)
    elif scan.origin is not None:
        v = scan.points.mean(axis=0) - np.asarray(scan.origin, float)
    else:
        centred = scan.points - scan.points.mean(axis=0)
        v = np.linalg.svd(centred[:: max(1, len(centred) // 20000)], full_matrices=False)[2][2]
    return v / np.linalg.norm(v)


def pixel_spacing(scan: Scan) -> float:
    """Median 3-D distance between horizontally or vertically adjacent valid pixels of a range image."""
    g = scan.grid
    pairs = [(g[:, :-1], g[:, 1:]), (g[:-1, :], g[1:, :])]
    d = [np.linalg.norm(scan.points[p[ok]] - scan.points[q[ok]], axis=1)
         for p, q in pairs for ok in [(p >= 0) & (q >= 0)]]
    d = np.concatenate(d)
    return float(np.median(d)) if len(d) else 1.0


def _frame(v):
    """Two unit vectors completing v to a right-handed orthonormal frame."""
    a = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(v, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(v, e1)


def _quadric_design(u, v):
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)


def _weighted_fit(X, y, w, ridge=1e-9):
    """Batched weighted least squares: X (..., m, p), y (..., m), w (..., m) -> beta (..., p)."""
    Xw = X * w[..., None]
    A = np.einsum("...mi,...mj->...ij", Xw, X)
    A += ridge * np.eye(X.shape[-1])
    return np.linalg.solve(A, np.einsum("...mi,...m->...i", Xw, y)[..., None])[..., 0]


def _lts_windows(X, y, valid, h, rng, subsets, csteps):
    """FAST-LTS on a batch of windows. X (B, m, 6) quadric design, y (B, m), valid (B, m) bool,
    h (B,) coverage. Returns beta (B, 6), residual r (B, m) and the consistency-corrected LTS scale (B,)."""
    B, m, _ = X.shape
    keys = rng.random((B, subsets, m))
    keys[~np.broadcast_to(valid[:, None, :], keys.shape)] = 2.0
    pick = np.argpartition(keys, 3, axis=-1)[..., :3]                          # (B, K, 3) elemental plane subsets
    Xs = np.take_along_axis(X[:, None, :, :3], pick[..., None], axis=2)       # (B, K, 3, 3)
    ys = np.take_along_axis(np.broadcast_to(y[:, None, :], keys.shape), pick, axis=2)
    det = np.linalg.det(Xs)
    ok = np.abs(det) > 1e-10
    Xs[~ok] = np.eye(3)
    beta = np.linalg.solve(Xs, ys[..., None])[..., 0]                         # (B, K, 3)
    r2 = (y[:, None, :] - np.einsum("bmi,bki->bkm", X[..., :3], beta)) ** 2
    r2[~np.broadcast_to(valid[:, None, :], r2.shape)] = np.inf
    r2[~ok] = np.inf
    hk = np.broadcast_to(h[:, None, None] - 1, (B, subsets, 1))
    objective = np.take_along_axis(np.cumsum(np.sort(r2, axis=-1), axis=-1), hk, axis=-1)[..., 0]
    best = np.argmin(np.where(np.isfinite(objective), objective, np.inf), axis=1)
    r2 = r2[np.arange(B), best]                                               # (B, m)
    for _ in range(csteps):                                                   # C-steps with the quadric
        cut = np.take_along_axis(np.sort(r2, axis=1), h[:, None] - 1, axis=1)
        w = (r2 <= cut).astype(float)
        beta = _weighted_fit(X, y, w)
        r = y - np.einsum("bmi,bi->bm", X, beta)
        r2 = np.where(valid, r * r, np.inf)
    n_valid = valid.sum(axis=1)
    alpha = h / n_valid
    q = norm.ppf((1 + alpha) / 2)
    factor = 1 - 2 * q * norm.pdf(q) / alpha                                  # E[z^2 | |z| < q] for z ~ N(0, 1)
    trimmed = np.take_along_axis(np.cumsum(np.sort(r2, axis=1), axis=1), h[:, None] - 1, axis=1)[:, 0] / h
    return beta, np.where(valid, y - np.einsum("bmi,bi->bm", X, beta), 0.0), np.sqrt(trimmed / factor)


def rlts_filter(scan: Scan, *, window: int = 7, stride: int = 2, k: float = 3.0, mode: str = "replace",
                subsets: int = 24, csteps: int = 3, seed: int = 0, batch: int = 3000) -> FilterResult:
    """Reject outliers of a range image by the RLTS filter (module docstring).

    window : odd window size in pixels; stride : window spacing (<= window // 3 keeps corners: some window
    around a corner pixel is then >= 70 % on the pixel's own surface); k : rejection threshold in units of
    the window's robust noise scale; mode : "replace" or "drop".
    """
    if scan.grid is None:
        raise ScanError(f"{scan.source}: the RLTS filter needs a range image (a pixel grid); "
                        "use statistical_outliers for unstructured clouds")
    if mode not in ("replace", "drop"):
        raise ValueError(f"mode must be 'replace' or 'drop', not {mode!r}")
    rng = np.random.default_rng(seed)
    v = view_axis(scan)
    e1, e2 = _frame(v)
    a, b, d = scan.points @ e1, scan.points @ e2, scan.points @ -v
    rows, cols = scan.grid.shape
    pr = (-(rows - window) % stride) if rows > window else window - rows
    pc = (-(cols - window) % stride) if cols > window else window - cols
    ids_img = np.pad(scan.grid, ((0, pr), (0, pc)), constant_values=-1)
    wins = sliding_window_view(ids_img, (window, window))[::stride, ::stride]
    n_r, n_c = wins.shape[:2]
    ids = wins.reshape(n_r * n_c, window * window)
    valid = ids >= 0
    p = 6
    usable = valid.sum(axis=1) >= max(2 * p + 2, window * window // 2)
    scale = max(pixel_spacing(scan) * window, 1e-12)

    n_w = len(ids)
    betas = np.zeros((n_w, p))
    centre = np.zeros((n_w, 3))
    sigma = np.full(n_w, np.inf)
    resid = np.zeros(ids.shape)
    for start in range(0, n_w, batch):
        sel = np.flatnonzero(usable[start:start + batch]) + start
        if not len(sel):
            continue
        vb, ib = valid[sel], np.where(valid[sel], ids[sel], 0)
        cnt = vb.sum(axis=1)
        mean = lambda z: (np.where(vb, z[ib], 0).sum(axis=1) / cnt)  # noqa: E731
        c3 = np.column_stack([mean(a), mean(b), mean(d)])
        X = _quadric_design((a[ib] - c3[:, :1]) / scale, (b[ib] - c3[:, 1:2]) / scale)
        y = np.where(vb, (d[ib] - c3[:, 2:]) / scale, 0.0)
        h = (cnt + p + 1) // 2
        beta, r, s_lts = _lts_windows(X, y, vb, h, rng, subsets, csteps)
        inl = vb & (np.abs(r) <= 2.5 * s_lts[:, None])                            # reweighting step
        beta = _weighted_fit(X, y, inl.astype(float))
        r = np.where(vb, y - np.einsum("bmi,bi->bm", X, beta), 0.0)
        dof = np.maximum(inl.sum(axis=1) - p, 1)
        sigma[sel] = np.sqrt((np.where(inl, r, 0.0) ** 2).sum(axis=1) / dof) * scale
        betas[sel], centre[sel], resid[sel] = beta, c3, r * scale

    judged = usable[:, None] & valid
    noise = float(np.median(sigma[usable])) if usable.any() else 0.0
    z = np.abs(resid) / np.clip(sigma, 0.5 * noise, 2.0 * noise)[:, None]
    score = np.full(scan.n, np.inf)
    np.minimum.at(score, ids[judged], z[judged])
    rejected = score > k
    rejected &= np.isfinite(score)                                                # unjudged pixels are kept

    replaced = np.zeros(scan.n, bool)
    points = scan.points.copy()
    if mode == "replace" and rejected.any():
        idx = np.flatnonzero(rejected)
        pos = np.argwhere(scan.grid >= 0)
        rc = np.empty((scan.n, 2), np.int64)
        rc[scan.grid[pos[:, 0], pos[:, 1]]] = pos
        r_, c_ = rc[idx].T
        wr = np.clip(np.rint((r_ - (window - 1) / 2) / stride).astype(int), 0, n_r - 1)
        wc = np.clip(np.rint((c_ - (window - 1) / 2) / stride).astype(int), 0, n_c - 1)
        w_id = wr * n_c + wc
        ok = usable[w_id] & (r_ - wr * stride < window) & (c_ - wc * stride < window)
        idx, w_id = idx[ok], w_id[ok]
        X = _quadric_design((a[idx] - centre[w_id, 0]) / scale, (b[idx] - centre[w_id, 1]) / scale)
        d_fit = centre[w_id, 2] + scale * np.einsum("ni,ni->n", X, betas[w_id])
        points[idx] += (d_fit - d[idx])[:, None] * -v
        replaced[idx] = True
    out = scan.replace(points=points)
    out = out.select(~rejected | replaced)
    return FilterResult(out, rejected, replaced, score, noise)


def statistical_outliers(points, k: int = 16, ratio: float = 2.0) -> np.ndarray:
    """(n,) bool, True for outliers: points whose mean distance to their k nearest neighbours exceeds the
    mean of that statistic by `ratio` standard deviations (PCL's StatisticalOutlierRemoval)."""
    points = np.asarray(points, float)
    dist, _ = cKDTree(points).query(points, k=k + 1, workers=-1)
    mean_d = dist[:, 1:].mean(axis=1)
    return mean_d > mean_d.mean() + ratio * mean_d.std()


def radius_outliers(points, radius: float, min_neighbors: int = 4) -> np.ndarray:
    """(n,) bool, True for points with fewer than `min_neighbors` other points within `radius`."""
    points = np.asarray(points, float)
    counts = cKDTree(points).query_ball_point(points, radius, workers=-1, return_length=True)
    return counts - 1 < min_neighbors
