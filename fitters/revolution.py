"""Surfaces of revolution from scans: axis, meridian profile, conic sections.

1. Axis from the normals (Pottmann & Randrup 1998, "Rotational and helical surface approximation for
   reverse engineering", Computing 60; Pottmann & Wallner, *Computational Line Geometry*, §6.3).  The
   normal lines of a surface of revolution all meet its axis.  In Plücker coordinates a normal line is
   (n, p x n) and a line (c, c̄) meets it iff  n . c̄ + (p x n) . c = 0;  minimising the sum of squares
   of that bilinear form subject to |c| = 1 is a small eigenproblem (c̄ is eliminated in closed form).
   Iteratively reweighted (Tukey biweight) against wrong normals at edges and outliers.  The pitch
   c . c̄ is then set to zero (a rotation, not a helical motion), giving direction c and the axis point
   c x c̄.
2. Refinement by minimising the profile's spread: in the (r, z) coordinates of the axis, points of the
   mantle (normal across the axis) must have one r per z-slab and points of the ends (normal along the
   axis) one z per r-slab; the four axis parameters are adjusted (scipy least_squares, soft_l1) to shrink
   the deviation from the slab means.
3. The profile (r, z) is fitted by lines, circular arcs (tangent where the part is smooth) and, where no
   conic holds, B-splines refined by knot insertion (`rgm.fitters.profile2d`).

The part frame: origin on the axis at the profile's lowest z, the axis as the frame's y axis (the paper's
pin, Figure 7: profile in the x-y plane, revolved about y), turned from the cloud's frame by the smallest
rotation that takes y to the axis (`axis_frame`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from rgm.errors import GeometryError
from rgm.fitters.profile2d import Profile, fit_conic_profile
from rgm.fitters.profile_spline import noise_sigma

__all__ = ["axis_from_normals", "refine_axis", "profile_coordinates", "RevolutionFit", "fit_revolution", "axis_frame"]


def _unit(v):
    return v / np.linalg.norm(v)


def axis_from_normals(points, normals, *, iterations: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Axis (point (3,), unit direction (3,)) of a surface of revolution from points and unit normals (n, 3)."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    centre = points.mean(axis=0)
    scale = np.sqrt(np.mean(np.sum((points - centre) ** 2, axis=1)))
    p = (points - centre) / scale
    rows = np.hstack([np.cross(p, normals), normals])    # (n, 6): residual = rows @ (c, c̄)
    w = np.ones(len(p))
    for _ in range(iterations):
        m = (rows * w[:, None]).T @ rows
        a, b, cc = m[:3, :3], m[:3, 3:], m[3:, 3:]
        cinv = np.linalg.pinv(cc, rcond=1e-8)
        reduced = a - b @ cinv @ b.T
        c = np.linalg.eigh(reduced)[1][:, 0]
        cbar = -cinv @ b.T @ c
        res = rows @ np.r_[c, cbar]
        s = 4.685 * 1.4826 * np.median(np.abs(res)) + 1e-12
        w = np.clip(1 - (res / s) ** 2, 0, None) ** 2
    cbar = cbar - (c @ cbar) * c                          # zero pitch: rotation, not helical motion
    return centre + scale * np.cross(c, cbar), _unit(c)


def profile_coordinates(points, axis_point, axis_dir) -> np.ndarray:
    """(n, 2) (r, z): distance from the axis and position along it."""
    d = points - axis_point
    z = d @ axis_dir
    r = np.linalg.norm(d - np.outer(z, axis_dir), axis=1)
    return np.column_stack([r, z])


def _perp_basis(d):
    e = np.eye(3)[np.argmin(np.abs(d))]
    u = _unit(np.cross(d, e))
    return u, np.cross(d, u)


def _slab_residuals(key, value, bins):
    """value minus the mean value of its slab of `key` (bins equal slabs over key's range)."""
    lo, hi = key.min(), key.max()
    idx = np.minimum(((key - lo) / max(hi - lo, 1e-300) * bins).astype(int), bins - 1)
    sums, counts = np.bincount(idx, value, bins), np.bincount(idx, None, bins)
    return value - (sums / np.maximum(counts, 1))[idx]


def refine_axis(points, normals, axis_point, axis_dir, *, bins: int = 60, max_points: int = 8000, seed: int = 0):
    """Refine an axis by minimising the profile's spread (module docstring, step 2), on at most
    `max_points` points (fixed-seed subsample).  Returns (point, direction, noise sigma of the profile
    (mm): from differences of consecutive r along z on the mantle and of z along r on the ends, which
    cancel the profile's own shape, `profile_spline.noise_sigma`; the direction's angular standard
    uncertainty (radians): the larger principal standard deviation of the two tilt parameters,
    s^2 (J^T J)^-1 with the solver's loss-weighted Jacobian J and s the residuals' robust scale
    (1.4826 MAD))."""
    if len(points) > max_points:
        keep = np.random.default_rng(seed).choice(len(points), max_points, replace=False)
        points, normals = points[keep], normals[keep]
    axis_dir = _unit(axis_dir)
    u, v = _perp_basis(axis_dir)
    mantle = np.abs(normals @ axis_dir) < 0.5
    ends = np.abs(normals @ axis_dir) > 0.9

    def axis_of(x):
        d = _unit(axis_dir + x[0] * u + x[1] * v)
        return axis_point + x[2] * u + x[3] * v, d

    def residuals(x):
        p, d = axis_of(x)
        rz = profile_coordinates(points, p, d)
        parts = []
        if mantle.sum() > 10:
            parts.append(_slab_residuals(rz[mantle, 1], rz[mantle, 0], bins))
        if ends.sum() > 10:
            parts.append(_slab_residuals(rz[ends, 0], rz[ends, 1], bins))
        return np.concatenate(parts)

    r0 = residuals(np.zeros(4))
    f_scale = max(1.4826 * np.median(np.abs(r0)), 1e-9)
    sol = least_squares(residuals, np.zeros(4), loss="soft_l1", f_scale=f_scale, diff_step=1e-6,
                        x_scale=np.r_[1e-2, 1e-2, f_scale * 10, f_scale * 10], max_nfev=60)
    p, d = axis_of(sol.x)
    rz = profile_coordinates(points, p, d)
    along = [rz[mantle][np.argsort(rz[mantle, 1]), 0], rz[ends][np.argsort(rz[ends, 0]), 1]]
    cov = (1.4826 * np.median(np.abs(sol.fun))) ** 2 * np.linalg.pinv(sol.jac.T @ sol.jac)
    angle_sigma = float(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0)))
    return p, d, noise_sigma(*(a for a in along if len(a) > 10)), angle_sigma


