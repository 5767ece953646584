"""Basis functions, evaluation, derivatives (vs finite differences and scipy), curvatures,
validation and immutability of the NURBS core."""
import numpy as np
import pytest
from geometry_strategies import curves, size, surfaces
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.geometry import NurbsCurve, NurbsSurface, basis_matrix
from rgm.geometry.basis import basis_derivatives, basis_functions, find_spans
from rgm.geometry.knots import uniform_knots

SETTINGS = settings(max_examples=40, deadline=None)


@SETTINGS
@given(curves(), st.integers(0, 2**31))
def test_basis_partition_of_unity_and_matrix(c, seed):
    u = np.random.default_rng(seed).uniform(0, 1, 50)
    values = basis_functions(c.knots, c.degree, u)
    assert np.allclose(values.sum(axis=1), 1.0, atol=1e-13) and values.min() >= -1e-15
    a = basis_matrix(c.knots, c.degree, u)
    assert a.shape == (50, c.n)
    h = a @ c.homogeneous                        # sparse matrix times the homogeneous polygon
    assert np.allclose(h[:, :-1] / h[:, -1:], c.evaluate(u), atol=1e-12)
    # derivative rows of the matrix sum to zero (the derivative of the constant 1)
    assert np.allclose(basis_matrix(c.knots, c.degree, u, order=1).sum(axis=1), 0.0, atol=1e-9)


@SETTINGS
@given(curves(), st.integers(0, 2**31))
def test_curve_derivatives_match_finite_differences(c, seed):
    rng = np.random.default_rng(seed)
    breaks = np.unique(c.knots)
    span = rng.integers(0, breaks.size - 1, 20)
    u = breaks[span] + (breaks[span + 1] - breaks[span]) * rng.uniform(0.2, 0.8, 20)  # off the knots
    h = 1e-6 * (breaks[span + 1] - breaks[span])
    d = c.derivatives(u, 2)
    assert np.allclose(d[0], c.evaluate(u), atol=1e-14)
    fd1 = (c.evaluate(u + h) - c.evaluate(u - h)) / (2 * h[:, None])
    fd2 = (c.derivatives(u + h, 1)[1] - c.derivatives(u - h, 1)[1]) / (2 * h[:, None])
    scale1 = 1 + np.abs(d[1]).max()
    scale2 = 1 + np.abs(d[2]).max()
    assert np.abs(fd1 - d[1]).max() <= 1e-5 * scale1
    assert np.abs(fd2 - d[2]).max() <= 1e-4 * scale2


@SETTINGS
@given(surfaces(), st.integers(0, 2**31))
def test_surface_derivatives_match_finite_differences(s, seed):
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 1, 30), rng.uniform(0, 1, 30)
    # stay away from knots so that one-sided kinks cannot spoil the differences
    ku, kv = np.unique(s.knots_u), np.unique(s.knots_v)
    ok = (np.abs(u[:, None] - ku).min(1) > 2e-3) & (np.abs(v[:, None] - kv).min(1) > 2e-3)
    u, v = u[ok], v[ok]
    if u.size == 0:
        return
    h = 1e-6
    d = s.derivatives(u, v, 2)
    d1 = s.derivatives
    checks = [
        (d[1, 0], (s.evaluate(u + h, v) - s.evaluate(u - h, v)) / (2 * h)),
        (d[0, 1], (s.evaluate(u, v + h) - s.evaluate(u, v - h)) / (2 * h)),
        (d[2, 0], (d1(u + h, v)[1, 0] - d1(u - h, v)[1, 0]) / (2 * h)),
        (d[1, 1], (d1(u, v + h)[1, 0] - d1(u, v - h)[1, 0]) / (2 * h)),
        (d[0, 2], (d1(u, v + h)[0, 1] - d1(u, v - h)[0, 1]) / (2 * h)),
    ]
    for exact, approx in checks:
        assert np.abs(exact - approx).max() <= 1e-4 * (1 + np.abs(exact).max())
    assert np.allclose(d[0, 0], s.evaluate(u, v), atol=1e-14)


@SETTINGS
@given(surfaces(), st.integers(0, 2**31))
def test_grid_matches_paired_evaluation(s, seed):
    rng = np.random.default_rng(seed)
    u, v = np.sort(rng.uniform(0, 1, 7)), rng.uniform(0, 1, 5)
    grid = s.evaluate_grid(u, v)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    assert np.abs(grid - s.evaluate(uu.ravel(), vv.ravel()).reshape(7, 5, 3)).max() <= 1e-13 * size(s)


def test_polynomial_surface_matches_scipy_ndbspline():
    from scipy.interpolate import NdBSpline

    rng = np.random.default_rng(3)
    knots = uniform_knots(3, 12)
    ctrl = rng.uniform(-1, 1, (12, 12, 3))
    s = NurbsSurface(3, 3, knots, knots, ctrl)
    uv = rng.uniform(0, 1, (5000, 2))
    reference = NdBSpline((knots, knots), ctrl, (3, 3))(uv)
    assert np.abs(s.evaluate(uv[:, 0], uv[:, 1]) - reference).max() < 1e-13


def test_sphere_curvatures_and_normals():
    from rgm.geometry.conics import arc_curve
    from rgm.geometry.revolve import revolution_surface

    r = 2.5
    half = arc_curve([0, 0, 0], [0, 0, -1], [1, 0, 0], r, 0.0, np.pi)   # meridian from pole to pole
    sphere = revolution_surface(half, [0, 0, 0], [0, 0, 1])
    rng = np.random.default_rng(1)
    u, v = rng.uniform(0.05, 0.95, 200), rng.uniform(0.05, 0.95, 200)
    k1, k2 = sphere.curvatures(u, v)
    assert np.allclose(np.abs(k1), 1 / r, rtol=1e-9) and np.allclose(np.abs(k2), 1 / r, rtol=1e-9)
    pts, normals = sphere.evaluate(u, v), sphere.normal(u, v)
    assert np.allclose(np.abs(np.einsum("md,md->m", normals, pts / r)), 1.0, atol=1e-9)


