"""Registration: known synthetic transforms, the real bunny against bun.conf, and honest statuses."""
from pathlib import Path

import numpy as np
import pytest

from rgm.fitters.filters import rlts_filter
from rgm.fitters.io import read_conf
from rgm.fitters.normals import estimate_normals
from rgm.fitters.register import coarse_align, icp, pose_error, register_views
from rgm.fitters.synthetic import render

BUNNY = Path(__file__).parent.parent / "data" / "bunny"


def _relative_truth(a, b):
    return np.linalg.inv(a.scan.pose) @ b.scan.pose


@pytest.mark.parametrize("part, dir_a, dir_b", [
    ("patch", (0.2, 0.1, -1.0), (-0.5, 0.3, -1.0)),
    ("box", (0.3, 0.5, -1.0), (0.7, 0.3, -1.0)),
])
def test_known_transform_recovered_after_filtering(part, dir_a, dir_b):
    """Noisy views (0.2 %) with 5 % outliers, filtered, registered with no initial pose."""
    a = render(part, dir_a, shape=(120, 120), seed=11)
    b = render(part, dir_b, shape=(120, 120), seed=12)
    fa = rlts_filter(a.scan, mode="drop").scan
    fb = rlts_filter(b.scan, mode="drop").scan
    na, nb = estimate_normals(fa), estimate_normals(fb)
    T, res = coarse_align(fb.points, fa.points, na, nb, seed=0)
    assert res.condition > 2e-3  # well constrained: the test is about accuracy
    angle, shift, _ = pose_error(T, _relative_truth(a, b), fb.points)
    assert np.degrees(angle) <= 0.05
    assert shift <= 0.001 * a.size
    assert res.converged and res.overlap > 0.5


def test_icp_from_a_nearby_pose_matches_the_coarse_result():
    a = render("patch", (0.0, 0.0, -1.0), shape=(120, 120), outliers=0.0, seed=1)
    b = render("patch", (0.3, 0.2, -1.0), shape=(120, 120), outliers=0.0, seed=2)
    truth = _relative_truth(a, b)
    rot = np.array([[np.cos(0.1), -np.sin(0.1), 0], [np.sin(0.1), np.cos(0.1), 0], [0, 0, 1]])
    init = truth.copy()
    init[:3, :3] = rot @ truth[:3, :3]
    init[:3, 3] += [3.0, -2.0, 1.0]
    res = icp(b.scan.points, a.scan.points, estimate_normals(a.scan), init, source_normals=estimate_normals(b.scan))
    angle, shift, _ = pose_error(res.transform, truth, b.scan.points)
    assert np.degrees(angle) < 0.05 and shift < 0.1
    assert res.iterations < 60 and res.converged


def test_bunny_views_from_identity_land_on_bun_conf():
    """Real data: three bunny views 45 degrees apart, identity start, incremental + refinement."""
    views = read_conf(BUNNY / "bun.conf")
    reports = register_views([v.replace(pose=np.eye(4)) for v in views])
    assert [r.status for r in reports] == ["reference", "ok", "ok"]
    for view, rep in zip(views, reports):
        _, _, rms = pose_error(rep.transform, view.pose, view.points)
        assert rms < 0.001  # metres: 1 mm
        assert rep.rms < 0.001
    assert reports[1].overlap > 0.5


def test_symmetric_part_is_flagged_degenerate():
    """A cylinder's views leave the rotation about its axis unconstrained: never a silent 'ok'."""
    a = render("cylinder", (0.0, 0.3, -1.0), shape=(120, 120), outliers=0.0, seed=3)
    b = render("cylinder", (0.0, -0.3, -1.0), shape=(120, 120), outliers=0.0, seed=4)
    sa = a.scan.replace(pose=np.eye(4))
    sb = b.scan.replace(pose=_relative_truth(a, b))
    reports = register_views([sa, sb], use_poses=True)
    assert reports[1].status == "degenerate"
    assert "rotation x" in reports[1].reasons[0]


def test_low_overlap_and_wrong_match_are_flagged():
    a = render("box", (0.2, 0.1, -1.0), shape=(100, 100), outliers=0.0, seed=5)
    b = render("box", (-0.2, -0.1, 1.0), shape=(100, 100), outliers=0.0, seed=6)  # the opposite side
    reports = register_views([a.scan.replace(pose=np.eye(4)), b.scan.replace(pose=_relative_truth(a, b))],
                             use_poses=True)
    assert reports[1].status != "ok"
    assert any(r.startswith("low_overlap") for r in reports[1].reasons)


def test_rgmc_register_command(tmp_path, capsys):
    import json

    from rgm.cli import main
    from rgm.fitters.io import read_scan

    out, rep, conf = tmp_path / "merged.ply", tmp_path / "reg.json", tmp_path / "out.conf"
    code = main(["register", str(BUNNY / "bun.conf"), "-o", str(out), "--report", str(rep), "--poses-out", str(conf)])
    assert code == 0
    report = json.loads(rep.read_text())
    assert [v["status"] for v in report["views"]] == ["reference", "ok", "ok"]
    truth = read_conf(BUNNY / "bun.conf")
    merged = read_scan(out)
    assert merged.n <= sum(v.n for v in truth) and merged.n > 0.9 * sum(v.n for v in truth)  # outliers dropped
    for view, entry in zip(truth, report["views"]):
        assert pose_error(np.array(entry["transform"]), view.pose, view.points)[2] < 0.001
    assert "bun045.ply" in capsys.readouterr().out
    # refuses to overwrite without --force, with a message and no traceback
    assert main(["register", str(BUNNY / "bun.conf"), "-o", str(out)]) == 1
    assert "exists" in capsys.readouterr().err
    assert main(["register", str(tmp_path / "missing.ply"), str(BUNNY / "bun000.ply"), "-o", str(tmp_path / "x.ply")]) == 1
    assert "no such file" in capsys.readouterr().err
