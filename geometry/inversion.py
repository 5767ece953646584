"""Point inversion: the closest point of a curve or surface to many query points at once.

Piegl & Tiller §6.1 (A6.x): a robust start from sampling, then Newton iteration on the
stationarity condition C'(u)·(C(u) - P) = 0 (curves) or S_u·r = S_v·r = 0 with r = S - P
(surfaces). Here the iteration is a bounded, damped Newton method run on all (point, start) pairs
as arrays:

- starts: several per point, from different basins of the sampled distance (local minima of the
  distance over the samples), and the best converged answer is kept. The sample grids adapt to
  the geometry: each knot span gets samples in proportion to its control polygon's length;
- pieces: where the curve or surface is only C0 (a knot of multiplicity >= p, e.g. polyline
  vertices) each start is confined to its smooth piece, and the sample at a kink is repeated on
  both sides, so minima on either side of a kink are reached with the right one-sided derivatives;
- step: Newton on the squared distance when its Hessian is positive definite, otherwise the
  Gauss–Newton matrix, damped Levenberg–Marquardt style;
- bounds: coordinates sitting on the domain boundary whose gradient points outward are frozen
  (an active set), the rest move; every step is clamped to the domain;
- damping: a step that does not reduce the distance is rejected and the damping raised, so the
  distance never increases and minima on the boundary are found too;
- global check: a surface of several smooth pieces (C0 knots: a revolution's quarter circles and its
  profile's corners, where the starts of one piece can miss another, and near a pole every piece's
  samples tie), or a rational net whose weights vary by more than WEIGHT_SPREAD (crowding its surface
  into stretches no sampling sees), has its answers made global by branch and bound on its Bézier
  patches' control boxes (`_branch_and_bound`; on such nets up to 3.5x the time of the sampled search).
"""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError

__all__ = ["closest_point_curve", "closest_point_surface", "distance_bound_surface", "gauss_newton_step"]

SEEDS = 6          # Newton starts per query point (surfaces: 4 basins + 2 nearest)
COARSE, FINE = 40, 240   # samples per direction (about) of the surface seed grids
MAX_ITER = 60
WEIGHT_SPREAD = 2.0   # rational nets whose weights vary more than this get the branch and bound


def _queries(points, dim):
    try:
        points = np.atleast_2d(np.asarray(points, dtype=float))
    except (TypeError, ValueError):
        raise GeometryError("query points must be numbers") from None
    if points.ndim != 2 or points.shape[1] != dim or not np.all(np.isfinite(points)):
        raise GeometryError(f"query points must be a finite (k, {dim}) array, got shape {points.shape}")
    return points


def _samples(knots, degree, n, polygon, budget=600):
    """Sample parameters adapted to the geometry, and the C0 breakpoints.

    polygon : (n-1,) lengths of the control polygon legs (for a surface direction, the largest over
    the other direction). A span gets between 2p+2 and 64 samples, about one per 1/64 of the whole
    polygon's length; the total is kept near `budget` (at least 1 per span). Returns (params (s,), breaks (b,)) where breaks
    are the domain ends and the C0 knots, and every interior C0 knot also appears once more just
    below itself, so that both one-sided pieces get a start there.
    """
    values, counts = np.unique(knots[degree:n + 1], return_counts=True)
    first = np.searchsorted(knots, values[:-1], side="right") - 1             # span index per span
    cumulative = np.r_[0.0, np.cumsum(polygon)]
    span_length = cumulative[first] - cumulative[first - degree]
    total = max(float(cumulative[-1]), 1e-300)
    per_span = np.clip(np.ceil(64 * span_length / total), 2 * degree + 2, 64).astype(int)
    per_span = np.maximum(per_span * min(1.0, budget / per_span.sum()), 1).astype(int)
    step = np.arange(per_span.sum()) - np.repeat(np.cumsum(per_span) - per_span, per_span)   # 0..c-1 per span
    params = np.repeat(values[:-1], per_span) + np.repeat(np.diff(values), per_span) * step / \
        np.repeat(per_span, per_span)
    kinks = values[1:-1][counts[1:-1] >= degree]
    breaks = np.r_[values[0], kinks, values[-1]]
    below = np.nextafter(kinks, -np.inf)
    return np.sort(np.concatenate([params, below, values[-1:]])), breaks


