"""Surface-surface intersection by marching: every point of the approximation lies within tol of both
surfaces (closest-point oracle), the error shrinks with tol, and a sphere cut by a planar B-spline
patch gives the known circle."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from rgm.geometry import NurbsSurface
from rgm.geometry.conics import arc_curve
from rgm.geometry.intersect import intersect_surfaces
from rgm.geometry.revolve import revolution_surface

KNOTS = np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1.0])
#: requested tolerances, coarse to fine: every level within its tol, the finest more accurate than the coarsest
TOLS = (1e-2, 1e-3, 1e-4)


def patch(seed: int, tilt: float, rational: bool) -> NurbsSurface:
    """Bicubic 5 x 5 patch over about [0, 10]^2: random heights around the plane z = tilt * (x - 5)."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(0, 10, 5), np.linspace(0, 10, 5), indexing="ij"), axis=2)
    g = g + rng.normal(0, 0.3, g.shape)
    z = tilt * (g[..., :1] - 5) + rng.normal(0, 1.2, (5, 5, 1))
    return NurbsSurface(3, 3, KNOTS, KNOTS, np.concatenate([g, z], axis=2),
                        rng.uniform(0.6, 1.6, (5, 5)) if rational else None)


def oracle_error(sa, sb, branches) -> float:
    worst = 0.0
    for br in branches:
        t = np.linspace(*br.curve.domain, 250)
        pts = br.curve.evaluate(t)
        worst = max(worst, sa.closest_point(pts)[-1].max(), sb.closest_point(pts)[-1].max(),
                    np.linalg.norm(sa.evaluate(*br.uv_a.evaluate(t).T) - pts, axis=1).max(),
                    np.linalg.norm(sb.evaluate(*br.uv_b.evaluate(t).T) - pts, axis=1).max())
    return float(worst)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rational=st.booleans())
def test_random_surfaces_points_within_tol_of_both_and_error_shrinks(seed, rational):
    sa = patch(seed, 0.0, rational)
    sb = patch(seed + 1, 0.9, not rational)
    # transpose sb so the two parameterisations differ
    sb = sb.swap_uv()
    errors = []
    for tol in TOLS:
        branches = intersect_surfaces(sa, sb, tol)
        assert branches, "a tilted surface crosses a flat one"
        assert all(br.max_error <= tol for br in branches)
        err = oracle_error(sa, sb, branches)
        assert err <= tol * (1 + 1e-6)
        errors.append(err)
    # a tighter tolerance gives a measurably more accurate curve, end to end over two decades
    assert errors[-1] < errors[0]


def test_sphere_and_planar_patch_meet_in_the_known_circle():
    radius, height, tol = 10.0, 3.0, 1e-4
    meridian = arc_curve([0, 0, 0], [0, 0, -1], [1, 0, 0], radius, 0.0, np.pi)
    sphere = revolution_surface(meridian, [0, 0, 0], [0, 0, 1], 0.0, 2 * np.pi)
    corners = np.array([[[-20, -20, height], [-20, 20, height]], [[20, -20, height], [20, 20, height]]], float)
    flat = NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], corners)
    branches = intersect_surfaces(sphere, flat, tol)
    pts = np.concatenate([br.curve.evaluate(np.linspace(*br.curve.domain, 400)) for br in branches])
    assert np.abs(np.hypot(pts[:, 0], pts[:, 1]) - np.sqrt(radius**2 - height**2)).max() <= tol
    assert np.abs(pts[:, 2] - height).max() <= tol
    assert np.diff(np.sort(np.arctan2(pts[:, 1], pts[:, 0]))).max() < 0.1
    assert len(branches) == 1


def _polyline(branch, n=300):
    return branch.curve.evaluate(np.linspace(*branch.curve.domain, n))


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), pick=st.integers(0, 2**16))
def test_near_traces_only_the_branches_that_pass_there_each_whole(seed, pick):
    """A bumpy surface crosses a flat one in several branches; asked for those near a few points of one,
    `intersect_surfaces(..., near=, radius=)` gives that branch and every other passing well within the
    radius, each the whole branch with its closedness (a match of a full run's within the tolerance both
    ways), and none far away."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    n, tol, radius = 8, 1e-3, 2.0
    knots = np.r_[0, 0, 0, np.linspace(0, 1, n - 2), 1, 1, 1]
    g = np.stack(np.meshgrid(np.linspace(0, 20, n), np.linspace(0, 20, n), indexing="ij"), axis=2)
    bumpy = NurbsSurface(3, 3, knots, knots, np.concatenate([g, rng.normal(0, 1.5, (n, n, 1))], axis=2))
    flat = NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1],
                        np.array([[[-1, -1, 0], [-1, 21, 0]], [[21, -1, 0], [21, 21, 0]]], float))
    full = intersect_surfaces(bumpy, flat, tol)
    if not full:
        return
    source = _polyline(full[pick % len(full)])
    near = source[rng.choice(len(source), 3, replace=False)]
    some = intersect_surfaces(bumpy, flat, tol, near=near, radius=radius)
    lines = [_polyline(b) for b in full]
    reach = np.array([cKDTree(line).query(near)[0].min() for line in lines])

    def matches(b, k):
        a, c = _polyline(b), lines[k]
        return (b.closed == full[k].closed and cKDTree(c).query(a)[0].max() <= 3 * tol
                and cKDTree(a).query(c)[0].max() <= 3 * tol)

    matched = [next((k for k in range(len(full)) if matches(b, k)), None) for b in some]
    assert None not in matched and len(set(matched)) == len(matched)
    assert pick % len(full) in matched
    assert set(np.flatnonzero(reach <= radius / 4)) <= set(matched)   # well within: found
    assert all(reach[k] <= radius + 2.0 for k in matched)             # none beyond a seed step of the radius
