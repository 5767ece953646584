"""Free-form fitting by knot insertion (issue 8): tolerance met, error never rises, adaptive beats uniform."""
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.fitters.freeform import (design_matrix, fit_curve, fit_surface, refinement_matrix, solve_grid,
                                  uniform_knots)
from rgm.geometry.inversion import closest_point_surface

SETTINGS = settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def smooth_grid(seed, rows=120, cols=100, noise=0.0):
    """A random smooth height field over 100 x 80 mm (mm): a gently curved base with one or two local
    features (Gaussian bumps 4-9 mm wide), the situation of a scanned part, where detail is local.
    Sampled at about 0.8 mm, so the narrowest bump spans five data lines: the refinement keeps two
    data lines per knot span at least (it approximates, never interpolates)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 100, rows), np.linspace(0, 80, cols), indexing="ij")
    a, b, c = rng.uniform(-1, 1, 3)
    z = a * ((x - 50) / 50) ** 2 * 10 + b * ((y - 40) / 40) ** 2 * 10 + c * (x - 50) * (y - 40) / 200
    for _ in range(rng.integers(1, 3)):
        cx, cy, w, h = rng.uniform(20, 80), rng.uniform(20, 60), rng.uniform(4, 9), rng.uniform(-6, 6)
        z += h * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * w**2))
    z += rng.normal(0, noise, z.shape) if noise else 0
    return np.stack([x, y, z], axis=-1)


def uniform_fit_error(grid, n, degree=3):
    k = uniform_knots(degree, n)
    u, v = np.linspace(0, 1, grid.shape[0]), np.linspace(0, 1, grid.shape[1])
    ctrl, Bu, Bv = solve_grid(u, v, grid, k, k, degree, degree)
    surf = np.einsum("ia,abd,jb->ijd", Bu.toarray(), ctrl, Bv.toarray())
    return np.linalg.norm(surf - grid, axis=2).max()


@SETTINGS
@given(seed=st.integers(0, 10_000))
def test_surface_meets_tolerance_and_error_never_rises(seed):
    grid = smooth_grid(seed, noise=0.01)
    tol = 0.08
    fit = fit_surface(grid, tol, params=(np.linspace(0, 1, grid.shape[0]), np.linspace(0, 1, grid.shape[1])))
    assert fit.stats.holds, fit.stopped
    assert fit.stats.max <= tol
    values = [v for _, v in fit.history]
    assert all(b <= a + 1e-12 for a, b in zip(values, values[1:])), values
    # the certificate is measured, not estimated: each residual is the parametric one re-evaluated here,
    # or, where that exceeds the tolerance, a distance to the surface between the true closest-point
    # distance (rgm.geometry's global search) and the parametric one
    Bu = design_matrix(np.linspace(0, 1, grid.shape[0]), fit.knots_u, 3).toarray()
    Bv = design_matrix(np.linspace(0, 1, grid.shape[1]), fit.knots_v, 3).toarray()
    dev = np.linalg.norm(np.einsum("ia,abd,jb->ijd", Bu, fit.ctrl, Bv) - grid, axis=2).ravel()
    near = dev <= tol
    assert np.allclose(fit.residuals[near], dev[near], rtol=1e-9, atol=1e-12)
    assert np.all(fit.residuals <= dev + 1e-12) and fit.stats.max == fit.residuals.max()
    if not near.all():
        exact = closest_point_surface(fit.nurbs(), grid.reshape(-1, 3)[~near])[3]
        assert np.all(fit.residuals[~near] >= exact - 1e-9)


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 10_000))
@example(seed=5107)   # failing spans too narrow to split: the refinement splits the spans beside them
def test_adaptive_net_is_smaller_than_the_smallest_uniform_net_that_meets_tol(seed):
    grid = smooth_grid(seed, noise=0.01)
    tol = 0.08
    params = (np.linspace(0, 1, grid.shape[0]), np.linspace(0, 1, grid.shape[1]))
    fit = fit_surface(grid, tol, params=params)
    assert fit.stats.holds
    n = 4
    while uniform_fit_error(grid, n) > tol:
        n += 1
    assert fit.n_ctrl <= n * n, (fit.ctrl.shape, n)


def test_scattered_points_meet_tolerance():
    grid = smooth_grid(7)
    rng = np.random.default_rng(1)
    pts = grid.reshape(-1, 3)[rng.choice(grid.shape[0] * grid.shape[1], 5000, replace=False)]
    fit = fit_surface(pts, 0.05)
    assert fit.stats.holds and fit.stats.max <= 0.05


def test_tolerance_below_the_noise_stops_honestly():
    grid = smooth_grid(3, noise=0.5)
    fit = fit_surface(grid, 0.01, max_ctrl=400)
    assert not fit.stats.holds
    assert fit.stopped  # says why instead of pretending


@SETTINGS
@given(seed=st.integers(0, 10_000), n=st.integers(4, 12))
def test_refinement_matrix_keeps_the_shape(seed, n):
    rng = np.random.default_rng(seed)
    k = uniform_knots(3, n)
    new = np.sort(np.r_[k, rng.uniform(0, 1, rng.integers(1, 6))])
    ctrl = rng.normal(size=(n, 2))
    s = np.linspace(0, 1, 301)
    before = design_matrix(s, k, 3) @ ctrl
    after = design_matrix(s, new, 3) @ (refinement_matrix(k, new, 3) @ ctrl)
    assert np.abs(before - after).max() <= 1e-12 * max(1.0, np.abs(ctrl).max()) * 10


def test_curve_refines_only_where_needed():
    """The paper's Figure 6: a profile with a local feature gets its new knots there."""
    x = np.linspace(0, 100, 800)
    y = 5 * np.tanh((x - 70) / 1.5)  # a sharp step near x = 70 mm, flat elsewhere
    fit = fit_curve(np.c_[x, y], 0.05)
    assert fit.stats.holds
    interior = fit.knots[4:-4]
    # chord-length parameter of x = 70 mm
    d = np.linalg.norm(np.diff(np.c_[x, y], axis=0), axis=1)
    s = np.r_[0, np.cumsum(d)] / d.sum()
    s70 = np.interp(70, x, s)
    near = np.abs(interior - s70) < 0.15
    assert near.sum() > 0.6 * len(interior)
    values = [v for _, v in fit.history]
    assert all(b <= a + 1e-12 for a, b in zip(values, values[1:]))


