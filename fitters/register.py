"""Registration of scan views: robust point-to-plane ICP, coarse alignment, incremental multi-view.

- `icp`: point-to-plane ICP (Chen & Medioni 1992) linearised about the current pose (Low 2004), with
  Tukey's biweight on the residuals (scale from the MAD), correspondences from a cKDTree (all cores)
  within a maximum distance that tightens as the fit improves (Zhang 1994: mean + 3 sd of the matched
  distances, never below a floor of a few point spacings).  Early iterations run on a subsample of the
  source; the last ones on all of it.  Convergence: relative change of the robust cost and a tiny step.
  The normal matrix J^T W J, with rotations scaled by the source's radius, tells how well each of the six
  motions is constrained (Gelfand et al., "Geometrically stable sampling for the ICP algorithm", 2003).
- `coarse_align`: no initial pose needed.  Many rotations (principal-axes matches plus uniform random
  ones) each get a few batched, trimmed point-to-point ICP steps on a small sample (Kabsch/Umeyama in
  batch); the best few are finished with `icp` and the one with the largest overlap wins.
- `register_views`: the paper's incremental scheme: every new view is registered against the union of
  the views placed so far, then optional global refinement of each view against all the others; every
  view gets a report with a status that says when not to trust it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rgm.fitters.io import Scan, ScanError
from rgm.fitters.normals import orient_normals, pca_normals

__all__ = ["IcpResult", "ViewReport", "icp", "coarse_align", "register_views", "pose_error", "rotation_angle"]


@dataclass(frozen=True, eq=False)
class IcpResult:
    """transform: (4, 4) source-to-target; rms: RMS point-to-plane residual of the inlying matches;
    overlap: fraction of source points within `min_dist` (3 point spacings) of the target, with
    compatible normals when known; iterations; converged; condition:
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
    theta = np.linalg.norm(w)
    if theta < 1e-15:
        return np.eye(3)
    k = w / theta
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K


