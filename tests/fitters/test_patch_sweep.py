"""A wrap whose profile rolls over (a can's rim) is parameterised along its profile and fitted as one closed
surface; an end across a crease is no part of that sweep."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st
from scipy.spatial import cKDTree

from rgm.fitters.creases import median_spacing
from rgm.fitters.normals import pca_normals
from rgm.fitters.patch_base import base_parameters
from rgm.fitters.patch_merge import claim_rims, take_rims
from rgm.fitters.patch_sweep import on_profile, rims, swept_parameters
from rgm.fitters.patches import _fit_piece, fit_one_piece

TOL = 0.2   # mm


def _section(t, half: tuple[float, float], corner: float):
    """Points (k, 2) and outward normals (k, 2) at arc lengths t of a rounded rectangle's boundary (half
    widths `half` in mm, corner radius `corner`)."""
    a, b = half[0] - corner, half[1] - corner
    pieces = [("line", (a, -b), (0, 1), 2 * b), ("arc", (a, b), 0.0, np.pi / 2 * corner),
              ("line", (a, b), (-1, 0), 2 * a), ("arc", (-a, b), np.pi / 2, np.pi / 2 * corner),
              ("line", (-a, b), (0, -1), 2 * b), ("arc", (-a, -b), np.pi, np.pi / 2 * corner),
              ("line", (-a, -b), (1, 0), 2 * a), ("arc", (a, -b), 3 * np.pi / 2, np.pi / 2 * corner)]
    ends = np.cumsum([p[3] for p in pieces])
    t = np.mod(t, ends[-1])
    k = np.searchsorted(ends, t, side="right")
    xy, nrm = np.zeros((len(t), 2)), np.zeros((len(t), 2))
    for i, (kind, c, d, length) in enumerate(pieces):
        m = k == i
        s = t[m] - (ends[i] - length)
        if kind == "line":
            n = np.array([d[1], -d[0]])
            xy[m], nrm[m] = np.asarray(c) + n * corner + s[:, None] * np.asarray(d), n
        else:
            ang = d + s / corner
            nrm[m] = np.c_[np.cos(ang), np.sin(ang)]
            xy[m] = np.asarray(c) + corner * nrm[m]
    return xy, nrm, ends[-1]


def _can(rng, roll: float, half=(16.0, 10.0), height=12.0, spacing=0.5):
    """A can's mantle (rounded-rectangle section, `height` mm) whose profile rolls outwards over its top
    into a bead of radius `roll` mm: up, over and down its outer side to the mantle's top height (a half
    turn of the profile, as a can's seam hangs outside), and a flat bottom across a right-angled crease.
    0.02 mm noise.
    Returns (points, mantle, bead, bottom indices, the bead's true profile arc length past the mantle)."""
    _, _, perimeter = _section(np.zeros(1), half, 4.0)
    n_mantle = int(perimeter * height / spacing ** 2)
    n_bead = int(perimeter * np.pi * roll / spacing ** 2)
    t, z = rng.uniform(0, perimeter, n_mantle), rng.uniform(0, height, n_mantle)
    xy, _, _ = _section(t, half, 4.0)
    mantle = np.c_[xy, z]
    t, phi = rng.uniform(0, perimeter, n_bead), rng.uniform(0, np.pi, n_bead)
    xy, nrm, _ = _section(t, half, 4.0)
    w, z = roll - roll * np.cos(phi), height + roll * np.sin(phi)   # up, over, down the outer side
    bead = np.c_[xy + w[:, None] * nrm, z]
    xy = rng.uniform(-np.array(half), np.array(half), (4 * n_mantle, 2))
    inside = _section_inside(xy, half, 4.0)
    bottom = np.c_[xy[inside][:n_mantle // 2], np.zeros(min(inside.sum(), n_mantle // 2))]
    points = np.r_[mantle, bead, bottom] + rng.normal(0, 0.02, (len(mantle) + len(bead) + len(bottom), 3))
    cut = np.cumsum([len(mantle), len(bead), len(bottom)])
    return points, np.arange(cut[0]), np.arange(cut[0], cut[1]), np.arange(cut[1], cut[2]), roll * phi


def _one_base(points, piece, spacing):
    """(base, (u, v)) of a piece parameterised on its own, as `rgm.fitters.patches` first does."""
    (sub, u, v, base), = base_parameters(points[piece], pca_normals(points[piece], 16)[0], spacing=spacing, depth=0)
    return base, (u, v)


def _section_inside(xy, half, corner):
    q = np.abs(xy) - (np.asarray(half) - corner)
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0) < corner


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), roll=st.floats(0.8, 1.5), aspect=st.floats(0.6, 1.0))
def test_the_parameter_runs_along_the_profile_over_the_roll(seed, roll, aspect):
    """On a rounded-rectangle can whose profile rolls over into a bead (its top horizontal, its outer side
    running down again), v follows the profile: on the bead it grows with the true arc length (over the
    top and down the far side, where the height falls), within a few point spacings."""
    rng = np.random.default_rng(seed)
    points, mantle, bead, _, arc = _can(rng, roll, half=(16.0, 16.0 * aspect))
    idx = np.r_[mantle, bead]
    spacing = median_spacing(cKDTree(points[idx]))
    normals = pca_normals(points[idx], 16)[0]
    u, v, base = swept_parameters(points[idx], normals, spacing, np.repeat([0, 1], [len(mantle), len(bead)]))
    assert base.closed and base.kind == "swept"
    v_bead = v[len(mantle):]
    scale = np.polyfit(arc, v_bead, 1)          # v is the arc length scaled to [0, 1] (either way): a line
    off = np.abs(np.polyval(scale, arc) - v_bead) / abs(scale[0])
    assert np.percentile(off, 95) <= 3 * spacing
    falling = arc > 0.6 * np.pi * roll          # down the outer side: v runs on as the height falls
    assert np.sign(scale[0]) * np.corrcoef(v_bead[falling], points[bead][falling, 2])[0, 1] < -0.9