@dataclass(frozen=True)
class RevolutionFit:
    """frame : (4, 4) part frame -> cloud frame (columns x, y = axis, z, origin).  profile : the meridian
    profile in (r, z) = (part x, part y).  sigma : robust noise scale of the profile points (mm).
    axis_sigma : standard uncertainty of the axis direction (radians; NaN when not measured)."""

    frame: np.ndarray
    profile: Profile
    sigma: float
    axis_sigma: float = float("nan")

    @property
    def length(self) -> float:
        """The profile's extent along the axis (mm)."""
        return float(np.ptp(self.profile.vertices[:, 1]))

    def distance(self, points) -> np.ndarray:
        """(n,) exact distance of cloud-frame points (n, 3) to the full surface of revolution."""
        return self.profile.distance(profile_coordinates(points, self.frame[:3, 3], self.frame[:3, 1]))


def fit_revolution(points, normals, *, tol: float, statistic: str = "p95", axis_hint=None, seed: int = 0,
                   profile_points=None, max_profile_points: int = 40000) -> RevolutionFit:
    """Fit a surface of revolution with a profile of lines, arcs and B-spline stretches to points and unit
    normals (n, 3) (mm).

    The axis comes from `points` and `normals` (a subsample is enough); the profile from
    `profile_points` (m, 3) (default: `points`), at most `max_profile_points` of them (a fixed-seed
    subsample: faces are fitted to many thousand points either way; the certificate measures all).

    axis_hint : optional unit vector (e.g. a superellipsoid's symmetry axis), tried as well when it differs
    from the axis of the normals (which is degenerate on a sphere: all normals meet many lines); the
    axis whose profile spreads least is kept.  tol : the requested tolerance (mm) on the
    certificate's `statistic` ("max", "p99", "p95"), to which B-spline stretches are refined; the inlier
    threshold of the profile segmentation is max(3 sigma, tol / 4).
    """
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    if len(points) < 50:
        raise GeometryError(f"a surface of revolution needs at least 50 points, got {len(points)}")
    starts = [axis_from_normals(points, normals)]
    if axis_hint is not None and abs(starts[0][1] @ axis_hint) < 0.9:
        starts.append((points.mean(axis=0), _unit(np.asarray(axis_hint, float))))
    p, d, sigma, axis_sigma = min((refine_axis(points, normals, *start) for start in starts), key=lambda fit: fit[2])
    d = d if d[np.argmax(np.abs(d))] > 0 else -d         # canonical: the axis' largest component positive
    rz = profile_coordinates(points if profile_points is None else np.asarray(profile_points, float), p, d)
    if len(rz) > max_profile_points:
        rz = rz[np.random.default_rng(seed).choice(len(rz), max_profile_points, replace=False)]
    thr = max(3.0 * sigma, tol / 4.0, 1e-9 * np.ptp(rz))
    profile = fit_conic_profile(rz, thr=thr, tol=tol, statistic=statistic, seed=seed)
    z0 = float(profile.vertices[:, 1].min())
    shifted = Profile(tuple(s.shifted(np.array([0.0, -z0])) for s in profile.segments))
    return RevolutionFit(axis_frame(p + z0 * d, d), shifted, sigma, axis_sigma)


