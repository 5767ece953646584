"""Surface-plane, surface-surface and curve-plane intersections by marching.

The intersection of two surfaces (or a surface and a plane) is the zero set of F(x) = 0, with one
more unknown than equations: x = (u, v) and F = n . (S(u, v) - o) for a plane; x = (u1, v1, u2, v2) and
F = S_a(u1, v1) - S_b(u2, v2) for two surfaces. The method (Patrikalakis & Maekawa, *Shape
Interrogation for CAD/CAM*, ch. 5; Barnhill & Kersey's marching) is:

1. Seeds: a sampled sign-change search (plane: signed distance on a parameter grid) or closest
   sample pairs between the two surfaces' grids (a k-d tree), all refined at once by minimum-norm
   Newton steps dx = -J^T (J J^T)^-1 F (vectorised over the seeds).
2. Marching from a seed in both directions along the tangent, the null vector of J (for two surfaces
   it is parallel to the cross product of the normals), with a predictor step of 3-D length h and a
   Newton corrector on the augmented square system [F = 0; t . (x - x_pred) = 0]. The step follows
   the curvature: the chord sagitta kappa h^2 / 8 stays below a target. A branch stops at the domain
   boundary (located exactly by replacing the step equation with x_j = bound) or when it closes.
3. Fitting: cubic interpolation (chord-length parameters) of the marched 3-D points and of their
   parameter-space images uv_a, uv_b. The error is measured on a dense sample: the distance of the
   3-D curve from S_a(uv_a(t)) and S_b(uv_b(t)) (or from the plane), which bounds its distance from
   both surfaces. If it exceeds tol / 2 (a margin for the error between samples), the branch's points
   are first refined in place (`_subdivide`): every interval halved, the midpoints projected onto F = 0
   all at once by minimum-norm Newton, up to three times (the error falls like h^4); where a midpoint
   does not converge or lands away from its interval's middle, the sagitta target shrinks (the error by
   about 16 per 4) and only that branch is marched again. A march is one point at a time; a subdivision one vector
   solve (`benchmarks/bench_intersect.py`: 2-7x faster at 1e-4..1e-6, same error bound).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.errors import GeometryError
from rgm.geometry.basis import basis_derivatives, find_spans
from rgm.geometry.power_form import power_form


@dataclass(frozen=True)
class IntersectionBranch:
    """One connected branch of an intersection.

    curve: 3-D NurbsCurve; uv_a / uv_b: 2-D NurbsCurves over the same parameter interval in the
    parameter spaces of the first / second surface (uv_b None when the second operand is a bare
    plane given by origin and normal); max_error: measured max distance (model units) of the 3-D curve
    from both surfaces along the uv images (dense sample), <= the requested tol; closed: the branch
    ends where it starts (a loop, possibly across a periodic seam).
    """

    curve: object
    uv_a: object
    uv_b: object | None
    max_error: float
    closed: bool = False


# --- the two zero-set problems -------------------------------------------------------------------

def _partials(surface, u, v):
    """S, S_u, S_v at paired parameters u, v (m,) inside the domain, each (m, 3).

    The same quantities as `surface.derivatives(u, v, 1)` (Piegl & Tiller A3.6 with the quotient
    rule of A4.4), computed directly from the basis derivatives (A2.3) and the homogeneous net: the
    exact fallback of `_evaluator` for degrees above the power form's.
    """
    pu, pv = surface.degree_u, surface.degree_v
    su, sv = find_spans(surface.knots_u, pu, u), find_spans(surface.knots_v, pv, v)
    nu = basis_derivatives(surface.knots_u, pu, u, 1, su)          # (2, m, pu+1)
    nv = basis_derivatives(surface.knots_v, pv, v, 1, sv)          # (2, m, pv+1)
    rows = su[:, None] - pu + np.arange(pu + 1)
    cols = sv[:, None] - pv + np.arange(pv + 1)
    patch = surface.homogeneous[rows[:, :, None], cols[:, None, :]]  # (m, pu+1, pv+1, 4)
    h = np.einsum("mi,mijk,mj->mk", nu[0], patch, nv[0])
    hu = np.einsum("mi,mijk,mj->mk", nu[1], patch, nv[0])
    hv = np.einsum("mi,mijk,mj->mk", nu[0], patch, nv[1])
    w = h[:, 3:]
    p = h[:, :3] / w
    return p, (hu[:, :3] - hu[:, 3:] * p) / w, (hv[:, :3] - hv[:, 3:] * p) / w


def _evaluator(surface):
    """(u, v) (m,) each -> S, S_u, S_v (m, 3) each: the surface's per-span power form
    (`rgm.geometry.power_form`, a span lookup and Horner steps; to round-off the same values) where it
    has one, else `_partials`. Marching asks for one point at a time, so the per-call cost is what
    matters: 32 us against 185 us a point on a 30 x 30 bicubic net; one point goes through the power
    form's Python-float path (`d1_one`, the same values), 17 us against 41 us."""
    power = power_form(surface)
    if power is None:
        return lambda u, v: _partials(surface, u, v)
    return lambda u, v: power.d1_one(float(u[0]), float(v[0])) if len(u) == 1 else power.d(u, v, 1)


