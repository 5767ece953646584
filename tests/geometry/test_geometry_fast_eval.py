"""The blocked, point-last surface evaluator against independent references: scipy's compiled
`NdBSpline` on the control net (polynomial) and on the homogeneous net (w*P, w) followed by the
division (rational: exact), for random degrees 1-5 and repeated knots, at random parameters, at
every distinct knot and at the domain ends, across block boundaries."""
from unittest.mock import patch

import numpy as np
from geometry_strategies import size, surfaces
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import NdBSpline

import rgm.geometry.surface as surface_module
from rgm.geometry.basis import basis_derivatives, basis_derivatives_t, basis_functions, basis_functions_t

SETTINGS = settings(max_examples=60, deadline=None)


def reference(s, u, v, nu=(0, 0)):
    """S(u_i, v_i) (or, polynomial only, a partial) by NdBSpline, the rational case homogeneously."""
    xi = np.column_stack([u, v])
    if not s.is_rational:
        return NdBSpline((s.knots_u, s.knots_v), s.ctrl, (s.degree_u, s.degree_v))(xi, nu=nu)
    h = NdBSpline((s.knots_u, s.knots_v), s.homogeneous, (s.degree_u, s.degree_v))(xi)
    return h[:, :3] / h[:, 3:]


def sample(s, seed: int, count: int = 200):
    """Random pairs, then every distinct knot of each direction against random partners, then the
    four corners: the domain ends and the span boundaries (where multiplicities matter)."""
    rng = np.random.default_rng(seed)
    ku, kv = np.unique(s.knots_u), np.unique(s.knots_v)
    u = np.r_[rng.uniform(0, 1, count), ku, rng.uniform(0, 1, kv.size), 0, 0, 1, 1]
    v = np.r_[rng.uniform(0, 1, count), rng.uniform(0, 1, ku.size), kv, 0, 1, 0, 1]
    return u, v


@SETTINGS
@given(surfaces(max_degree=5), st.integers(0, 2**31), st.integers(1, 50))
def test_evaluate_matches_ndbspline_and_homogeneous_reference(s, seed, chunk):
    u, v = sample(s, seed)
    expected = reference(s, u, v)
    assert np.abs(s.evaluate(u, v) - expected).max() <= 1e-12 * size(s)
    with patch.object(surface_module, "_CHUNK", chunk):        # many blocks, ragged last block
        assert np.abs(s.evaluate(u, v) - expected).max() <= 1e-12 * size(s)
        assert np.abs(s.derivatives(u, v, 1)[0, 0] - expected).max() <= 1e-12 * size(s)


@SETTINGS
@given(surfaces(max_degree=5), st.integers(0, 2**31))
def test_polynomial_partials_match_ndbspline(s, seed):
    if s.is_rational:
        s = type(s)(s.degree_u, s.degree_v, s.knots_u, s.knots_v, s.ctrl)
    rng = np.random.default_rng(seed)
    u, v = np.r_[rng.uniform(0, 1, 100), 0, 1], np.r_[rng.uniform(0, 1, 100), 1, 0]
    d = s.derivatives(u, v, 2)
    for k, l in ((1, 0), (0, 1), (2, 0), (1, 1), (0, 2)):
        expected = reference(s, u, v, nu=(k, l))
        assert np.abs(d[k, l] - expected).max() <= 1e-11 * (size(s) + np.abs(expected).max())


@SETTINGS
@given(st.integers(1, 5), st.integers(0, 2**31))
def test_transposed_basis_layouts_agree(degree, seed):
    from geometry_strategies import random_knots

    rng = np.random.default_rng(seed)
    knots = random_knots(rng, degree, degree + 1 + int(rng.integers(0, 8)))
    u = np.r_[rng.uniform(0, 1, 50), np.unique(knots)]
    values = basis_functions_t(knots, degree, u)
    assert values.shape == (degree + 1, u.size)
    assert np.array_equal(basis_functions(knots, degree, u), values.T)
    ders = basis_derivatives_t(knots, degree, u, 2)
    assert ders.shape == (3, degree + 1, u.size)
    assert np.allclose(ders[0], values, atol=1e-14, rtol=0)
    assert np.array_equal(basis_derivatives(knots, degree, u, 2), ders.transpose(0, 2, 1))


@SETTINGS
@given(surfaces(max_degree=5), st.integers(0, 2**31))
def test_power_form_one_point_path_is_the_vectorised_path_bit_for_bit(s, seed):
    """Marching evaluates one point at a time through the power form's Python-float path (`d1_one`): it
    runs the vectorised path's Horner steps in the same order, so points and partials are equal to the
    last bit (random degrees 1-5, rational or not, at random parameters, every knot, the domain ends and
    parameters outside the domain, which both clip)."""
    from rgm.geometry.power_form import power_form

    form = power_form(s)
    u, v = sample(s, seed, count=40)
    rng = np.random.default_rng(seed)
    u, v = np.r_[u, rng.uniform(-0.5, 1.5, 10)], np.r_[v, rng.uniform(-0.5, 1.5, 10)]
    many = form.d(u, v, 1)
    for i in range(len(u)):
        one = form.d1_one(float(u[i]), float(v[i]))
        for a, b in zip(many, one):
            assert np.array_equal(a[i:i + 1], b)
