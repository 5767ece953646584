"""`rgmc verify` measures the seams between trimmed faces from the file (`rgm.fitters.seam_check`):
`rgmc fit` records each face's worst seam gap (`@fit(g0: ...)`) as verify will measure it, and verify
holds a seam to the tolerance, or to what the fit recorded where the fit left it open."""
from __future__ import annotations

import re

import numpy as np
import pytest

from rgm.cli import main
from rgm.fitters.io import write_ply

SEAM = re.compile(r"seam (\S+) \| (\S+): G0 gap max ([0-9.]+) mm.*: (holds|no worse than recorded|FAILS)")


def _plate_model(gap: float, tol: float, g0: float | None) -> str:
    """Two faces of the plate z = 0 (mm): A over x in [0, 20], B over x in [20 + gap, 40 + gap], y in
    [0, 20], each a bilinear surface trimmed by a loop of four lines, with @fit annotations."""
    out = ["units mm;", f"tolerance {tol};", ""]
    for name, x0 in (("a", 0.0), ("b", 20.0 + gap)):
        net = ", ".join(f"{x} {y} 0" for x in (x0, x0 + 20) for y in (0, 20))
        corners = [(0, 0), (1, 0), (1, 1), (0, 1), (0, 0)]
        lines = ",\n    ".join(f"bspline(1, knots([0, 0, 1, 1]), net 2 [{p[0]} {p[1]}, {q[0]} {q[1]}])"
                               for p, q in zip(corners[:-1], corners[1:]))
        record = "" if g0 is None else f", g0: {g0}mm"
        out += [f"surface_{name} := bsurface(degree_u: 1, degree_v: 1, knots_u: knots([0, 0, 1, 1]),",
                f"    knots_v: knots([0, 0, 1, 1]), net: net 2 x 2 [{net}]);",
                f"boundary_{name} := loop(\n    {lines});",
                f'@fit(points: 1, max: 0mm, rms: 0mm, p95: 0mm, tol: {tol}mm, coverage: 1, statistic: "p95"{record})',
                f"part_{name} := trim(surface_{name}, outer: boundary_{name}, holes: []);", ""]
    return "\n".join(out + ["export part_a, part_b;", ""])


@pytest.fixture(scope="module")
def plate_scan(tmp_path_factory):
    """The whole plate x in [0, 41], y in [0, 20] scanned 0.5 mm apart (jittered, 0.02 mm of noise)."""
    rng = np.random.default_rng(7)
    x, y = np.meshgrid(np.arange(0.25, 41, 0.5), np.arange(0.25, 20, 0.5))
    pts = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    pts[:, :2] += rng.uniform(-0.15, 0.15, (len(pts), 2))
    pts[:, 2] += rng.normal(0, 0.02, len(pts))
    path = tmp_path_factory.mktemp("plate") / "plate.ply"
    write_ply(path, pts)
    return path


@pytest.mark.parametrize("tol, g0, code, verdict", [
    (2.0, None, 0, "holds"),                         # 1 mm apart, within a 2 mm tolerance
    (0.5, None, 1, "FAILS"),                         # over 0.5 mm, and the fit did not say so
    (0.5, 1.0, 0, "no worse than recorded"),         # the fit left it open at 1 mm and said so
    (0.5, 0.9, 1, "FAILS"),                          # ... at 0.9 mm: an edit opened it further
])
def test_a_seam_is_held_to_the_tolerance_or_to_what_the_fit_recorded(tmp_path, plate_scan, capsys, tol, g0, code,
                                                                      verdict):
    model = tmp_path / "plate.rgm"
    model.write_text(_plate_model(1.0, tol, g0))
    assert main(["verify", str(model), str(plate_scan)]) == code
    seams = SEAM.findall(capsys.readouterr().err)
    assert [(a, b, v) for a, b, _, v in seams] == [("part_a", "part_b", verdict)]
    assert abs(float(seams[0][2]) - 1.0) <= 0.02


def test_rgmc_fit_records_the_seams_verify_measures_and_verify_accepts_them(tmp_path, capsys):
    """A free-form slab seen obliquely (its top and two sides, split at the creases into three trimmed
    faces sharing their intersections): every face records its worst seam gap, and `rgmc verify`
    measures the same seams, to the printed digits, and accepts them. Along the shared edges they are
    within the tolerance (p95); the largest gaps, 1.7 and 2.1 mm, are where a side's free border (the
    view's silhouette) meets the crease, a spacing or two from the corner: samples there have the top's
    points across their edge, as along a seam, and read the notch."""
    from rgm.fitters.synthetic import render

    view = render("patch", (1.0, 0.8, -1.0), shape=(100, 100), outliers=0.0, seed=2)
    scan = tmp_path / "slab.ply"
    write_ply(scan, view.scan.world_points())
    out = tmp_path / "slab.rgm"
    assert main(["fit", str(scan), "--tol", "0.5", "-o", str(out)]) == 0
    summary = re.search(r"seams: (\d+) of (\d+) within tol 0.5 mm", capsys.readouterr().err)
    assert summary and int(summary[2]) >= 2
    text = out.read_text()
    recorded = {name: float(g) for g, name in re.findall(r"g0: ([0-9.]+)mm,?\s*\)\s*(\w+) := trim", text)}
    assert len(recorded) >= 2, text[:400]
    assert main(["verify", str(out), str(scan)]) == 0
    err = capsys.readouterr().err
    seams = SEAM.findall(err)
    assert len(seams) == int(summary[2]) and all(v in ("holds", "no worse than recorded") for *_, v in seams)
    assert all(p95 <= 0.5 for p95 in map(float, re.findall(r"p95 ([0-9.]+) mm \(\d+ edge", err)))
    worst = {}
    for a, b, gap, _ in seams:
        for name in (a, b):
            worst[name] = max(worst.get(name, 0.0), float(gap))
    assert worst == pytest.approx(recorded, abs=1e-4)