class _PlaneProblem:
    """F(u, v) = n . (S(u, v) - o): 1 equation, 2 unknowns."""

    def __init__(self, surface, origin, normal):
        self.surface = surface
        self._d1 = _evaluator(surface)
        self.origin = np.asarray(origin, float)
        n = np.asarray(normal, float)
        self.normal = n / np.linalg.norm(n)
        (u0, u1), (v0, v1) = surface.domain
        self.lo, self.hi = np.array([u0, v0]), np.array([u1, v1])

    def eval(self, x):
        """x (m, 2) -> F (m, 1), J (m, 1, 2), P (m, 3), dP (m, 3, 2)."""
        p, su, sv = self._d1(x[:, 0], x[:, 1])
        f = ((p - self.origin) @ self.normal)[:, None]
        dp = np.stack([su, sv], axis=2)
        return f, np.einsum("k,mkn->mn", self.normal, dp)[:, None, :], p, dp

    def seeds(self, samples: int):
        """Parameters (k, 2) where the signed distance changes sign between grid neighbours."""
        u = np.linspace(self.lo[0], self.hi[0], samples)
        v = np.linspace(self.lo[1], self.hi[1], samples)
        d = (self.surface.evaluate_grid(u, v) - self.origin) @ self.normal
        uv = np.stack(np.meshgrid(u, v, indexing="ij"), axis=2)
        out = []
        for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                     ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
            da, db = d[a], d[b]
            hit = (da * db <= 0) & (da != db)
            w = (da / np.where(da == db, 1.0, da - db))[hit]
            out.append(uv[a][hit] + w[:, None] * (uv[b][hit] - uv[a][hit]))
        return np.concatenate(out) if out else np.zeros((0, 2))


class _SurfaceProblem:
    """F(u1, v1, u2, v2) = S_a(u1, v1) - S_b(u2, v2): 3 equations, 4 unknowns."""

    def __init__(self, sa, sb):
        self.sa, self.sb = sa, sb
        self._da, self._db = _evaluator(sa), _evaluator(sb)
        (a0, a1), (b0, b1) = sa.domain
        (c0, c1), (d0, d1) = sb.domain
        self.lo, self.hi = np.array([a0, b0, c0, d0]), np.array([a1, b1, c1, d1])

    def eval(self, x):
        pa, ua, va = self._da(x[:, 0], x[:, 1])
        pb, ub, vb = self._db(x[:, 2], x[:, 3])
        z = np.zeros_like(ua)
        return (pa - pb, np.stack([ua, va, -ub, -vb], axis=2), pa, np.stack([ua, va, z, z], axis=2))

    def seeds(self, samples: int):
        """Parameter quadruples (k, 4) of close sample pairs (k-d tree over both surfaces' grids)."""
        from scipy.spatial import cKDTree

        grids = []
        for lo, hi, s in ((self.lo[:2], self.hi[:2], self.sa), (self.lo[2:], self.hi[2:], self.sb)):
            u, v = np.linspace(lo[0], hi[0], samples), np.linspace(lo[1], hi[1], samples)
            pts = s.evaluate_grid(u, v)
            spacing = max(np.linalg.norm(np.diff(pts, axis=0), axis=2).max(),
                          np.linalg.norm(np.diff(pts, axis=1), axis=2).max())
            uu, vv = np.meshgrid(u, v, indexing="ij")
            grids.append((pts.reshape(-1, 3), np.column_stack([uu.ravel(), vv.ravel()]), spacing))
        (pa, ua, ha), (pb, ub, hb) = grids
        dist, idx = cKDTree(pa).query(pb)
        near = dist <= 0.75 * (ha + hb)
        return np.column_stack([ua[idx[near]], ub[near]])