def _piece_bounds(t, breaks):
    """Bounds (lo, hi) of the smooth piece holding each parameter t; an interior right end is
    moved just below its knot so that evaluation there uses the left piece's derivatives."""
    idx = np.clip(np.searchsorted(breaks, t, side="right") - 1, 0, breaks.size - 2)
    hi = breaks[idx + 1]
    hi = np.where(idx + 1 < breaks.size - 1, np.nextafter(hi, -np.inf), hi)
    return breaks[idx], hi


def _chords(grid, axis):
    """(s-1,) chord lengths between consecutive rows (axis 0) or columns (axis 1) of an evaluated
    grid (a, b, 3), the largest across the other direction."""
    legs = np.linalg.norm(np.diff(grid, axis=axis), axis=-1)
    return legs.max(axis=1 - axis)


def _by_chord(coarse, chords, fine, breaks):
    """Fine sample parameters: as many as `fine` (the control polygon's adapted samples), half of them
    as they are and half spread uniformly in the chord length measured on the `coarse` samples, with
    the domain's ends, its kinks (the interior `breaks`) and their one-sided copies. A rational net's
    weights can crowd much of the surface into a short stretch of parameter that its control polygon
    does not show; the chords do, and the stretch gets its share of samples."""
    length = np.r_[0.0, np.cumsum(chords)]
    if length[-1] <= 0:
        return fine
    spread = np.interp(np.linspace(0.0, length[-1], max(fine.size // 2, 2)), length, coarse)
    kinks = breaks[1:-1]
    return np.unique(np.r_[fine[::2], spread, breaks, np.nextafter(kinks, -np.inf)])


def _polygon(ctrl, axis):
    """Control polygon leg lengths along `axis` of a net, maximised over the other axes: (n-1,)."""
    legs = np.moveaxis(np.linalg.norm(np.diff(ctrl, axis=axis), axis=-1), axis, 0)
    return legs.reshape(legs.shape[0], -1).max(axis=1)


def _nearest_seeds(sample_points, neighbours, queries, count, candidates=32):
    """Indices (k, count) of close samples to every query point: among its `candidates` nearest
    (k-d tree), the local minima of the distance (no grid neighbour closer) first, best first."""
    from scipy.spatial import cKDTree

    near = min(candidates, sample_points.shape[0])
    dist, index = cKDTree(sample_points).query(queries, k=near)
    dist, index = dist.reshape(-1, near), index.reshape(-1, near)
    around = np.linalg.norm(sample_points[neighbours[index]] - queries[:, None, None, :], axis=-1)
    is_min = np.all(around >= dist[..., None] * (1 - 1e-9), axis=-1)
    order = np.argsort(np.where(is_min, dist, dist + np.inf), axis=1, kind="stable")[:, :min(count, near)]
    return np.take_along_axis(index, order, 1)


def _local_minimum_seeds(sample_points, shape, queries, count):
    """Indices (k, count) of samples that are local minima of the distance to each query (no
    grid neighbour is closer), best first; one start per basin of the sampled distance function.

    shape : (a, b), the samples being an a x b grid flattened row-major (a curve's: (n, 1)); the
    neighbours are the four across the grid lines (`_grid_neighbours`), compared as shifted views of
    the distances rather than gathered. Distances are computed in blocks of queries, so memory stays
    bounded; the cost is k x s.
    """
    s = sample_points.shape[0]
    count = min(count, s)
    out = np.empty((queries.shape[0], count), dtype=int)
    block = max(1, (1 << 21) // s)
    for start in range(0, queries.shape[0], block):
        q = queries[start:start + block]
        d2 = np.einsum("qsd,qsd->qs", *(2 * [sample_points[None] - q[:, None]]))
        # ties count as minima, so the two copies of a kink sample (one per side) both qualify; a
        # sample on the grid's edge has itself as its neighbour beyond it, which never disqualifies
        g = d2.reshape(len(q), *shape)
        floor = g * (1 - 1e-9)
        is_min = np.ones(g.shape, bool)
        is_min[:, 1:] &= g[:, :-1] >= floor[:, 1:]
        is_min[:, :-1] &= g[:, 1:] >= floor[:, :-1]
        is_min[:, :, 1:] &= g[:, :, :-1] >= floor[:, :, 1:]
        is_min[:, :, :-1] &= g[:, :, 1:] >= floor[:, :, :-1]
        key = np.where(is_min.reshape(len(q), s), d2, np.inf)
        best = np.argpartition(key, count - 1, axis=1)[:, :count]
        order = np.argsort(np.take_along_axis(key, best, 1), axis=1)
        best = np.take_along_axis(best, order, 1)
        # fewer basins than `count`: repeat the best one
        missing = ~np.isfinite(np.take_along_axis(key, best, 1))
        out[start:start + block] = np.where(missing, best[:, :1], best)
    return out


def _grid_neighbours(a, b):
    """Neighbour indices (a*b, 4) on an a x b grid flattened row-major (edges point to themselves)."""
    i, j = np.divmod(np.arange(a * b), b)
    return np.stack([np.maximum(i - 1, 0) * b + j, np.minimum(i + 1, a - 1) * b + j,
                     i * b + np.maximum(j - 1, 0), i * b + np.minimum(j + 1, b - 1)], axis=1)


def _newton(evaluate, x, lo, hi, target):
    """Bounded, damped Newton minimisation of |F(x) - target|^2 for many starts at once.

    evaluate(x (N, k)) -> (F (N, d), J (N, d, k), H (N, d, k, k)): value, first and second
    derivatives. x : (N, k) starts; lo, hi : (N, k) bounds per start; target : (N, d).
    Returns (x (N, k), dist (N,), F (N, d)).

    Levenberg–Marquardt damping: the step solves (M + λ diag(JᵀJ)) s = -g, with M the Newton
    Hessian where positive definite, else JᵀJ; λ shrinks after a step that lowers the distance and
    grows after one that does not (which is then rejected). Strongly anisotropic
    parameterisations (a short knot span beside a long one) converge without line searches.
    """
    x = np.clip(x, lo, hi)
    f, jac, hess = evaluate(x)
    dist2 = np.einsum("nd,nd->n", f - target, f - target)
    lam = np.full(x.shape[0], 1e-3)
    active = np.arange(x.shape[0])
    tiny = 1e-14 * np.maximum(hi - lo, 1e-300)
    eye = np.eye(x.shape[1])
    for _ in range(MAX_ITER):
        if active.size == 0:
            break
        xa, ja, la, ha = x[active], jac[active], lo[active], hi[active]
        r = f[active] - target[active]
        grad = np.einsum("ndk,nd->nk", ja, r)
        gauss = np.einsum("ndk,ndl->nkl", ja, ja)
        newton = gauss + np.einsum("ndkl,nd->nkl", hess[active], r)
        frozen = ((xa <= la) & (grad > 0)) | ((xa >= ha) & (grad < 0))
        free = (~frozen).astype(float)
        mask = free[:, :, None] * free[:, None, :]
        pinned = eye * (1.0 - free)[:, None, :]
        step = _solve(newton * mask + pinned, gauss * mask + pinned, grad * free, lam[active])
        moved = np.clip(xa + step, la, ha) - xa
        tf, tj, th = evaluate(xa + moved)
        td = np.einsum("nd,nd->n", tf - target[active], tf - target[active])
        ok = td <= dist2[active]
        accepted = active[ok]
        x[accepted], f[accepted], jac[accepted], hess[accepted] = xa[ok] + moved[ok], tf[ok], tj[ok], th[ok]
        dist2[accepted] = td[ok]
        lam[active] = np.where(ok, lam[active] * 0.3, lam[active] * 10.0)
        small = np.all(np.abs(moved) <= tiny[active], axis=1)
        active = active[~small & (lam[active] < 1e12)]
    return x, np.sqrt(dist2), f


def _solve(newton, gauss, grad, lam):
    """Marquardt step s = -(M + λ diag(JᵀJ))⁻¹ g, M the Newton matrix where positive definite and
    JᵀJ elsewhere; a tiny ridge keeps degenerate parameterisations (surface poles) solvable."""
    def positive(m):
        if m.shape[1] == 1:
            return m[:, 0, 0] > 0
        return (m[:, 0, 0] > 0) & (np.linalg.det(m) > 0)
    base = np.where(positive(newton)[:, None, None], newton, gauss)
    diag = np.einsum("nkk->nk", gauss)
    scale = 1e-12 * np.maximum(diag.max(axis=1, keepdims=True), 1e-300)
    damping = (lam[:, None] * diag + scale)[:, :, None] * np.eye(grad.shape[1])
    return -np.linalg.solve(base + damping, grad[..., None])[..., 0]


def _best(queries, x, dist, f, count):
    """Among the `count` starts of every query pick the closest converged point."""
    k = queries.shape[0]
    choice = np.argmin(dist.reshape(k, count), axis=1)
    flat = np.arange(k) * count + choice
    return x[flat], f[flat], dist[flat]


def closest_point_curve(curve, points):
    """Closest points of `curve` to `points (k, d)`: returns (u (k,), pts (k, d), dist (k,)).

    Starts: the best local minima of the distance over the geometry-adapted samples (one per
    basin), then the bounded damped Newton iteration, each start confined to its smooth piece.
    """
    queries = _queries(points, curve.dim)
    params, breaks = _samples(curve.knots, curve.degree, curve.n, _polygon(curve.ctrl, 0))
    seeds = _local_minimum_seeds(curve.evaluate(params), (params.size, 1), queries, SEEDS)
    count = seeds.shape[1]
    x0 = params[seeds].reshape(-1, 1)
    lo, hi = _piece_bounds(x0, breaks)
    target = np.repeat(queries, count, axis=0)

    def evaluate(x):
        d = curve.derivatives(x[:, 0], 2)
        return d[0], d[1][:, :, None], d[2][:, :, None, None]

    x, dist, f = _newton(evaluate, x0, lo, hi, target)
    u, pts, dist = _best(queries, x, dist, f, count)
    return u[:, 0], pts, dist


def closest_point_surface(surface, points):
    """Closest points of `surface` to `points (k, 3)`: (u (k,), v (k,), pts (k, 3), dist (k,)).

    Starts: the basins (local minima) of the distance sampled on a coarse geometry-adapted grid,
    and the local minima among the nearest samples of a fine grid, half of whose samples are spread by
    the coarse grid's chord lengths (`_by_chord`); then the bounded damped Newton iteration, each start
    confined to its smooth patch.
    """
    queries = _queries(points, 3)
    dirs = ((surface.knots_u, surface.degree_u, surface.nu, _polygon(surface.ctrl, 0)),
            (surface.knots_v, surface.degree_v, surface.nv, _polygon(surface.ctrl, 1)))
    (cu, bu), (cv, bv) = (_samples(*d, COARSE) for d in dirs)
    coarse = surface.evaluate_grid(cu, cv)
    fu, fv = (_by_chord(t, _chords(coarse, axis), _samples(*dirs[axis], FINE)[0], b)
              for axis, (t, b) in enumerate(((cu, bu), (cv, bv))))
    coarse, fine = coarse.reshape(-1, 3), surface.evaluate_grid(fu, fv).reshape(-1, 3)
    basins = _local_minimum_seeds(coarse, (cu.size, cv.size), queries, SEEDS - 2)
    nearest = _nearest_seeds(fine, _grid_neighbours(fu.size, fv.size), queries, SEEDS - basins.shape[1])
    x0 = np.concatenate([np.stack([cu[basins // cv.size], cv[basins % cv.size]], axis=-1),
                         np.stack([fu[nearest // fv.size], fv[nearest % fv.size]], axis=-1)], axis=1)
    count = x0.shape[1]
    x0 = x0.reshape(-1, 2)
    (lo_u, hi_u), (lo_v, hi_v) = _piece_bounds(x0[:, 0], bu), _piece_bounds(x0[:, 1], bv)
    lo, hi = np.stack([lo_u, lo_v], axis=1), np.stack([hi_u, hi_v], axis=1)
    target = np.repeat(queries, count, axis=0)

    def evaluate(x):
        d = surface.derivatives(x[:, 0], x[:, 1], 2)
        jac = np.stack([d[1, 0], d[0, 1]], axis=-1)
        hess = np.stack([np.stack([d[2, 0], d[1, 1]], -1), np.stack([d[1, 1], d[0, 2]], -1)], -2)
        return d[0, 0], jac, hess

    x, dist, f = _newton(evaluate, x0, lo, hi, target)
    uv, pts, dist = _best(queries, x, dist, f, count)
    kinked = len(bu) > 2 or len(bv) > 2      # C0 knots: pieces the starts may miss (a revolution's quarters)
    if kinked or (surface.is_rational and surface.weights.max() > WEIGHT_SPREAD * surface.weights.min()):
        uv, pts, dist = _branch_and_bound(surface, evaluate, queries, uv, pts, dist)
    return uv[:, 0], uv[:, 1], pts, dist


def _bezier_patches(surface):
    """The surface's Bézier patches: homogeneous nets (B, p+1, q+1, 4) and parameter rectangles (B, 2, 2)
    ([[u0, v0], [u1, v1]]), by inserting every interior knot up to its degree."""
    out = surface
    for direction, p in (("u", surface.degree_u), ("v", surface.degree_v)):
        knots = out.knots_u if direction == "u" else out.knots_v
        values, counts = np.unique(knots, return_counts=True)
        add = np.repeat(values[1:-1], np.maximum(p - counts[1:-1], 0))
        if len(add):
            out = out.refine(direction, add)
    p, q = out.degree_u, out.degree_v
    bu, bv = np.unique(out.knots_u), np.unique(out.knots_v)
    h = out.homogeneous
    nets = np.stack([h[i * p:i * p + p + 1, j * q:j * q + q + 1] for i in range(len(bu) - 1) for j in range(len(bv) - 1)])
    rects = np.array([[[bu[i], bv[j]], [bu[i + 1], bv[j + 1]]] for i in range(len(bu) - 1) for j in range(len(bv) - 1)])
    return nets, rects


def _halves(nets, axis):
    """de Casteljau at the middle along `axis` (1: u, 2: v) of Bézier nets (P, p+1, q+1, 4): (first, second)."""
    cur = np.moveaxis(nets, axis, 0)
    first, second = [cur[0]], [cur[-1]]
    while len(cur) > 1:
        cur = 0.5 * (cur[:-1] + cur[1:])
        first.append(cur[0])
        second.append(cur[-1])
    return np.moveaxis(np.stack(first), 0, axis), np.moveaxis(np.stack(second[::-1]), 0, axis)


def _box_distance(lo, hi, x):
    """Distances from points x (..., 3) to axis-aligned boxes [lo, hi] (..., 3) (0 inside), broadcast."""
    return np.linalg.norm(np.maximum(lo - x, 0) + np.maximum(x - hi, 0), axis=-1)


def _nearest_per_query(qi, d):
    """Indices of the least `d` among the entries of each query index in `qi` (one per query present)."""
    order = np.lexsort((d, qi))
    return order[np.r_[True, qi[order][1:] != qi[order][:-1]]] if len(order) else order


def _branch_and_bound(surface, evaluate, queries, uv, pts, dist, levels: int = 10, keep: int = 8):
    """The answers (uv (k, 2), pts (k, 3), dist (k,)) made global by branch and bound on the Bézier
    patches: a patch lies in the box of its control points (positive weights: the convex hull
    property), so one whose box is not nearer a query than its best answer holds no nearer point. The
    patches whose boxes are nearer are halved both ways (de Casteljau), `levels` times, the answer
    tightened by their corners (points of the surface) and the `keep` nearest boxes of each query kept;
    a Newton start from the middle of each, confined to its Bézier patch, then gives the answer. Rational
    nets whose weights vary much crowd their surface into stretches of parameter (dips 0.002 wide) that
    no sampling spread by the net sees; the boxes see them. No queries: nothing to tighten."""
    if not len(queries):
        return uv, pts, dist
    nets, rects = _bezier_patches(surface)
    euclid = nets[..., :3] / nets[..., 3:]
    size = float(np.linalg.norm(euclid.reshape(-1, 3).max(axis=0) - euclid.reshape(-1, 3).min(axis=0))) or 1.0
    eps = 1e-9 * size
    lo_box, hi_box = euclid.min(axis=(1, 2)), euclid.max(axis=(1, 2))
    found = []                       # the (query, patch) pairs whose patch's box is nearer than the answer
    step = max(1, (1 << 22) // (3 * len(nets)))
    for start in range(0, len(queries), step):
        x = queries[start:start + step, None]
        a, b = np.nonzero(_box_distance(lo_box[None], hi_box[None], x) < dist[start:start + step, None] - eps)
        found.append((a + start, b))
    qi, pi = np.concatenate([a for a, _ in found]), np.concatenate([b for _, b in found])
    home = rects[pi]                                                        # each pair's Bézier patch
    cur, box = nets[pi], rects[pi]

    for level in range(levels + 1):
        e = cur[..., :3] / cur[..., 3:]
        lower = _box_distance(e.min(axis=(1, 2)), e.max(axis=(1, 2)), queries[qi])
        corners = e[:, [0, -1, 0, -1], [0, 0, -1, -1]]                       # (P, 4, 3) points on the surface
        cd = np.linalg.norm(corners - queries[qi][:, None], axis=2)
        c_uv = np.stack([box[:, [0, 1, 0, 1], 0], box[:, [0, 0, 1, 1], 1]], axis=2)   # (P, 4, 2)
        j = cd.argmin(axis=1)
        cdj = cd[np.arange(len(cd)), j]
        first = _nearest_per_query(qi, cdj)
        win = first[cdj[first] < dist[qi[first]]]
        uv[qi[win]], pts[qi[win]], dist[qi[win]] = c_uv[win, j[win]], corners[win, j[win]], cdj[win]
        live = lower < dist[qi] - eps
        qi, cur, box, home, lower = qi[live], cur[live], box[live], home[live], lower[live]
        if len(qi) == 0:
            return uv, pts, dist
        order = np.lexsort((lower, qi))                                       # each query's `keep` nearest
        rank = np.arange(len(order)) - np.searchsorted(qi[order], qi[order])
        pick = order[rank < keep]
        qi, cur, box, home = qi[pick], cur[pick], box[pick], home[pick]
        if level == levels:
            break
        mid = 0.5 * (box[:, 0] + box[:, 1])
        halves, boxes = [], []
        for side_u, half_u in enumerate(_halves(cur, 1)):
            for side_v, half in enumerate(_halves(half_u, 2)):
                second = np.array([side_u, side_v], bool)          # the second half along u, along v
                halves.append(half)
                boxes.append(np.stack([np.where(second, mid, box[:, 0]), np.where(second, box[:, 1], mid)], axis=1))
        cur, box = np.concatenate(halves), np.concatenate(boxes)
        qi, home = np.tile(qi, 4), np.tile(home, (4, 1, 1))
    x0 = 0.5 * (box[:, 0] + box[:, 1])
    top = np.r_[surface.domain[0][1], surface.domain[1][1]]
    hi = np.where(home[:, 1] < top, np.nextafter(home[:, 1], -np.inf), home[:, 1])
    x, d, f = _newton(evaluate, x0, home[:, 0], hi, queries[qi])
    first = _nearest_per_query(qi, d)
    take = first[d[first] < dist[qi[first]]]
    uv[qi[take]], pts[qi[take]], dist[qi[take]] = x[take], f[take], d[take]
    return uv, pts, dist


def distance_bound_surface(surface, points, iterations: int = 5):
    """Upper bounds (k,) of the distances of `points (k, 3)` to `surface`: each the distance to a point of
    the surface found locally (the nearest node of the coarse seed grid, then Gauss-Newton steps, the
    least distance met kept). A bound whatever the start, since it is a distance to the surface, and
    tight for points near it: enough to decide that points lie within a tolerance of the surface
    without the global search of `closest_point_surface`, which only the points left over need."""
    from scipy.spatial import cKDTree

    queries = _queries(points, 3)
    gu, _ = _samples(surface.knots_u, surface.degree_u, surface.nu, _polygon(surface.ctrl, 0), COARSE)
    gv, _ = _samples(surface.knots_v, surface.degree_v, surface.nv, _polygon(surface.ctrl, 1), COARSE)
    nodes = surface.evaluate_grid(gu, gv).reshape(-1, 3)
    best, idx = cKDTree(nodes).query(queries)
    uv = np.stack([gu[idx // gv.size], gv[idx % gv.size]], axis=1)
    (u0, u1), (v0, v1) = surface.domain
    for _ in range(iterations):
        d = surface.derivatives(uv[:, 0], uv[:, 1], 1)
        su, sv, r = d[1, 0], d[0, 1], queries - d[0, 0]
        best = np.minimum(best, np.linalg.norm(r, axis=1))
        du, dv = gauss_newton_step(su, sv, r)
        uv = np.stack([np.clip(uv[:, 0] + du, u0, u1), np.clip(uv[:, 1] + dv, v0, v1)], axis=1)
    return np.minimum(best, np.linalg.norm(queries - surface.evaluate(uv[:, 0], uv[:, 1]), axis=1))


def gauss_newton_step(su, sv, r):
    """(du (m,), dv (m,)): the Gauss-Newton step of |S(u, v) - X|^2 at partials su, sv (m, 3) and residual
    r = X - S (m, 3), from the normal equations [Su.Su Su.Sv; Su.Sv Sv.Sv] d = [Su.r; Sv.r] with a
    relative 1e-14 on the diagonal (a degenerate point, such as a pole, takes a zero step)."""
    a11, a12, a22 = (su * su).sum(1), (su * sv).sum(1), (sv * sv).sum(1)
    b1, b2 = (su * r).sum(1), (sv * r).sum(1)
    reg = 1e-14 * (a11 + a22) + 1e-300
    det = (a11 + reg) * (a22 + reg) - a12 * a12
    ok = np.abs(det) > 0
    du = np.where(ok, ((a22 + reg) * b1 - a12 * b2) / np.where(ok, det, 1.0), 0.0)
    dv = np.where(ok, ((a11 + reg) * b2 - a12 * b1) / np.where(ok, det, 1.0), 0.0)
    return du, dv
