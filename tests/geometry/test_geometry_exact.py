"""Exact rational forms: circles of constant radius, arcs, conics, and revolution surfaces equal to
the analytic revolution; extrusions, ruled surfaces, planes and composite curves."""
import numpy as np
import pytest
from geometry_strategies import curves
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.geometry.conics import (arc_curve, arc_three_points, circle_curve, conic_arc, line_curve,
                                 polyline_curve)
from rgm.geometry.revolve import (composite_curve, evaluate_revolution, extrusion_surface,
                                  plane_surface, revolution_surface, ruled_surface)

SETTINGS = settings(max_examples=40, deadline=None)
U = np.linspace(0, 1, 1001)
finite = st.floats(-10, 10)
vectors = st.tuples(finite, finite, finite).map(np.array)


@SETTINGS
@given(vectors, vectors.filter(lambda n: np.linalg.norm(n) > 1e-3), st.floats(1e-3, 1e3))
def test_circle_has_constant_radius(center, normal, radius):
    c = circle_curve(center, normal, radius)
    pts = c.evaluate(U)
    assert np.abs(np.linalg.norm(pts - center, axis=1) - radius).max() <= 1e-13 * (radius + np.abs(center).max())
    assert np.abs((pts - center) @ (normal / np.linalg.norm(normal))).max() <= 1e-12 * (radius + np.abs(center).max())
    assert np.allclose(c.start, c.end, atol=1e-12 * (radius + np.abs(center).max()))


@SETTINGS
@given(st.floats(-7, 7), st.floats(0.01, 2 * np.pi), st.floats(0.1, 10))
def test_arc_sweeps_its_angles(a0, sweep, radius):
    arc = arc_curve([1, 2, 3], [1, 0, 0], [0, 1, 0], radius, a0, a0 + sweep)
    rel = arc.evaluate(U) - [1, 2, 3]
    assert np.abs(np.linalg.norm(rel, axis=1) - radius).max() <= 1e-12 * (radius + 3)
    angles = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    assert np.all(np.diff(angles) > 0)                                   # monotone, no turning back
    assert abs((angles[-1] - angles[0]) - sweep) <= 1e-9


@SETTINGS
@given(st.floats(0.1, 5), st.lists(st.floats(0, 2 * np.pi), min_size=3, max_size=3, unique=True),
       st.sampled_from([2, 3]))
def test_arc_through_three_points(radius, angles, dim):
    a = np.sort(angles)
    if min(np.diff(a).min(), 2 * np.pi - (a[2] - a[0])) < 0.05:
        return
    pts = np.c_[radius * np.cos(a), radius * np.sin(a), np.zeros(3)][:, :dim] + 0.5
    arc = arc_three_points(*pts)
    curve = arc.evaluate(U)
    assert np.abs(np.linalg.norm(curve[:, :2] - 0.5, axis=1) - radius).max() <= 1e-11 * radius + 1e-12
    assert np.allclose(arc.start, pts[0], atol=1e-11) and np.allclose(arc.end, pts[2], atol=1e-11)
    assert arc.closest_point(pts[1:2])[2][0] <= 1e-9                     # passes through the middle


def test_conic_arcs_are_exact():
    p = [2 * np.cos(0.6), np.sin(0.6)]
    ellipse = conic_arc([2, 0], [0, 1], [0, 1], [-1, 0], p).evaluate(U)
    assert np.abs(ellipse[:, 0] ** 2 / 4 + ellipse[:, 1] ** 2 - 1).max() < 1e-14
    parabola = conic_arc([-1, 1], [1, -2], [1, 1], [1, 2], [0, 0])
    pts = parabola.evaluate(U)
    assert np.abs(pts[:, 1] - pts[:, 0] ** 2).max() < 1e-14 and np.allclose(parabola.weights, 1)
    h0, h2 = np.array([np.cosh(-1), np.sinh(-1)]), np.array([np.cosh(1), np.sinh(1)])
    hyperbola = conic_arc(h0, h0[::-1], h2, h2[::-1], [np.cosh(0.3), np.sinh(0.3)])
    pts = hyperbola.evaluate(U)
    assert np.abs(pts[:, 0] ** 2 - pts[:, 1] ** 2 - 1).max() < 1e-13 and hyperbola.weights[1] > 1
    with pytest.raises(GeometryError, match="parallel"):
        conic_arc([0, 0], [1, 0], [0, 1], [1, 0], [0.5, 0.5])