# --- Newton on many points at once ---------------------------------------------------------------

def _newton_min_norm(problem, x, eps: float, iters: int = 12):
    """Project points x (m, n) onto F = 0 by minimum-norm Newton steps; returns (x, converged (m,))."""
    for _ in range(iters):
        f, j, _, _ = problem.eval(x)
        jjt = j @ np.swapaxes(j, 1, 2)
        try:
            y = np.linalg.solve(jjt, f[..., None])
        except np.linalg.LinAlgError:
            y = np.linalg.lstsq(jjt[0], f[0], rcond=None)[0][None, :, None] if len(x) == 1 else \
                np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(jjt, f)])[..., None]
        x = np.clip(x - (np.swapaxes(j, 1, 2) @ y)[..., 0], problem.lo, problem.hi)
    f = problem.eval(x)[0]
    return x, np.linalg.norm(f, axis=1) <= eps


def _tangent(j, dp):
    """Unit 3-D tangents T (m, 3) and parameter directions t (m, n) with dP t = T, from the Jacobian
    j (m, k, n) and dP (m, 3, n): t spans the null space of J (for two surfaces T is parallel to the
    cross product of the normals)."""
    t = np.linalg.svd(j)[2][:, -1, :]
    big = np.einsum("mkn,mn->mk", dp, t)
    scale = np.linalg.norm(big, axis=1, keepdims=True)
    return big / scale, t / scale


def _solve_square(problem, x, extra_row, extra_rhs, eps, iters=12):
    """Newton on the square system [F(x) = 0; extra_row . x = extra_rhs] for one point x (n,).

    Returns (x, (F, J, P, dP) at x) once |F| <= eps, or None when Newton fails to converge."""
    for _ in range(iters):
        ev = problem.eval(x[None])
        f, j = ev[0][0], ev[1][0]
        r = np.concatenate([f, [extra_row @ x - extra_rhs]])
        if np.linalg.norm(f) <= eps and abs(r[-1]) <= 1e-9 * np.abs(extra_row).max() * (1 + np.abs(x).max()):
            return x, ev
        try:
            x = np.clip(x - np.linalg.solve(np.vstack([j, extra_row]), r), problem.lo, problem.hi)
        except np.linalg.LinAlgError:
            return None
    return None


# --- marching ------------------------------------------------------------------------------------

