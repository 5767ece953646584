"""Surface refinement by knot insertion to a tolerance, without chasing noise.

`fit_surface` is the paper's recipe for free-form surfaces (its Figure 5, the face mask): an initial net
whose size comes from a surface characterisation, least-squares control points, and knots inserted in
the middle of only those knot spans whose data exceed the tolerance, until the certified statistic holds
or a stated limit is reached.

Never chasing noise: a span is split only while each half keeps `min_lines` (default 1) data lines (grid
rows or columns; about sqrt(n) scattered points make one line), and the net never exceeds one control
point per `data_per_ctrl` (default 2) data points. Least squares with m coefficients on n points absorbs
a share m/n of pure noise's variance, so at that limit noise of scale sigma keeps an RMS residual of
sigma/sqrt(2) or more: a tolerance below the noise is reported as not met, not met by interpolating the
noise. Detail as fine as the sampling is fitted: on the face scan (3.3-4.4 mm pitch) the net that meets
0.4 mm at its samples is nearer the scanner's own mesh between them (at its cell centres) than the net
stopped at a quarter of the data (tests/fitters/test_freeform_fit.py): it follows the face, it does not
oscillate: the smoothing term is the surface's bending energy (`rgm.fitters.freeform.solve_scattered`),
which decides the control points that a net this dense leaves free.

Residuals (model units) are what the certificate measures, closest-point distances, where it matters:
the parametric residual |S(u_i, v_i) - P_i| bounds a point's distance from above, and where it exceeds
the tolerance a few Gauss-Newton steps from (u_i, v_i) find the foot point (`rgm.fitters.freeform_measure.foot_distances`). Whether
the statistic meets the tolerance is then decided as on the exact distances (each residual stays an upper
bound of its point's distance), and the refinement chases only what is really off the surface, not the
tangential slack of the parameterisation.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError
from rgm.fitters.freeform import (DATA_PER_CTRL, SMOOTHING, Extension, ScatteredBasis, SurfaceFit, _span_index,
                                  _split_candidates, design_matrix, fit_stats, grid_parameters, plane_parameters,
                                  refinement_matrix, solve_grid, solve_scattered, statistic_value)
from rgm.fitters.freeform_measure import foot_distances
from rgm.geometry.knots import uniform_knots

__all__ = ["fit_surface", "initial_net_size"]

#: what a data point's residual may cost (in tol^2) for the continuation where no data are to bend as much as
#: the data do (`Extension.weighed`): small, so the data decide the surface and the continuation only
#: stays as calm as they are
EXTENSION = 0.01
_SAMPLE = 2000   # far points whose foot points tell whether computing all of theirs can decide anything


def initial_net_size(grid: np.ndarray | None, mask, degree: int, n_points: int) -> int:
    """Initial control points per direction from a surface characterisation: the number of geometrically
    homogeneous patches (connected regions of equal sign of mean and Gaussian curvature, estimated on the
    data grid) sets the net size, as in the paper; without a grid, the point count sets a coarse size.
    Either way the initial net keeps eight data points or more per control point. A grid larger than
    256 a side is characterised on every s-th row and column (s = its size / 256, rounded up): the
    patches that count cover 1 % of it, far coarser than that sampling."""
    if grid is None or min(grid.shape[:2]) < 7:
        return degree + 1 + int(np.clip(np.sqrt(n_points) / 40, 0, 6))
    from scipy import ndimage

    step = -(-max(grid.shape[:2]) // 256)
    grid, mask = grid[::step, ::step], None if mask is None else mask[::step, ::step]
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
    size = degree + 1 + int(np.clip(np.ceil(np.sqrt(max(patches, 1))), 1, 12))
    return int(np.clip(np.sqrt(n_points / 8), degree + 1, size))


class _SurfaceProblem:
    """The data of a surface fit and how to solve and measure it on given knot vectors: the separable
    solve for a full grid, the sparse normal equations otherwise. Residuals are per data point."""

    def __init__(self, points, mask, params, degree, smoothing, statistic, anchors=None, closed_u=False,
                 sides=None):
        pts = np.asarray(points, float)
        self.degree, self.smoothing, self.statistic, self.grid = degree, smoothing, statistic, None
        self.anchors, self.closed_u, self._extension = anchors, closed_u, None
        if (anchors is not None or closed_u or sides is not None) and pts.ndim == 3:
            raise GeometryError("anchor points, closed nets and sides need scattered data (a grid is solved "
                                "separably)")
        if pts.ndim == 3:
            valid = np.isfinite(pts).all(axis=2)
            mask = valid if mask is None else (np.asarray(mask, bool) & valid)
            if mask.sum() < (degree + 1) ** 2:
                raise GeometryError("too few valid grid points to fit a surface")
            self.ug, self.vg = grid_parameters(np.where(mask[..., None], pts, 0.0), mask) if params is None else params
            self.mask = mask
            ii, jj = np.nonzero(mask)
            self.u, self.v, self.data = self.ug[ii], self.vg[jj], pts[ii, jj]
            self.lines = (ii, jj)
            self.grid = pts if mask.all() else None
            self.planes = None if self.grid is None else [np.ascontiguousarray(pts[..., k]) for k in range(3)]
            self.shape = pts.shape[:2]
            self.char = (pts, mask)
        else:
            if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < (degree + 1) ** 2:
                raise GeometryError(f"need at least {(degree + 1) ** 2} points (n, 3) to fit a surface")
            if not np.isfinite(pts).all():
                raise GeometryError("points contain NaN or infinite coordinates")
            self.u, self.v = plane_parameters(pts)[:2] if params is None else map(np.asarray, params)
            self.data = pts
            self.lines = None
            self.char = (None, None)
        self.extended = pts.ndim == 2   # a range image's cells are its data: no continuation to hold
        self.sides = [np.arange(len(self.data))] if sides is None else \
            [np.flatnonzero(np.asarray(sides) == side) for side in np.unique(sides)]

    def extension(self, ku, kv, tol: float) -> Extension | None:
        """The `Extension` of scattered data (None for a range grid, or once `extended` is switched off),
        weighed at tolerance `tol` against the surface fitted without it on the first knot vectors asked
        for (`Extension.weighed`, share EXTENSION), then kept for the whole refinement: one weight, so
        knot insertion compares like with like."""
        if not self.extended:
            return None
        if self._extension is None or self._extension[0] != tol:
            ext = Extension.of(self.u, self.v)
            if len(ext.uv):
                p = self.degree
                plain = solve_scattered(self.u, self.v, self.data, ku, kv, p, p, self.smoothing, self.anchors,
                                        self.closed_u)[0]
                ext = ext.weighed(plain, ku, kv, p, p, tol, EXTENSION)
            self._extension = (tol, ext)
        return self._extension[1]

    def anchors_met(self, ku, kv, ctrl) -> bool:
        """Whether the anchors (if refined for: `Anchors.tol`) are within their tolerance at p95."""
        a = self.anchors
        if a is None or a.tol is None:
            return True
        return float(np.percentile(a.residuals(ku, kv, self.degree, self.degree, ctrl), 95)) <= a.tol

    def solve(self, ku, kv, tol):
        """Control net (nu, nv, 3) and residuals (n,) on the knot vectors ku, kv (`residuals`)."""
        p = self.degree
        if self.grid is not None:
            ctrl = solve_grid(self.ug, self.vg, self.grid, ku, kv, p, p, self.smoothing)[0]
        else:
            ctrl = solve_scattered(self.u, self.v, self.data, ku, kv, p, p, self.smoothing, self.anchors,
                                   self.closed_u, self.extension(ku, kv, tol))[0]
        return ctrl, self.residuals(ku, kv, ctrl, tol)

    def residuals(self, ku, kv, ctrl, tol):
        """(n,) parametric residuals, replaced by foot-point distances where they exceed `tol` when that
        can decide whether the statistic holds: not when few enough exceed it already, nor when the foot
        points of a sample of them (`_SAMPLE`) leave too many above it still (the net is refined
        either way, and the parametric residuals, upper bounds, show where)."""
        p = self.degree
        if self.grid is not None:
            Bu, Bv = design_matrix(self.ug, ku, p), design_matrix(self.vg, kv, p)
            res = _grid_distance(Bu, Bv, ctrl, self.planes)
        else:
            res = np.linalg.norm(ScatteredBasis.build(self.u, self.v, ku, kv, p, p).evaluate(ctrl) - self.data, axis=1)
        far = np.flatnonzero(res > tol)
        share = 0.0 if self.statistic == "max" else 1 - float(self.statistic[1:]) / 100
        allowed = int(share * (len(res) - 1))
        if all(np.count_nonzero(res[side] > tol) <= int(share * (len(side) - 1)) for side in self.sides):
            return res
        from rgm.geometry import NurbsSurface

        surface = NurbsSurface(p, p, ku, kv, ctrl, None)

        def feet(idx):
            return foot_distances(surface, np.c_[self.u[idx], self.v[idx]], self.data[idx], res[idx], self.within_data)

        if len(far) > _SAMPLE:
            probe = far[:: len(far) // _SAMPLE]
            if np.mean(feet(probe) > tol) * len(far) > 1.5 * allowed + 1:
                return res
        res[far] = feet(far)
        return res

    def value(self, res: np.ndarray) -> float:
        """The statistic of the residuals (n,) that decides whether the fit holds: on each side's own points,
        the worst side's."""
        return max(statistic_value(res[side], self.statistic) for side in self.sides)

    def within_data(self, uv: np.ndarray) -> np.ndarray:
        """(k,) bool: parameters uv (k, 2) in the pixel of some data point (within half a data spacing of
        its parameters along u and along v): inside the data's region, whose pixel contour the trimming
        loops follow (a foot point beyond it would be trimmed away: the certificate does not measure to it).
        A grid looks the pixel up; scattered data ask a k-d tree of their parameters."""
        if self.lines is not None:
            inside = np.ones(len(uv), bool)
            index = []
            for t, x in zip((self.ug, self.vg), uv.T):
                half = 0.5 * np.diff(t)
                edges = np.r_[t[0] - half[0], t[:-1] + half, t[-1] + half[-1]]   # pixel borders
                i = np.searchsorted(edges, x, side="right") - 1
                inside &= (i >= 0) & (i < len(t))
                index.append(np.clip(i, 0, len(t) - 1))
            return inside & self.mask[index[0], index[1]]
        if not hasattr(self, "_tree"):
            from scipy.spatial import cKDTree

            uv0 = np.c_[self.u, self.v]
            self._scale = 1.0 / max(float(np.median(cKDTree(uv0).query(uv0, k=2)[0][:, 1])), 1e-300)
            self._tree = cKDTree(uv0 * self._scale)
        return self._tree.query(uv * self._scale, p=np.inf, distance_upper_bound=0.5)[0] <= 0.5

    def worst_per_direction(self, res):
        """(params_u, worst_u, params_v, worst_v): each data line's worst residual for the span search
        (a grid's rows and columns that hold data; every point of scattered data)."""
        if self.grid is not None:
            r = res.reshape(self.shape)
            return self.ug, r.max(axis=1), self.vg, r.max(axis=0)
        if self.lines is not None:
            out = []
            for line, params in zip(self.lines, (self.ug, self.vg)):
                worst = np.full(len(params), -1.0)
                np.maximum.at(worst, line, res)
                out += [params[worst >= 0], worst[worst >= 0]]
            return tuple(out)
        return self.u, res, self.v, res

    def per_line(self) -> float:
        """Parameters in `worst_per_direction` per data line: 1 for a grid; sqrt(n) for n scattered
        points (about sqrt(n) points lie along a line across them)."""
        return 1.0 if self.lines is not None else float(np.sqrt(len(self.data)))