@SETTINGS
@given(curves(), vectors, vectors.filter(lambda n: np.linalg.norm(n) > 1e-2),
       st.floats(-3, 3), st.floats(0.05, 2 * np.pi), st.integers(0, 2**31))
def test_revolution_equals_analytic(profile, point, axis, start, sweep, seed):
    surface = revolution_surface(profile, point, axis, start, start + sweep)
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(0, 1, 300), rng.uniform(0, 1, 300)
    pts = surface.evaluate(u, v)
    # recover each point's angle about the axis relative to its profile point, then compare with
    # the analytic rotation of that profile point
    k = axis / np.linalg.norm(axis)
    p0 = profile.evaluate(v) - point
    r0 = p0 - np.outer(p0 @ k, k)
    r1 = (pts - point) - np.outer((pts - point) @ k, k)
    angle = np.arctan2(np.cross(r0, r1) @ k, np.einsum("md,md->m", r0, r1))
    analytic = evaluate_revolution(profile, point, axis, angle, v)
    scale = 1 + np.abs(point).max() + np.abs(profile.ctrl).max()
    assert np.abs(analytic - pts).max() <= 1e-12 * scale
    # the angle grows monotonically with u from start (u = 0) to start + sweep (u = 1)
    vs = np.linspace(0, 1, 21)
    radial = np.linalg.norm(np.cross(profile.evaluate(vs) - point, k), axis=1)
    along = surface.evaluate(np.linspace(0, 1, 101), np.full(101, vs[np.argmax(radial)])) - point
    r = along - np.outer(along @ k, k)
    turn = np.arctan2(np.cross(r[0], r[1:]) @ k, r[1:] @ r[0])
    turn = np.unwrap(np.concatenate([[0.0], turn]))
    assert (np.diff(turn) > 0).all() and turn[-1] == pytest.approx(sweep, abs=1e-9)
    ends = evaluate_revolution(profile, point, axis, np.full(2, start + sweep), np.array([0.3, 0.7]))
    assert np.abs(surface.evaluate([1, 1], [0.3, 0.7]) - ends).max() <= 1e-12 * scale


def test_extrusion_ruled_plane():
    rng = np.random.default_rng(2)
    c0 = arc_curve([0, 0, 0], [1, 0, 0], [0, 1, 0], 1, 0, 2)
    c1 = polyline_curve(rng.uniform(-1, 1, (4, 3)) + [0, 0, 3])
    u, v = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    ext = extrusion_surface(c0, [0, 0, 2])
    assert np.allclose(ext.evaluate(u, v), c0.evaluate(u) + v[:, None] * [0, 0, 2], atol=1e-14)
    ruled = ruled_surface(c0, c1)
    pts, a, b = ruled.evaluate(u, v), c0.evaluate(u), c1.evaluate(u)
    # every point lies on the segment from c0(u) to c1(u), and the ends are the rails
    t = np.einsum("md,md->m", pts - a, b - a) / np.einsum("md,md->m", b - a, b - a)
    assert np.allclose(pts, a + t[:, None] * (b - a), atol=1e-12) and np.all((t > -1e-12) & (t < 1 + 1e-12))
    assert np.allclose(ruled.evaluate(u, np.zeros(200)), a, atol=1e-13)
    assert np.allclose(ruled.evaluate(u, np.ones(200)), b, atol=1e-13)
    plane = plane_surface([1, 1, 1], [2, 0, 0], [1, 1, 0], (2, 3))
    assert plane.domain == ((-1, 1), (-1.5, 1.5))
    assert np.allclose(plane.evaluate([1, -1], [1.5, 0]), [[2, 2.5, 1], [0, 1, 1]])


def test_composite_curve_joins_pieces():
    a = line_curve([0, 0, 0], [1, 0, 0])
    b = arc_three_points([1, 0, 0], [2, 1, 0], [1, 2, 0])
    c = polyline_curve([[1, 2, 0], [0, 2, 0], [0, 1, 0]])
    joined = composite_curve([a, b, c])
    assert joined.degree == 2 and joined.domain == (0, 1)
    t = np.linspace(0, 1, 50)
    for i, piece in enumerate((a, b, c)):
        assert np.abs(joined.evaluate((i + t) / 3) - piece.evaluate(t)).max() < 1e-13
    with pytest.raises(GeometryError, match="starts .* away"):
        composite_curve([a, line_curve([5, 0, 0], [6, 0, 0])])