def _march(problem, x0, direction: float, sag: float, hmax: float, eps: float):
    """March from x0 (n,) along +-tangent; returns (params (k, n), closed).

    The march stops at the domain boundary, when it closes at its start, or when it comes back onto
    its own path in the same direction (it entered a loop away from its start, e.g. past a near
    singular point where two branches almost touch): a march never circles a loop twice."""
    xs = [x0]
    path, heading = np.empty((64, 3)), np.empty((64, 3))   # 3-D points and unit tangents so far
    ev = problem.eval(x0[None])
    tan3, tpar = _tangent(ev[1], ev[3])
    tan3, tpar = direction * tan3[0], direction * tpar[0]
    p_start = p_last = ev[2][0]
    h = hmax
    hmin = hmax * 1e-6
    travelled = 0.0
    for _ in range(100000):
        if h < hmin:
            break
        x_pred = xs[-1] + h * tpar
        over = np.maximum(problem.lo - x_pred, x_pred - problem.hi) / (problem.hi - problem.lo)
        landing = over.max() > 0
        if landing:  # the step leaves the domain: land exactly on the boundary it crosses
            k = int(np.argmax(over))
            bound = problem.lo[k] if x_pred[k] < problem.lo[k] else problem.hi[k]
            solved = _solve_square(problem, np.clip(x_pred, problem.lo, problem.hi), np.eye(len(x0))[k], bound, eps)
        else:
            solved = _solve_square(problem, x_pred, tpar, tpar @ x_pred, eps)
        if solved is None:
            h *= 0.5
            continue
        x_new, ev = solved
        t3, tp = _tangent(ev[1], ev[3])
        t3, tp = t3[0], tp[0]
        if t3 @ tan3 < 0:
            t3, tp = -t3, -tp
        angle = np.arccos(np.clip(t3 @ tan3, -1.0, 1.0))
        p_new = ev[2][0]
        chord = np.linalg.norm(p_new - p_last)
        kappa = angle / max(chord, 1e-300)
        if angle > 0.35 or chord > 2 * h or kappa * chord ** 2 / 8 > 1.5 * sag:
            h = 0.5 * h if angle > 0.35 or chord > 2 * h else min(0.5 * h, np.sqrt(8 * sag / kappa))
            continue
        if landing:
            xs.append(x_new)
            return np.array(xs), False
        travelled += chord
        # closed when back at the start in space *and* in parameters (not across a periodic seam)
        if (len(xs) > 3 and travelled > 2 * h and np.linalg.norm(p_new - p_start) < h
                and np.linalg.norm(x_new - x0) < 2 * h * np.linalg.norm(tpar)):
            xs.append(x0.copy())  # the loop closed
            return np.array(xs), True
        if len(xs) >= len(path):
            path, heading = np.resize(path, (2 * len(path), 3)), np.resize(heading, (2 * len(path), 3))
        path[len(xs) - 1], heading[len(xs) - 1] = p_last, tan3
        if len(xs) > 8:
            earlier = slice(0, len(xs) - 6)
            near = np.linalg.norm(path[earlier] - p_new, axis=1) < 0.5 * h
            if (near & (heading[earlier] @ t3 > 0.5)).any():
                xs.append(x_new)
                return np.array(xs), False
        xs.append(x_new)
        p_last, tan3, tpar = p_new, t3, tp
        h = min(hmax, 0.9 * np.sqrt(8 * sag / max(kappa, 1e-300)), 2 * h)
    return np.array(xs), False


def _trace(problem, seed, sag, hmax, eps):
    fwd, closed = _march(problem, seed, 1.0, sag, hmax, eps)
    if closed:
        return fwd, True
    back, _ = _march(problem, seed, -1.0, sag, hmax, eps)
    return np.concatenate([back[::-1], fwd[1:]]), False


def _seg_distance(points, polyline):
    """Distance (k,) of points (k, 3) from the polyline (s, 3) (s >= 1)."""
    if len(polyline) == 1:
        return np.linalg.norm(points - polyline[0], axis=1)
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    w = np.clip(np.einsum("ksd,sd->ks", points[:, None, :] - a, ab) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
    closest = a + w[..., None] * ab
    return np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)


# --- fitting and measuring -----------------------------------------------------------------------

def _fit(values, t, box=None):
    """Cubic (or lower, for few points) interpolating clamped NurbsCurve through values (k, d) at t.

    With `box` (lo (d,), hi (d,)) the control points are clamped into it, so by the convex hull
    property a parameter-space curve never leaves its surface's domain; the error measurement that
    follows sees any change this makes."""
    from scipy.interpolate import make_interp_spline

    from rgm.geometry import NurbsCurve

    k = min(3, len(t) - 1)
    spl = make_interp_spline(t, values, k=k)
    ctrl = spl.c if box is None else np.clip(spl.c, box[0], box[1])
    return NurbsCurve(k, spl.t, ctrl, None)


def _fit_branch(problem, xs, closed, split: int):
    p = problem.eval(xs)[2]
    chord = np.linalg.norm(np.diff(p, axis=0), axis=1)
    if len(chord) == 0 or chord.max() == 0:
        return None
    # A near-duplicate point (a seed on the boundary, a landing just past the last step) would make
    # the interpolant wiggle: drop it, keeping the branch's end points.
    drop = np.concatenate([[False], chord < 0.05 * np.median(chord[chord > 0])])
    if drop[-1]:
        drop[-1], drop[-2] = False, len(drop) > 2
    xs, p = xs[~drop], p[~drop]
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t /= t[-1]
    curve = _fit(p, t)
    uv_a = _fit(xs[:, :2], t, (problem.lo[:2], problem.hi[:2]))
    uv_b = _fit(xs[:, 2:4], t, (problem.lo[2:], problem.hi[2:])) if split == 4 else None
    return curve, uv_a, uv_b, t