def fit_surface(points, tol: float, *, mask=None, params=None, degree: int = 3,
                n_initial: int | None = None, max_ctrl: int = 40000, statistic: str = "max",
                smoothing: float = SMOOTHING, prune: int = 8, min_lines: float = 1.0,
                data_per_ctrl: float = DATA_PER_CTRL, anchors=None, closed_u: bool = False, sides=None) -> SurfaceFit:
    """Least-squares bicubic (by default) B-spline surface of `points` refined by knot insertion.

    points: (n, 3) scattered points, or a grid (rows, cols, 3) with optional `mask` (rows, cols) of valid
        cells (a range image keeps its grid: the grid gives the parameterisation).
    params: optional parameters (u, v): per grid row and column for a grid, per point otherwise.
    tol: tolerance in model units for the `statistic` ("max", or "p99" etc. for scans whose noise makes
        a maximum meaningless) of the parametric residuals.
    smoothing: the weight per data point of the surface's bending energy at the approximation limit
        (`rgm.fitters.freeform.solve_scattered`: coarser nets get less).
    anchors: optional `rgm.fitters.freeform.Anchors` for scattered data: points the surface is pulled
        through at fixed parameters by a weighted penalty in every solve (`solve_scattered`); they are
        not data, and the residuals and the certificate are the data's alone. With `Anchors.tol`, the
        spans whose anchors are missed by more are refined too (within the same limits), and the
        refinement goes on until both hold; the bisection and the pruning keep both.
    sides: optional labels (n,) of scattered points (two patches fitted as one, `rgm.fitters.patch_merge`):
        the statistic must hold on each side's points on its own, or a narrow side would hide among the
        other's (5 % of the points may lie anywhere at p95); the certificate is still the whole's.
    closed_u: scattered data only: u is an angle round a closed wrap, u = 0 and u = 1 the same points; every
        net is closed C1 across them (`rgm.fitters.freeform.closure_u`), knot insertion keeping it so.
    Refinement stops when the statistic is met; when every span that exceeds the tolerance holds fewer
    than 2 `min_lines` data lines, and so do the spans within `degree` of it, or the net would exceed one control point per `data_per_ctrl` data
    points (see the module docstring); or when the net would exceed `max_ctrl` (the last step then
    inserts the worst of its knots that stay within the limit).
    `SurfaceFit.stopped` says which, and `stats.holds` is False then. Once the tolerance holds, the last
    insertion step is bisected (the fewest of its knots, worst spans first, that still meet it); then
    knots whose neighbourhood is far inside the tolerance are removed in one batch, and up to `prune`
    single knots, quietest first, each only when the fit still holds without it.
    Scattered data are fitted with their `Extension`: where the unit parameter
    square has no data the surface is held to bend no more than over its data, so a patch that reaches
    past its data continues it calmly instead of as its noise extrapolates. Where that fit misses the
    tolerance, the fit without it is tried and kept if it holds or comes closer: the extension never
    costs a certificate.
    """
    prob = _SurfaceProblem(points, mask, params, degree, smoothing, statistic, anchors, closed_u, sides)
    fit = _refine(prob, tol, n_initial, max_ctrl, statistic, prune, min_lines, data_per_ctrl)
    if not fit.stats.holds and prob.extended:
        prob.extended = False
        plain = _refine(prob, tol, n_initial, max_ctrl, statistic, prune, min_lines, data_per_ctrl)
        if plain.stats.holds or plain.stats.value < fit.stats.value:
            fit = plain
    return fit


