"""Free-form fitting: least-squares B-spline curves and surfaces refined by knot insertion to a tolerance.

The paper's recipe (its Figure 6 for a profile, Figure 5 for the face mask): start from a coarse knot
vector whose size comes from a surface characterisation, solve for the control points in the least-squares
sense, measure the error of every data point, insert knots in the middle of *only those knot spans* whose
points exceed the tolerance, and solve again, until the certified statistic holds or a stated limit on
control points is reached. This module holds the bases, the solvers and the curve fit; the surface loop,
with its approximation limit (no net finer than the data), is `rgm.fitters.freeform_surface.fit_surface`.

The error of a data point is its parametric residual |S(u_i, v_i) - P_i| (model units), an upper bound of
its closest-point distance; the surface loop replaces it by the foot-point distance where it exceeds the
tolerance, so what it certifies is what the certificate measures.

Spaces are nested under knot insertion, so the unsmoothed least-squares error can only fall; with the
smoothing term (the surface's bending energy, which keeps spans without data well posed) a refinement step that would raise the error is
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
from rgm.geometry.basis import basis_derivatives_t, basis_functions, find_spans
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


def _split_candidates(x, res, knots, degree, tol, min_count, greed=0.5):
    """Midpoints of the spans to refine, worst first, and their worst residuals: the spans whose worst
    residual exceeds both `tol` and `greed` times the worst of all and that hold at least 2 `min_count`
    of the data parameters `x` (so that each half keeps about `min_count`: a net finer than the data
    would interpolate the samples and their noise). Splitting only the worst spans each round (a
    least-squares error spreads over neighbouring spans) avoids over-refining. When every span over
    `tol` is too narrow, the splittable spans beside them are split instead (`_beside_narrow`)."""
    idx, breaks = _span_index(x, knots, degree)
    worst = np.zeros(len(breaks) - 1)
    np.maximum.at(worst, idx, res)
    splittable = np.bincount(idx, minlength=len(breaks) - 1) >= 2 * min_count
    if not splittable.any():
        return np.zeros(0), np.zeros(0)
    bad = np.nonzero((worst > max(tol, greed * worst[splittable].max())) & splittable)[0]
    if not len(bad):
        bad = _beside_narrow(worst, splittable, tol, degree)
    bad = bad[np.argsort(-worst[bad], kind="stable")]
    return 0.5 * (breaks[bad] + breaks[bad + 1]), worst[bad]


def _beside_narrow(worst, splittable, tol, degree):
    """Spans to split when every span over `tol` is too narrow to split: the nearest splittable span
    on each side of each of them, if it lies within `degree` spans (the B-splines over a span reach
    that far: a knot inserted there adds one that overlaps the narrow span and relieves it). The
    returned spans' `worst` is raised to the narrow span's, so they are ranked by what they relieve."""
    narrow = np.flatnonzero((worst > tol) & ~splittable)
    ok = np.flatnonzero(splittable)
    if not len(narrow) or not len(ok):
        return np.zeros(0, int)
    at = np.searchsorted(ok, narrow)
    left, right = ok[np.clip(at - 1, 0, len(ok) - 1)], ok[np.clip(at, 0, len(ok) - 1)]
    use_l, use_r = (at > 0) & (narrow - left <= degree), (at < len(ok)) & (right - narrow <= degree)
    picked = np.r_[left[use_l], right[use_r]]
    score = np.r_[worst[narrow[use_l]], worst[narrow[use_r]]]
    np.maximum.at(worst, picked, score)
    return np.unique(picked)


# --------------------------------------------------------------------------------------------- results
def fit_stats(res: np.ndarray, tol: float, statistic: str) -> Certificate:
    """The certificate of a set of residuals (model units): `statistic` is "max", "p99" or "p95"."""
    return certify(res, tol, statistic=statistic)


def statistic_value(res: np.ndarray, statistic: str) -> float:
    """The value of `statistic` ("max", "p99", "p95") of residuals (n,) >= 0, exactly as the certificate
    computes it (numpy's linear-interpolation percentile), without sorting them all: only the values
    above a bound taken from a strided sample are partitioned (all of them if too few lie above it)."""
    if statistic == "max":
        return float(res.max())
    q = {"p99": 0.99, "p95": 0.95}[statistic]
    n = len(res)
    pos = q * (n - 1)
    lo = int(np.floor(pos))
    top = res
    if n > 20000:
        sample = res[::max(1, n // 10000)]
        top = res[res >= np.quantile(sample, max(0.0, q - 0.03))]
        if len(top) < n - lo:
            top = res
    k = lo - (n - len(top))
    part = np.partition(top, [k, min(k + 1, len(top) - 1)])
    a, b, t = part[k], part[min(k + 1, len(top) - 1)], pos - lo
    return float(b - (b - a) * (1 - t) if t >= 0.5 else a + (b - a) * t)   # numpy's lerp, to the bit


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
        new = _split_candidates(t, res, knots, degree, tol, 1)[0]
        if len(new) == 0:
            return CurveFit(degree, knots, ctrl, stats, tuple(history), "no span can be split further")
        if len(ctrl) + len(new) > max_ctrl:
            return CurveFit(degree, knots, ctrl, stats, tuple(history), f"control-point limit {max_ctrl} reached")
        prev = (ctrl, knots, stats)
        knots = np.sort(np.r_[knots, new])


def refinement_matrix(knots, new_knots, degree) -> np.ndarray:
    """Matrix R (n_new, n_old) with N_old = N_new R, so that control points P_new = R P_old describe the
    same spline on the refined knot vector `new_knots` (a superset of `knots`): knot refinement
    (Piegl & Tiller A5.4) applied to the identity as control points."""
    from rgm.geometry.knots import refine_knots

    values, new_counts = np.unique(new_knots, return_counts=True)
    old_counts = np.searchsorted(knots, values, side="right") - np.searchsorted(knots, values, side="left")
    inserted = np.repeat(values, new_counts - old_counts)
    n_old = len(knots) - degree - 1
    return refine_knots(np.asarray(knots, float), degree, np.eye(n_old), inserted)[1]


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
    def build(cls, u, v, ku, kv, p, q, derivative: tuple[int, int] = (0, 0)) -> "ScatteredBasis":
        """The basis at (u, v), or its partial derivative d^a/du^a d^b/dv^b for `derivative` (a, b)."""
        nu, nv = len(ku) - p - 1, len(kv) - q - 1
        su, sv = find_spans(ku, p, u), find_spans(kv, q, v)
        a, b = derivative
        bu = basis_derivatives_t(ku, p, u, a, su)[a].T if a else basis_functions(ku, p, u, su)
        bv = basis_derivatives_t(kv, q, v, b, sv)[b].T if b else basis_functions(kv, q, v, sv)
        first = (su - p) * nv + (sv - q)
        offsets = (np.arange(p + 1)[:, None] * nv + np.arange(q + 1)[None, :]).ravel()
        vals = (bu[:, :, None] * bv[:, None, :]).reshape(len(u), -1)
        return cls(first[:, None] + offsets, vals, first, (nu, nv))

    def matrix(self) -> sp.csr_matrix:
        """The sparse design matrix (m, nu nv): row i holds vals[i] at columns cols[i]."""
        m, k = self.vals.shape
        return sp.csr_matrix((self.vals.ravel(), self.cols.ravel(), np.arange(0, m * k + 1, k)),
                             shape=(m, self.shape[0] * self.shape[1]))

    def evaluate(self, ctrl: np.ndarray) -> np.ndarray:
        """Surface points (m, 3) for a control net (nu, nv, 3): a sparse product, no (m, k, 3) gather."""
        return self.matrix() @ ctrl.reshape(-1, 3)

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


@dataclass(frozen=True)
class Anchors:
    """Points a fitted surface is pulled through at fixed parameters: a penalty constraint in the least
    squares (`solve_scattered`), not data (the residuals and the certificate are the data's alone).
    uv (k, 2) in the surface's parameters, xyz (k, 3); `weight` each, relative to a data point's. With
    `tol`, the refinement (`rgm.fitters.freeform_surface.fit_surface`) also inserts knots in the spans
    whose anchors are missed by more, until their 95th percentile is within it (where the data allow)."""

    uv: np.ndarray
    xyz: np.ndarray
    weight: float = 10.0
    tol: float | None = None

    def basis(self, ku, kv, p, q) -> "ScatteredBasis":
        return ScatteredBasis.build(self.uv[:, 0], self.uv[:, 1], ku, kv, p, q)

    def residuals(self, ku, kv, p, q, ctrl) -> np.ndarray:
        """|S(uv_a) - xyz_a| (k,) for the control net (nu, nv, 3) on ku, kv."""
        return np.linalg.norm(self.basis(ku, kv, p, q).evaluate(ctrl) - self.xyz, axis=1)


@dataclass(frozen=True)
class Extension:
    """Where the unit parameter square holds no data: the surface there (a patch reaches past its data to meet
    its neighbours) continues its data bending no more than they do. `uv` (k, 2): the midpoints of a square
    grid over [0, 1]^2 farther from every data parameter than 1.5 cells and 1.5 data spacings, each standing
    for `area` of the domain; `weight` per data point of their thin-plate energy (`solve_scattered`), sum area
    (|S_uu|^2 + 2 |S_uv|^2 + |S_vv|^2) (model units squared, parameters over [0, 1]). Without it a net whose
    spans reach past the data is decided there only by how the data's noise extrapolates: a small patch's
    surface ran up to 90 times its size away, folding back across its own seams."""

    uv: np.ndarray
    area: float
    weight: float = 0.0
    covered: np.ndarray | None = None   # the grid's other samples: where the data are

    @classmethod
    def of(cls, u, v, resolution: int = 48) -> "Extension":
        """The empty and covered samples of the parameters (u, v) (n,) (weight 0: `weighed`)."""
        from scipy.spatial import cKDTree

        uv = np.column_stack([u, v])
        tree = cKDTree(uv)
        sample = uv[::max(1, len(uv) // 20000)]     # the median spacing from a sample: as good, and cheap
        spacing = float(np.median(tree.query(sample, k=2)[0][:, 1])) if len(uv) > 1 else 0.0
        g = (np.arange(resolution) + 0.5) / resolution
        grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
        far = tree.query(grid, distance_upper_bound=1.5 * max(1.0 / resolution, spacing))[0] == np.inf
        return cls(grid[far], 1.0 / resolution**2, 0.0, grid[~far])

    def weighed(self, ctrl, ku, kv, p: int, q: int, tol: float, share: float) -> "Extension":
        """This extension weighed against the surface (control net (nu, nv, 3) on ku, kv) fitted without it:
        a continuation bending as much per unit area as that surface does over its data costs a data point
        `share` tol^2 (and one ten times wilder a hundred times that). The data's bending is taken at
        least tol^2 per unit area (flat data: the continuation stays about as flat)."""
        if not len(self.uv) or self.covered is None or not len(self.covered):
            return self
        C = ctrl.reshape(-1, 3)
        inside = Extension(self.covered, self.area)
        bending = float(np.einsum("id,id->", C, inside.energy(ku, kv, p, q) @ C))
        bending /= len(self.covered) * self.area
        weight = share * tol**2 / (len(self.uv) * self.area * max(bending, tol**2))
        return Extension(self.uv, self.area, weight, None)

    def energy(self, ku, kv, p: int, q: int) -> sp.csr_matrix:
        """The thin-plate energy's matrix E (nu nv, nu nv): sum over the samples of the energy of the
        surface with control net C is trace(C' E C)."""
        u, v = self.uv[:, 0], self.uv[:, 1]
        E = None
        for a, b, c in ((2, 0, 1.0), (1, 1, 2.0), (0, 2, 1.0)):
            D = ScatteredBasis.build(u, v, ku, kv, p, q, (a, b)).matrix()
            E = c * self.area * (D.T @ D) if E is None else E + c * self.area * (D.T @ D)
        return E


#: the densest net the surface loop builds: one control point per this many data points
DATA_PER_CTRL = 2.0
#: weight of the bending energy per data point at that density (dimensionless: see `_penalty`)
SMOOTHING = 1e-9


def _bending(knots, degree: int, count: int) -> tuple[float, sp.csr_matrix]:
    """(1/h, D'D) for one direction of a net on `knots`: h the mean knot span (parameter units) and D the
    second differences of the control points. With them the bending energy of the surface along that
    direction, the integral of |S_uu|^2 over the parameter domain (model units squared), is about
    h_v / h_u^3 * sum |D_u C|^2: second differences of control points approximate h^2 S_uu."""
    inv_h = (count - degree) / max(float(knots[-1] - knots[0]), 1e-300)
    D = _second_difference(count)
    return inv_h, (D.T @ D).tocsr()


def _penalty(smoothing: float, n_ctrl: int, n_data: int) -> float:
    """The bending energy's weight per data point for a net of n_ctrl control points on n_data points:
    `smoothing` times the square of the net's density relative to the densest (DATA_PER_CTRL), at most
    1. In full where few points determine each control point (the penalty decides what they leave free,
    spans without data included); vanishing for a net much coarser than the data, which any penalty
    would only bias."""
    return smoothing * min(1.0, DATA_PER_CTRL * n_ctrl / max(n_data, 1)) ** 2


def closure_u(ku, p: int, nu: int, nv: int) -> sp.csr_matrix:
    """(nu nv, (nu - 2) nv) map from free control points to a net closed C1 across u = 0 / u = 1 (a
    surface that wraps round, its cut at the domain's ends): P_{n-1} = P_0, and P_1 - P_0 = r (P_{n-1} -
    P_{n-2}) with r = h_0 / h_last, the first and last knot spans (clamped ends: S_u(0) = p/h_0 (P_1 - P_0),
    S_u(1) = p/h_last (P_{n-1} - P_{n-2})). Free columns: 0, 2, 3, ..., n-2 of the net."""
    if nu < 4:
        raise GeometryError(f"a net closed in u needs at least 4 control points along u, got {nu}")
    r = (ku[p + 1] - ku[p]) / (ku[nu] - ku[nu - 1])
    free = np.r_[0, np.arange(2, nu - 1)]                      # net column of each free column
    rows = [free, [nu - 1], [1, 1]]
    cols = [np.arange(len(free)), [0], [0, len(free) - 1]]      # P_1 = (1 + r) P_0 - r P_{n-2}
    vals = [np.ones(len(free)), [1.0], [1.0 + r, -r]]
    tu = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nu, nu - 2))
    return sp.kron(tu, sp.identity(nv), format="csr")


def solve_scattered(u, v, points, ku, kv, p, q, smoothing=SMOOTHING, anchors=None, closed_u: bool = False,
                    extension: Extension | None = None):
    """Least-squares control net (nu, nv, 3) for scattered points (n, 3) at parameters (u, v), minimising
    sum |S(u_i, v_i) - P_i|^2 + n * w * (bending energy along u + along v) (see `_bending`), w the
    `_penalty` of `smoothing`: a penalty on the surface, not on its net. `anchors` (`Anchors`) add
    sum weight |S(uv_a) - xyz_a|^2: points the surface is to pass through at fixed parameters (a penalty
    constraint, such as a boundary curve shared with a neighbour, `rgm.fitters.patches`), not data.
    `closed_u`: the net is closed C1 across u = 0 / u = 1 (`closure_u`), exactly, for a surface that
    wraps round. `extension` (`Extension`) adds n * weight times the thin-plate energy where the domain
    has no data. Returns (ctrl, basis)."""
    basis = ScatteredBasis.build(np.asarray(u, float), np.asarray(v, float), ku, kv, p, q)
    nu, nv = basis.shape
    M, rhs = basis.normal_equations(points)
    if anchors is not None:
        A = anchors.basis(ku, kv, p, q).matrix()
        M = M + anchors.weight * (A.T @ A)
        rhs = rhs + anchors.weight * (A.T @ anchors.xyz)
    (iu, Ru), (iv, Rv) = _bending(ku, p, nu), _bending(kv, q, nv)
    w = len(points) * _penalty(smoothing, nu * nv, len(points))
    R = w * iu**3 / iv * sp.kron(Ru, sp.identity(nv)) + w * iv**3 / iu * sp.kron(sp.identity(nu), Rv)
    M = M + R
    if extension is not None and len(extension.uv):
        M = M + len(points) * extension.weight * extension.energy(ku, kv, p, q)
    if closed_u:
        T = closure_u(ku, p, nu, nv)
        M, rhs = T.T @ M @ T, T.T @ rhs
    M = (M + 1e-14 * M.diagonal().max() * sp.identity(M.shape[0])).tocsc()
    ctrl = scipy.sparse.linalg.splu(M).solve(rhs)   # sparse LU of the banded normal matrix: no dense BLAS
    if closed_u:
        ctrl = T @ ctrl
    return ctrl.reshape(nu, nv, 3), basis


def solve_grid(u, v, grid, ku, kv, p, q, smoothing=SMOOTHING):
    """Separable least squares for a full grid (rows, cols, 3): C = Mu^-1 Bu' Z Bv Mv^-1 with
    Mu = Bu'Bu + rows * w / h_u^3 * Du'Du (likewise v; w the `_penalty` of `smoothing`), the curve form
    of `solve_scattered`'s bending penalty per direction, each solved by banded Cholesky (half-bandwidth
    max(p, 2): no dense factorisation, no multithreaded BLAS). Returns (ctrl (nu, nv, 3), Bu, Bv)."""
    Bu, Bv = design_matrix(u, ku, p), design_matrix(v, kv, q)
    nu, nv = Bu.shape[1], Bv.shape[1]
    rows, cols = grid.shape[:2]
    w = _penalty(smoothing, nu * nv, rows * cols)

    def normal(B, knots, degree):
        inv_h, R = _bending(knots, degree, B.shape[1])
        return (B.T @ B).tocsr() + w * B.shape[0] * inv_h**3 * R

    T = (Bu.T.tocsr() @ grid.reshape(rows, -1)).reshape(nu, cols, 3)                  # (nu, cols, 3)
    T = (Bv.T.tocsr() @ T.transpose(1, 0, 2).reshape(cols, -1)).reshape(nv, nu, 3)    # (nv, nu, 3)
    T = _solve_spd_banded(normal(Bv, kv, q), T.reshape(nv, -1), max(q, 2)).reshape(nv, nu, 3)
    ctrl = _solve_spd_banded(normal(Bu, ku, p), T.transpose(1, 0, 2).reshape(nu, -1), max(p, 2))
    return ctrl.reshape(nu, nv, 3), Bu, Bv


def __getattr__(name):
    """`fit_surface` (the surface refinement loop) lives in `rgm.fitters.freeform_surface`."""
    if name == "fit_surface":
        from rgm.fitters.freeform_surface import fit_surface

        return fit_surface
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
