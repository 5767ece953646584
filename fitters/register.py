"""Registration of scan views: robust point-to-plane ICP, coarse alignment, incremental multi-view.

- `icp`: point-to-plane ICP (Chen & Medioni 1992) linearised about the current pose (Low 2004), with
  Tukey's biweight on the residuals (scale from the MAD), correspondences from a cKDTree (all cores)
  within a maximum distance that tightens as the fit improves (Zhang 1994: mean + 3 sd of the matched
  distances, never below a floor of a few point spacings).  Early iterations run on a small subsample of
  the source with approximate matches; the last ones on a larger one, with a few reweighting steps per
  correspondence search.  Convergence: relative change of the robust cost and a tiny step.
  The normal matrix J^T W J, with rotations scaled by the source's radius, tells how well each of the six
  motions is constrained (Gelfand et al., "Geometrically stable sampling for the ICP algorithm", 2003).
- `coarse_align`: no initial pose needed.  Many rotations (principal-axes matches plus uniform random
  ones) at a few anchor positions each get a few batched, trimmed point-to-point ICP steps on a small
  sample (Kabsch/Umeyama in batch; nearest points from a distance-transform lookup table); the best few
  are polished together by batched point-to-plane steps, and the one with the most points on the
  target's surface is finished with `icp`.
- `refine_poses`: global refinement, all poses at once by simultaneous point-to-plane least squares
  against each other, one view fixed as the gauge.
- `register_views`: the paper's incremental scheme: every new view is registered against the union of
  the views placed so far (failed views are retried once the model has grown), then the global
  refinement; every view gets a report with a status that says when not to trust it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rgm.fitters.io import Scan, ScanError
from rgm.fitters.normals import orient_normals, pca_normals

__all__ = ["IcpResult", "ViewReport", "icp", "coarse_align", "refine_poses", "register_views", "view_features",
           "pose_error", "rotation_angle", "tight_overlap"]


@dataclass(frozen=True, eq=False)
class IcpResult:
    """transform: (4, 4) source-to-target; rms: RMS point-to-plane residual of the inlying matches;
    overlap: fraction of source points within `min_dist` (3 point spacings) of the target, with
    compatible normals when known; iterations (correspondence searches); converged; condition:
    smallest / largest eigenvalue of the scaled 6x6 normal matrix; weak_direction: (6,) its eigenvector
    (rotation about x, y, z scaled by the radius, then translation x, y, z); max_dist: final distance."""

    transform: np.ndarray
    rms: float
    overlap: float
    iterations: int
    converged: bool
    condition: float
    weak_direction: np.ndarray
    max_dist: float


def rotation_angle(r) -> float:
    """Rotation angle (radians) of a (3, 3) rotation matrix."""
    return float(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))


def pose_error(estimate, truth, points) -> tuple[float, float, float]:
    """(angle in radians, translation at the centroid, RMS displacement over `points` (n, 3)) between
    two (4, 4) poses applied to the same points."""
    d = (points @ estimate[:3, :3].T + estimate[:3, 3]) - (points @ truth[:3, :3].T + truth[:3, 3])
    c = points.mean(axis=0)
    dc = (estimate[:3, :3] - truth[:3, :3]) @ c + estimate[:3, 3] - truth[:3, 3]
    return (rotation_angle(estimate[:3, :3] @ truth[:3, :3].T), float(np.linalg.norm(dc)),
            float(np.sqrt((d ** 2).sum(axis=1).mean())))


def _rodrigues(w) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors w (..., 3) (axis times angle in radians)."""
    w = np.asarray(w, float)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    tiny = theta < 1e-8
    safe = np.where(tiny, 1.0, theta)
    a = np.where(tiny, 1.0, np.sin(safe) / safe)                # series limits at theta -> 0
    b = np.where(tiny, 0.5, (1 - np.cos(safe)) / safe ** 2)
    return np.eye(3) + a * K + b * (K @ K)


def _motion(x, c) -> np.ndarray:
    """(..., 4, 4) rigid motions p -> R(x[:3]) (p - c) + c + x[3:] of 6-vectors x (..., 6) (rotation vector in
    radians, then translation) about the points c (..., 3)."""
    R = _rodrigues(x[..., :3])
    M = np.zeros(x.shape[:-1] + (4, 4))
    M[..., :3, :3] = R
    M[..., :3, 3] = c - (R @ c[..., None])[..., 0] + x[..., 3:]
    M[..., 3, 3] = 1.0
    return M


def _plane_solve(J, w, r) -> tuple[np.ndarray, np.ndarray]:
    """One Gauss-Newton step of the weighted point-to-plane cost sum w (r + J x)^2, batched: J (F, k, 6)
    rows [(p - c) x n, n], w (F, k) weights (0 = no match), r (F, k) residuals n . (p - q) (Low 2004).
    Returns x (F, 6) (rotation vector about c, then translation) and the normal matrices A (F, 6, 6)."""
    Jw = J * w[..., None]
    A = Jw.transpose(0, 2, 1) @ J
    b = np.einsum("fki,fk->fi", Jw, r)
    damp = 1e-12 * np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(6)
    return np.linalg.solve(A + damp, -b[..., None])[..., 0], A