def test_cylinder_principal_curvatures():
    from rgm.geometry.conics import line_curve
    from rgm.geometry.revolve import revolution_surface

    cylinder = revolution_surface(line_curve([3, 0, 0], [3, 0, 5]), [0, 0, 0], [0, 0, 1])
    k1, k2 = cylinder.curvatures(np.linspace(0.01, 0.99, 50), np.linspace(0, 1, 50))
    curv = np.sort(np.abs(np.stack([k1, k2])), axis=0)
    assert np.allclose(curv[0], 0, atol=1e-12) and np.allclose(curv[1], 1 / 3, rtol=1e-9)


def test_validation_messages():
    pts = np.zeros((4, 3))
    cases = [
        (lambda: NurbsCurve(3, [0, 0, 0, 1, 1, 1], pts), "need n \\+ p \\+ 1 = 8"),
        (lambda: NurbsCurve(3, [0, 0, 0, 0, 1, 0.5, 1, 1], pts), "non-decreasing"),
        (lambda: NurbsCurve(3, [0, 0, 0, 0, 1, 1, 1, 1], pts, [1, 1, 0, 1]), "weights must be finite and > 0"),
        (lambda: NurbsCurve(3, [0, 0, 0, 0, 1, 1, 1, 1], pts, [1, 1, 1]), "weights must have shape"),
        (lambda: NurbsCurve(0, [0, 1], pts[:1]), "degree must be an integer >= 1"),
        (lambda: NurbsCurve(1, [0, 0, 1, 1], np.zeros((2, 4))), "control points must have shape"),
        (lambda: NurbsCurve(1, [0, 0, 0, 1, 1], np.zeros((3, 3))), "repeated 3 times"),
        (lambda: NurbsCurve(2, [0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1], np.zeros((6, 3))), "discontinuous"),
        (lambda: NurbsCurve(1, [1, 1, 1, 1], np.zeros((2, 3))), "empty domain"),
        (lambda: NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1], np.zeros((2, 2, 3))), "knots_v has 3 knots"),
        (lambda: NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], np.zeros((2, 2, 3)), np.ones(4)),
         "weights must have shape \\(2, 2\\)"),
    ]
    for build, message in cases:
        with pytest.raises(GeometryError, match=message):
            build()
    c = NurbsCurve(1, [0, 0, 1, 1], np.eye(2, 3))
    with pytest.raises(GeometryError, match="outside the domain"):
        c.evaluate([1.5])
    s = NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], np.zeros((2, 2, 3)))
    with pytest.raises(GeometryError, match="pair up"):
        s.evaluate([0.1, 0.2], [0.3])


def test_objects_are_immutable_copies():
    ctrl = np.eye(3)
    c = NurbsCurve(2, [0, 0, 0, 1, 1, 1], ctrl)
    ctrl[0, 0] = 42.0                       # the caller's array is copied
    assert c.ctrl[0, 0] == 1.0
    with pytest.raises(ValueError):
        c.ctrl[0, 0] = 2.0
    with pytest.raises(ValueError):
        c.knots[0] = -1.0
    with pytest.raises(AttributeError):
        c.degree = 3
    s = NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], np.zeros((2, 2, 3)))
    with pytest.raises(AttributeError):
        s.ctrl = None


@given(curves(), surfaces())
def test_pickled_curves_and_surfaces_come_back_the_same_and_immutable(c, s):
    """Results holding geometry (a fitted PatchSet, a model) go to worker processes and to disk by pickle:
    the copies evaluate bit for bit as the originals and are as immutable (rebuilt by the constructor)."""
    import pickle

    c2, s2 = pickle.loads(pickle.dumps(c)), pickle.loads(pickle.dumps(s))
    t = np.linspace(*c.domain, 7)
    assert np.array_equal(c2.evaluate(t), c.evaluate(t)) and (c2.weights is None) == (c.weights is None)
    (u0, u1), (v0, v1) = s.domain
    u, v = np.linspace(u0, u1, 5), np.linspace(v0, v1, 5)
    assert np.array_equal(s2.evaluate(u, v), s.evaluate(u, v))
    with pytest.raises(AttributeError):
        c2.degree = 1
    with pytest.raises(ValueError):
        s2.ctrl[0, 0, 0] = 1.0


def test_transform_bbox_and_spans():
    rng = np.random.default_rng(5)
    c = NurbsCurve(3, uniform_knots(3, 6), rng.uniform(-1, 1, (6, 3)), rng.uniform(0.5, 2, 6))
    m = np.eye(4)
    m[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    m[:3, 3] = [1, 2, 3]
    u = np.linspace(0, 1, 101)
    moved = c.transform(m)
    assert np.allclose(moved.evaluate(u), c.evaluate(u) @ m[:3, :3].T + m[:3, 3], atol=1e-13)
    box = c.bbox()
    pts = c.evaluate(u)
    assert np.all(pts >= box[0] - 1e-15) and np.all(pts <= box[1] + 1e-15)
    knots = np.array([0, 0, 0, 0.5, 0.5, 1, 1, 1.0])
    assert list(find_spans(knots, 2, np.array([0, 0.25, 0.5, 0.75, 1.0]))) == [2, 2, 4, 4, 4]
    d = basis_derivatives(knots, 2, np.array([0.3]), 3)
    assert d.shape == (4, 1, 3) and np.all(d[3] == 0)
