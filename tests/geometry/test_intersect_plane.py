"""Surface-plane and curve-plane intersections by marching.

Oracles: the geometry core's closest point on the surface (every sampled point of the approximation
lies within tol of the surface) and the exact signed distance to the plane; a sphere cut by a plane
is a known circle; curve-plane crossings match the sign changes of a dense sample.
"""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from rgm.geometry import NurbsCurve, NurbsSurface
from rgm.geometry.conics import arc_curve
from rgm.geometry.intersect import intersect_curve_plane, intersect_surface_plane
from rgm.geometry.revolve import revolution_surface

KNOTS = np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1.0])
#: requested tolerances, coarse to fine: every level within its tol, the finest more accurate than the coarsest
TOLS = (1e-2, 1e-3, 1e-4)


def random_patch(seed: int, rational: bool) -> NurbsSurface:
    """A bicubic 5 x 5 patch over [0, 10]^2 with random heights (and weights)."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(0, 10, 5), np.linspace(0, 10, 5), indexing="ij"), axis=2)
    ctrl = np.concatenate([g + rng.normal(0, 0.4, g.shape), rng.normal(0, 1.5, (5, 5, 1))], axis=2)
    weights = rng.uniform(0.5, 2.0, (5, 5)) if rational else None
    return NurbsSurface(3, 3, KNOTS, KNOTS, ctrl, weights)


def oracle_error(surface, origin, normal, branches) -> float:
    """Max over dense samples of each branch: distance to the surface (closest point) and to the plane,
    and how far the uv image lands from the 3-D curve."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    worst = 0.0
    for br in branches:
        t = np.linspace(*br.curve.domain, 300)
        pts = br.curve.evaluate(t)
        to_surface = surface.closest_point(pts)[-1].max()
        to_plane = np.abs((pts - origin) @ n).max()
        along_uv = np.linalg.norm(surface.evaluate(*br.uv_a.evaluate(t).T) - pts, axis=1).max()
        worst = max(worst, to_surface, to_plane, along_uv)
    return float(worst)


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rational=st.booleans(),
       tilt=st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8)), at=st.tuples(st.floats(0.2, 0.8), st.floats(0.2, 0.8)))
def test_surface_plane_points_lie_within_tol_of_both_and_error_shrinks(seed, rational, tilt, at):
    surface = random_patch(seed, rational)
    origin = surface.evaluate(np.array([at[0]]), np.array([at[1]]))[0]
    normal = np.array([tilt[0], tilt[1], 1.0])
    errors = []
    for tol in TOLS:
        branches = intersect_surface_plane(surface, origin, normal, tol)
        assert branches, "the plane passes through a point of the surface"
        assert all(br.max_error <= tol for br in branches)
        err = oracle_error(surface, origin, normal, branches)
        assert err <= tol * (1 + 1e-6)
        errors.append(err)
    # a tighter tolerance gives a measurably more accurate curve, end to end over two decades
    assert errors[-1] < errors[0]


def test_sphere_cut_by_a_plane_is_the_known_circle():
    radius, height, tol = 10.0, 4.0, 1e-4
    meridian = arc_curve([0, 0, 0], [0, 0, -1], [1, 0, 0], radius, 0.0, np.pi)   # south pole to north pole
    sphere = revolution_surface(meridian, [0, 0, 0], [0, 0, 1], 0.0, 2 * np.pi)
    branches = intersect_surface_plane(sphere, [0, 0, height], [0, 0, 1], tol)
    pts = np.concatenate([br.curve.evaluate(np.linspace(*br.curve.domain, 400)) for br in branches])
    assert np.abs(np.hypot(pts[:, 0], pts[:, 1]) - np.sqrt(radius**2 - height**2)).max() <= tol
    assert np.abs(pts[:, 2] - height).max() <= tol
    gaps = np.diff(np.sort(np.arctan2(pts[:, 1], pts[:, 0])))
    assert gaps.max() < 0.1, "the whole circle is covered"
    for br in branches:  # the seam splits nothing: each branch's ends meet in 3-D
        assert np.linalg.norm(br.curve.evaluate(np.array(br.curve.domain))[0]
                              - br.curve.evaluate(np.array(br.curve.domain))[1]) <= tol
    assert len(branches) == 1


def test_plane_missing_the_surface_gives_no_branch():
    surface = random_patch(7, False)
    assert intersect_surface_plane(surface, [0, 0, 100], [0, 0, 1], 1e-3) == []


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), offset=st.floats(-1.0, 1.0))
def test_curve_plane_crossings_match_dense_sign_changes(seed, offset):
    rng = np.random.default_rng(seed)
    ctrl = rng.normal(0, 3, (8, 3))
    knots = np.concatenate([[0] * 4, np.sort(rng.uniform(0.05, 0.95, 4)), [1] * 4])
    curve = NurbsCurve(3, knots, ctrl, rng.uniform(0.5, 2, 8))
    origin, normal = np.array([0, 0, offset]), np.array([0.3, -0.2, 1.0])
    params, pts = intersect_curve_plane(curve, origin, normal)
    n = normal / np.linalg.norm(normal)
    assert np.all(np.abs((pts - origin) @ n) <= 1e-9 * (1 + np.abs(ctrl).max()))
    d = (curve.evaluate(np.linspace(0, 1, 20001)) - origin) @ n
    assert len(params) == np.count_nonzero(d[:-1] * d[1:] < 0)


