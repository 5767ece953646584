"""Knot insertion, refinement, splitting, degree elevation, reversal and reparameterisation leave
random curves and surfaces unchanged (max deviation <= 1e-12 x size)."""
import numpy as np
import pytest
from geometry_strategies import curves, size, surfaces
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.geometry.knots import clamp, clamped_knots, uniform_knots
from rgm.geometry import NurbsCurve

SETTINGS = settings(max_examples=40, deadline=None)
U = np.linspace(0.0, 1.0, 257)
GRID = np.linspace(0.0, 1.0, 23)


def deviation(a, b, u=U):
    return np.abs(a.evaluate(u) - b.evaluate(u)).max()


def surface_deviation(a, b, u=GRID, v=GRID):
    return np.abs(a.evaluate_grid(u, v) - b.evaluate_grid(u, v)).max()


@SETTINGS
@given(curves(), st.floats(0.01, 0.99), st.integers(1, 4))
def test_insert_knot_keeps_curve(c, t, times):
    times = min(times, c.degree)
    from rgm.geometry.knots import multiplicity
    times = min(times, c.degree - multiplicity(c.knots, t))
    if times < 1:
        return
    d = c.insert_knot(t, times)
    assert d.n == c.n + times
    assert deviation(c, d) <= 1e-12 * size(c)


@SETTINGS
@given(curves(), st.lists(st.integers(1, 999), min_size=1, max_size=6, unique=True))
def test_refine_keeps_curve(c, new):
    d = c.refine(np.array(new) / 1000 + 1e-7)      # off the random knots (rounded to 6 places)
    assert d.n == c.n + len(new)
    assert deviation(c, d) <= 1e-12 * size(c)


@SETTINGS
@given(curves(), st.floats(0.01, 0.99))
def test_split_keeps_curve(c, t):
    a, b = c.split(t)
    ua, ub = U[U <= t], U[U >= t]
    assert a.domain == (0.0, t) and b.domain == (t, 1.0)
    err = max(np.abs(a.evaluate(ua) - c.evaluate(ua)).max(), np.abs(b.evaluate(ub) - c.evaluate(ub)).max())
    assert err <= 1e-12 * size(c)


@SETTINGS
@given(curves(max_degree=5), st.integers(1, 3))
def test_elevate_keeps_curve(c, times):
    d = c.elevate(times)
    assert d.degree == c.degree + times
    # every distinct knot gains multiplicity `times`
    assert d.n == c.n + times * (np.unique(c.knots).size - 1)
    assert deviation(c, d) <= 1e-12 * size(c)


@SETTINGS
@given(curves(), st.floats(-5, 5), st.floats(0.1, 10))
def test_reverse_and_reparameterize(c, u0, width):
    r = c.reverse()
    assert np.abs(r.evaluate(U) - c.evaluate(1.0 - U)).max() <= 1e-12 * size(c)
    p = c.reparameterize(u0, u0 + width)
    assert p.domain == (u0, u0 + width)
    assert np.abs(p.evaluate(u0 + width * U) - c.evaluate(U)).max() <= 1e-12 * size(c)


@SETTINGS
@given(surfaces(), st.sampled_from("uv"), st.floats(0.01, 0.99), st.integers(1, 3))
def test_surface_insert_and_refine(s, direction, t, times):
    degree = s.degree_u if direction == "u" else s.degree_v
    t = round(t, 3) + 1e-7
    d = s.insert_knot(direction, t, min(times, degree))
    assert surface_deviation(s, d) <= 1e-12 * size(s)
    r = s.refine(direction, [0.25 + 3e-7, 0.5 + 3e-7, t])
    assert surface_deviation(s, r) <= 1e-12 * size(s)