def test_a_wrap_takes_its_rolled_rim_as_one_closed_surface_but_not_its_bottom():
    """The can's mantle and its rolled rim (no surface over the height serves the rim: its union with the
    mantle is split) are one closed surface swept along the profile, two faces, within the tolerance on
    the mantle's points and the rim's each; the mantle and its flat bottom across the crease are not."""
    points, mantle, bead, bottom, _ = _can(np.random.default_rng(4), 1.5)
    spacing = median_spacing(cKDTree(points))
    union = np.r_[mantle, bead]
    assert len(base_parameters(points[union], pca_normals(points[union], 16)[0], spacing=spacing)) > 1
    sides = np.repeat([0, 1], [len(mantle), len(bead)])
    faces = fit_one_piece(points, union, TOL, "p95", 4000, 16, spacing, sides)
    assert len(faces) == 2 and faces[0].base.wrap is faces[1].base.wrap is not None
    assert faces[0].base.kind == "swept"
    assert sorted(np.concatenate([f.indices for f in faces]).tolist()) == sorted(union.tolist())
    for side in (mantle, bead):
        off = np.concatenate([f.shape.distance(points[np.intersect1d(f.indices, side)]) for f in faces])
        assert np.percentile(off, 95) <= TOL
    ends = np.r_[mantle, bottom]
    assert fit_one_piece(points, ends, TOL, "p95", 4000, 16, spacing,
                         np.repeat([0, 1], [len(mantle), len(bottom)])) == []


def test_a_wrap_takes_the_pieces_of_its_rim_together():
    """The can's rolled rim cut into three pieces along the turn (as the crease finder leaves a rim two or
    three point spacings wide), each fitted as the pipeline fits a patch: the wrap takes all three at once,
    one closed surface swept along the profile, within the tolerance on each piece's points; the bottom
    across the crease stays a face of its own."""
    points, mantle, bead, bottom, _ = _can(np.random.default_rng(6), 1.2)
    spacing = median_spacing(cKDTree(points))

    def fit(idx, sides=None):
        return fit_one_piece(points, idx, TOL, "p95", 4000, 16, spacing, sides)

    turn = np.arctan2(*(points[bead, :2] - points[mantle, :2].mean(axis=0)).T[::-1])
    pieces = [bead[(turn >= a) & (turn < a + 2 * np.pi / 3)] for a in (-np.pi, -np.pi / 3, np.pi / 3)]
    patches = fit(mantle) + fit(bottom)
    for piece in pieces:
        patches += _fit_piece(points, piece, *_one_base(points, piece, spacing), TOL, "p95", 4000, 16, spacing, [])
    assert len(patches) >= 6
    merged, notes = take_rims(points, patches, fit, lambda idx, sides: rims(
        points[idx], pca_normals(points[idx], 16)[0], spacing, sides), spacing, TOL, "p95")
    assert len(notes) == 1 and len(merged) == 3
    wrap = [p for p in merged if p.base.wrap is not None]
    assert len(wrap) == 2 and wrap[0].base.kind == "swept"
    assert sorted(np.concatenate([f.indices for f in wrap]).tolist()) == sorted(np.r_[mantle, bead].tolist())
    for piece in pieces:
        off = np.concatenate([f.shape.distance(points[np.intersect1d(f.indices, piece)]) for f in wrap])
        assert np.percentile(off, 95) <= TOL