#: a rational patch and a nearly horizontal plane whose section has two branches passing close to each
#: other: a march from one of them used to enter the other loop and circle it 100,000 steps long
LOOPING_NET = np.array([
    [[0.222, -0.382, 0.811], [-0.209, 3.061, -0.67], [-0.246, 5.192, -0.271], [-0.074, 6.945, -0.244], [0.607, 10.014, -1.306]],
    [[2.82, -0.029, -1.032], [2.695, 3.056, 2.453], [2.557, 4.864, -1.876], [2.244, 7.664, 1.388], [2.137, 9.49, 1.11]],
    [[4.973, -0.004, -3.614], [5.097, 1.712, -1.98], [5.343, 5.238, 1.196], [4.469, 6.832, 0.245], [4.44, 10.23, 0.524]],
    [[7.815, -0.415, 2.06], [7.816, 2.158, 2.992], [7.456, 5.354, 1.123], [7.551, 8.045, -1.765], [7.065, 10.087, 1.97]],
    [[9.611, 0.262, -1.052], [10.662, 3.029, -0.611], [9.783, 5.422, 0.151], [9.456, 6.991, 1.776], [9.936, 10.091, -0.499]],
])
LOOPING_WEIGHTS = np.array([
    [1.372, 0.554, 1.27, 0.972, 0.568],
    [1.974, 0.533, 1.833, 1.249, 0.761],
    [1.236, 0.581, 1.805, 0.793, 0.773],
    [1.107, 0.82, 1.497, 1.116, 0.731],
    [0.937, 0.827, 1.426, 0.797, 1.226],
])


def test_a_march_that_enters_another_loop_stops_after_one_turn():
    surface = NurbsSurface(3, 3, KNOTS, KNOTS, LOOPING_NET, LOOPING_WEIGHTS)
    origin, normal = np.array([4.9008, 5.1391, 0.29288]), np.array([-0.0634, 0.0, 1.0])
    branches = intersect_surface_plane(surface, origin, normal, 1e-4)
    assert branches and oracle_error(surface, origin, normal, branches) <= 1e-4 * (1 + 1e-6)
    assert max(br.curve.n for br in branches) < 1000      # each branch marched once round, not 100,000 steps



@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rational=st.booleans(), sag=st.sampled_from([0.05, 0.2]))
def test_a_march_refined_in_place_stays_on_the_intersection_and_never_folds(seed, rational, sag):
    """`_subdivide`: a branch marched at a coarse step, its intervals halved with the midpoints projected
    onto the intersection, either meets a tighter tolerance with every point still in order along the
    branch (consecutive chords never turn back: no fold), within it by the oracle (closest points on the
    surface, the plane's signed distance), or declines (None: the branch is marched again)."""
    from rgm.geometry.intersect import (IntersectionBranch, _PlaneProblem, _fit_branch, _measure, _newton_min_norm,
                                        _subdivide, _trace)

    surface = random_patch(seed, rational)
    origin = surface.evaluate(np.array([0.5]), np.array([0.5]))[0]
    normal = np.array([0.3, -0.2, 1.0])
    problem = _PlaneProblem(surface, origin, normal)
    x0 = _newton_min_norm(problem, np.array([[0.5, 0.5]]), 1e-12)[0][0]
    xs, closed = _trace(problem, x0, sag, 2.0, 1e-12)
    coarse = _measure(problem, *_fit_branch(problem, xs, closed, 2))
    tol = coarse / 4
    refined = _subdivide(problem, xs, closed, 1e-12, tol)
    if refined is None:
        return
    (curve, uv_a, _, t), err = refined
    assert err <= tol / 2 and len(t) > len(xs)
    pts = surface.evaluate(*uv_a.evaluate(t).T)
    chords = np.diff(pts, axis=0)
    assert np.all(np.einsum("ij,ij->i", chords[1:], chords[:-1]) > 0)
    assert oracle_error(surface, origin, normal, [IntersectionBranch(curve, uv_a, None, err, closed)]) <= tol


def test_a_march_refined_in_place_meets_the_tolerance_a_finer_march_would():
    """The case `_subdivide` is for: a branch within a few times the tolerance, refined instead of
    marched again, within tol / 2 by its own measure and within tol by the oracle."""
    from rgm.geometry.intersect import (IntersectionBranch, _PlaneProblem, _fit_branch, _measure, _newton_min_norm,
                                        _subdivide, _trace)

    surface = random_patch(7, False)
    origin = surface.evaluate(np.array([0.5]), np.array([0.5]))[0]
    normal = np.array([0.3, -0.2, 1.0])
    problem = _PlaneProblem(surface, origin, normal)
    x0 = _newton_min_norm(problem, np.array([[0.5, 0.5]]), 1e-12)[0][0]
    xs, closed = _trace(problem, x0, 0.05, 2.0, 1e-12)
    coarse = _measure(problem, *_fit_branch(problem, xs, closed, 2))
    refined = _subdivide(problem, xs, closed, 1e-12, coarse / 4)
    assert refined is not None
    (curve, uv_a, _, t), err = refined
    assert err <= coarse / 8
    assert oracle_error(surface, origin, normal, [IntersectionBranch(curve, uv_a, None, err, closed)]) <= coarse / 4