def _refine(prob, tol, n_initial, max_ctrl, statistic, prune, min_lines, data_per_ctrl) -> SurfaceFit:
    """The refinement of `fit_surface` on one problem: knot insertion from the initial net until the
    statistic holds or a limit stops it, then bisection of the last step and pruning."""
    degree = prob.degree
    limit = max((degree + 1) ** 2, int(len(prob.data) / data_per_ctrl))
    ku = kv = uniform_knots(degree, n_initial or initial_net_size(*prob.char, degree, len(prob.data)))
    prev, history, stopped, step, final = None, [], "", None, ""
    while True:
        ctrl, res = prob.solve(ku, kv, tol)
        value = prob.value(res)
        if prev is not None and value > prev[3] and prob.anchors is None:  # keep the refined previous shape
            ctrl = np.einsum("ia,abd,jb->ijd", refinement_matrix(prev[1], ku, degree), prev[0],
                             refinement_matrix(prev[2], kv, degree), optimize=True)
            res = prob.residuals(ku, kv, ctrl, tol)
            value = prob.value(res)
        history.append((ctrl.shape[0] * ctrl.shape[1], value))
        met = prob.anchors_met(ku, kv, ctrl)
        if (value <= tol and met) or final:
            stopped = "" if value <= tol else final
            break
        pu, wu, pv, wv = prob.worst_per_direction(res)
        if not met:   # the anchors' spans too, their residuals scaled to the data's tolerance
            a = prob.anchors
            excess = a.residuals(ku, kv, degree, degree, ctrl) * (tol / a.tol)
            pu, wu, pv, wv = np.r_[pu, a.uv[:, 0]], np.r_[wu, excess], np.r_[pv, a.uv[:, 1]], np.r_[wv, excess]
        greed = 0.5 if value > 4 * tol else 0.8  # near the goal, split only the worst spans
        lines = min_lines * prob.per_line()
        step = (_split_candidates(pu, wu, ku, degree, tol, lines, greed),
                _split_candidates(pv, wv, kv, degree, tol, lines, greed))
        new_u, new_v = step[0][0], step[1][0]
        if len(new_u) + len(new_v) == 0:
            stopped = (f"approximation limit reached: every knot span whose error exceeds the tolerance, and "
                       f"every span beside it, holds fewer than {2 * min_lines:g} data lines, and a finer net would interpolate the samples "
                       f"and their noise")
            break
        cap = min(max_ctrl, limit)
        if (ctrl.shape[0] + len(new_u)) * (ctrl.shape[1] + len(new_v)) > cap:
            # the last step: the worst of its knots that the limit leaves room for
            final = (f"control-net limit {max_ctrl} reached" if max_ctrl <= limit else
                     f"approximation limit reached: the net would exceed one control point per "
                     f"{data_per_ctrl:g} of the {len(prob.data)} data points")
            step = _within(step, ctrl.shape[:2], cap)
            new_u, new_v = step[0][0], step[1][0]
            if len(new_u) + len(new_v) == 0:
                stopped = final
                break
        prev = (ctrl, ku, kv, value)
        ku, kv = np.sort(np.r_[ku, new_u]), np.sort(np.r_[kv, new_v])
    if value <= tol and prev is not None:
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
            ctrl2, res2 = prob.solve(ku2, kv2, tol)
            value2 = prob.value(res2)
            if value2 <= tol and prob.anchors_met(ku2, kv2, ctrl2):
                hi = mid
                ku, kv, ctrl, res, value = ku2, kv2, ctrl2, res2, value2
            else:
                lo = mid
    if value <= tol and prune:
        ku, kv, ctrl, res = _prune(prob, ku, kv, ctrl, res, tol, statistic, prune)
    return SurfaceFit(degree, degree, ku, kv, ctrl, fit_stats(res, tol, statistic), res, tuple(history), stopped)