@SETTINGS
@given(surfaces(), st.sampled_from("uv"), st.floats(0.01, 0.99))
def test_surface_split(s, direction, t):
    a, b = s.split(direction, t)
    lo, hi = GRID[GRID <= t], GRID[GRID >= t]
    if direction == "u":
        err = max(np.abs(a.evaluate_grid(lo, GRID) - s.evaluate_grid(lo, GRID)).max(),
                  np.abs(b.evaluate_grid(hi, GRID) - s.evaluate_grid(hi, GRID)).max())
    else:
        err = max(np.abs(a.evaluate_grid(GRID, lo) - s.evaluate_grid(GRID, lo)).max(),
                  np.abs(b.evaluate_grid(GRID, hi) - s.evaluate_grid(GRID, hi)).max())
    assert err <= 1e-12 * size(s)


@SETTINGS
@given(surfaces(), st.sampled_from("uv"), st.integers(1, 2))
def test_surface_elevate_reverse_reparameterize(s, direction, times):
    e = s.elevate(direction, times)
    assert (e.degree_u, e.degree_v) == ((s.degree_u + times, s.degree_v) if direction == "u"
                                        else (s.degree_u, s.degree_v + times))
    assert surface_deviation(s, e) <= 1e-12 * size(s)
    r = s.reverse(direction)
    flipped = r.evaluate_grid(1 - GRID, GRID) if direction == "u" else r.evaluate_grid(GRID, 1 - GRID)
    assert np.abs(flipped - s.evaluate_grid(GRID, GRID)).max() <= 1e-12 * size(s)
    p = s.reparameterize(direction, -2.0, 3.0)
    mapped = p.evaluate_grid(-2 + 5 * GRID, GRID) if direction == "u" else p.evaluate_grid(GRID, -2 + 5 * GRID)
    assert np.abs(mapped - s.evaluate_grid(GRID, GRID)).max() <= 1e-12 * size(s)


def test_clamp_unclamped_curve():
    rng = np.random.default_rng(7)
    c = NurbsCurve(3, np.sort(rng.uniform(0, 4, 11)), rng.uniform(-1, 1, (7, 3)), rng.uniform(0.5, 2, 7))
    knots, pw = clamp(c.knots, 3, c.homogeneous)
    d = NurbsCurve.from_homogeneous(3, knots, pw)
    u = np.linspace(*c.domain, 101)
    assert knots[0] == knots[3] == c.domain[0] and knots[-1] == knots[-4] == c.domain[1]
    assert np.abs(d.evaluate(u) - c.evaluate(u)).max() <= 1e-12
    assert np.abs(c.elevate().evaluate(u) - c.evaluate(u)).max() <= 1e-12


def test_knot_helpers_and_errors():
    assert list(uniform_knots(2, 5)) == [0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1]
    assert list(clamped_knots(1, [0.5])) == [0, 0, 0.5, 1, 1]
    c = NurbsCurve(2, uniform_knots(2, 4), np.eye(4, 3))
    with pytest.raises(GeometryError, match="strictly inside"):
        c.insert_knot(1.0)
    with pytest.raises(GeometryError, match="repeat an interior knot 4 times"):
        c.insert_knot(0.5, 3)
    with pytest.raises(GeometryError, match="strictly inside"):
        c.split(0.0)
    with pytest.raises(GeometryError, match="direction"):
        from rgm.geometry import NurbsSurface
        NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], np.zeros((2, 2, 3))).refine("w", [0.5])


@SETTINGS
@given(st.lists(st.floats(0.001, 0.999), min_size=0, max_size=8), st.floats(0, 1), st.floats(0.01, 1),
       st.floats(-50, 50), st.floats(1e-3, 100))
def test_rescaled_knots_keep_every_end_copy_exact(interior, a, width, u0, new_width):
    """Every copy of an end knot maps to the new end exactly (a copy rounded below its neighbour made a
    knot vector decrease: a closed wrap's face, cut from 1 - d to 1.5 + d, was refused)."""
    from rgm.geometry.knots import rescale_knots

    b = a + width
    knots = clamped_knots(3, np.unique(a + np.asarray(interior) * width), (a, b))
    for lo, hi in ((0.0, 1.0), (u0, u0 + new_width)):
        out = rescale_knots(knots, 3, lo, hi)
        assert np.all(out[:4] == lo) and np.all(out[-4:] == hi) and np.all(np.diff(out) >= 0)