@pytest.mark.parametrize("bad", [np.zeros((0, 3)), np.full((30, 3), np.nan), np.ones((40, 3))])
def test_bad_point_sets_are_refused(bad):
    with pytest.raises(GeometryError):
        fit_surface(bad, 0.1)


def _face_grid():
    """The face scan's range grid (mm; tests/data/fran, VTK example data) without the statistical
    outliers `rgmc fit` filters out: (grid (rows, cols, 3), mask, filtered points (n, 3))."""
    from pathlib import Path

    from rgm.fitters.io import read_scan
    from rgm.fitters.pipeline import filtered_points

    scan = read_scan(Path(__file__).resolve().parents[1] / "data" / "fran" / "fran_cut.ply")
    points, cells, _ = filtered_points([scan], 1000.0)
    mask = cells >= 0
    grid = np.full(cells.shape + (3,), np.nan)
    grid[mask] = points[cells[mask]]
    return grid, mask, points


def test_the_face_mask_meets_0_4mm_and_follows_the_face_between_its_samples():
    """The paper's face mask at its 3.3-4.4 mm scan-line pitch: the fit meets T = 0.4 mm (p95 of the
    closest-point distances, measured here by the independent closest-point search of the certificate)
    with fewer control points than half the data. Not by oscillating through the samples: between them,
    at the centres of the scanner's own mesh cells, the surface is nearer that mesh than the fit stopped at
    a quarter of the data (the former limit), by every figure (p95, max, RMS)."""
    from rgm.fitters.freeform import grid_parameters
    from rgm.fitters.freeform_measure import TrimmedNurbs

    grid, mask, points = _face_grid()
    params = grid_parameters(np.where(mask[..., None], grid, 0.0), mask)
    fit = fit_surface(grid, 0.4, mask=mask, params=params, statistic="p95")
    coarse = fit_surface(grid, 0.4, mask=mask, params=params, statistic="p95", data_per_ctrl=4, min_lines=2)
    assert fit.stats.holds and fit.n_ctrl < len(points) / 2, (fit.stopped, fit.ctrl.shape)
    assert not coarse.stats.holds and "approximation limit" in coarse.stopped
    d = TrimmedNurbs(fit.nurbs()).inner_distance(points)
    assert np.percentile(d, 95) <= 0.4 + 1e-9

    cells = mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:] & mask[1:, 1:]
    centres = (0.25 * (grid[:-1, :-1] + grid[1:, :-1] + grid[:-1, 1:] + grid[1:, 1:]))[cells]

    def between(f):
        e = TrimmedNurbs(f.nurbs()).inner_distance(centres)
        return np.array([np.percentile(e, 95), e.max(), np.sqrt(np.mean(e * e))])

    assert np.all(between(fit) < between(coarse)), (between(fit), between(coarse))