def _within(step, shape, cap):
    """The candidate knots of a refinement step ((u midpoints, scores), (v midpoints, scores)), worst
    first, that a net of `shape` (nu, nv) takes while it keeps at most `cap` control points."""
    (cu, eu), (cv, ev) = step
    nu, nv = shape
    keep_u, keep_v = [], []
    for i in np.argsort(-np.r_[eu, ev], kind="stable"):
        if i < len(cu) and (nu + len(keep_u) + 1) * (nv + len(keep_v)) <= cap:
            keep_u.append(i)
        elif i >= len(cu) and (nu + len(keep_u)) * (nv + len(keep_v) + 1) <= cap:
            keep_v.append(i - len(cu))
    return (cu[keep_u], eu[keep_u]), (cv[keep_v], ev[keep_v])


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


def _prune(prob, ku, kv, ctrl, res, tol, statistic, attempts, slack=0.4):
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
        ctrl2, res2 = prob.solve(ku2, kv2, tol)
        if prob.value(res2) <= tol and prob.anchors_met(ku2, kv2, ctrl2):
            ku, kv, ctrl, res = ku2, kv2, ctrl2, res2
    return ku, kv, ctrl, res


def _grid_distance(Bu, Bv, ctrl, planes):
    """|S(u_i, v_j) - P_ij| (rows * cols,) on the data grid from the sparse design matrices Bu (rows, nu),
    Bv (cols, nv): per coordinate Bu (Bv C_k')' - P_k, squared and summed in place. Sparse products (p+1
    non-zeros a row) do a quarter of a dense product's work and no multithreaded BLAS call, which on a
    loaded machine costs ten times more than it saves."""
    total = None
    for k in range(3):
        d = Bu @ (Bv @ ctrl[:, :, k].T).T
        d -= planes[k]
        np.square(d, out=d)
        total = d if total is None else np.add(total, d, out=total)
    return np.sqrt(total, out=total).ravel()

