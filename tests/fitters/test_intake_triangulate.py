"""Triangulation to a tolerance: every input point within T of the mesh, checked by independent oracles."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from rgm.fitters.io import ScanError, Scan, read_scan, scan_from_depth
from rgm.fitters.synthetic import render
from rgm.fitters.triangulate import triangulate

BUNNY = Path(__file__).parent.parent / "data" / "bunny"


def _pixel_of(scan):
    """(n, 2) pixel (col, row) of every point of a range image."""
    pos = np.argwhere(scan.grid >= 0)
    out = np.empty((scan.n, 2))
    out[scan.grid[pos[:, 0], pos[:, 1]]] = pos[:, ::-1]
    return out


def _oracle(scan, mesh, depth_axis):
    """Brute force over all (triangle, pixel) pairs: each valid pixel's smallest error along the view
    over the triangles containing it (inf if none), and whether a triangle covers an invalid pixel."""
    rows, cols = scan.grid.shape
    r, c = np.mgrid[0:rows, 0:cols]
    return _brute(np.column_stack([c.ravel(), r.ravel()]).astype(float), scan.grid.ravel(),
                  _pixel_of(scan), scan.points @ depth_axis, mesh)


def _brute(q, qid, uv, depth, mesh):
    """q (k, 2) query positions with point ids qid (k,) (-1: invalid pixel); uv (n, 2), depth (n,) of the
    points. Returns (smallest error per point over the triangles containing it, covers-invalid flag)."""
    tri_px = uv[mesh.vertex_index][mesh.triangles]                         # (m, 3, 2)
    tri_d = depth[mesh.vertex_index][mesh.triangles]                       # (m, 3)
    a, b, cc = tri_px[:, 0], tri_px[:, 1], tri_px[:, 2]
    det = (b[:, 0] - a[:, 0]) * (cc[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (cc[:, 0] - a[:, 0])
    best = np.full(len(depth), np.inf)
    best[mesh.vertex_index] = 0.0
    covers_invalid = False
    for s in range(0, len(a), 256):
        sl = slice(s, s + 256)
        dx, dy = q[None, :, 0] - a[sl, None, 0], q[None, :, 1] - a[sl, None, 1]
        u = (dx * (cc[sl, None, 1] - a[sl, None, 1]) - dy * (cc[sl, None, 0] - a[sl, None, 0])) / det[sl, None]
        v = (dy * (b[sl, None, 0] - a[sl, None, 0]) - dx * (b[sl, None, 1] - a[sl, None, 1])) / det[sl, None]
        inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
        covers_invalid |= bool((inside & (qid[None, :] < 0)).any())
        ti, pi = np.nonzero(inside & (qid[None, :] >= 0))
        uu, vv = u[ti, pi], v[ti, pi]
        zi = (1 - uu - vv) * tri_d[s + ti, 0] + uu * tri_d[s + ti, 1] + vv * tri_d[s + ti, 2]
        np.minimum.at(best, qid[pi], np.abs(depth[qid[pi]] - zi))
    return best, covers_invalid


@st.composite
def range_images(draw):
    rows, cols = draw(st.integers(20, 56)), draw(st.integers(20, 56))
    seed = draw(st.integers(0, 2 ** 31 - 1))
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:rows, 0:cols].astype(float)
    z = np.zeros((rows, cols))
    for _ in range(draw(st.integers(1, 5))):  # smooth bumps of random size and sign
        cx, cy, w, h = rng.uniform(0, cols), rng.uniform(0, rows), rng.uniform(2, 15), rng.uniform(-5, 5)
        z += h * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * w * w))
    if draw(st.booleans()):  # a step (depth discontinuity) across a random line
        nx, ny = rng.normal(size=2)
        z += np.where(nx * (x - cols / 2) + ny * (y - rows / 2) > 0, rng.uniform(8, 20), 0.0)
    z += rng.normal(0, draw(st.sampled_from([0.0, 0.02, 0.1])), z.shape)
    if draw(st.booleans()):  # invalid pixels: a hole and a ragged border
        z[(x - rng.uniform(0, cols)) ** 2 + (y - rng.uniform(0, rows)) ** 2 < rng.uniform(4, 60)] = np.nan
        z[rng.random(z.shape) < 0.02] = np.nan
    return scan_from_depth(z), draw(st.sampled_from([0.05, 0.2, 0.5, 1.0]))


@settings(max_examples=40, deadline=None)
@given(range_images())
def test_every_point_within_tolerance_of_the_mesh(case):
    scan, tol = case
    mesh = triangulate(scan, tol)
    best, covers_invalid = _oracle(scan, mesh, np.array([0.0, 0.0, 1.0]))
    assert not covers_invalid                                          # no triangle over an invalid pixel
    covered = np.isfinite(best)
    assert (best[covered] <= tol * (1 + 1e-9) + 1e-12).all()
    assert (~covered).sum() == mesh.uncovered
    # only pixels next to trouble are left out: an invalid pixel, the image border or a depth step
    g = np.pad(scan.grid, 1, constant_values=-1)
    z = np.pad(np.where(scan.grid >= 0, scan.points[np.maximum(scan.grid, 0), 2], np.nan), 1, constant_values=np.nan)
    trouble = np.zeros(scan.grid.shape, bool)
    rows, cols = scan.grid.shape
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            nb_g = g[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols]
            nb_z = z[1 + dr:1 + dr + rows, 1 + dc:1 + dc + cols]
            trouble |= (nb_g < 0) | (np.abs(nb_z - z[1:-1, 1:-1]) > 6.0 * np.hypot(dr, dc))
    lonely = np.flatnonzero(~covered)
    assert trouble[scan.grid >= 0][np.argsort(scan.grid[scan.grid >= 0])][lonely].all()
    assert mesh.max_error <= tol and abs(mesh.max_error - best[covered].max()) < 1e-9
    # no triangle spans a discontinuity: no edge steeper than the slope limit (6 = 80 degrees)
    p = mesh.vertices
    for i, j in ((0, 1), (1, 2), (2, 0)):
        e = p[mesh.triangles[:, j]] - p[mesh.triangles[:, i]]
        assert (np.abs(e[:, 2]) <= 6.0 * np.hypot(e[:, 0], e[:, 1]) + 1e-9).all()


def test_box_range_image_keeps_the_step_and_is_coarse_on_flat_faces():
    view = render("box", (0.3, 0.4, -1.0), shape=(120, 120), noise=0.0, outliers=0.0)
    mesh = triangulate(view.scan, 0.05)
    assert mesh.max_error <= 0.05 and mesh.uncovered <= 0.01 * view.scan.n
    assert len(mesh.triangles) < 0.2 * view.scan.n                    # planes need few triangles
    normals = np.cross(mesh.vertices[mesh.triangles[:, 1]] - mesh.vertices[mesh.triangles[:, 0]],
                       mesh.vertices[mesh.triangles[:, 2]] - mesh.vertices[mesh.triangles[:, 0]])
    assert (normals[:, 2] > 0).all()                                   # facing the sensor (+z)


def test_bunny_view_to_half_a_millimetre():
    scan = read_scan(BUNNY / "bun000.ply")
    mesh = triangulate(scan, 0.0005)
    best, covers_invalid = _oracle(scan, mesh, np.array([0.0, 0.0, 1.0]))
    assert not covers_invalid
    assert best[np.isfinite(best)].max() <= 0.0005
    assert len(mesh.vertices) < scan.n


def test_unstructured_view_in_its_best_fit_plane():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-20, 20, size=(1500, 2))
    z = 3 * np.sin(xy[:, 0] / 6) + 0.05 * xy[:, 1] ** 2 / 10
    tilt = np.array([[1, 0, 0], [0, np.cos(0.4), -np.sin(0.4)], [0, np.sin(0.4), np.cos(0.4)]])
    pts = np.column_stack([xy, z]) @ tilt.T
    mesh = triangulate(Scan(pts), 0.1)
    centred = pts - pts.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]                 # the best-fit plane, independently
    best, _ = _brute(centred @ axes[:2].T, np.arange(len(pts)), centred @ axes[:2].T, centred @ axes[2], mesh)
    assert best.max() <= 0.1 + 1e-9
    assert mesh.uncovered == 0 and len(mesh.vertices) < 0.5 * len(pts)


def test_bad_input():
    with pytest.raises(ScanError, match="tolerance must be positive"):
        triangulate(Scan(np.eye(3)), 0.0)
    with pytest.raises(ScanError, match="collinear"):
        triangulate(Scan(np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])), 0.1)


def test_rgmc_triangulate_command(tmp_path, capsys):
    import json

    from rgm.cli import main

    y, x = np.mgrid[0:60, 0:80].astype(float)
    depth = 5 * np.exp(-((x - 40) ** 2 + (y - 30) ** 2) / 200)
    depth[:10, :10] = np.nan
    np.save(tmp_path / "d.npy", depth)
    out, rep = tmp_path / "m.ply", tmp_path / "t.json"
    assert main(["triangulate", str(tmp_path / "d.npy"), "--tol", "0.05", "-o", str(out), "--report", str(rep)]) == 0
    report = json.loads(rep.read_text())
    assert report["max_error"] <= 0.05 and report["triangles"] > 0
    mesh = read_scan(out)
    assert len(mesh.faces) == report["triangles"]
    assert "triangles" in capsys.readouterr().out
    assert main(["triangulate", str(tmp_path / "d.npy"), "--tol", "-1", "-o", str(tmp_path / "n.ply")]) == 1
    assert "--tol must be positive" in capsys.readouterr().err