def test_a_tolerance_below_the_noise_is_not_met_by_absorbing_the_noise():
    """Noise of 0.3 mm (its p95 0.59 mm) and T = 0.35 mm on the p95: no surface meets that honestly. At one
    control point per two data points the least-squares residual keeps half the noise variance, so the
    fit stops at the approximation limit and says so instead of interpolating the noise."""
    grid = smooth_grid(5, rows=60, cols=50, noise=0.3)
    fit = fit_surface(grid, 0.35, statistic="p95")
    assert not fit.stats.holds and "approximation limit" in fit.stopped
    assert fit.stats.value > 0.35


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), nu=st.integers(4, 9), nv=st.integers(4, 9))
def test_the_extension_energy_is_the_thin_plate_energy_of_the_surface_where_no_data_are(seed, nu, nv):
    """`Extension.energy` E gives trace(C' E C) = sum of area (|S_uu|^2 + 2 |S_uv|^2 + |S_vv|^2) over the
    empty samples, the partials from NurbsSurface.derivatives (an independent evaluation); an affine net
    (Greville abscissae) has none, so a flat patch's continuation is never pulled."""
    from rgm.fitters.freeform import Extension
    from rgm.geometry import NurbsSurface

    rng = np.random.default_rng(seed)
    ku = np.r_[np.zeros(4), np.sort(rng.uniform(0, 1, nu - 4)), np.ones(4)]
    kv = np.r_[np.zeros(4), np.sort(rng.uniform(0, 1, nv - 4)), np.ones(4)]
    u, v = rng.uniform(0.2, 0.7, 300), rng.uniform(0.3, 0.8, 300)     # data in the middle only
    ext = Extension.of(u, v)
    assert len(ext.uv) and np.all(np.min(np.hypot(ext.uv[:, :1] - u, ext.uv[:, 1:] - v), axis=1) > 1.5 / 48)
    ctrl = rng.normal(0, 10, (nu, nv, 3))
    E = ext.energy(ku, kv, 3, 3)
    d = NurbsSurface(3, 3, ku, kv, ctrl).derivatives(ext.uv[:, 0], ext.uv[:, 1], 2)
    direct = ext.area * np.sum(d[2, 0] ** 2 + 2 * d[1, 1] ** 2 + d[0, 2] ** 2)
    C = ctrl.reshape(-1, 3)
    assert np.einsum("id,id->", C, E @ C) == pytest.approx(direct, rel=1e-9)
    gu = np.array([ku[i + 1:i + 4].mean() for i in range(nu)])
    gv = np.array([kv[j + 1:j + 4].mean() for j in range(nv)])
    a, b, c = rng.normal(0, 5, (3, 3))
    affine = a + gu[:, None, None] * b + gv[None, :, None] * c
    A = affine.reshape(-1, 3)
    assert abs(np.einsum("id,id->", A, E @ A)) < 1e-9 * (1 + np.einsum("id,id->", C, E @ C))


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_surface_reaching_past_its_data_continues_them_calmly(seed):
    """Noisy points (0.05 mm) of the paraboloid z = 0.002 (x-50)^2 + 0.001 (y-50)^2 over the middle 40 x 40
    mm of a 100 x 100 mm domain (parameters x/100, y/100: the surface reaches 30 mm past the data on every
    side, as a patch does to meet its neighbours). With the extension energy the fitted surface stays
    within 2.5 mm of the paraboloid over the whole domain (measured 1.3-1.9 mm on 24 seeds); fitted without
    it, with the same net and certificate, it ran 3.3-39 mm off as the noise extrapolated."""
    import rgm.fitters.freeform_surface as fs

    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0.3, 0.7, 800), rng.uniform(0.3, 0.7, 800)
    z = 0.002 * (100 * u - 50) ** 2 + 0.001 * (100 * v - 50) ** 2
    p = np.c_[100 * u, 100 * v, z + rng.normal(0, 0.05, 800)]
    g = np.linspace(0, 1, 41)
    U, V = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    truth = 0.002 * (100 * U - 50) ** 2 + 0.001 * (100 * V - 50) ** 2
    off = {}
    for share in (fs.EXTENSION, 0.0):
        saved, fs.EXTENSION = fs.EXTENSION, share
        try:
            fit = fit_surface(p, 0.2, params=(u, v), statistic="p95")
        finally:
            fs.EXTENSION = saved
        assert fit.stats.holds
        off[share] = (fit.n_ctrl, float(np.abs(fit.nurbs().evaluate(U, V)[:, 2] - truth).max()))
    (n_ext, ext), (n_plain, plain) = off[fs.EXTENSION], off[0.0]
    assert n_ext <= n_plain and ext < 2.5 and ext < plain


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_narrow_side_meets_the_tolerance_on_its_own_points(seed):
    """6000 scattered points of a gentle surface (100 x 80 mm, 0.02 mm noise) with a sharp bump (3 mm wide,
    3 mm high) whose 2 % of the points make one side: at p95 the fit may leave the bump out (0.43-0.67 mm
    off at p95 on its points, seeds 0-5, at tol 0.1 mm), and does so on this data; with `sides` (two
    patches fitted as one) the statistic holds on each side's points on its own."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([0, 0], [100, 80], (6000, 2))
    r2 = ((xy - rng.uniform([25, 25], [75, 55])) ** 2).sum(1)
    z = 0.002 * (xy[:, 0] - 50) ** 2 + 3 * np.exp(-r2 / (2 * 3.0 ** 2)) + rng.normal(0, 0.02, len(xy))
    points, side = np.c_[xy, z], (r2 < 7.5 ** 2).astype(int)
    tol = 0.1
    plain = fit_surface(points, tol, statistic="p95")
    fit = fit_surface(points, tol, statistic="p95", sides=side)
    assert plain.stats.holds and np.percentile(plain.residuals[side == 1], 95) > tol
    assert fit.stats.holds
    for s in (0, 1):
        assert np.percentile(fit.residuals[side == s], 95) <= tol
