"""Superellipsoid recovery: size a1..a3, shape eps1, eps2 and pose (11 parameters) from 3-D points.

The superellipsoid in its own frame is the zero set of the inside-outside function (Barr 1981)

    F(x, y, z) = ( |x/a1|^(2/eps2) + |y/a2|^(2/eps2) )^(eps2/eps1) + |z/a3|^(2/eps1),

F < 1 inside, F = 1 on the surface, F > 1 outside.  Recovery follows Solina & Bajcsy (1990),
"Recovery of parametric models from range images", IEEE PAMI 12(2): minimise

    sum_i ( sqrt(a1 a2 a3) * (F(R^T (x_i - t))^eps1 - 1) )^2

over the 11 parameters; the sqrt(a1 a2 a3) factor favours the smallest superellipsoid that explains the
points, and the power eps1 makes the residual roughly proportional to the distance.  rgm adds what makes
it work on scans:

- the cloud is normalised first (centre of its robust extent, RMS radius 1), so the fit does not depend
  on the cloud's frame or units;
- several starts from the moments (PCA axes, each axis in turn as the eps1 axis, a small eps grid); each
  start runs a few iterations on a subsample and the best is refined;
- `scipy.optimize.least_squares` with a robust loss (soft_l1) whose scale `f_scale` is a MAD estimate of
  the residuals, so outliers lose their pull;
- an analytic Jacobian (vectorised over points; rotation by xyz Euler angles about the start's axes).

The fit-quality measure is the median radial Euclidean distance (Jaklič, Leonardis & Solina,
*Segmentation and Recovery of Superquadrics*, 2000, eq. 2.49: d = |x| |1 - F^(-eps1/2)|) divided by the
mean semi-axis: 0.01 means the typical point lies within 1 % of the part's size of the fitted surface.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

__all__ = ["Superellipsoid", "fit_superellipsoid", "fit_superellipsoid_plain", "EPS_BOUNDS"]

#: bounds on eps1, eps2: convex shapes from box-like (0.1) to ellipsoid (1.0)
EPS_BOUNDS = (0.1, 1.0)
_TINY = 1e-12


@dataclass(frozen=True)
class Superellipsoid:
    """A recovered superellipsoid.

    size : (3,) semi-axes a1, a2, a3 in the cloud's units.
    eps : (2,) shape eps1 (latitude, along the local z axis) and eps2 (longitude, in the local xy plane).
    rotation : (3, 3) columns are the local x, y, z axes in the cloud's frame.
    center : (3,) the local origin in the cloud's frame.
    quality : median radial distance / mean semi-axis (dimensionless, smaller is better).
    inlier_fraction : share of the points within 3 robust scales of the surface.
    """

    size: np.ndarray
    eps: np.ndarray
    rotation: np.ndarray
    center: np.ndarray
    quality: float
    inlier_fraction: float

    @property
    def params(self) -> np.ndarray:
        """(11,) a1 a2 a3 eps1 eps2, the local axes' xyz Euler angles (radians), then the centre."""
        return np.concatenate([self.size, self.eps, _euler_from_matrix(self.rotation), self.center])

    def to_local(self, points) -> np.ndarray:
        """(n, 3) points in the superellipsoid's frame."""
        return (np.asarray(points, float) - self.center) @ self.rotation

    def inside_outside(self, points) -> np.ndarray:
        """(n,) F of the module docstring at `points` (cloud frame)."""
        return _inside_outside(self.to_local(points), self.size, self.eps)

    def radial_distance(self, points) -> np.ndarray:
        """(n,) radial Euclidean distance |x| |1 - F^(-eps1/2)| (Jaklič et al. 2000), cloud units."""
        p = self.to_local(points)
        f = _inside_outside(p, self.size, self.eps)
        return np.linalg.norm(p, axis=1) * np.abs(1.0 - f ** (-self.eps[0] / 2.0))

    def surface_points(self, directions) -> np.ndarray:
        """(n, 3) surface points met by rays from the centre along unit `directions` (n, 3) (local frame
        directions, returned in the cloud frame): x = u F(u)^(-eps1/2)."""
        u = np.asarray(directions, float)
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        f = _inside_outside(u, self.size, self.eps)
        return (u * f[:, None] ** (-self.eps[0] / 2.0)) @ self.rotation.T + self.center


