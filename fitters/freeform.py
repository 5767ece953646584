"""Free-form fitting: least-squares B-spline curves and surfaces refined by knot insertion to a tolerance.

The paper's recipe (its Figure 6 for a profile, Figure 5 for the face mask): start from a coarse knot
vector whose size comes from a surface characterisation, solve for the control points in the least-squares
sense, measure the error of every data point, insert knots in the middle of *only those knot spans* whose
points exceed the tolerance, and solve again, until the certified statistic holds or a stated limit on
control points is reached.

The error of a data point is its parametric residual |S(u_i, v_i) - P_i| (model units). It is an upper
bound of the point's closest-point distance to the surface, so a fit certified with it is conservative.

Spaces are nested under knot insertion, so the unsmoothed least-squares error can only fall; with the small
smoothing term (which keeps spans without data well posed) a refinement step that would raise the error is
replaced by the previous surface with the knots inserted (same shape), so the certified error never rises.

Linear algebra: design matrices come from `scipy.interpolate.BSpline.design_matrix` (sparse CSR, p+1
non-zeros a row); scattered data use sparse normal equations of the row-wise Kronecker product (p+1)(q+1)
non-zeros a row; full grids use the separable solve C = (Bu'Bu + λRu)^-1 Bu' Z Bv (Bv'Bv + λRv)^-1
(Piegl & Tiller §9.4 for the least-squares set-up).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg
from scipy.interpolate import BSpline

from rgm.errors import GeometryError
from rgm.fitters.certificate import Certificate, certify
from rgm.geometry.basis import basis_functions, find_spans
from rgm.geometry.knots import uniform_knots


# --------------------------------------------------------------------------------------------- bases
def design_matrix(x: np.ndarray, knots: np.ndarray, degree: int) -> sp.csr_matrix:
    """Sparse B-spline basis matrix N (m, n) with N[i, j] = N_j,p(x_i); x within the knot domain."""
    x = np.clip(np.asarray(x, float), knots[degree], knots[-degree - 1])
    return BSpline.design_matrix(x, knots, degree).tocsr()


def _second_difference(n: int) -> sp.csr_matrix:
    """(n-2, n) second-difference operator: a discrete bending energy of a control polygon."""
    if n < 3:
        return sp.csr_matrix((0, n))
    return sp.diags([np.ones(n - 2), -2 * np.ones(n - 2), np.ones(n - 2)], [0, 1, 2], shape=(n - 2, n)).tocsr()


def _span_index(x: np.ndarray, knots: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Index of the non-empty knot span holding each x, and the span breakpoints (distinct knots)."""
    breaks = np.unique(knots[degree:len(knots) - degree])
    idx = np.clip(np.searchsorted(breaks, x, side="right") - 1, 0, len(breaks) - 2)
    return idx, breaks


def _split_candidates(x, res, knots, degree, tol, min_width, greed=0.5):
    """Midpoints of the spans to refine, worst first, and their worst residuals: the spans whose worst
    residual exceeds both `tol` and `greed` times the worst of all (spans narrower than `min_width` are
    kept). Splitting only the worst spans each round (a least-squares error spreads over neighbouring
    spans) avoids over-refining."""
    idx, breaks = _span_index(x, knots, degree)
    worst = np.zeros(len(breaks) - 1)
    np.maximum.at(worst, idx, res)
    bad = np.nonzero((worst > max(tol, greed * worst.max())) & (np.diff(breaks) > min_width))[0]
    bad = bad[np.argsort(-worst[bad], kind="stable")]
    return 0.5 * (breaks[bad] + breaks[bad + 1]), worst[bad]


def _spans_to_split(x, res, knots, degree, tol, min_width, greed=0.5):
    return _split_candidates(x, res, knots, degree, tol, min_width, greed)[0]


# --------------------------------------------------------------------------------------------- results
def fit_stats(res: np.ndarray, tol: float, statistic: str) -> Certificate:
    """The certificate of a set of residuals (model units): `statistic` is "max", "p99" or "p95"."""
    return certify(res, tol, statistic=statistic)


@dataclass(frozen=True)
class CurveFit:
    degree: int
    knots: np.ndarray
    ctrl: np.ndarray          # (n, d)
    stats: Certificate
    history: tuple = ()        # (n_ctrl, value) after each solve
    stopped: str = ""          # why refinement stopped when the tolerance is not met


