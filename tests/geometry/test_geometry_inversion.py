"""Closest points are true minima: on random curves and surfaces, no point of a dense sampling is
closer to the query than the returned point, and the returned point lies on the geometry."""
import numpy as np
import pytest
from geometry_strategies import curves, size, surfaces
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from rgm.errors import GeometryError
from rgm.geometry.conics import circle_curve, polyline_curve

SETTINGS = settings(max_examples=25, deadline=None)


@SETTINGS
@given(curves(), st.integers(0, 2**31))
def test_curve_closest_points_are_minima(c, seed):
    queries = np.random.default_rng(seed).uniform(-1.5, 1.5, (60, 3))
    u, pts, dist = c.closest_point(queries)
    dense = c.evaluate(np.linspace(0, 1, 50001))
    sampled, _ = cKDTree(dense).query(queries)
    assert np.all(dist <= sampled + 1e-10 * size(c))
    assert np.allclose(c.evaluate(u), pts, atol=1e-13 * size(c))
    assert np.allclose(np.linalg.norm(pts - queries, axis=1), dist)


@SETTINGS
@given(surfaces(), st.integers(0, 2**31))
def test_surface_closest_points_are_minima(s, seed):
    queries = np.random.default_rng(seed).uniform(-1.5, 1.5, (60, 3))
    u, v, pts, dist = s.closest_point(queries)
    grid = np.linspace(0, 1, 451)
    sampled, _ = cKDTree(s.evaluate_grid(grid, grid).reshape(-1, 3)).query(queries)
    assert np.all(dist <= sampled + 1e-10 * size(s))
    assert np.allclose(s.evaluate(u, v), pts, atol=1e-13 * size(s))
    (u0, u1), (v0, v1) = s.domain
    assert np.all((u >= u0) & (u <= u1) & (v >= v0) & (v <= v1))


@SETTINGS
@given(surfaces(), st.integers(0, 2**31))
def test_distance_bound_is_a_bound(s, seed):
    """`distance_bound_surface` (the model check that 3-D trimming curves lie on their surface: samples
    it does not find within the tolerance get the global search) never reports less than the true
    distance, on any surface, for points anywhere."""
    from rgm.geometry.inversion import distance_bound_surface

    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = s.domain
    pts = np.concatenate([rng.uniform(-1.5, 1.5, (60, 3)), s.evaluate(rng.uniform(u0, u1, 60), rng.uniform(v0, v1, 60))])
    assert np.all(distance_bound_surface(s, pts) >= s.closest_point(pts)[3] - 1e-12 * size(s))


@pytest.mark.parametrize("seed", range(5))
def test_distance_bound_finds_points_on_a_smooth_patch(seed):
    """On a smooth bicubic patch (a fitted scan's kind) every point of the surface is found on it, so
    the global search is left for points that are off it."""
    from rgm.geometry import NurbsSurface
    from rgm.geometry.inversion import distance_bound_surface

    rng = np.random.default_rng(seed)
    k = np.concatenate([np.zeros(4), np.sort(rng.uniform(0.1, 0.9, 4)), np.ones(4)])
    g = np.linspace(0, 100, 8)
    x, y = np.meshgrid(g, g, indexing="ij")
    s = NurbsSurface(3, 3, k, k, np.stack([x, y, rng.uniform(-15, 15, (8, 8))], axis=-1), rng.uniform(0.5, 2, (8, 8)))
    on = s.evaluate(rng.uniform(0, 1, 500), rng.uniform(0, 1, 500))
    assert distance_bound_surface(s, on).max() <= 1e-9 * 100


def test_interior_minimum_is_stationary_and_circle_is_exact():
    circle = circle_curve([0, 0, 0], [0, 0, 1], 2.0)
    rng = np.random.default_rng(4)
    q = np.c_[rng.uniform(-5, 5, (200, 2)), rng.uniform(-1, 1, 200)]
    u, pts, dist = circle.closest_point(q)
    radial = np.linalg.norm(q[:, :2], axis=1)
    assert np.allclose(dist, np.hypot(radial - 2.0, q[:, 2]), atol=1e-12)
    tangent = circle.derivatives(u, 1)[1]
    # first-order condition, relative to |C'| |C - q| (the distance is flat near a minimum, so
    # the parameter is only determined to about sqrt(machine epsilon))
    cosine = np.einsum("md,md->m", tangent, pts - q) / (np.linalg.norm(tangent, axis=1) * np.maximum(dist, 1e-300))
    assert np.abs(cosine).max() < 1e-6


def test_polyline_kinks_and_errors():
    line = polyline_curve([[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    u, pts, dist = line.closest_point([[0.9, 0.95, 0], [2, -1, 0]])
    assert np.allclose(pts, [[1, 0.95, 0], [1, 0, 0]], atol=1e-13)
    with pytest.raises(GeometryError, match="query points"):
        line.closest_point(np.zeros((2, 2)))