# ------------------------------------------------------------------------------------ the model
def _inside_outside(p, size, eps):
    e1, e2 = eps
    lx, ly, lz = (np.log(np.maximum(np.abs(p[:, k]) / size[k], _TINY)) for k in range(3))
    pxy = np.exp(2.0 / e2 * lx) + np.exp(2.0 / e2 * ly)
    return np.exp(np.minimum(e2 / e1 * np.log(pxy), 700.0)) + np.exp(np.minimum(2.0 / e1 * lz, 700.0))


def _euler(angles):
    """R = Rz(g) Ry(b) Rx(a) and its three partial derivatives (3, 3) each, in closed form."""
    ca, sa, cb, sb, cg, sg = (f(t) for t in angles for f in (np.cos, np.sin))
    r = np.array([[cg * cb, cg * sb * sa - sg * ca, cg * sb * ca + sg * sa],
                  [sg * cb, sg * sb * sa + cg * ca, sg * sb * ca - cg * sa],
                  [-sb, cb * sa, cb * ca]])
    da = np.array([[0.0, cg * sb * ca + sg * sa, -cg * sb * sa + sg * ca],
                   [0.0, sg * sb * ca - cg * sa, -sg * sb * sa - cg * ca],
                   [0.0, cb * ca, -cb * sa]])
    db = np.array([[-cg * sb, cg * cb * sa, cg * cb * ca],
                   [-sg * sb, sg * cb * sa, sg * cb * ca],
                   [-cb, -sb * sa, -sb * ca]])
    dg = np.array([[-sg * cb, -sg * sb * sa - cg * ca, -sg * sb * ca + cg * sa],
                   [cg * cb, cg * sb * sa - sg * ca, cg * sb * ca + sg * sa],
                   [0.0, 0.0, 0.0]])
    return r, (da, db, dg)


def _euler_from_matrix(r):
    b = np.arcsin(np.clip(-r[2, 0], -1.0, 1.0))
    return np.array([np.arctan2(r[2, 1], r[2, 2]), b, np.arctan2(r[1, 0], r[0, 0])])


def _residuals(theta, x, r0, want_jac):
    """Solina–Bajcsy residuals (n,) and, if asked, their Jacobian (n, 11) with respect to
    theta = (a1, a2, a3, eps1, eps2, alpha, beta, gamma, tx, ty, tz); the rotation is r0 @ R(alpha, beta, gamma)."""
    a, (e1, e2), ang, t = theta[:3], theta[3:5], theta[5:8], theta[8:]
    ra, dra = _euler(ang)
    m = r0 @ ra
    d = x - t
    p = d @ m
    absp = np.maximum(np.abs(p), _TINY)
    lp = np.log(absp / a)
    ea = np.array([2.0 / e2, 2.0 / e2, 2.0 / e1])
    pw = np.exp(np.minimum(ea * lp, 700.0))            # A, B, C
    pxy = pw[:, 0] + pw[:, 1]
    lpxy = np.log(pxy)
    q = np.exp(np.minimum(e2 / e1 * lpxy, 700.0))
    f = q + pw[:, 2]
    lf = np.log(f)
    g = np.exp(e1 * lf)
    s = np.sqrt(a[0] * a[1] * a[2])
    res = s * (g - 1.0)
    if not want_jac:
        return res
    dq_dp = e2 / e1 * q / pxy
    dg_df = e1 * g / f
    # derivatives of A, B, C with respect to their coordinate, semi-axis and exponent
    dpw_dx = ea * np.exp(np.minimum((ea - 1.0) * lp, 700.0)) / a * np.sign(p)
    dpw_da = -ea * pw / a
    dpw_de = -(ea ** 2 / 2.0) * pw * lp                # d/de of exp((2/e) l) = -(2/e^2) l (.)
    chain = np.column_stack([dq_dp, dq_dp, np.ones_like(f)])
    jac = np.empty((len(x), 11))
    jac[:, :3] = (s / (2.0 * a)) * (g - 1.0)[:, None] + s * (dg_df[:, None] * chain * dpw_da)
    df_de1 = q * (-e2 / e1 ** 2) * lpxy + dpw_de[:, 2]
    df_de2 = q * lpxy / e1 + dq_dp * (dpw_de[:, 0] + dpw_de[:, 1])
    jac[:, 3] = s * g * (lf + e1 * df_de1 / f)
    jac[:, 4] = s * dg_df * df_de2
    grad_p = (s * dg_df)[:, None] * chain * dpw_dx    # d res / d p, (n, 3)
    for k in range(3):
        jac[:, 5 + k] = np.einsum("ij,ij->i", grad_p, d @ (r0 @ dra[k]))
    jac[:, 8:] = -grad_p @ m.T
    return res, jac


