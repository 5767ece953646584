"""Seams closed by growing a trim (`rgm.fitters.seam_cover`): where two patches' surfaces pass within the
tolerance of each other but their trims stop short (no edge shared), one face's trim is grown to the
other's edge. The oracle is independent of the growing: points of the true surface across the band
between the halves' data lie within the tolerance of a face as trimmed after, and did not before."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from rgm.fitters.creases import median_spacing
from rgm.fitters.patch_base import Base, reach_past, unit_box
from rgm.fitters.patches import _covered, _fit_patch, g0_gaps, written_face
from rgm.fitters.trimloops import check_loops


def _halves(seed, gap, tilt_deg):
    """Two patches of a gently curved sheet (z = 0.002 x^2 mm) 60 x 40 mm, split at x = 0 with a band
    `gap` mm wide left without data, the right half tilted by `tilt_deg` about the y axis (their surfaces
    then cross at a small angle: no edge is shared there, as on a fitted bottle's shoulder)."""
    rng = np.random.default_rng(seed)
    p = np.c_[rng.uniform(-30, 30, 6000), rng.uniform(-20, 20, 6000)]
    p = p[np.abs(p[:, 0]) > gap / 2]
    z = 0.002 * p[:, 0] ** 2 + rng.normal(0, 0.02, len(p))
    right = p[:, 0] > 0
    t = np.radians(tilt_deg)
    x = np.where(right, p[:, 0] * np.cos(t), p[:, 0])
    z = np.where(right, z + p[:, 0] * np.sin(t), z)
    pts = np.c_[x, p[:, 1], z]
    return pts, np.flatnonzero(~right), np.flatnonzero(right)


def _hole(patches, tilt_deg, tol):
    """The largest distance from the sheet's true surface across the band between the two halves' data
    (x in [-0.6, 0.6] mm, |y| <= 18: away from the free borders) to the nearer of the two faces as
    trimmed: over `tol`, the model has a hole there."""
    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 7), np.linspace(-18, 18, 61))
    x, y = x.ravel(), y.ravel()
    t = np.radians(tilt_deg)
    z = 0.002 * x**2 + np.where(x > 0, x * np.sin(t), 0.0)
    probe = np.c_[np.where(x > 0, x * np.cos(t), x), y, z]
    return float(np.minimum(*(written_face(q.shape).distance(probe) for q in patches)).max())


@pytest.mark.parametrize("seed", [0, 1])
def test_a_gap_between_trims_closes_where_the_surfaces_pass_within_tol(seed):
    tol = 0.3
    points, left, right = _halves(seed, gap=1.2, tilt_deg=1.0)
    spacing = median_spacing(cKDTree(points))
    patches = []
    for idx in (left, right):
        uv = unit_box(points[idx][:, :2])
        patches.append(_fit_patch(points, idx, Base("plane", 1.0), reach_past(points[idx], *uv, 5 * spacing),
                                  tol, "p95", 4000))
    gaps = g0_gaps(points, patches, 5 * spacing)
    assert len(gaps) == 1 and gaps[0].max > 2 * tol     # the trims stop at their data, 1.2 mm apart
    assert _hole(patches, 1.0, tol) > 2 * tol
    grown, after = _covered(points, patches, gaps, tol, "p95", 5 * spacing)
    # the surfaces and their certificates are the ones fitted; only a trim changed, and it is valid
    assert all(g.shape.fit is p.shape.fit for g, p in zip(grown, patches))
    assert sum(g.shape is not p.shape for g, p in zip(grown, patches)) == 1
    assert all(check_loops(g.shape.loops.outer, g.shape.loops.holes) == [] for g in grown)
    # no hole is left across the band (independent of the seam measure), and the seam's samples are
    # within the tolerance of the other face but at its ends, where a grown face's free border runs on
    # past the other's corner (g0_gaps counts those samples too: it does not know the border is free)
    assert _hole(grown, 1.0, tol) <= tol
    assert len(after) == 1 and after[0].p95 <= tol and after[0].max < gaps[0].max

def test_a_gap_the_surfaces_do_not_close_is_left_as_measured():
    """Surfaces 20 degrees apart leave more than the tolerance between them a few tenths of a mm from
    where they cross: nothing to cover within it, so the seam keeps its figure (no trim is grown to a
    surface that is not there)."""
    tol = 0.05
    points, left, right = _halves(2, gap=1.2, tilt_deg=20.0)
    spacing = median_spacing(cKDTree(points))
    patches = []
    for idx in (left, right):
        uv = unit_box(points[idx][:, :2])
        patches.append(_fit_patch(points, idx, Base("plane", 1.0), reach_past(points[idx], *uv, 5 * spacing),
                                  tol, "p95", 4000))
    gaps = g0_gaps(points, patches, 5 * spacing)
    grown, after = _covered(points, patches, gaps, tol, "p95", 5 * spacing)
    assert after[0].max > tol
    assert after[0].max >= 0.9 * gaps[0].max or all(g.shape is p.shape for g, p in zip(grown, patches))