@dataclass(frozen=True)
class SurfaceFit:
    degree_u: int
    degree_v: int
    knots_u: np.ndarray
    knots_v: np.ndarray
    ctrl: np.ndarray          # (nu, nv, 3)
    stats: Certificate
    residuals: np.ndarray = field(repr=False)
    history: tuple = ()        # (control points, statistic) after each knot-insertion step
    stopped: str = ""

    @property
    def n_ctrl(self) -> int:
        return self.ctrl.shape[0] * self.ctrl.shape[1]

    def nurbs(self):
        from rgm.geometry import NurbsSurface

        return NurbsSurface(self.degree_u, self.degree_v, self.knots_u, self.knots_v, self.ctrl, None)


# --------------------------------------------------------------------------------------------- curves
def chord_parameters(points: np.ndarray) -> np.ndarray:
    """Chord-length parameters in [0, 1] for an ordered polyline (m, d) (Piegl & Tiller eq. 9.5)."""
    d = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.r_[0.0, np.cumsum(d)]
    if s[-1] <= 0:
        raise GeometryError("all points of the curve coincide")
    return s / s[-1]


def _solve_spd_banded(M: sp.spmatrix, rhs: np.ndarray, bandwidth: int) -> np.ndarray:
    """Solve M x = rhs for a symmetric positive definite banded M (sparse) by banded Cholesky:
    O(n b^2) instead of O(n^3) (the B-spline normal matrix has half-bandwidth = degree)."""
    n = M.shape[0]
    M = M.tocoo()
    upper = M.col >= M.row
    ab = np.zeros((bandwidth + 1, n))
    ab[bandwidth + M.row[upper] - M.col[upper], M.col[upper]] = M.data[upper]
    return scipy.linalg.solveh_banded(ab, rhs)


def _solve_curve(t, points, knots, degree, smoothing, fix_ends):
    B = design_matrix(t, knots, degree)
    n = B.shape[1]
    D = _second_difference(n)
    M = (B.T @ B).tocsr()
    lam = smoothing * M.diagonal().sum() / max(n, 1)
    M = (M + lam * (D.T @ D)).tocsr()
    rhs = B.T @ points
    band = max(degree, 2)
    if fix_ends:  # interpolate the first and last point: eliminate those two control points
        ctrl = np.empty((n, points.shape[1]))
        ctrl[0], ctrl[-1] = points[0], points[-1]
        rhs_i = rhs[1:-1] - M[1:-1][:, [0, n - 1]] @ ctrl[[0, n - 1]]
        ctrl[1:-1] = _solve_spd_banded(M[1:-1][:, 1:-1], rhs_i, band) if n > 2 else rhs_i
        return ctrl, B
    return _solve_spd_banded(M, rhs, band), B


def fit_curve(points, tol: float, *, params=None, degree: int = 3, n_initial: int | None = None,
              max_ctrl: int = 500, statistic: str = "max", smoothing: float = 1e-9,
              fix_ends: bool = True) -> CurveFit:
    """Least-squares B-spline curve through ordered `points` (m, d), refined by knot insertion until the
    `statistic` ("max" or e.g. "p99") of the residuals is <= `tol` (model units) or `max_ctrl` is reached.

    The paper's Figure 6: only spans whose points exceed the tolerance receive a new knot.
    """
    points = np.asarray(points, float)
    if points.ndim != 2 or len(points) < degree + 1 or not np.isfinite(points).all():
        raise GeometryError(f"need at least {degree + 1} finite points to fit a degree-{degree} curve")
    t = chord_parameters(points) if params is None else np.asarray(params, float)
    knots = uniform_knots(degree, n_initial or degree + 1)
    history, prev = [], None
    min_width = 1.0 / max(len(points), 1)
    while True:
        ctrl, B = _solve_curve(t, points, knots, degree, smoothing, fix_ends)
        res = np.linalg.norm(B @ ctrl - points, axis=1)
        stats = fit_stats(res, tol, statistic)
        if prev is not None and stats.value > prev[2].value:  # keep the better, refined shape
            ctrl = refinement_matrix(prev[1], knots, degree) @ prev[0]
            res = np.linalg.norm(B @ ctrl - points, axis=1)
            stats = fit_stats(res, tol, statistic)
        history.append((len(ctrl), stats.value))
        if stats.holds:
            return CurveFit(degree, knots, ctrl, stats, tuple(history))
        new = _spans_to_split(t, res, knots, degree, tol, min_width)
        if len(new) == 0:
            return CurveFit(degree, knots, ctrl, stats, tuple(history), "no span can be split further")
        if len(ctrl) + len(new) > max_ctrl:
            return CurveFit(degree, knots, ctrl, stats, tuple(history), f"control-point limit {max_ctrl} reached")
        prev = (ctrl, knots, stats)
        knots = np.sort(np.r_[knots, new])