def test_a_band_beside_the_profile_is_no_rim():
    """Of the neighbours of a wrap, the rolled rim keeps to its rim; a band of a lid's points 3 mm wide
    running in from the mantle 2 mm below the roll (as the crease finder leaves pieces of the can's lid
    along its rim) is shallow too but lies off the profile, and the bottom runs in to the axis: neither is
    a rim, and a sweep of the wrap with either is refused."""
    rng = np.random.default_rng(8)
    points, mantle, bead, bottom, _ = _can(rng, 1.2)
    ring = points[bead[::3], :2] - points[mantle, :2].mean(axis=0)
    inward = ring * (1 - rng.uniform(0.2, 3.0, len(ring)) / np.linalg.norm(ring, axis=1))[:, None]
    band = np.c_[inward + points[mantle, :2].mean(axis=0), np.full(len(ring), 10.0)]
    points = np.r_[points, band + rng.normal(0, 0.02, band.shape)]
    band = np.arange(len(points) - len(band), len(points))
    spacing = median_spacing(cKDTree(points[mantle]))
    for others, want in (([bead, band, bottom], [1]), ([bead], [1]), ([band], []), ([bottom], [])):
        idx = np.concatenate([mantle] + others)
        sides = np.repeat(np.arange(len(others) + 1), [len(mantle)] + [len(o) for o in others])
        normals = pca_normals(points[idx], 16)[0]
        assert rims(points[idx], normals, spacing, sides).tolist() == want
        assert (swept_parameters(points[idx], normals, spacing, sides) is None) == (want != [1] * len(others))


def test_a_swept_wrap_claims_the_points_of_its_roll_a_lid_took():
    """Points of the start of the can's roll (40 % of its first 60 degrees, among the wrap's own) went to a
    flat lid across the mantle's top (as the crease finder hands a tight roll's crease points to the lid's
    tangent plane): once mantle and roll are swept, the wrap takes them back, each side within the
    tolerance, and the lid keeps its own."""
    points, mantle, bead, _, arc = _can(np.random.default_rng(9), 1.2)
    rng = np.random.default_rng(10)
    centre = points[mantle, :2].mean(axis=0)
    ring = points[mantle[:1500], :2] - centre
    disc = ring * rng.uniform(0.3, 0.95, (len(ring), 1))
    lid_xy = np.r_[disc + centre]
    points = np.r_[points, np.c_[lid_xy, np.full(len(lid_xy), 12.0)] + rng.normal(0, 0.02, (len(lid_xy), 3))]
    lid = np.arange(len(points) - len(lid_xy), len(points))
    early = bead[arc < np.pi / 3 * 1.2]                  # the roll's first 60 degrees: 40 % of them to the lid
    start = early[rng.uniform(size=len(early)) < 0.4]
    spacing = median_spacing(cKDTree(points))

    def fit(idx, sides=None):
        return fit_one_piece(points, idx, TOL, "p95", 4000, 16, spacing, sides)

    wrap_idx = np.r_[mantle, np.setdiff1d(bead, start)]
    wrap = fit(wrap_idx, np.r_[np.zeros(len(mantle), int), np.ones(len(wrap_idx) - len(mantle), int)])
    lid_fit = fit(np.r_[lid, start])
    assert len(wrap) == 2 and wrap[0].base.kind == "swept" and len(lid_fit) == 1
    claimed, notes = claim_rims(points, wrap + lid_fit, fit, lambda idx, sides: on_profile(
        points[idx], pca_normals(points[idx], 16)[0], spacing, sides), TOL)
    assert len(notes) == 1
    faces = [p for p in claimed if p.base.wrap is not None]
    (rest,) = [p for p in claimed if p.base.wrap is None]
    took = np.concatenate([f.indices for f in faces])
    # most of them (those within a point spacing of the wrap's profile and half the tolerance of its surface)
    assert np.isin(start, took).mean() >= 0.5 and not np.isin(lid, took).any()
    assert rest.shape.fit.stats.holds and np.isin(lid, rest.indices).all()
    for side in (mantle, start):
        off = np.concatenate([f.shape.distance(points[np.intersect1d(f.indices, side)]) for f in faces])
        assert np.percentile(off, 95) <= TOL


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(16, 400), flat=st.booleans(), split=st.integers(1, 15))
def test_any_union_gets_parameters_in_the_unit_square_or_none(seed, n, flat, split):
    """The merge tries the sweep on whatever union a base does not serve: on random clouds (flat, or a
    noisy tube with a random side cut off) it returns None or parameters in [0, 1]², never an error."""
    rng = np.random.default_rng(seed)
    t, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 5, n)
    points = np.c_[rng.uniform(-5, 5, (n, 2)), rng.normal(0, 0.01, n)] if flat else \
        np.c_[4 * np.cos(t), 4 * np.sin(t), z] + rng.normal(0, 0.05, (n, 3))
    sides = (np.arange(n) < split).astype(int)
    spacing = median_spacing(cKDTree(points))
    out = swept_parameters(points, pca_normals(points, min(16, n))[0], spacing, sides)
    if out is not None:
        u, v, base = out
        assert base.closed and np.all((u >= 0) & (u < 1)) and np.all((v >= 0) & (v <= 1))
    assert len(rims(points, pca_normals(points, min(16, n))[0], spacing, sides)) <= 1
