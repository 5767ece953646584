"""Superellipsoid recovery on synthetic data: random sizes (10-100), shapes (eps in [0.1, 1]), poses,
1 % noise and 5 % outliers.

Bounds (measured over 40 seeds, then given a margin; see benchmarks/bench_superellipsoid.py), met by at
least 85 % of random cases (the failures are thin shapes; see the bounded-recovery test):
- surface error: the median radial distance of the true (noise-free) surface to the fit <= 1.5 % of the
  mean semi-axis, its 90th percentile <= 5 %;
- size error: sorted semi-axes within 8 % of the largest (a superellipsoid's axes are only defined up to
  the symmetries of its shape, hence sorted);
- shape error: |eps1 - eps1'|, |eps2 - eps2'| <= 0.2 when the fit chose the same symmetry (z) axis.
"""
from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from recovery_scans import random_rotation, superellipsoid_cloud
import pytest

from rgm.fitters.superellipsoid import (_HIGH, _LOW, Superellipsoid, _model, _normalise, _residuals, _rho, _solve,
                                        _starts, fit_superellipsoid, fit_superellipsoid_plain)


def _random_superellipsoid(rng):
    return Superellipsoid(rng.uniform(10, 100, 3), rng.uniform(0.1, 1.0, 2), random_rotation(rng),
                          rng.uniform(-500, 500, 3), 0.0, 0.0)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_analytic_jacobian_matches_central_differences(seed):
    """At rotation increment 0, where the solver evaluates it (it folds accepted rotations into r0)."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(40, 3))
    theta = np.r_[rng.uniform(0.5, 2, 3), rng.uniform(0.15, 1.0, 2), np.zeros(3), rng.uniform(-0.5, 0.5, 3)]
    r0 = random_rotation(rng)
    _, jac = _residuals(theta, x, r0, True)
    h = 1e-6
    numeric = np.column_stack([(_residuals(theta + h * e, x, r0, False) - _residuals(theta - h * e, x, r0, False))
                               / (2 * h) for e in np.eye(11)])
    assert np.allclose(jac, numeric, rtol=1e-4, atol=1e-5 * np.abs(jac).max())


def _recovery_errors(seed, n=3000):
    rng = np.random.default_rng(seed)
    truth = _random_superellipsoid(rng)
    points, _ = superellipsoid_cloud(truth, n, noise=0.01, outliers=0.05, rng=rng)
    fit = fit_superellipsoid(points)
    surface = fit.radial_distance(truth.surface_points(rng.normal(size=(2000, 3)))) / truth.size.mean()
    size = np.max(np.abs(np.sort(fit.size) - np.sort(truth.size))) / truth.size.max()
    same_axis = abs(fit.rotation[:, 2] @ truth.rotation[:, 2]) > 0.95
    shape = np.max(np.abs(fit.eps - truth.eps)) if same_axis else 0.0
    return np.median(surface), np.percentile(surface, 90), size, shape, fit.quality


def test_recovery_with_noise_and_outliers_is_bounded():
    """20 random superellipsoids: at least 85 % within the strict bounds, at most 1 gross failure.

    Known failures (measured over seeds 500-529: 505, 522, 523, 525; this test runs 500-519): thin shapes, the smallest semi-axis about
    1/8 of the largest.  The noise, 1 % of the *mean* semi-axis, is then 5-10 % of the thin one; the
    robust inside-outside cost prefers long axes 10-20 % short (523, 525), and for thin discs (505, 522)
    every start converges to a small box-like shape inside the disc (median surface error ~18 %).  The
    truth has the lower least-squares cost on the inliers, so these are local minima of the Solina cost.
    """
    errors = np.array([_recovery_errors(seed) for seed in range(500, 520)])
    median, p90, size, shape, quality = errors.T
    strict = (median <= 0.015) & (p90 <= 0.05) & (size <= 0.08) & (shape <= 0.2)
    assert strict.mean() >= 0.85, errors[~strict]
    assert np.sum(median > 0.03) <= 1, errors[median > 0.03]


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.001, 1000.0))
@example(275, 1.0)   # a flat valley of the cost: sizes 0.6 % apart, exponents 2 %, the same surface to 0.2 %
def test_fit_is_independent_of_frame_and_scale(seed, scale):
    rng = np.random.default_rng(seed)
    truth = _random_superellipsoid(rng)
    points, _ = superellipsoid_cloud(truth, 1500, rng=rng)
    rot, shift = random_rotation(rng), rng.uniform(-1e3, 1e3, 3)
    a = fit_superellipsoid(points)
    b = fit_superellipsoid(scale * points @ rot.T + shift)
    # the same surface (its parameters are defined up to the shape's symmetries, e.g. a1 <-> a2, and, where
    # the cost is flat, to the trade between a semi-axis and the exponents: 1 %)
    on_a = scale * a.surface_points(rng.normal(size=(500, 3))) @ rot.T + shift
    assert np.median(b.radial_distance(on_a)) <= 2e-3 * scale * a.size.mean()
    assert np.allclose(np.sort(b.size), scale * np.sort(a.size), rtol=1e-2)
    assert np.allclose(b.center, scale * rot @ a.center + shift, atol=5e-3 * scale * a.size.max())
    assert abs(b.quality - a.quality) < 1e-3


def test_robust_fit_beats_the_plain_fit_with_outliers():
    errors = {"robust": [], "plain": []}
    for seed in range(2):
        rng = np.random.default_rng(100 + seed)
        truth = _random_superellipsoid(rng)
        points, _ = superellipsoid_cloud(truth, 1200, noise=0.01, outliers=0.05, rng=rng)
        true_surface = truth.surface_points(rng.normal(size=(1000, 3)))
        for name, fitter in (("robust", fit_superellipsoid), ("plain", fit_superellipsoid_plain)):
            fit = fitter(points)
            errors[name].append(np.median(fit.radial_distance(true_surface)) / truth.size.mean())
    assert np.mean(errors["robust"]) * 3 < np.mean(errors["plain"])


@pytest.mark.parametrize("loss", ["linear", "soft_l1", "cauchy"])
def test_solver_reaches_the_minimum_scipy_least_squares_finds(loss):
    """The batched Levenberg–Marquardt solver against scipy.optimize.least_squares (trf, same loss,
    scale, bounds and start, finite-difference Jacobian): no higher a robust cost."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(7)
    points, _ = superellipsoid_cloud(_random_superellipsoid(rng), 600, noise=0.01, outliers=0.05, rng=rng)
    c, scale = _normalise(points)
    xn = (points - c) / scale
    r0, size, centre = _starts(xn)[0]
    theta0 = np.r_[size, 0.8, 0.8, 0.0, 0.0, 0.0, centre]
    f_scale = np.array([1.4826 * np.median(np.abs(_residuals(theta0, xn, r0, False)))])
    ours, r_ours = _solve(xn, r0[None], theta0[None], loss, f_scale, 300, rtol=1e-12)
    ref = least_squares(lambda th: _residuals(th, xn, r0, False), theta0, loss=loss, f_scale=f_scale[0],
                        bounds=(_LOW, _HIGH), max_nfev=600, method="trf")

    def cost(theta, axes):
        return _rho(_model(theta[None], xn, axes[None], False), loss, f_scale)[0].sum()

    assert cost(ours[0], r_ours[0]) <= cost(ref.x, r0) * (1 + 1e-6)


def test_bad_input_gives_a_clear_error():
    with pytest.raises(ValueError, match="at least 20 points"):
        fit_superellipsoid(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="non-finite"):
        fit_superellipsoid(np.full((50, 3), np.nan))