def _measure(problem, curve, uv_a, uv_b, t, samples_per_interval: int = 8):
    """Max distance of the 3-D curve from both surfaces along the uv images, densely sampled."""
    s = np.unique(np.concatenate([np.linspace(t[i], t[i + 1], samples_per_interval, endpoint=False)
                                  for i in range(len(t) - 1)] + [[1.0]]))
    c = curve.evaluate(s)
    if uv_b is None:
        on_a = problem.surface.evaluate(*uv_a.evaluate(s).T)
        return float(max(np.linalg.norm(c - on_a, axis=1).max(), np.abs((c - problem.origin) @ problem.normal).max()))
    ea = np.linalg.norm(c - problem.sa.evaluate(*uv_a.evaluate(s).T), axis=1).max()
    eb = np.linalg.norm(c - problem.sb.evaluate(*uv_b.evaluate(s).T), axis=1).max()
    return float(max(ea, eb))


def _size(surface) -> float:
    box = np.asarray(surface.bbox())
    return float(np.linalg.norm(box[1] - box[0]))


def _subdivide(problem, xs, closed: bool, eps: float, tol: float, rounds: int = 3):
    """A marched branch xs (k, n) refined by halving every interval instead of marching again: the
    midpoints in parameters projected onto F = 0 all at once (`_newton_min_norm`), up to `rounds` times
    until the fitted branch is within tol / 2 (cubic interpolation errs like h^4: a halving divides the
    error by about 16). Returns ((curve, uv_a, uv_b, t), error), or None where a midpoint does not
    converge or lands away from the middle of its interval (the march then runs again with a finer step)."""
    for _ in range(rounds):
        p = problem.eval(xs)[2]
        chord = np.linalg.norm(p[1:] - p[:-1], axis=1)
        split = np.flatnonzero(chord > 0.1 * np.median(chord))   # not the sliver a landing step leaves
        mid, ok = _newton_min_norm(problem, 0.5 * (xs[split] + xs[split + 1]), eps)
        if not ok.all():
            return None
        # each midpoint between its neighbours along their chord, near its middle (a projection that slid
        # along the curve would fold the branch back on itself)
        pm, a, ab = problem.eval(mid)[2], p[split], p[split + 1] - p[split]
        w = np.einsum("ij,ij->i", pm - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
        if np.any((w < 0.25) | (w > 0.75)):
            return None
        xs = np.insert(xs, split + 1, mid, axis=0)
        fitted = _fit_branch(problem, xs, closed, len(problem.lo))
        if fitted is None:
            return None
        err = _measure(problem, *fitted)
        if err <= 0.5 * tol:
            return fitted, err
    return None


def _near(problem, x, region) -> np.ndarray:
    """(m,) bool: the points of parameters x (m, n) within `region` = (points (k, 3), radius) (all: None)."""
    if region is None or len(x) == 0:
        return np.ones(len(x), bool)
    from scipy.spatial import cKDTree

    points, radius = region
    return np.isfinite(cKDTree(points).query(problem.eval(x)[2], distance_upper_bound=radius)[0])


def _solve(problem, size: float, tol: float, samples: int, region=None) -> list[IntersectionBranch]:
    if not tol > 0:
        raise GeometryError(f"intersection tolerance must be positive, got {tol}")
    eps = min(tol * 1e-3, 1e-9 * size + 1e-300) if size > 0 else tol * 1e-3
    eps = max(eps, 1e-13 * size)
    seeds = problem.seeds(samples)
    if len(seeds) == 0:
        return []
    seeds, ok = _newton_min_norm(problem, seeds, eps)
    seeds = seeds[ok & _near(problem, seeds, region)]
    hmax = size / 8
    # Cubic interpolation of points whose chord sagitta is s errs by about s^2 / (6 R) on a curve of
    # radius R: start from s = sqrt(tol * size) and shrink it until the measured error holds.
    sag = min(np.sqrt(tol * size), size / 64)
    accepted: list[tuple[IntersectionBranch, np.ndarray, float]] = []   # (branch, polyline, reach)
    pending = seeds
    worst = np.inf
    for _ in range(12):
        retry, worst = [], 0.0
        for _, pts, reach in accepted:  # seeds already on an accepted branch
            pending = pending[_seg_distance(problem.eval(pending)[2], pts) > reach] if len(pending) else pending
        while len(pending):
            xs, closed = _trace(problem, pending[0], sag, hmax, eps)
            pts = problem.eval(xs)[2]
            reach = 4 * sag + 1e-9 * size
            covered = _seg_distance(problem.eval(pending)[2], pts) <= reach
            covered[0] = True
            fitted = _fit_branch(problem, xs, closed, len(problem.lo))
            if fitted is not None:
                curve, uv_a, uv_b, t = fitted
                err = _measure(problem, curve, uv_a, uv_b, t)
                if err > 0.5 * tol:   # the march's points, subdivided, may already hold it
                    finer = _subdivide(problem, xs, closed, eps, tol)
                    if finer is not None:
                        (curve, uv_a, uv_b, t), err = finer
                if err <= 0.5 * tol:  # margin for the error between the measured samples
                    accepted.append((IntersectionBranch(curve, uv_a, uv_b, err, closed), pts, reach))
                else:  # march these seeds again with a finer step
                    retry.append(pending[covered])
                    worst = max(worst, err)
            pending = pending[~covered]
        if not retry:
            return [branch for branch, _, _ in accepted]
        pending = np.concatenate(retry)
        # Shrink every step (also where the curve is nearly straight) by the factor the measured
        # error asks for, assuming it falls at least like h^3 (cubic interpolation: h^4).
        f = float(np.clip(0.9 * (0.5 * tol / worst) ** (1 / 3), 0.2, 0.7))
        sag, hmax = sag * f * f, hmax * f
    raise GeometryError(f"intersection did not reach tolerance {tol:g} (best {worst:.3g}); "
                        "the surfaces may touch tangentially")


def _samples(surface, base: int = 24) -> int:
    spans = max(len(np.unique(surface.knots_u)), len(np.unique(surface.knots_v)))
    return int(min(120, max(base, 4 * spans)))


def intersect_surface_plane(surface, origin, normal, tol: float) -> list[IntersectionBranch]:
    """Branches of NurbsSurface ∩ plane(origin (3,), normal (3,)) within `tol` (model units).

    Each branch has `uv_a` in the surface's parameter space and `uv_b = None` (plane coordinates are
    an affine image of `curve`; `rgm.model.lazy` adds them).
    """
    problem = _PlaneProblem(surface, origin, normal)
    return _solve(problem, _size(surface), tol, _samples(surface))


def intersect_surfaces(sa, sb, tol: float, near=None, radius: float = 0.0) -> list[IntersectionBranch]:
    """Branches of NurbsSurface sa ∩ NurbsSurface sb within `tol`; transversal intersections only.

    With `near` (k, 3): only the branches that pass within `radius` of those points, each traced whole over
    both surfaces exactly as without it (the same seeds, marches and fits; closed loops stay closed): where
    one stretch of a large pair's intersection is wanted, the branches elsewhere cost nothing."""
    problem = _SurfaceProblem(sa, sb)
    size = max(_size(sa), _size(sb))
    region = None if near is None else (np.asarray(near, float).reshape(-1, 3), float(radius))
    return _solve(problem, size, tol, max(_samples(sa, 32), _samples(sb, 32)), region)


def intersect_curve_plane(curve, origin, normal, iters: int = 60):
    """Parameters (k,) and points (k, 3) where a 3-D NurbsCurve crosses the plane (sign changes of the
    signed distance on a dense sample, refined by vectorised bisection to machine precision).
    Tangential touches without a sign change are not reported."""
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    o = np.asarray(origin, float)
    u0, u1 = curve.domain
    spans = len(np.unique(curve.knots))
    u = np.linspace(u0, u1, max(64, 16 * spans))
    d = (curve.evaluate(u) - o) @ n
    exact = u[d == 0]
    hit = np.nonzero((d[:-1] * d[1:]) < 0)[0]
    lo, hi, dlo = u[hit], u[hit + 1], d[hit]
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        dm = (curve.evaluate(mid) - o) @ n if len(mid) else mid
        same = np.sign(dm) == np.sign(dlo)
        lo, hi, dlo = np.where(same, mid, lo), np.where(same, hi, mid), np.where(same, dm, dlo)
    params = np.sort(np.concatenate([exact, 0.5 * (lo + hi)]))
    return params, curve.evaluate(params) if len(params) else np.zeros((0, 3))
