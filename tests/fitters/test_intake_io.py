"""Scan readers: PLY ascii/binary, range grids, text clouds, .conf poses, and clear refusals."""
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from rgm.errors import RgmError
from rgm.fitters.io import (
    Scan, ScanError, conf_from_pose, pose_from_conf, read_conf, read_scan, read_views, scan_from_depth,
    write_conf, write_ply,
)

BUNNY = Path(__file__).parent.parent / "data" / "bunny"
SHARED = Path("/work/shared/data")


def test_bunny_copy_range_grid_and_poses():
    views = read_conf(BUNNY / "bun.conf")
    assert [Path(v.source).name for v in views] == ["bun000.ply", "bun045.ply", "bun090.ply", "bun180.ply",
                                                    "bun270.ply", "top2.ply", "top3.ply", "bun315.ply",
                                                    "chin.ply", "ear_back.ply"]
    v0 = views[0]
    assert v0.grid.shape == (100, 128)
    valid = v0.grid >= 0
    assert valid.sum() == v0.n  # every point is in exactly one cell
    assert np.array_equal(np.sort(v0.grid[valid]), np.arange(v0.n))
    # neighbouring cells hold neighbouring points: ~4 x 0.5 mm apart along a row
    r, c = np.nonzero(valid[:, :-1] & valid[:, 1:])
    step = np.linalg.norm(v0.points[v0.grid[r, c + 1]] - v0.points[v0.grid[r, c]], axis=1)
    assert 0.0015 < np.median(step) < 0.003
    assert np.allclose(v0.pose, np.eye(4))
    # bun090 is a ~90 degree turn about y
    angle = np.degrees(np.arccos((np.trace(views[2].pose[:3, :3]) - 1) / 2))
    assert abs(angle - 90) < 1.0


@pytest.mark.skipif(not (SHARED / "stanford-bunny").exists(), reason="shared data not present")
def test_binary_bunny_copies_match_the_originals():
    """The binary copies (bun180 ...) hold exactly every 4th row and column of the original ASCII views."""
    for name in ("bun180.ply", "ear_back.ply"):
        copy = read_scan(BUNNY / name)
        original = read_scan(SHARED / "stanford-bunny" / name).decimate(4)
        assert b"binary_little_endian" in (BUNNY / name).read_bytes()[:100]
        assert np.array_equal(copy.grid, original.grid)
        assert np.allclose(copy.points, original.points, atol=1e-7)
        assert np.array_equal(copy.view_dir, original.view_dir)


def test_binary_lists_of_any_length(tmp_path):
    """Binary PLY lists of mixed lengths (triangles and quads; a range grid's empty and one-index cells) are
    read vectorised: triangles kept, other polygons skipped, grid cells in place; truncation refused."""
    pts = np.arange(18, dtype="<f4").reshape(6, 3)
    polys = [[0, 1, 2], [1, 2, 3, 4], [3, 4, 5], [], [0, 5, 1]]
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
            "property float z\nelement face 5\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = b"".join(bytes([len(f)]) + np.array(f, "<i4").tobytes() for f in polys)
    (tmp_path / "m.ply").write_bytes(head + pts.tobytes() + body)
    assert read_scan(tmp_path / "m.ply").faces.tolist() == [[0, 1, 2], [3, 4, 5], [0, 5, 1]]
    (tmp_path / "cut.ply").write_bytes(head + pts.tobytes() + body[:-3])
    with pytest.raises(ScanError, match="cut.ply: file ends inside element `face`"):
        read_scan(tmp_path / "cut.ply")
    grid = [-1, 0, 1, -1, 2, -1]
    head = ("ply\nformat binary_big_endian 1.0\nobj_info num_cols 3\nobj_info num_rows 2\nelement vertex 3\n"
            "property float x\nproperty float y\nproperty float z\nelement range_grid 6\n"
            "property list uchar int vertex_indices\nend_header\n").encode()
    body = b"".join(b"\x00" if g < 0 else b"\x01" + np.array([g], ">i4").tobytes() for g in grid)
    (tmp_path / "g.ply").write_bytes(head + pts[:3].astype(">f4").tobytes() + body)
    scan = read_scan(tmp_path / "g.ply")
    assert scan.grid.tolist() == [[-1, 0, 1], [-1, 2, -1]] and np.allclose(scan.points, pts[:3])