def refinement_matrix(knots, new_knots, degree) -> np.ndarray:
    """Matrix R (n_new, n_old) with N_old = N_new R, so that control points P_new = R P_old describe the
    same spline on the refined knot vector. Computed as an exact least-squares projection on a sample
    that is unisolvent for the refined space (the spaces are nested, so the residual is round-off)."""
    breaks = np.unique(new_knots)
    s = np.unique(breaks[:-1, None] + np.diff(breaks)[:, None] * np.linspace(0.0, 1.0, degree + 2))
    Bo = design_matrix(s, knots, degree).toarray()
    Bn = design_matrix(s, new_knots, degree).toarray()
    return np.linalg.lstsq(Bn, Bo, rcond=None)[0]


# --------------------------------------------------------------------------------------------- surfaces
def grid_parameters(grid: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Averaged chord-length parameters (rows,), (cols,) in [0, 1] of a point grid (rows, cols, 3)
    (Piegl & Tiller eq. 9.8-9.9); invalid cells (mask False) are skipped in the averages."""
    def along(g, m):
        d = np.linalg.norm(np.diff(g, axis=0), axis=2)
        ok = m[1:] & m[:-1]
        d = np.where(ok, d, np.nan)
        step = np.nanmedian(d, axis=1)
        step = np.where(np.isfinite(step) & (step > 0), step, np.nan)
        fill = np.nanmedian(step) if np.isfinite(step).any() else 1.0
        step = np.where(np.isfinite(step), step, fill)
        c = np.r_[0.0, np.cumsum(step)]
        return c / c[-1]
    mask = np.ones(grid.shape[:2], bool) if mask is None else mask
    return along(grid, mask), along(grid.transpose(1, 0, 2), mask.T)


def plane_parameters(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Parameters of scattered points by projection onto their best-fit (PCA) plane, scaled to [0, 1]².

    Returns u, v (n,) and the 3x3 frame (rows: u axis, v axis, normal)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    uv = (points - c) @ vt[:2].T
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    if np.any(hi - lo <= 0):
        raise GeometryError("the points are collinear: no surface can be parameterised over them")
    uv = (uv - lo) / (hi - lo)
    return uv[:, 0], uv[:, 1], vt


@dataclass(frozen=True)
class ScatteredBasis:
    """The non-zero tensor-product basis values of scattered parameters: row i of the design matrix
    holds `vals[i]` at columns `cols[i]` ((p+1)(q+1) each), and `cell[i]` names its knot cell."""

    cols: np.ndarray   # (m, (p+1)(q+1)) int, flat control-point indices i_u * nv + j_v
    vals: np.ndarray   # (m, (p+1)(q+1)) float
    cell: np.ndarray   # (m,) int
    shape: tuple       # (nu, nv)

    @classmethod
    def build(cls, u, v, ku, kv, p, q) -> "ScatteredBasis":
        nu, nv = len(ku) - p - 1, len(kv) - q - 1
        su, sv = find_spans(ku, p, u), find_spans(kv, q, v)
        bu, bv = basis_functions(ku, p, u, su), basis_functions(kv, q, v, sv)
        first = (su - p) * nv + (sv - q)
        offsets = (np.arange(p + 1)[:, None] * nv + np.arange(q + 1)[None, :]).ravel()
        vals = (bu[:, :, None] * bv[:, None, :]).reshape(len(u), -1)
        return cls(first[:, None] + offsets, vals, first, (nu, nv))

    def evaluate(self, ctrl: np.ndarray) -> np.ndarray:
        """Surface points (m, 3) for a control net (nu, nv, 3)."""
        return np.einsum("mk,mkd->md", self.vals, ctrl.reshape(-1, 3)[self.cols])

    def normal_equations(self, points: np.ndarray):
        """A'A (sparse, N x N) and A'P (N, 3), summed per knot cell: points in one cell share their
        (p+1)(q+1) columns, so each cell contributes one small dense Gram matrix B_c'B_c, computed for
        many cells at once as a batched matrix product over cells padded to a common point count."""
        order = np.argsort(self.cell, kind="stable")
        cell, vals, pts = self.cell[order], self.vals[order], points[order]
        cells, first, counts = np.unique(cell, return_index=True, return_counts=True)
        k = vals.shape[1]
        gram = np.empty((len(cells), k, k))
        moment = np.empty((len(cells), k, 3))
        by_count = np.argsort(counts, kind="stable")
        lo = 0
        while lo < len(cells):  # groups of cells with similar counts keep the padding small
            hi = lo + 1
            while hi < len(cells) and counts[by_count[hi]] * (hi + 1 - lo) <= 2 * counts[by_count[lo:hi + 1]].sum() + 64 * k:
                hi += 1
            group = by_count[lo:hi]
            width = counts[group].max()
            slot = np.arange(width)[None, :]
            take = np.minimum(first[group][:, None] + slot, len(cell) - 1)
            live = (slot < counts[group][:, None])[:, :, None]
            b = np.where(live, vals[take], 0.0)                      # (cells, width, k)
            gram[group] = np.matmul(b.transpose(0, 2, 1), b)
            moment[group] = np.matmul(b.transpose(0, 2, 1), np.where(live, pts[take], 0.0))
            lo = hi
        cols = self.cols[order][first]                        # (cells, k) global columns per cell
        n = self.shape[0] * self.shape[1]
        rows_i = np.broadcast_to(cols[:, :, None], gram.shape).ravel()
        cols_j = np.broadcast_to(cols[:, None, :], gram.shape).ravel()
        M = sp.coo_matrix((gram.ravel(), (rows_i, cols_j)), shape=(n, n)).tocsc()
        rhs = np.zeros((n, 3))
        np.add.at(rhs, cols.ravel(), moment.reshape(-1, 3))
        return M, rhs


def _smoothing_matrix(nu: int, nv: int) -> sp.csr_matrix:
    """Bending energy of a control net: second differences along u and along v, (nu nv, nu nv)."""
    Du, Dv = _second_difference(nu), _second_difference(nv)
    return (sp.kron(Du.T @ Du, sp.identity(nv)) + sp.kron(sp.identity(nu), Dv.T @ Dv)).tocsr()


def solve_scattered(u, v, points, ku, kv, p, q, smoothing=1e-6):
    """Least-squares control net (nu, nv, 3) for scattered points (n, 3) at parameters (u, v), with a
    bending-energy term weighted by `smoothing` relative to the data term. Returns (ctrl, basis)."""
    basis = ScatteredBasis.build(np.asarray(u, float), np.asarray(v, float), ku, kv, p, q)
    nu, nv = basis.shape
    M, rhs = basis.normal_equations(points)
    R = _smoothing_matrix(nu, nv)
    lam = smoothing * M.diagonal().sum() / max(R.diagonal().sum(), 1e-300)
    M = (M + lam * R + 1e-14 * M.diagonal().max() * sp.identity(nu * nv)).tocsc()
    if nu * nv <= 2500:
        ctrl = scipy.linalg.solve(M.toarray(), rhs, assume_a="pos")
    else:
        ctrl = scipy.sparse.linalg.splu(M).solve(rhs)
    return ctrl.reshape(nu, nv, 3), basis


def solve_grid(u, v, grid, ku, kv, p, q, smoothing=1e-6):
    """Separable least squares for a full grid (rows, cols, 3): C = Mu^-1 Bu' Z Bv Mv^-1 with
    Mu = Bu'Bu + λ Du'Du (likewise v). Returns (ctrl (nu, nv, 3), Bu, Bv)."""
    Bu, Bv = design_matrix(u, ku, p), design_matrix(v, kv, q)

    def normal(B):
        M = (B.T @ B).toarray()
        D = _second_difference(B.shape[1])
        return M + smoothing * np.trace(M) / max(B.shape[1], 1) * (D.T @ D).toarray()

    Mu, Mv = normal(Bu), normal(Bv)
    rows, cols = grid.shape[:2]
    T = (Bu.T @ grid.reshape(rows, -1)).reshape(Bu.shape[1], cols, 3)          # (nu, cols, 3)
    T = np.stack([(Bv.T @ T[:, :, k].T).T for k in range(3)], axis=2)          # (nu, nv, 3)
    T = scipy.linalg.cho_solve(scipy.linalg.cho_factor(Mu), T.reshape(Bu.shape[1], -1)).reshape(T.shape)
    ctrl = scipy.linalg.cho_solve(scipy.linalg.cho_factor(Mv), T.transpose(1, 0, 2).reshape(Bv.shape[1], -1))
    return ctrl.reshape(Bv.shape[1], Bu.shape[1], 3).transpose(1, 0, 2), Bu, Bv


def initial_net_size(grid: np.ndarray | None, mask, degree: int, n_points: int) -> int:
    """Initial control points per direction from a surface characterisation: the number of geometrically
    homogeneous patches (connected regions of equal sign of mean and Gaussian curvature, estimated on the
    data grid) sets the net size, as in the paper; without a grid, the point count sets a coarse size."""
    if grid is None or min(grid.shape[:2]) < 7:
        return degree + 1 + int(np.clip(np.sqrt(n_points) / 40, 0, 6))
    from scipy import ndimage

    z = grid[..., 2] if mask is None else np.where(mask, grid[..., 2], np.nan)
    zs = ndimage.uniform_filter(np.nan_to_num(z, nan=np.nanmean(z)), size=5)
    zu, zv = np.gradient(zs)
    zuu, zuv = np.gradient(zu)
    _, zvv = np.gradient(zv)
    H = zuu + zvv
    K = zuu * zvv - zuv**2
    eps_h, eps_k = 0.1 * np.nanstd(H), 0.1 * np.nanstd(K)
    label = 3 * np.sign(np.where(np.abs(H) > eps_h, H, 0)) + np.sign(np.where(np.abs(K) > eps_k, K, 0))
    patches = 0
    for value in np.unique(label):
        lab, count = ndimage.label(label == value)
        sizes = np.bincount(lab.ravel())[1:]
        patches += int(np.sum(sizes > 0.01 * label.size))
    return degree + 1 + int(np.clip(np.ceil(np.sqrt(max(patches, 1))), 1, 12))


class _SurfaceProblem:
    """The data of a surface fit and how to solve and measure it on given knot vectors: the separable
    solve for a full grid, the sparse normal equations otherwise. Residuals are per data point."""

    def __init__(self, points, mask, params, degree, smoothing):
        pts = np.asarray(points, float)
        self.degree, self.smoothing, self.grid = degree, smoothing, None
        if pts.ndim == 3:
            valid = np.isfinite(pts).all(axis=2)
            mask = valid if mask is None else (np.asarray(mask, bool) & valid)
            if mask.sum() < (degree + 1) ** 2:
                raise GeometryError("too few valid grid points to fit a surface")
            self.ug, self.vg = grid_parameters(np.where(mask[..., None], pts, 0.0), mask) if params is None else params
            ii, jj = np.nonzero(mask)
            self.u, self.v, self.data = self.ug[ii], self.vg[jj], pts[ii, jj]
            self.grid = pts if mask.all() else None
            self.shape = pts.shape[:2]
            self.char = (pts, mask)
        else:
            if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < (degree + 1) ** 2:
                raise GeometryError(f"need at least {(degree + 1) ** 2} points (n, 3) to fit a surface")
            if not np.isfinite(pts).all():
                raise GeometryError("points contain NaN or infinite coordinates")
            self.u, self.v = plane_parameters(pts)[:2] if params is None else map(np.asarray, params)
            self.data = pts
            self.char = (None, None)

    def solve(self, ku, kv):
        """Control net (nu, nv, 3) and residuals (n,) on the knot vectors ku, kv."""
        p = self.degree
        if self.grid is not None:
            ctrl, Bu, Bv = solve_grid(self.ug, self.vg, self.grid, ku, kv, p, p, self.smoothing)
            return ctrl, self.residuals(ku, kv, ctrl, (Bu, Bv))
        ctrl, basis = solve_scattered(self.u, self.v, self.data, ku, kv, p, p, self.smoothing)
        return ctrl, np.linalg.norm(basis.evaluate(ctrl) - self.data, axis=1)

    def residuals(self, ku, kv, ctrl, bases=None):
        p = self.degree
        if self.grid is not None:
            Bu, Bv = bases or (design_matrix(self.ug, ku, p), design_matrix(self.vg, kv, p))
            return np.linalg.norm(_grid_eval(Bu, Bv, ctrl) - self.grid, axis=2).ravel()
        return np.linalg.norm(ScatteredBasis.build(self.u, self.v, ku, kv, p, p).evaluate(ctrl) - self.data, axis=1)

    def worst_per_direction(self, res):
        """(params_u, worst_u, params_v, worst_v): each data line's worst residual for the span search."""
        if self.grid is not None:
            r = res.reshape(self.shape)
            return self.ug, r.max(axis=1), self.vg, r.max(axis=0)
        return self.u, res, self.v, res


def fit_surface(points, tol: float, *, mask=None, params=None, degree: int = 3,
                n_initial: int | None = None, max_ctrl: int = 40000, statistic: str = "max",
                smoothing: float = 1e-7, prune: int = 8) -> SurfaceFit:
    """Least-squares bicubic (by default) B-spline surface of `points` refined by knot insertion.

    points: (n, 3) scattered points, or a grid (rows, cols, 3) with optional `mask` (rows, cols) of valid
        cells (a range image keeps its grid: the grid gives the parameterisation).
    params: optional parameters (u, v): per grid row and column for a grid, per point otherwise.
    tol: tolerance in model units for the `statistic` ("max", or "p99" etc. for scans whose noise makes
        a maximum meaningless) of the parametric residuals.
    Refinement stops when the statistic is met, when no span can be split, or when the control net
    would exceed `max_ctrl`; `SurfaceFit.stopped` says which, and `stats.holds` is False then. The last
    insertion step is then bisected (the fewest of its knots, worst spans first, that still meet the
    tolerance); then knots whose neighbourhood is far inside the tolerance are removed in one batch, and
    up to `prune` single knots, quietest first, each only when the fit still holds without it.
    """
    prob = _SurfaceProblem(points, mask, params, degree, smoothing)
    ku = kv = uniform_knots(degree, n_initial or initial_net_size(*prob.char, degree, len(prob.data)))
    prev, history, stopped, step = None, [], "", None
    while True:
        ctrl, res = prob.solve(ku, kv)
        stats = fit_stats(res, tol, statistic)
        if prev is not None and stats.value > prev[3].value:  # keep the refined previous shape
            ctrl = np.einsum("ia,abd,jb->ijd", refinement_matrix(prev[1], ku, degree), prev[0],
                             refinement_matrix(prev[2], kv, degree), optimize=True)
            res = prob.residuals(ku, kv, ctrl)
            stats = fit_stats(res, tol, statistic)
        history.append((ctrl.shape[0] * ctrl.shape[1], stats.value))
        if stats.holds:
            break
        pu, wu, pv, wv = prob.worst_per_direction(res)
        greed = 0.5 if stats.value > 4 * tol else 0.8  # near the goal, split only the worst spans
        step = (_split_candidates(pu, wu, ku, degree, tol, 0.5 / len(np.unique(pu)), greed),
                _split_candidates(pv, wv, kv, degree, tol, 0.5 / len(np.unique(pv)), greed))
        new_u, new_v = step[0][0], step[1][0]
        if len(new_u) + len(new_v) == 0:
            stopped = "no knot span can be split further: the data's sampling or noise limits the fit"
            break
        if (ctrl.shape[0] + len(new_u)) * (ctrl.shape[1] + len(new_v)) > max_ctrl:
            stopped = f"control-net limit {max_ctrl} reached"
            break
        prev = (ctrl, ku, kv, stats)
        ku, kv = np.sort(np.r_[ku, new_u]), np.sort(np.r_[kv, new_v])
    if stats.holds and prev is not None:
        # the last step may have overshot: bisect (three probes) on how many of its knots, worst first,
        # are needed to meet the tolerance
        (cu, eu), (cv, ev) = step
        order = np.argsort(-np.r_[eu, ev], kind="stable")
        lo, hi = 0, len(order)
        for _ in range(3):
            if hi - lo <= 1:
                break
            mid = (lo + hi) // 2
            take = order[:mid]
            ku2 = np.sort(np.r_[prev[1], cu[take[take < len(cu)]]])
            kv2 = np.sort(np.r_[prev[2], cv[take[take >= len(cu)] - len(cu)]])
            ctrl2, res2 = prob.solve(ku2, kv2)
            stats2 = fit_stats(res2, tol, statistic)
            if stats2.holds:
                hi = mid
                ku, kv, ctrl, res, stats = ku2, kv2, ctrl2, res2, stats2
            else:
                lo = mid
    if stats.holds and prune:
        ku, kv, ctrl, res, stats = _prune(prob, ku, kv, ctrl, res, stats, tol, statistic, prune)
    return SurfaceFit(degree, degree, ku, kv, ctrl, stats, res, tuple(history), stopped)


def _neighbourhood_error(x, res, knots, degree):
    """Interior break points and the worse of the two spans' worst residuals on either side of each."""
    idx, breaks = _span_index(x, knots, degree)
    worst = np.zeros(len(breaks) - 1)
    np.maximum.at(worst, idx, res)
    return breaks[1:-1], np.maximum(worst[:-1], worst[1:])


def _without(knots, degree, drop_values):
    inner = knots[degree + 1:-degree - 1]
    keep = ~np.isin(inner, drop_values)
    return np.r_[knots[:degree + 1], inner[keep], knots[-degree - 1:]]


def _prune(prob, ku, kv, ctrl, res, stats, tol, statistic, attempts, slack=0.4):
    """Knot removal after the tolerance holds: first one batch (every other knot whose neighbouring
    spans both stay below slack x tol), then single knots, quietest neighbourhood first, `attempts`
    re-solves in all; each removal is kept only if the re-solved fit still holds."""
    def candidates(res):
        pu, wu, pv, wv = prob.worst_per_direction(res)
        bu, eu = _neighbourhood_error(pu, wu, ku, prob.degree)
        bv, ev = _neighbourhood_error(pv, wv, kv, prob.degree)
        return bu, eu, bv, ev

    bu, eu, bv, ev = candidates(res)
    batch = (bu[(eu < slack * tol) & (np.arange(len(bu)) % 2 == 0)],
             bv[(ev < slack * tol) & (np.arange(len(bv)) % 2 == 0)])
    tried = set()
    for attempt in range(int(attempts) + 1):
        if attempt == 0:
            drop_u, drop_v = batch
            if len(drop_u) + len(drop_v) == 0:
                continue
        else:
            bu, eu, bv, ev = candidates(res)
            order = [i for i in np.argsort(np.r_[eu, ev], kind="stable")
                     if (i < len(bu), float(bu[i] if i < len(bu) else bv[i - len(bu)])) not in tried]
            if not order:
                break
            i = order[0]
            drop_u, drop_v = ((bu[i],), ()) if i < len(bu) else ((), (bv[i - len(bu)],))
            tried.add((i < len(bu), float(bu[i] if i < len(bu) else bv[i - len(bu)])))
        ku2, kv2 = _without(ku, prob.degree, drop_u), _without(kv, prob.degree, drop_v)
        ctrl2, res2 = prob.solve(ku2, kv2)
        stats2 = fit_stats(res2, tol, statistic)
        if stats2.holds:
            ku, kv, ctrl, res, stats = ku2, kv2, ctrl2, res2, stats2
    return ku, kv, ctrl, res, stats


def _grid_eval(Bu, Bv, ctrl):
    """Surface points on the data grid (rows, cols, 3) from the design matrices: Bu C Bv'."""
    T = np.stack([(Bu @ ctrl[:, :, k]) for k in range(3)], axis=2)              # (rows, nv, 3)
    return np.stack([(Bv @ T[:, :, k].T).T for k in range(3)], axis=2)         # (rows, cols, 3)
