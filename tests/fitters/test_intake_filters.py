"""RLTS range-image filter and cloud outlier removal, against synthetic parts with known truth."""
import numpy as np
import pytest

from rgm.fitters.filters import radius_outliers, rlts_filter, statistical_outliers
from rgm.fitters.io import ScanError, scan_from_depth
from rgm.fitters.normals import estimate_normals
from rgm.fitters.synthetic import render

VIEWS = [("box", (0.3, 0.4, -1.0)), ("cylinder", (0.2, -0.5, -1.0)), ("patch", (0.1, 0.2, -1.0))]


@pytest.mark.parametrize("part, direction", VIEWS)
def test_rlts_removes_outliers_and_keeps_good_points_and_edges(part, direction):
    view = render(part, direction, shape=(160, 160), seed=3)
    assert 0.04 < view.outlier.mean() < 0.06
    res = rlts_filter(view.scan, mode="replace")
    good = ~view.outlier
    assert res.rejected[view.outlier].mean() >= 0.95
    assert res.rejected[good].mean() <= 0.02
    assert res.rejected[good & view.edge].mean() <= 0.05  # edges and corners kept
    # kept points are untouched: nothing is smoothed, least of all across a step
    kept = ~res.rejected
    assert np.allclose(res.scan.points[np.cumsum(~res.rejected | res.replaced)[kept] - 1], view.scan.points[kept])
    # replaced outliers land back on the surface (within a few noise sigmas) for most pixels
    rep = np.flatnonzero(res.replaced & view.outlier & ~view.edge)
    new_pos = np.cumsum(~res.rejected | res.replaced)[rep] - 1
    err = np.abs(res.scan.points[new_pos, 2] - view.clean[rep, 2])
    assert np.median(err) < 3 * 0.002 * view.size
    # the robust scale matches the simulated noise (0.2 % of 100 mm) to within 25 %
    assert 0.15 < res.sigma < 0.25


def test_drop_mode_shrinks_the_scan_and_keeps_the_grid_consistent():
    view = render("box", (0.3, 0.4, -1.0), shape=(96, 96), seed=1)
    res = rlts_filter(view.scan, mode="drop")
    assert res.scan.n == view.scan.n - res.rejected.sum()
    ok = res.scan.grid >= 0
    assert ok.sum() == res.scan.n


def test_rlts_needs_a_grid():
    view = render("patch", shape=(40, 40))
    with pytest.raises(ScanError, match="range image"):
        rlts_filter(view.scan.replace(grid=None))


def test_step_edge_is_not_blurred():
    """A clean step of 20 noise sigmas: no pixel on either side is rejected or moved."""
    rng = np.random.default_rng(0)
    depth = np.where(np.arange(60)[None, :] < 31, 0.0, 4.0) + np.zeros((60, 1)) + rng.normal(0, 0.2, (60, 60))
    scan = scan_from_depth(depth)
    res = rlts_filter(scan)
    assert res.rejected.sum() <= 0.01 * scan.n
    step_cols = np.isin(scan.points[:, 0], (29.0, 30.0, 31.0, 32.0))
    assert not res.rejected[step_cols].any()
    kept = ~res.rejected
    assert np.array_equal(res.scan.points[np.cumsum(kept | res.replaced)[kept] - 1], scan.points[kept])


def test_cloud_outlier_removal_finds_scattered_points():
    view = render("patch", (0.1, 0.2, -1.0), shape=(120, 120), outliers=0.0, seed=2)
    rng = np.random.default_rng(5)
    lo, hi = view.scan.points.min(axis=0), view.scan.points.max(axis=0)
    junk = rng.uniform(lo - 10, hi + 10, size=(300, 3))
    pts = np.vstack([view.scan.points, junk])
    truth = np.r_[np.zeros(view.scan.n, bool), np.ones(300, bool)]
    # junk that happens to lie on the surface is not an outlier by any measure: count it as good
    from scipy.spatial import cKDTree
    on_surface = cKDTree(view.scan.points).query(junk)[0] < 1.0
    truth[view.scan.n:] &= ~on_surface
    sor = statistical_outliers(pts, k=12, ratio=1.0)
    ror = radius_outliers(pts, radius=3.0, min_neighbors=3)
    for flagged in (sor, ror):
        assert flagged[truth].mean() >= 0.9
        assert flagged[~truth].mean() <= 0.02


def test_normals_face_the_sensor_and_match_the_surface():
    view = render("patch", (0.1, 0.2, -1.0), shape=(100, 100), outliers=0.0, seed=4)
    n = estimate_normals(view.scan, k=16)
    assert np.allclose(np.linalg.norm(n, axis=1), 1)
    assert (n @ np.array([0, 0, 1.0]) > 0).mean() > 0.99  # the sensor is on +z of its frame
    # compare with the true normal from the noise-free points' SDF gradient
    from rgm.fitters.synthetic import freeform_patch_sdf
    pose = view.scan.pose
    world = view.clean @ pose[:3, :3].T + pose[:3, 3]
    eps = 1e-4
    grad = np.stack([(freeform_patch_sdf(world + eps * e) - freeform_patch_sdf(world - eps * e)) / (2 * eps)
                     for e in np.eye(3)], axis=1)
    grad /= np.linalg.norm(grad, axis=1, keepdims=True)
    true_n = grad @ pose[:3, :3]  # back to the sensor frame
    cos = np.einsum("ij,ij->i", n, true_n)
    interior = ~view.edge
    assert np.median(np.degrees(np.arccos(np.clip(cos[interior], -1, 1)))) < 3.0