def _spacing(tree: cKDTree, n_sample: int = 1000) -> float:
    """Median nearest-neighbour distance (file units) of about `n_sample` of the tree's points."""
    pts = tree.data[:: max(1, tree.n // n_sample)]
    return float(np.median(tree.query(pts, k=2)[0][:, 1]))


#: first-stage correspondences are approximate nearest neighbours, within (1 + APPROX) of the nearest
#: distance (Greenspan & Yurick 2003): the stage only brings the pose near; the final one is exact
APPROX = 1.0


def _workers(n: int) -> int:
    """cKDTree workers for a query of n points: all cores from a few thousand points on (below, starting
    the threads costs more than they save)."""
    return -1 if n > 2000 else 1


def _centroid(p) -> np.ndarray:
    """Mean (3,) of the rows of p (n, 3), as a matrix-vector product: numpy's mean over axis 0 of an
    (n, 3) array is several times slower."""
    return np.ones(len(p)) @ p / len(p)


def _tukey_step(p, q, n, conf, spacing: float, kernel: float):
    """One reweighted Gauss-Newton step of the point-to-plane cost for matches p -> (q, n) (k, 3) with
    target confidences conf (k,) or None: residuals r = n . (p - q), Tukey's biweight with the scale
    from their MAD (at least 5 % of the point spacing), linearised about the centroid c of p.
    Returns (x (6,) rotation vector about c and translation, c, normal matrix A (6, 6), r, w)."""
    d = p - q
    r = d[:, 0] * n[:, 0] + d[:, 1] * n[:, 1] + d[:, 2] * n[:, 2]
    s = max(1.4826 * float(np.median(np.abs(r))), 0.05 * spacing)
    w = np.clip(1 - (r / (kernel * s)) ** 2, 0, None) ** 2
    if conf is not None:
        w = w * conf
    c = _centroid(p)
    J = np.empty((len(p), 6))
    e = p - c
    J[:, 0] = e[:, 1] * n[:, 2] - e[:, 2] * n[:, 1]                  # (p - c) x n, then n
    J[:, 1] = e[:, 2] * n[:, 0] - e[:, 0] * n[:, 2]
    J[:, 2] = e[:, 0] * n[:, 1] - e[:, 1] * n[:, 0]
    J[:, 3:] = n
    x, A = _plane_solve(J[None], w[None], r[None])
    return x[0], c, A[0], r, w


def icp(source, target, target_normals, init=None, *, source_normals=None, target_weights=None,
        tree: cKDTree | None = None, spacing: float | None = None, max_dist: float | None = None,
        min_dist: float | None = None, max_iter: int = 60, tol: float = 1e-5, sample: int = 1000,
        final_sample: int = 10000, reweight: int = 3, kernel: float = 3.0, seed: int = 0) -> IcpResult:
    """Robust point-to-plane ICP of source (n, 3) onto target (m, 3) with unit normals (m, 3).

    init : (4, 4) initial source-to-target transform; source_normals : (n, 3), if given, matches whose
    normals differ by more than 45 degrees are dropped (edges, the other side of a thin wall);
    spacing : the target's point spacing (default: measured on the tree); target_weights : (m,)
    confidence of each target point (e.g. its planarity, low at creases);
    max_dist : initial correspondence distance (default: 3 x the median initial distance of the first
    stage's points, from its first search, which stops at a third of the source's RMS radius, and at most
    that radius); min_dist : its floor (default: 3 x the target's point spacing);
    sample : source points used in the first stage (approximate matches, one step each), which hands
    over when the step or the cost change falls below 10 x the final thresholds;
    final_sample : source points of the final stage (a random subset, Rusinkiewicz & Levoy 2001,
    containing the first stage's), which runs to convergence: the motion between two searches under
    1 % of the point spacing, far below the pose's own uncertainty, or a relative change of the cost
    under `tol`; more points hardly change the pose, whose error is bias, not variance;
    reweight : final-stage steps per correspondence search: the Tukey weights converge linearly (each
    reweighting about halves the step) and a step costs a fifth of a search on 10,000 points, so the
    matches are kept while the steps still count (until one falls below a third of the threshold);
    kernel : Tukey's constant in units of the MAD scale of the residuals (3.0 trades a little
    efficiency for less pull from the rim of the overlap).
    """
    source = np.asarray(source, float)
    tree = tree or cKDTree(target, balanced_tree=False)   # sliding midpoint: builds ~30 % faster, queries as fast
    T = np.eye(4) if init is None else np.array(init, float)
    spacing = _spacing(tree) if spacing is None else spacing
    min_dist = 3 * spacing if min_dist is None else min_dist
    order = np.random.default_rng(seed).permutation(len(source))         # nested random samples: its prefixes
    subset, everything = np.sort(order[:sample]), np.sort(order[:final_sample])
    e = source - _centroid(source)
    radius = float(np.sqrt(np.einsum("ij,ij->", e, e) / len(source)))
    full = len(subset) == len(everything)
    src = source[subset]
    src_n = None if source_normals is None else source_normals[subset]
    prev_cost, it, converged = np.inf, 0, False
    A = np.eye(6)
    rms, overlap = np.inf, None
    while it < max_iter:
        it += 1
        p = src @ T[:3, :3].T + T[:3, 3]
        dist, j = tree.query(p, distance_upper_bound=radius / 3 if max_dist is None else max_dist,
                             workers=_workers(len(p)), eps=0.0 if full else APPROX)
        if max_dist is None:   # the first search stops at radius / 3: a median beyond it means the cap; the
            max_dist = min(max(3 * float(np.median(dist)), min_dist), radius)      # first step uses what it found
            dist[dist > max_dist] = np.inf
        hit = np.flatnonzero(np.isfinite(dist))
        j = j[hit]
        n = np.take(target_normals, j, axis=0)
        if src_n is not None:                                       # compatible normals only
            agree = np.einsum("ij,ij->i", np.take(src_n, hit, axis=0) @ T[:3, :3].T, n) > 0.7
            hit, j, n = hit[agree], j[agree], n[agree]
        dist = dist[hit]
        if full:  # overlap at the tight distance, from this pass (the last step is tiny at convergence)
            overlap = float((dist <= min_dist).sum() / len(p))
        if len(hit) < 6:
            break
        src_hit, q = np.take(src, hit, axis=0), np.take(target, j, axis=0)
        conf = None if target_weights is None else target_weights[j]
        p, step_len = np.take(p, hit, axis=0), 0.0
        for k in range(reweight if full else 1):        # reweighting steps with these matches
            if k:
                p = src_hit @ T[:3, :3].T + T[:3, 3]
            x, c, A, r, w = _tukey_step(p, q, n, conf, spacing, kernel)
            T = _motion(x, c) @ T
            step = np.linalg.norm(x[:3]) * radius + np.linalg.norm(x[3:])
            step_len += step
            if step < 1e-2 / 3 * spacing:
                break
        inl = w > 0
        rms = float(np.sqrt((r[inl] ** 2).mean())) if inl.any() else np.inf
        cost = float((w * r * r).sum() / max(w.sum(), 1e-300))
        max_dist = max(min_dist, min(max_dist, float(dist.mean() + 3 * dist.std())))
        loose = 1.0 if full else 10.0                   # the first stage hands over at 10x looser thresholds
        if step_len < 1e-2 * loose * spacing or abs(prev_cost - cost) <= tol * loose * cost:
            if full:
                converged = True
                break
            src, full, prev_cost = source[everything], True, np.inf           # finish on the larger sample
            src_n = None if source_normals is None else source_normals[everything]
            continue
        prev_cost = cost
    if overlap is None or not full:
        p_all = source @ T[:3, :3].T + T[:3, 3]
        d_all, j_all = tree.query(p_all, distance_upper_bound=min_dist, workers=_workers(len(p_all)))
        matched = np.isfinite(d_all)
        if source_normals is not None:
            j_all = np.where(matched, j_all, 0)
            matched &= np.einsum("ij,ij->i", source_normals @ T[:3, :3].T, target_normals[j_all]) > 0.7
        overlap = float(matched.mean())
    D = np.diag([1 / radius] * 3 + [1.0] * 3)
    ev, evec = np.linalg.eigh(D @ A @ D)
    return IcpResult(T, rms, overlap, it, converged, float(ev[0] / max(ev[-1], 1e-300)), evec[:, 0], max_dist)


def _uniform_rotations(n, rng):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


def _principal_axis_rotations(src, dst):
    """The 4 proper rotations taking src's principal axes onto dst's (sign ambiguities)."""
    def axes(p):
        return np.linalg.svd(p - p.mean(axis=0), full_matrices=False)[2].T
    a, b = axes(src), axes(dst)
    out = []
    for sx in (1, -1):
        for sy in (1, -1):
            s = np.diag([sx, sy, sx * sy * np.linalg.det(a) * np.linalg.det(b)])
            out.append(b @ s @ a.T)
    return np.array(out)


class _CellNearest:
    """Approximate nearest neighbours by table lookup, for the many candidate poses of `coarse_align`.

    A voxel grid of `cells` cells along the longest side of the points' bounding box (plus a margin of
    `pad` cells) stores in every cell the index of a point in the occupied cell nearest to it (exact
    Euclidean distance transform with indices over the cell lattice, scipy.ndimage).  A query costs a few
    array operations; the point returned is within about one cell diagonal of the true nearest point, and
    its distance is the exact distance to that point.  Queries outside the grid use its border cells.
    """

    def __init__(self, points, cells: int = 64, pad: int = 2):
        from scipy.ndimage import distance_transform_edt

        self.points = np.asarray(points, float)
        lo, hi = self.points.min(axis=0), self.points.max(axis=0)
        self.cell = max(float((hi - lo).max()) / cells, 1e-300)
        self.lo = lo - pad * self.cell
        self.shape = np.floor((hi - self.lo) / self.cell).astype(np.int64) + pad + 1
        key = self._cells(self.points)
        owner = np.full(self.shape, -1, np.int64)
        owner[tuple(key.T)] = np.arange(len(self.points))
        near = distance_transform_edt(owner < 0, return_distances=False, return_indices=True)
        self.table = owner[tuple(near)].ravel()

    def _cells(self, p):
        return np.clip(np.floor((p - self.lo) / self.cell).astype(np.int64), 0, self.shape - 1)

    def query(self, p):
        """p (..., 3) -> (distance (...), index (...)) of the tabulated near point."""
        k = self._cells(p)
        j = self.table[(k[..., 0] * self.shape[1] + k[..., 1]) * self.shape[2] + k[..., 2]]
        return np.linalg.norm(p - self.points[j], axis=-1), j


def _polish(source, source_normals, target, target_normals, target_weights, tree: cKDTree, inits,
            spacing: float, bound: float, *, sample: int = 500, iters: int = 15, kernel: float = 3.0,
            seed: int = 0) -> np.ndarray:
    """Robust point-to-plane ICP of F initial poses at once (the finalists of `coarse_align`).

    source (n, 3) with unit normals (n, 3); target (m, 3) with unit normals (m, 3), confidences (m,) or
    None, and its k-d tree; inits (F, 4, 4); spacing: the target's point spacing; bound: the largest
    correspondence distance (file units).  `iters` Gauss-Newton steps as in `icp` (Tukey weights on the
    MAD scale, matches with normals more than 45 degrees apart dropped), all poses on the same `sample`
    source points, batched; each pose's correspondence distance starts at 3 x its median distance
    (at most `bound`: far queries are the k-d tree's slowest) and tightens to mean + 3 sd, never below
    3 spacings.
    Returns the polished poses (F, 4, 4)."""
    rng = np.random.default_rng(seed)
    sub = np.arange(len(source)) if len(source) <= sample else rng.choice(len(source), sample, replace=False)
    src, src_n = source[sub], source_normals[sub]
    T = np.array(inits, float)
    F, k = len(T), len(src)
    rows = np.arange(F)
    min_dist, max_dist = 3 * spacing, None
    for _ in range(iters):
        Rt = T[:, :3, :3].transpose(0, 2, 1)
        p = src @ Rt + T[:, None, :3, 3]
        bounds = np.full(F, bound) if max_dist is None else max_dist
        d, j = map(np.array, zip(*(tree.query(p[f], distance_upper_bound=bounds[f], workers=_workers(k))
                                   for f in range(F))))
        j = np.minimum(j, len(target) - 1)
        if max_dist is None:
            max_dist = np.clip(3 * np.median(d, axis=1), min_dist, bound)
        n = target_normals[j]
        ok = (d <= max_dist[:, None]) & (np.einsum("fki,fki->fk", src_n @ Rt, n) > 0.7)
        cnt = ok.sum(axis=1)
        r = np.einsum("fki,fki->fk", p - target[j], n)
        a = np.sort(np.where(ok, np.abs(r), np.inf), axis=1)[rows, np.maximum(cnt - 1, 0) // 2]   # median
        s = np.maximum(np.where(cnt > 0, 1.4826 * a, 0.0), 0.05 * spacing)
        w = np.clip(1 - (r / (kernel * s[:, None])) ** 2, 0, None) ** 2 * ok          # Tukey biweight
        if target_weights is not None:
            w = w * target_weights[j]
        c = np.einsum("fk,fki->fi", ok, p) / np.maximum(cnt, 1)[:, None]
        x, _ = _plane_solve(np.concatenate([np.cross(p - c[:, None], n), n], axis=-1), w, r)
        T = _motion(x, c) @ T
        dm = np.where(ok, d, 0.0)
        mean = dm.sum(axis=1) / np.maximum(cnt, 1)
        sd = np.sqrt(np.maximum((dm ** 2).sum(axis=1) / np.maximum(cnt, 1) - mean ** 2, 0))
        max_dist = np.where(cnt > 0, np.maximum(min_dist, np.minimum(max_dist, mean + 3 * sd)), max_dist)
    return T


def coarse_align(source, target, target_normals, source_normals=None, *, target_weights=None,
                 tree: cKDTree | None = None, spacing: float | None = None, anchors=None,
                 n_rotations: int = 600, min_per_anchor: int = 150, n_sample: int = 100, keep: float = 0.6,
                 steps: int = 8, finalists: int = 10, prune_at=(4, 6),
                 seed: int = 0) -> tuple[np.ndarray, IcpResult]:
    """Initial pose of source (n, 3) on target (m, 3) without any prior: sampled rotation search scored by
    the trimmed (fraction `keep`) point-to-point residual of matches whose normals agree (both views'
    normals face their sensors, so a back-to-front match has opposite normals), finished by `icp`.

    anchors : (k, 3) places on the target where the source's centroid may land (default: the target's
    centroid; a multi-view model passes each view's centroid too, since a new view overlaps only part
    of it).  Every anchor gets the identity, the 4 principal-axes matches and its own
    max(min_per_anchor, n_rotations // k) uniform random rotations, so the search costs about the same
    for one anchor or many while the union of the rotations grows denser.  Each candidate takes `steps`
    batched trimmed point-to-point ICP steps on `n_sample` source points against a 4000-point sample of
    the target (nearest points from `_CellNearest`, one table lookup each); the worse three quarters are
    pruned at the steps in `prune_at`.  The `finalists` best distinct rotations (> 20 degrees apart) are
    polished together (`_polish`, point-to-plane on the full target), the one with the largest
    `tight_overlap` is finished by `icp`.  spacing : the target's point spacing (default: measured).
    Returns (transform, result of the final icp)."""
    source = np.asarray(source, float)
    tree = tree or cKDTree(target)
    spacing = _spacing(tree) if spacing is None else spacing
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(source), min(n_sample, len(source)), replace=False)
    sample = source[pick]
    if source_normals is None:
        source_normals = orient_normals(pca_normals(source, 16)[0], source)
    sample_n = np.asarray(source_normals, float)[pick]
    keep_t = rng.choice(len(target), min(4000, len(target)), replace=False)
    small, small_n = target[keep_t], target_normals[keep_t]
    lookup = _CellNearest(small)
    bound = 0.5 * float(np.sqrt(((small - small.mean(axis=0)) ** 2).sum(axis=1).mean()))
    cs = source.mean(axis=0)
    anchors = target.mean(axis=0)[None] if anchors is None else np.asarray(anchors, float).reshape(-1, 3)
    per_anchor = max(min_per_anchor, n_rotations // len(anchors))               # each anchor: its own set
    fixed = np.concatenate([np.eye(3)[None], _principal_axis_rotations(source, target)])
    R = np.concatenate([np.concatenate([fixed, _uniform_rotations(per_anchor, rng)]) for _ in anchors])
    t = np.repeat(anchors, len(R) // len(anchors), axis=0) - R @ cs
    m = int(keep * len(sample))
    for step in range(steps):                                                  # batched trimmed ICP
        p = sample @ R.transpose(0, 2, 1) + t[:, None, :]                      # (candidates, k, 3)
        d, j = lookup.query(p)
        agree = ((sample_n @ R.transpose(0, 2, 1)) * small_n[j]).sum(axis=-1) > 0.5
        d = np.where(agree, np.minimum(d, bound), bound)
        sel = np.argpartition(d, m - 1, axis=1)[:, :m]                         # the m best matches
        ds = np.take_along_axis(d, sel, 1)
        if step in prune_at:                                                   # prune the hopeless
            alive = np.argsort(ds.mean(axis=1))[: max(4 * finalists, len(R) // 4)]
            R, t, p, j, ds, sel = R[alive], t[alive], p[alive], j[alive], ds[alive], sel[alive]
        ps = np.take_along_axis(p, sel[..., None], 1)
        qs = small[np.take_along_axis(j, sel, 1)]
        w = (ds < bound).astype(float)[..., None]                              # weighted Kabsch
        ws = np.maximum(w.sum(axis=1), 1.0)
        pc, qc = (w * ps).sum(axis=1) / ws, (w * qs).sum(axis=1) / ws
        H = (w * (ps - pc[:, None])).transpose(0, 2, 1) @ (qs - qc[:, None])
        U, _, Vt = np.linalg.svd(H)
        S = np.ones((len(H), 3))
        S[:, 2] = np.sign(np.linalg.det(Vt.transpose(0, 2, 1) @ U.transpose(0, 2, 1)))
        dR = Vt.transpose(0, 2, 1) @ (S[:, :, None] * U.transpose(0, 2, 1))
        R = dR @ R
        t = np.einsum("nij,nj->ni", dR, t - pc) + qc
    score = ds.mean(axis=1)
    chosen = []                                                                # distinct rotations only
    for i in np.argsort(score):
        if all(rotation_angle(R[i] @ R[j].T) > np.radians(20) for j in chosen):
            chosen.append(i)
            if len(chosen) == finalists:
                break
    inits = np.tile(np.eye(4), (len(chosen), 1, 1))
    inits[:, :3, :3], inits[:, :3, 3] = R[chosen], t[chosen]
    polished = _polish(source, source_normals, target, target_normals, target_weights, tree, inits, spacing,
                       bound, seed=seed)
    fits = [tight_overlap(source, T, target, target_normals, tree, spacing=spacing) for T in polished]
    best = polished[int(np.argmax(fits))]
    res = icp(source, target, target_normals, best, source_normals=source_normals,
              target_weights=target_weights, tree=tree, spacing=spacing)
    return res.transform, res


def tight_overlap(source, transform, target, target_normals, tree: cKDTree, noise: float | None = None,
                  spacing: float | None = None) -> float:
    """Fraction of source points (n, 3), moved by `transform`, lying within 2 point spacings (default:
    measured on the tree) of the target and within 3 noise levels (default: a tenth of a spacing) of its
    tangent plane."""
    spacing = _spacing(tree) if spacing is None else spacing
    noise = 0.1 * spacing if noise is None else noise
    p = source @ transform[:3, :3].T + transform[:3, 3]
    d, j = tree.query(p, distance_upper_bound=2 * spacing, workers=_workers(len(p)))
    ok = np.isfinite(d)
    r = np.abs(np.einsum("ij,ij->i", p[ok] - target[j[ok]], target_normals[j[ok]]))
    return float((r < 3 * noise).sum() / len(p))


@dataclass
class ViewReport:
    """One view's registration: pose (4, 4) view-to-common-frame, RMS residual, overlap fraction (near the
    model), inlier fraction (on the model's surface within the noise), iterations, condition (of the
    6 x 6 normal matrix, as in `IcpResult`), status ("reference", "ok", or the first failed check) and
    every failed check in reasons."""

    source: str
    transform: np.ndarray
    rms: float = 0.0
    overlap: float = 1.0
    iterations: int = 0
    condition: float = 1.0
    inliers: float = 1.0
    status: str = "reference"
    reasons: list = field(default_factory=list)

    def to_json(self) -> dict:
        return {"file": self.source, "transform": np.round(self.transform, 12).tolist(),
                "rms": self.rms if np.isfinite(self.rms) else None,
                "overlap": self.overlap, "inliers": self.inliers, "iterations": self.iterations,
                "condition": self.condition,
                "status": self.status, "reasons": self.reasons}


def _judge(res: IcpResult, inliers: float, noise: float, min_overlap: float, min_condition: float) -> list[str]:
    """The reasons not to trust a registration (empty: trust it). `inliers` is the fraction of the view
    lying on the model's tangent planes within 3 noise levels: a wrong pose can keep a fair overlap at
    a few point spacings, never many points on the surface."""
    reasons = []
    if res.overlap < min_overlap or inliers < 0.5 * min_overlap:
        reasons.append(f"low_overlap: {res.overlap:.0%} of the view is near the model and {inliers:.0%} on it "
                       f"(need {min_overlap:.0%} and {0.5 * min_overlap:.0%})")
    if res.condition < min_condition:
        names = ["rotation x", "rotation y", "rotation z", "translation x", "translation y", "translation z"]
        weak = names[int(np.argmax(np.abs(res.weak_direction)))]
        reasons.append(f"degenerate: the surfaces leave {weak} nearly unconstrained "
                       f"(eigenvalue ratio {res.condition:.1e} < {min_condition:.0e})")
    if res.rms > 4 * noise:
        reasons.append(f"high_residual: RMS {res.rms:.3g} is {res.rms / noise:.1f}x the noise level {noise:.3g}")
    if not res.converged:
        reasons.append(f"not_converged after {res.iterations} iterations")
    return reasons


def refine_poses(points, normals, poses, free, *, weights=None, noise: float | None = None,
                 max_rounds: int = 30, sample: int = 8000, neighbours: int = 8, kernel: float = 3.0,
                 tol: float = 1e-5, seed: int = 0) -> tuple[list, dict, dict]:
    """Global refinement: all poses at once by simultaneous robust point-to-plane least squares.

    points, normals : per view (n_v, 3) in the view's own frame (unit normals facing the view's sensor);
    poses : per view (4, 4) view-to-common-frame, or None for a view to leave out; free : indices of the
    views whose poses move; the other views with a pose stay fixed (at least one: the gauge).
    weights : per view (n_v,) confidence of each point (planarity) or None; noise : noise level (file
    units) for the inlier fractions (default: a tenth of the point spacing).

    Every round, all views are put in the common frame in one k-d tree, and each point of a fixed random
    sample (`sample` per view) is matched to the nearest point of another view among its `neighbours`
    nearest (normals at most 45 degrees apart), within a distance that starts at 2 x `min_dist`
    (`min_dist` = 3 point spacings of a single view) and tightens as in `icp`.  A match (p of view i,
    q of view j, normal n at q) has the residual r = n . (p - q); a small motion (w_k, t_k) of pose k about
    its view's centroid c_k changes it by [(p - c_i) x n, n] . (w_i, t_i) - [(p - c_j) x n, n] . (w_j, t_j)
    (exact to first order, the turn of n included), so the matches form a sparse Jacobian over the free
    poses (12 entries a row).  One Gauss-Newton step of the Tukey-weighted cost (scale from the MAD of all
    residuals) moves all free poses together (Neugebauer 1997, "Reconstruction of real-world objects via
    simultaneous registration and robust combination of multiple range images"; Pulli 1999).
    Convergence: the largest pose step below 3e-3 spacings, or a relative change of the cost below `tol`.

    Returns (poses, results, inliers): the refined poses (list, None where given None); for every free
    view an `IcpResult` from the last round (rms of its inlying matches, overlap = fraction of its sample
    matched within `min_dist`, iterations = rounds, converged, and the condition of its own 6 x 6 block,
    the view as a source against the others held fixed, scaled as in `icp`); and the fraction of its
    sample within 2 spacings of the other views and 3 noise levels of their tangent planes (as
    `tight_overlap`).
    """
    from scipy.sparse import csr_matrix

    used = [k for k, T in enumerate(poses) if T is not None]
    free = [k for k in dict.fromkeys(free) if k in used]
    if len(free) == len(used):
        raise ValueError("refine_poses needs at least one fixed view (the gauge)")
    poses = [None if T is None else np.array(T, float) for T in poses]
    rng = np.random.default_rng(seed)
    sizes = [len(points[k]) for k in used]
    start = dict(zip(used, np.cumsum([0] + sizes)))
    label = np.repeat(used, sizes)
    wt = np.concatenate([np.ones(len(points[k])) if weights is None else weights[k] for k in used])
    picks = np.concatenate([start[k] + (np.arange(len(points[k])) if len(points[k]) <= sample
                                        else np.sort(rng.choice(len(points[k]), sample, replace=False)))
                            for k in used])
    qlab = label[picks]
    spacing = float(np.median([_spacing(cKDTree(points[k])) for k in used]))
    min_dist = 3 * spacing
    noise = 0.1 * spacing if noise is None else noise
    centre = {k: points[k].mean(axis=0) for k in used}                    # in the view's own frame
    radius = {k: float(np.sqrt(((points[k] - centre[k]) ** 2).sum(axis=1).mean())) for k in used}
    slot = np.full(len(poses), -1)
    slot[free] = np.arange(len(free))
    world, world_n = np.empty((len(label), 3)), np.empty((len(label), 3))
    max_dist, prev_cost, rounds, converged = 2 * min_dist, np.inf, 0, False
    while rounds < max_rounds:
        rounds += 1
        c_w = np.zeros((len(poses), 3))
        for k in used:
            R, t = poses[k][:3, :3], poses[k][:3, 3]
            world[start[k]:start[k] + len(points[k])] = points[k] @ R.T + t
            world_n[start[k]:start[k] + len(points[k])] = normals[k] @ R.T
            c_w[k] = R @ centre[k] + t
        q, qn = world[picks], world_n[picks]
        d, nb = cKDTree(world).query(q, k=neighbours, distance_upper_bound=max_dist, workers=_workers(len(q)))
        nb = np.where(np.isfinite(d), nb, 0)
        ok = np.isfinite(d) & (label[nb] != qlab[:, None]) & (np.einsum("qi,qki->qk", qn, world_n[nb]) > 0.7)
        has = ok.any(axis=1)
        first = ok.argmax(axis=1)[has]
        src, tgt, dist = picks[has], nb[has, first], d[has, first]
        i, j = label[src], label[tgt]
        p, n = world[src], world_n[tgt]
        r = np.einsum("mi,mi->m", p - world[tgt], n)
        s = max(1.4826 * float(np.median(np.abs(r))), 0.05 * spacing) if len(r) else 0.05 * spacing
        w = np.clip(1 - (r / (kernel * s)) ** 2, 0, None) ** 2 * wt[tgt]     # Tukey biweight
        a_i = np.hstack([np.cross(p - c_w[i], n), n])
        a_j = -np.hstack([np.cross(p - c_w[j], n), n])
        cols = np.hstack([6 * slot[i][:, None] + np.arange(6), 6 * slot[j][:, None] + np.arange(6)])
        vals = np.hstack([a_i, a_j])
        keep = cols >= 0                                                    # fixed poses: no unknowns
        J = csr_matrix((vals[keep], (np.repeat(np.arange(len(r)), 12).reshape(-1, 12)[keep], cols[keep])),
                       shape=(len(r), 6 * len(free)))
        H = (J.T @ J.multiply(w[:, None])).toarray()
        g = J.T @ (w * r)
        x = np.linalg.solve(H + 1e-12 * np.trace(H) * np.eye(len(H)), -g)
        step_len = 0.0
        for k in free:
            xk = x[6 * slot[k]:6 * slot[k] + 6]
            poses[k] = _motion(xk, c_w[k]) @ poses[k]
            step_len = max(step_len, np.linalg.norm(xk[:3]) * radius[k] + np.linalg.norm(xk[3:]))
        cost = float((w * r * r).sum() / max(w.sum(), 1e-300))
        if len(dist):
            max_dist = max(min_dist, min(max_dist, float(dist.mean() + 3 * dist.std())))
        if step_len < 3e-3 * spacing or abs(prev_cost - cost) <= tol * cost:
            converged = True
            break
        prev_cost = cost
    results, inliers = {}, {}
    for k in free:                                  # statistics of the last round (its step is tiny)
        mine = i == k
        n_k = int((qlab == k).sum())
        inl = mine & (w > 0)
        own = (a_i[mine].T * w[mine]) @ a_i[mine]
        D = np.diag([1 / radius[k]] * 3 + [1.0] * 3)
        ev, evec = np.linalg.eigh(D @ own @ D)
        results[k] = IcpResult(poses[k], float(np.sqrt((r[inl] ** 2).mean())) if inl.any() else np.inf,
                               float((mine & (dist <= min_dist)).sum() / n_k), rounds, converged,
                               float(ev[0] / max(ev[-1], 1e-300)), evec[:, 0], max_dist)
        inliers[k] = float((mine & (dist <= 2 * spacing) & (np.abs(r) < 3 * noise)).sum() / n_k)
    return poses, results, inliers


def view_features(scan: Scan, k: int = 16) -> tuple[np.ndarray, np.ndarray, float]:
    """What registration needs of a view: robust PCA normals (n, 3) on k neighbours, oriented to the
    sensor; confidences (n,) = 1 / (1 + (sigma / median sigma)^2) from each point's local plane-fit
    residual sigma (low at creases, rims and noisy spots, whose tangent planes are poor targets); and
    the view's noise level, the median sigma (file units)."""
    n, sig = pca_normals(scan.points, k)
    noise = float(np.median(sig))
    return orient_normals(n, scan.points, scan), 1 / (1 + (sig / max(noise, 1e-300)) ** 2), noise


def register_views(scans: list[Scan], *, use_poses: bool = False, refine: bool = True, k_normals: int = 16,
                   min_overlap: float = 0.25, min_condition: float = 2e-3, seed: int = 0) -> list[ViewReport]:
    """Register views incrementally into the frame of the first one (the paper's scheme), then refine all
    poses together.

    1. Every view in turn is registered against the union of the trusted views placed so far (the model
       constructed so far): `icp` from its `pose` when use_poses (e.g. poses read from a .conf), else
       `coarse_align` anchored at the model's and every placed view's centroid.
    2. A view that fails a check (`_judge`) stays out of the model; once the model has grown, failed views
       are tried again against it, until a pass places no new view.
    3. refine (with at least three trusted views): `refine_poses` moves all trusted views but the first
       (the gauge) together against each other; their reports then give the refined statistics.
    Returns one `ViewReport` per view; `transform` is the view's pose in the first view's frame.
    """
    if not scans:
        raise ScanError("no views to register")
    normals, weights, noise = zip(*(view_features(s, k_normals) for s in scans))
    noise_level = max(float(np.median(noise)) * np.sqrt(2), 1e-300)           # two noisy surfaces meet
    poses = [np.array(s.pose if use_poses else np.eye(4), float) for s in scans]
    if use_poses:
        base = np.linalg.inv(poses[0])
        poses = [base @ p for p in poses]
    start = [p.copy() for p in poses]
    reports = [ViewReport(scans[0].source, poses[0])] + [None] * (len(scans) - 1)
    trusted = [0]                            # the model constructed so far: views whose pose is trusted
    tried_with = {}                          # view -> size of the model it was last registered against

    def place(i):
        pts = np.concatenate([scans[k].points @ poses[k][:3, :3].T + poses[k][:3, 3] for k in trusted])
        nrm = np.concatenate([normals[k] @ poses[k][:3, :3].T for k in trusted])
        wts = np.concatenate([weights[k] for k in trusted])
        tree = cKDTree(pts)
        spacing = _spacing(tree)
        if use_poses:
            res = icp(scans[i].points, pts, nrm, start[i], source_normals=normals[i], target_weights=wts,
                      tree=tree, spacing=spacing, seed=seed)
        else:
            centres = [pts.mean(axis=0)] + [poses[k][:3, :3] @ scans[k].points.mean(axis=0) + poses[k][:3, 3]
                                            for k in trusted] if len(trusted) > 1 else None
            _, res = coarse_align(scans[i].points, pts, nrm, normals[i], target_weights=wts, tree=tree,
                                  spacing=spacing, anchors=centres, seed=seed + i)
        poses[i] = res.transform
        rep = ViewReport(scans[i].source, res.transform, res.rms, res.overlap, res.iterations, res.condition)
        rep.inliers = tight_overlap(scans[i].points, res.transform, pts, nrm, tree, noise_level, spacing)
        rep.reasons = _judge(res, rep.inliers, noise_level, min_overlap, min_condition)
        reports[i], tried_with[i] = rep, len(trusted)
        if not rep.reasons:
            trusted.append(i)

    for i in range(1, len(scans)):
        place(i)
    retry = [i for i in range(1, len(scans)) if i not in trusted and tried_with[i] < len(trusted)]
    while retry:
        for i in retry:
            place(i)
        retry = [i for i in range(1, len(scans)) if i not in trusted and tried_with[i] < len(trusted)]
    if refine and len(trusted) > 2:
        _, results, inliers = refine_poses(
            [s.points for s in scans], normals, [poses[k] if k in trusted else None for k in range(len(scans))],
            trusted[1:], weights=weights, noise=noise_level, seed=seed)
        for k, res in results.items():
            rep = reports[k]
            rep.transform, rep.rms, rep.overlap, rep.condition = res.transform, res.rms, res.overlap, res.condition
            rep.iterations += res.iterations
            rep.inliers = inliers[k]
            rep.reasons = _judge(res, rep.inliers, noise_level, min_overlap, min_condition)
    for rep in reports[1:]:
        rep.status = rep.reasons[0].split(":")[0].split(" ")[0] if rep.reasons else "ok"
    return reports