@pytest.mark.skipif(not (SHARED / "pcl").exists(), reason="shared data not present")
def test_pcl_organised_binary_cloud_keeps_grid_and_drops_nan():
    scan = read_scan(SHARED / "pcl" / "table_scene_mug_stereo_textured.ply")
    assert scan.grid.shape == (480, 640)
    assert scan.n == (scan.grid >= 0).sum() < 480 * 640
    assert np.isfinite(scan.points).all()
    assert np.allclose(scan.origin, 0)


@settings(max_examples=30, deadline=None)
@given(n=st.integers(3, 200), binary=st.booleans(), seed=st.integers(0, 10_000))
def test_ply_round_trip(tmp_path_factory, n, binary, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3)).astype(np.float32).astype(float)
    faces = rng.integers(0, n, size=(max(1, n // 2), 3))
    path = tmp_path_factory.mktemp("ply") / "a.ply"
    if binary:
        write_ply(path, pts, faces)
    else:  # ascii written by hand, as other tools do
        lines = ["ply", "format ascii 1.0", f"element vertex {n}", "property float x", "property float y",
                 "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices",
                 "end_header"] + [" ".join(str(float(v)) for v in p) for p in pts] + ["3 " + " ".join(map(str, f)) for f in faces]
        path.write_text("\n".join(lines) + "\n")
    scan = read_scan(path)
    assert np.allclose(scan.points, pts)
    assert np.array_equal(scan.faces, faces)


def test_big_endian_binary_ply(tmp_path):
    pts = np.array([[0, 0, 0], [1, 2, 3], [4, 5, 6.5]], ">f4")
    head = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    (tmp_path / "b.ply").write_bytes(head + pts.tobytes())
    assert np.allclose(read_scan(tmp_path / "b.ply").points, pts.astype(float))


def test_text_clouds(tmp_path):
    (tmp_path / "a.xyz").write_text("# x y z\n0 0 0\n1 0 0 7\n0 1 0\n")
    (tmp_path / "a.pts").write_text("3\n0 0 0 5 1 2 3\n1 0 0 5 1 2 3\n0,1,0\n")
    for f in ("a.xyz", "a.pts"):
        assert np.allclose(read_scan(tmp_path / f).points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_depth_grids_with_mask(tmp_path):
    depth = np.arange(12, dtype=float).reshape(3, 4)
    depth[0, 1] = np.nan
    mask = np.ones((3, 4), bool)
    mask[2, 3] = False
    np.save(tmp_path / "d.npy", depth)
    np.save(tmp_path / "m.npy", mask)
    scan = read_scan(tmp_path / "d.npy", mask=tmp_path / "m.npy", pitch=0.5)
    assert scan.n == 10 and scan.grid[0, 1] == -1 and scan.grid[2, 3] == -1
    assert np.allclose(scan.points[scan.grid[1, 2]], [1.0, 0.5, 6.0])
    np.savez(tmp_path / "d.npz", depth=depth, mask=mask)
    assert read_scan(tmp_path / "d.npz").n == 10
    (tmp_path / "d.grid").write_text("1 2 nan\n4 5 6\n")
    assert read_scan(tmp_path / "d.grid").grid.tolist() == [[0, 1, -1], [2, 3, 4]]


def test_pose_conf_round_trip(tmp_path):
    views = read_conf(BUNNY / "bun.conf")
    for v in views:
        t, q = conf_from_pose(v.pose)
        assert np.allclose(pose_from_conf(t, q), v.pose)
    write_conf(tmp_path / "out.conf", views, [v.pose for v in views])
    again = read_views([BUNNY / "bun045.ply"], poses=tmp_path / "out.conf")
    assert np.allclose(again[0].pose, views[1].pose, atol=1e-8)


def test_select_and_decimate_keep_grid_consistent():
    scan = read_scan(BUNNY / "bun000.ply")
    keep = np.arange(scan.n) % 3 != 0
    sub = scan.select(keep)
    ok = sub.grid >= 0
    assert np.allclose(sub.points[sub.grid[ok]], scan.points[scan.grid[ok]])
    dec = scan.decimate(2)
    ok = dec.grid >= 0
    assert np.allclose(dec.points[dec.grid[ok]], scan.points[scan.grid[::2, ::2][ok]])


@pytest.mark.parametrize("content, message", [
    (b"", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n", "empty"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 nan 0\n", "NaN"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 inf\n1 1 0\n", "infinite"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n1 2 3\n1 2 3\n", "all 3 points are equal"),
    (b"ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n", "grid size mismatch"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty flot x\nend_header\n", "unreadable PLY header"),
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n", "ends inside"),
])
def test_bad_ply_is_refused_with_file_name(tmp_path, content, message):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(ScanError, match=message) as info:
        read_scan(path)
    assert "bad.ply" in str(info.value)
    assert isinstance(info.value, RgmError)


def test_other_refusals(tmp_path):
    (tmp_path / "e.xyz").write_text("")
    with pytest.raises(ScanError, match="e.xyz.*empty"):
        read_scan(tmp_path / "e.xyz")
    with pytest.raises(ScanError, match="no such file"):
        read_scan(tmp_path / "missing.ply")
    with pytest.raises(ScanError, match="unknown scan format"):
        (tmp_path / "a.foo").write_text("x")
        read_scan(tmp_path / "a.foo")
    with pytest.raises(ScanError, match="grid size mismatch"):
        scan_from_depth(np.zeros((3, 4)), mask=np.ones((4, 3), bool))
    (tmp_path / "r.grid").write_text("1 2 3\n4 5\n")
    with pytest.raises(ScanError, match="grid size mismatch"):
        read_scan(tmp_path / "r.grid")
    with pytest.raises(ScanError, match="all 12 points are equal"):
        scan_from_depth(np.ones((3, 4, 3)))


def test_mesh_formats_through_trimesh(tmp_path):
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scan = read_scan(tmp_path / "t.obj")
    assert scan.n == 3 and scan.faces.tolist() == [[0, 1, 2]]
    assert isinstance(scan, Scan)


def test_stl_ascii_and_binary(tmp_path):
    """STL through trimesh: a tetrahedron written by hand as ASCII and as binary STL (the binary one
    written with numpy: 80-byte header, count, 50-byte records); corners shared by faces come back once
    (trimesh merges STL's per-face vertices) and every face uses the right corners."""
    corners = np.array([[0, 0, 0], [10, 0, 0], [0, 20, 0], [0, 0, 30]], float)
    tris = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    lines = ["solid tet"]
    for t in tris:
        lines += ["facet normal 0 0 0", "outer loop"] + [f"vertex {x} {y} {z}" for x, y, z in corners[t]]
        lines += ["endloop", "endfacet"]
    (tmp_path / "a.stl").write_text("\n".join(lines + ["endsolid tet"]) + "\n")
    rec = np.zeros(len(tris), np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
    rec["v"] = corners[tris]
    (tmp_path / "b.stl").write_bytes(b"\0" * 80 + np.uint32(len(tris)).tobytes() + rec.tobytes())
    for name in ("a.stl", "b.stl"):
        scan = read_scan(tmp_path / name)
        assert scan.n == 4 and len(scan.faces) == 4
        got = {tuple(sorted(map(tuple, scan.points[f]))) for f in scan.faces}
        assert got == {tuple(sorted(map(tuple, corners[t]))) for t in tris}
    (tmp_path / "bad.stl").write_bytes(b"\0" * 80 + np.uint32(0).tobytes())
    with pytest.raises(ScanError, match="bad.stl"):
        read_scan(tmp_path / "bad.stl")
