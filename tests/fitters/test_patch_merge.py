"""Neighbouring patches one surface serves are merged; patches across a crease, or a sliver across one, are not."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial import cKDTree

from rgm.fitters.creases import median_spacing
from rgm.fitters.patch_merge import merge_neighbours, neighbour_pairs
from rgm.fitters.patches import fit_one_piece

TOL = 0.2   # mm


def _scatter(rng, n, lo, hi):
    return rng.uniform(lo, hi, size=(n, 2))


def _fitted(points, groups):
    spacing = median_spacing(cKDTree(points))

    def fit(idx, sides=None):
        return fit_one_piece(points, idx, TOL, "p95", 2000, 16, spacing, sides)

    return [fit(g)[0] for g in groups], fit, spacing


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cut=st.floats(-15, 15), tilt=st.floats(-1.0, 1.0))
def test_a_smooth_surface_cut_in_two_becomes_one_patch(seed, cut, tilt):
    """A smooth bump (60 x 60 mm, 0.02 mm noise) cut in two by an arbitrary line: the two patches merge into
    one whose surface meets the tolerance on all the points, with no more control points than both had."""
    rng = np.random.default_rng(seed)
    xy = _scatter(rng, 2500, -30, 30)
    z = 6 * np.exp(-(xy ** 2).sum(1) / 600) + 0.05 * xy[:, 0] + rng.normal(0, 0.02, len(xy))
    points = np.c_[xy, z]
    side = xy[:, 0] + tilt * xy[:, 1] < cut
    groups = [np.flatnonzero(side), np.flatnonzero(~side)]
    patches, fit, spacing = _fitted(points, groups)
    assert neighbour_pairs(points, patches, spacing) == [(0, 1)]
    merged, notes = merge_neighbours(points, patches, fit, spacing, TOL, "p95")
    assert len(merged) == 1 and len(notes) == 1
    one = merged[0]
    assert sorted(one.indices.tolist()) == list(range(len(points)))
    assert one.shape.fit.stats.holds and one.shape.fit.n_ctrl <= sum(p.shape.fit.n_ctrl for p in patches)
    assert np.percentile(one.shape.distance(points[one.indices]), 95) <= TOL


def test_two_faces_across_a_sharp_edge_stay_apart():
    """Two planes meeting at 90 degrees (the edge of a box) and a 3 mm strip bent at 90 degrees off a
    large plane (a sliver across a crease: 2.6 % of the union's points, which p95 alone lets a single
    surface of 24 control points ignore: its p95 on the strip is 1.6 mm) are not merged."""
    rng = np.random.default_rng(7)
    top = _scatter(rng, 1500, 0, 40)
    side = _scatter(rng, 1500, 0, 40)
    points = np.r_[np.c_[top, np.zeros(len(top))], np.c_[np.full(len(side), 40.0), side[:, 0], -side[:, 1]]]
    points = points + rng.normal(0, 0.02, points.shape)
    groups = [np.arange(1500), np.arange(1500, 3000)]
    patches, fit, spacing = _fitted(points, groups)
    merged, notes = merge_neighbours(points, patches, fit, spacing, TOL, "p95")
    assert len(merged) == 2 and notes == []

    rng = np.random.default_rng(3)
    strip = rng.uniform([0, 0], [40, 3], size=(40, 2))
    points = np.r_[np.c_[top, np.zeros(len(top))], np.c_[np.full(len(strip), 40.0), strip[:, 0], -strip[:, 1]]]
    points = points + rng.normal(0, 0.02, points.shape)
    groups = [np.arange(1500), np.arange(1500, len(points))]
    patches, fit, spacing = _fitted(points, groups)
    assert neighbour_pairs(points, patches, spacing) == [(0, 1)]
    merged, notes = merge_neighbours(points, patches, fit, spacing, TOL, "p95")
    assert len(merged) == 2 and notes == []


def _can(rng, flange: bool):
    """A closed mantle (r 30 mm, 40 mm high, 0.02 mm noise) and a 60-degree strip along its top rim: a bead
    rolled outwards (1 mm out over 4 mm of height, its normal turning up to 38 degrees, as a can's rim)
    or a flat flange 4 mm wide (a real crease). Returns (points, mantle indices, strip indices)."""
    t, z = rng.uniform(0, 2 * np.pi, 7500), rng.uniform(0, 40, 7500)
    mantle = np.c_[30 * np.cos(t), 30 * np.sin(t), z]
    t = rng.uniform(0, np.pi / 3, 150)
    if flange:
        r, z = rng.uniform(30.5, 34, len(t)), np.full(len(t), 40.0)
    else:
        z = rng.uniform(40.5, 44, len(t))
        r = 30 + np.sin(np.pi * (z - 40) / 4)
    strip = np.c_[r * np.cos(t), r * np.sin(t), z]
    points = np.r_[mantle, strip] + rng.normal(0, 0.02, (len(mantle) + len(strip), 3))
    return points, np.arange(len(mantle)), np.arange(len(mantle), len(points))


@pytest.mark.parametrize("flange", [False, True])
def test_a_closed_wrap_takes_a_bead_along_its_rim_but_not_a_flange(flange):
    """A closed mantle's two faces and a strip along its rim: the rolled bead is absorbed (one closed surface,
    two faces, meets the tolerance on the bead's points and on the mantle's each), the flange across a
    right-angled crease is not."""
    points, mantle, strip = _can(np.random.default_rng(5), flange)
    spacing = median_spacing(cKDTree(points))

    def fit(idx, sides=None):
        return fit_one_piece(points, idx, TOL, "p95", 2000, 16, spacing, sides)

    wrap, (bead,) = fit(mantle), fit(strip)
    assert len(wrap) == 2 and all(face.base.wrap is wrap[0].base.wrap is not None for face in wrap)
    merged, notes = merge_neighbours(points, wrap + [bead], fit, spacing, TOL, "p95")
    if flange:
        assert len(merged) == 3 and notes == []
        return
    assert len(merged) == 2 and len(notes) == 1
    assert merged[0].base.wrap is merged[1].base.wrap is not None
    assert sorted(np.concatenate([face.indices for face in merged]).tolist()) == list(range(len(points)))
    for side in (mantle, strip):
        off = np.concatenate([face.shape.distance(points[np.intersect1d(face.indices, side)]) for face in merged])
        assert np.percentile(off, 95) <= TOL