def axis_frame(origin, axis_dir) -> np.ndarray:
    """(4, 4) part frame -> cloud frame with its origin at `origin` (3,) and its y axis along the unit
    `axis_dir` (3,): the smallest rotation taking world y to the axis (about y x axis_dir; none when the
    axis is y), so that a part whose axis is a world axis is placed by at most one 90 deg turn."""
    y = np.array([0.0, 1.0, 0.0])
    d = _unit(np.asarray(axis_dir, float))
    k = np.cross(y, d)
    s, c = np.linalg.norm(k), float(y @ d)
    frame = np.eye(4)
    if s > 1e-15:
        kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]]) / s
        frame[:3, :3] = np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)           # Rodrigues' formula
    elif c < 0:
        frame[:3, :3] = np.diag([-1.0, -1.0, 1.0])                          # a half turn about z
    frame[:3, 3] = origin
    return frame


def sample_revolution(profile: Profile, frame, spacing: float) -> np.ndarray:
    """(m, 3) points on the surface of revolution of `profile` in the part frame `frame` (4, 4) (profile
    r along frame x, z along frame y), about `spacing` apart (for coverage)."""
    rz = np.vstack([seg.sample(spacing) for seg in profile.segments])
    counts = np.maximum(8, (2 * np.pi * rz[:, 0] / spacing).astype(int))
    idx = np.repeat(np.arange(len(rz)), counts)
    phi = 2 * np.pi * (np.arange(len(idx)) - np.repeat(np.cumsum(counts) - counts, counts)) / counts[idx]
    r, z = rz[idx, 0], rz[idx, 1]
    local = np.column_stack([r * np.cos(phi), z, -r * np.sin(phi)])
    return local @ frame[:3, :3].T + frame[:3, 3]