# --------------------------------------------------------------------------------- recovery
def _robust_centre(x):
    """Mean of the 90 % of points nearest the mean: moves with the cloud under rotations and scaling
    (a coordinate-wise median or percentile would depend on the frame)."""
    c = x.mean(axis=0)
    d = np.linalg.norm(x - c, axis=1)
    return x[d <= np.percentile(d, 90)].mean(axis=0)


def _normalise(points):
    c = _robust_centre(points)
    scale = np.sqrt(np.mean(np.sum((points - c) ** 2, axis=1)))
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError("superellipsoid fit needs points that are not all equal")
    return c, scale


def _starts(x):
    """Start poses from the moments: PCA axes, each in turn as the local z axis, and each also turned by
    45 deg about that z axis (PCA axes are arbitrary where two moments are nearly equal); each axis' sign
    makes the third moment positive, so the starts turn with the cloud; semi-axes from the 2-98 % extent
    along each axis."""
    med = _robust_centre(x)
    _, vecs = np.linalg.eigh(np.cov((x - med).T))
    vecs = vecs * np.where(np.sum(((x - med) @ vecs) ** 3, axis=0) < 0, -1.0, 1.0)  # frame-free signs
    c = np.sqrt(0.5)
    spins = (np.eye(3), np.array([[c, -c, 0.0], [c, c, 0.0], [0.0, 0.0, 1.0]]))
    out = []
    for perm, spin in itertools.product(((0, 1, 2), (1, 2, 0), (2, 0, 1)), spins):
        r0 = vecs[:, perm] @ spin
        if np.linalg.det(r0) < 0:
            r0 = r0 * np.array([1.0, 1.0, -1.0])
        proj = (x - med) @ r0
        lo, hi = np.percentile(proj, [2, 98], axis=0)
        centre = med + r0 @ ((lo + hi) / 2.0)
        size = np.maximum((hi - lo) / 2.0, 1e-3)
        out.append((r0, size, centre))
    return out


_LOWER = np.r_[[1e-3] * 3, [EPS_BOUNDS[0]] * 2, [-np.pi] * 3, [-np.inf] * 3]
_UPPER = np.r_[[np.inf] * 3, [EPS_BOUNDS[1]] * 2, [np.pi] * 3, [np.inf] * 3]


def _solve(x, r0, theta0, loss, f_scale, max_nfev, tr_solver="exact"):
    sol = least_squares(lambda th: _residuals(th, x, r0, False), theta0,
                        jac=lambda th: _residuals(th, x, r0, True)[1],
                        bounds=(_LOWER, _UPPER), loss=loss, f_scale=f_scale, max_nfev=max_nfev,
                        x_scale=1.0, method="trf", tr_solver=tr_solver)
    return sol


#: in normalised units (RMS radius 1) a semi-axis beyond this is a runaway "tube" solution (a huge
#: superellipsoid whose flat sides pass through the data), not a fit
_MAX_SEMI_AXIS = 4.0


def _median_distance(theta, r0, x):
    """Median radial distance of x to the candidate theta; infinite for runaway candidates."""
    if np.max(theta[:3]) > _MAX_SEMI_AXIS:
        return np.inf
    rot = r0 @ _euler(theta[5:8])[0]
    se = Superellipsoid(theta[:3], theta[3:5], rot, theta[8:], 0.0, 0.0)
    return float(np.median(se.radial_distance(x)))