def _spacing(tree: cKDTree, n_sample: int = 1000) -> float:
    pts = tree.data[:: max(1, tree.n // n_sample)]
    return float(np.median(tree.query(pts, k=2)[0][:, 1]))


def icp(source, target, target_normals, init=None, *, source_normals=None, target_weights=None,
        tree: cKDTree | None = None, max_dist: float | None = None, min_dist: float | None = None,
        max_iter: int = 60, tol: float = 1e-5, sample: int = 4000, final_sample: int = 16000,
        kernel: float = 3.0, seed: int = 0) -> IcpResult:
    """Robust point-to-plane ICP of source (n, 3) onto target (m, 3) with unit normals (m, 3).

    init : (4, 4) initial source-to-target transform; source_normals : (n, 3), if given, matches whose
    normals differ by more than 45 degrees are dropped (edges, the other side of a thin wall);
    target_weights : (m,) confidence of each target point (e.g. its planarity, low at creases);
    max_dist : initial correspondence distance (default: 3 x the median initial distance); min_dist : its
    floor (default: 3 x the target's point spacing); sample : source points used in the first stage;
    final_sample : source points (a random subset, Rusinkiewicz & Levoy 2001) of the final stage, which
    runs to convergence; more points hardly change the pose, whose error is bias, not variance; kernel : Tukey's constant in units of the MAD scale of the residuals
    (3.0 trades a little efficiency for less pull from the rim of the overlap).
    """
    source = np.asarray(source, float)
    tree = tree or cKDTree(target)
    T = np.eye(4) if init is None else np.array(init, float)
    spacing = _spacing(tree)
    min_dist = 3 * spacing if min_dist is None else min_dist
    rng = np.random.default_rng(seed)
    def pick(k):
        return np.arange(len(source)) if len(source) <= k else np.sort(rng.choice(len(source), k, replace=False))

    subset, everything = pick(sample), pick(final_sample)
    radius = float(np.sqrt(((source - source.mean(axis=0)) ** 2).sum(axis=1).mean()))
    if max_dist is None:
        d0 = tree.query(source[subset] @ T[:3, :3].T + T[:3, 3])[0]
        max_dist = max(3 * float(np.median(d0)), min_dist)
    use, full = subset, len(subset) == len(everything)
    prev_cost, it, converged = np.inf, 0, False
    A = np.eye(6)
    rms, overlap = np.inf, None
    while it < max_iter:
        it += 1
        p = source[use] @ T[:3, :3].T + T[:3, 3]
        dist, j = tree.query(p, distance_upper_bound=max_dist, workers=-1 if len(p) > 20000 else 1)
        ok = np.isfinite(dist)
        j = np.where(ok, j, 0)
        if source_normals is not None:
            ok &= np.einsum("ij,ij->i", source_normals[use] @ T[:3, :3].T, target_normals[j]) > 0.7
        if full:  # overlap at the tight distance, from this pass (the last step is tiny at convergence)
            overlap = float((ok & (dist <= min_dist)).mean())
        if ok.sum() < 6:
            break
        p, q, n, dist, j = p[ok], target[j[ok]], target_normals[j[ok]], dist[ok], j[ok]
        r = np.einsum("ij,ij->i", p - q, n)
        s = max(1.4826 * float(np.median(np.abs(r))), 0.05 * spacing)
        w = np.clip(1 - (r / (kernel * s)) ** 2, 0, None) ** 2                # Tukey biweight
        if target_weights is not None:
            w = w * target_weights[j]
        c = p.mean(axis=0)
        J = np.hstack([np.cross(p - c, n), n])
        A = (J.T * w) @ J
        x = np.linalg.solve(A + 1e-12 * np.trace(A) * np.eye(6), -(J.T @ (w * r)))
        step = np.eye(4)
        step[:3, :3] = _rodrigues(x[:3])
        step[:3, 3] = c - step[:3, :3] @ c + x[3:]
        T = step @ T
        inl = w > 0
        rms = float(np.sqrt((r[inl] ** 2).mean())) if inl.any() else np.inf
        cost = float((w * r * r).sum() / max(w.sum(), 1e-300))
        step_len = np.linalg.norm(x[:3]) * radius + np.linalg.norm(x[3:])
        max_dist = max(min_dist, min(max_dist, float(dist.mean() + 3 * dist.std())))
        if step_len < 3e-3 * spacing or abs(prev_cost - cost) <= tol * cost:
            if full:
                converged = True
                break
            use, full, prev_cost = everything, True, np.inf                   # finish on the larger sample
            continue
        prev_cost = cost
    if overlap is None or not full:
        p_all = source @ T[:3, :3].T + T[:3, 3]
        d_all, j_all = tree.query(p_all, distance_upper_bound=min_dist, workers=-1)
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


def coarse_align(source, target, target_normals, source_normals=None, *, target_weights=None,
                 tree: cKDTree | None = None, anchors=None,
                 n_rotations: int = 600, n_sample: int = 100, keep: float = 0.6, steps: int = 8,
                 finalists: int = 10, prune_at=(4, 6), seed: int = 0) -> tuple[np.ndarray, IcpResult]:
    """Initial pose of source (n, 3) on target (m, 3) without any prior: sampled rotation search scored by
    the trimmed (fraction `keep`) point-to-point residual of matches whose normals agree (both views'
    normals face their sensors, so a back-to-front match has opposite normals), finished by `icp`.
    anchors : (k, 3) places on the target where the source's centroid may land (default: the target's
    centroid; a multi-view model passes each view's centroid too, since a new view overlaps only part
    of it). Returns (transform, result of the winning icp)."""
    source = np.asarray(source, float)
    tree = tree or cKDTree(target)
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(source), min(n_sample, len(source)), replace=False)
    sample = source[pick]
    if source_normals is None:
        source_normals = orient_normals(pca_normals(source, 16)[0], source)
    sample_n = np.asarray(source_normals, float)[pick]
    keep_t = rng.choice(len(target), min(4000, len(target)), replace=False)
    small, small_n = target[keep_t], target_normals[keep_t]
    small_tree = cKDTree(small)
    bound = 0.5 * float(np.sqrt(((small - small.mean(axis=0)) ** 2).sum(axis=1).mean()))
    rots = np.concatenate([np.eye(3)[None], _principal_axis_rotations(source, target),
                           _uniform_rotations(n_rotations, rng)])
    cs = source.mean(axis=0)
    anchors = target.mean(axis=0)[None] if anchors is None else np.asarray(anchors, float).reshape(-1, 3)
    R = np.tile(rots, (len(anchors), 1, 1))
    t = np.repeat(anchors, len(rots), axis=0) - R @ cs
    m = int(keep * len(sample))
    for step in range(steps):                                                  # batched trimmed ICP
        p = np.einsum("nij,kj->nki", R, sample) + t[:, None, :]
        d, j = small_tree.query(p.reshape(-1, 3), distance_upper_bound=bound, workers=-1)
        j = np.minimum(j, len(small) - 1).reshape(p.shape[:2])
        agree = np.einsum("nij,kj,nki->nk", R, sample_n, small_n[j]) > 0.5
        d = np.where(agree, np.minimum(d.reshape(p.shape[:2]), bound), bound)
        q = small[j]
        order = np.argsort(d, axis=1)
        if step in prune_at:                                                   # prune the hopeless
            alive = np.argsort(np.take_along_axis(d, order[:, :m], 1).mean(axis=1))[: max(4 * finalists, len(R) // 4)]
            R, t, p, q, d, order = R[alive], t[alive], p[alive], q[alive], d[alive], order[alive]
        sel = order[:, :m]
        ps = np.take_along_axis(p, sel[..., None], 1)
        qs = np.take_along_axis(q, sel[..., None], 1)
        w = (np.take_along_axis(d, sel, 1) < bound).astype(float)[..., None]  # weighted Kabsch
        ws = np.maximum(w.sum(axis=1), 1.0)
        pc, qc = (w * ps).sum(axis=1) / ws, (w * qs).sum(axis=1) / ws
        H = np.einsum("nki,nkj->nij", w * (ps - pc[:, None]), qs - qc[:, None])
        U, _, Vt = np.linalg.svd(H)
        S = np.ones((len(H), 3))
        S[:, 2] = np.sign(np.linalg.det(Vt.transpose(0, 2, 1) @ U.transpose(0, 2, 1)))
        dR = Vt.transpose(0, 2, 1) @ (S[:, :, None] * U.transpose(0, 2, 1))
        R = dR @ R
        t = np.einsum("nij,nj->ni", dR, t - pc) + qc
    score = np.sort(d, axis=1)[:, :m].mean(axis=1)
    chosen = []                                                                # distinct rotations only
    for i in np.argsort(score):
        if all(rotation_angle(R[i] @ R[j].T) > np.radians(20) for j in chosen):
            chosen.append(i)
            if len(chosen) == finalists:
                break
    best, best_fit = None, -1.0
    for i in chosen:
        init = np.eye(4)
        init[:3, :3], init[:3, 3] = R[i], t[i]
        res = icp(source, target, target_normals, init, source_normals=source_normals,
                  target_weights=target_weights, tree=tree, sample=1000, max_iter=15)
        fit = tight_overlap(source, res.transform, target, target_normals, tree)
        if fit > best_fit:
            best, best_fit = res, fit
    res = icp(source, target, target_normals, best.transform, source_normals=source_normals,
              target_weights=target_weights, tree=tree)
    return res.transform, res


def tight_overlap(source, transform, target, target_normals, tree: cKDTree, noise: float | None = None) -> float:
    """Fraction of source points (n, 3), moved by `transform`, lying within 2 point spacings of the target
    and within 3 noise levels (default: a tenth of a spacing) of its tangent plane."""
    spacing = _spacing(tree)
    noise = 0.1 * spacing if noise is None else noise
    p = source @ transform[:3, :3].T + transform[:3, 3]
    d, j = tree.query(p, distance_upper_bound=2 * spacing, workers=-1)
    ok = np.isfinite(d)
    r = np.abs(np.einsum("ij,ij->i", p[ok] - target[j[ok]], target_normals[j[ok]]))
    return float((r < 3 * noise).sum() / len(p))


@dataclass
class ViewReport:
    """One view's registration: pose (4, 4) view-to-common-frame, RMS residual, overlap fraction (near the
    model), inlier fraction (on the model's surface within the noise), iterations, status ("reference", "ok", or the first failed check) and every failed check in reasons."""

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


def register_views(scans: list[Scan], *, use_poses: bool = False, refine: bool = True, k_normals: int = 16,
                   min_overlap: float = 0.25, min_condition: float = 2e-3, seed: int = 0) -> list[ViewReport]:
    """Register views incrementally into the frame of the first one.

    use_poses : start every view from its `pose` (e.g. read from a .conf) instead of a coarse search.
    refine : after the incremental pass, re-register each view against all the others once more.
    Views that fail a check are reported and kept out of the model the later views register against.
    Returns one `ViewReport` per view; `transform` is the view's pose in the first view's frame.
    """
    if not scans:
        raise ScanError("no views to register")
    normals, weights, noise = [], [], []
    for s in scans:
        n, sig = pca_normals(s.points, k_normals)
        normals.append(orient_normals(n, s.points, s))
        noise.append(float(np.median(sig)))
        weights.append(1 / (1 + (sig / max(noise[-1], 1e-300)) ** 2))          # low at creases and edges
    noise_level = float(np.median(noise)) * np.sqrt(2)                        # two noisy surfaces meet
    poses = [np.array(s.pose if use_poses else np.eye(4), float) for s in scans]
    if use_poses:
        base = np.linalg.inv(poses[0])
        poses = [base @ p for p in poses]
    reports = [ViewReport(scans[0].source, poses[0])]

    def model(indices):
        pts = np.concatenate([scans[i].points @ poses[i][:3, :3].T + poses[i][:3, 3] for i in indices])
        nrm = np.concatenate([normals[i] @ poses[i][:3, :3].T for i in indices])
        return pts, nrm, np.concatenate([weights[i] for i in indices])

    trusted = [0]                            # the model constructed so far: views whose pose is trusted
    for i in range(1, len(scans)):
        tgt, tgt_n, tgt_w = model(trusted)
        tree = cKDTree(tgt)
        centres = [tgt.mean(axis=0)] + [poses[k][:3, :3] @ scans[k].points.mean(axis=0) + poses[k][:3, 3]
                                        for k in trusted] if len(trusted) > 1 else None
        if use_poses:
            res = icp(scans[i].points, tgt, tgt_n, poses[i], source_normals=normals[i], target_weights=tgt_w,
                      tree=tree, seed=seed)
        else:
            _, res = coarse_align(scans[i].points, tgt, tgt_n, normals[i], target_weights=tgt_w, tree=tree,
                                  anchors=centres, seed=seed + i)
        poses[i] = res.transform
        reports.append(ViewReport(scans[i].source, res.transform, res.rms, res.overlap, res.iterations,
                                  res.condition))
        inl = tight_overlap(scans[i].points, res.transform, tgt, tgt_n, tree, max(noise_level, 1e-300))
        reports[-1].inliers = inl
        reports[-1].reasons = _judge(res, inl, noise_level, min_overlap, min_condition)
        if not reports[-1].reasons:
            trusted.append(i)
    if refine and len(scans) > 2:
        for i in range(1, len(scans)):
            others = [j for j in trusted if j != i]
            if not others:
                continue
            tgt, tgt_n, tgt_w = model(others)
            tree = cKDTree(tgt)
            res = icp(scans[i].points, tgt, tgt_n, poses[i], source_normals=normals[i], target_weights=tgt_w,
                      tree=tree, seed=seed)
            poses[i] = res.transform
            rep = reports[i]
            rep.transform, rep.rms, rep.overlap, rep.condition = res.transform, res.rms, res.overlap, res.condition
            rep.iterations += res.iterations
            rep.inliers = tight_overlap(scans[i].points, res.transform, tgt, tgt_n, tree, max(noise_level, 1e-300))
            rep.reasons = _judge(res, rep.inliers, noise_level, min_overlap, min_condition)
            if not rep.reasons and i not in trusted:
                trusted.append(i)
    for rep in reports[1:]:
        rep.status = rep.reasons[0].split(":")[0].split(" ")[0] if rep.reasons else "ok"
    return reports