def _refine(x, r0, theta, losses):
    """Refine with each loss in turn, re-estimating the robust scale from the current residuals: soft_l1,
    then the redescending Cauchy loss, under which points inside the part (whose Solina residual is
    bounded by -sqrt(a1 a2 a3)) no longer pull the surface inwards.
    Returns (median radial distance, r0, theta)."""
    for loss in losses:
        f_scale = max(1.4826 * np.median(np.abs(_residuals(theta, x, r0, False))), 1e-4)
        theta = _solve(x, r0, theta, loss, f_scale, 30).x
    return _median_distance(theta, r0, x), r0, theta


def _finish(theta, r0, c, scale, points_n):
    ra, _ = _euler(theta[5:8])
    rot = r0 @ ra
    partial = Superellipsoid(theta[:3], theta[3:5], rot, theta[8:], 0.0, 0.0)
    dist = partial.radial_distance(points_n)
    med = float(np.median(dist))
    sigma = 1.4826 * med + 1e-9
    quality = med / float(np.mean(theta[:3]))
    inliers = float(np.mean(dist < 3.0 * sigma + 0.005 * np.mean(theta[:3])))
    return Superellipsoid(theta[:3] * scale, theta[3:5].copy(), rot, theta[8:] * scale + c, quality, inliers)


def fit_superellipsoid(points, *, max_points: int = 600, seed: int = 0,
                       eps_starts=((1.0, 1.0), (0.3, 0.3)), refine_best: int = 2) -> Superellipsoid:
    """Recover a superellipsoid from `points` (n, 3), n >= 20, robust to a few per cent outliers.

    The fit runs on at most `max_points` points (a fixed-seed random subsample; the starts use a quarter of
    them), and the `refine_best` best starts are refined; `quality` is measured on all points.  Returns size, shape, pose in the cloud's own units/frame.
    """
    points = np.asarray(points, float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 20:
        raise ValueError(f"superellipsoid fit needs at least 20 points of shape (n, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("superellipsoid fit got non-finite points")
    c, scale = _normalise(points)
    xn = (points - c) / scale
    rng = np.random.default_rng(seed)
    sub = xn[rng.choice(len(xn), max_points, replace=False)] if len(xn) > max_points else xn
    coarse = sub[: max(60, len(sub) // 5)]
    candidates = []
    for r0, size, centre in _starts(sub):
        for e in eps_starts:
            theta0 = np.r_[size, e, 0.0, 0.0, 0.0, centre]
            f_scale = max(1.4826 * np.median(np.abs(_residuals(theta0, coarse, r0, False))), 1e-3)
            th = _solve(coarse, r0, theta0, "soft_l1", f_scale, 10).x
            # robust costs differ in f_scale: compare the starts by median radial distance
            candidates.append((_median_distance(th, r0, coarse), r0, th))
    candidates.sort(key=lambda cand: cand[0])
    half = sub[: max(60, len(sub) // 2)]
    finals = [_refine(half, r0, th, ("soft_l1",)) for _, r0, th in candidates[:refine_best]]
    _, r0, theta = min(finals, key=lambda cand: cand[0])
    score, _, refined = _refine(sub, r0, theta, ("soft_l1", "cauchy"))
    if np.isfinite(score):  # keep the previous estimate if the last refinement ran away
        theta = refined
    return _finish(theta, r0, c, scale, xn)


def fit_superellipsoid_plain(points) -> Superellipsoid:
    """The plain Solina–Bajcsy fit for comparison: one start from the moments (PCA axes in eigenvalue
    order, eps = 1), ordinary least squares (no robust loss), all points, same residual and Jacobian."""
    points = np.asarray(points, float)
    c, scale = _normalise(points)
    xn = (points - c) / scale
    r0, size, centre = _starts(xn)[0]
    theta0 = np.r_[size, 1.0, 1.0, 0.0, 0.0, 0.0, centre]
    theta = _solve(xn, r0, theta0, "linear", 1.0, 200).x
    return _finish(theta, r0, c, scale, xn)
