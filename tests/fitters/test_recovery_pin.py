"""The paper's cylindrical pin (Figure 7), reproduced: simulated range views -> `rgmc fit` -> a `revolve`
with `radius` and `length` within 0.05 mm, a file that checks clean and evaluates, and `rgmc verify`
that holds on the scans and fails after a hand edit."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from recovery_scans import PIN_LENGTH, PIN_RADIUS, pin_views, random_rotation
from rgm.cli import main
from rgm.fitters.io import write_ply

import rgm


def _param(text, name):
    m = re.search(rf"^param {name} := ([0-9.]+)mm;", text, re.M)
    assert m, f"no param {name} in\n{text}"
    return float(m.group(1))


def _write_views(tmp_path, views):
    paths = []
    for k, v in enumerate(views):
        write_ply(tmp_path / f"pin_{k}.ply", v)
        paths.append(str(tmp_path / f"pin_{k}.ply"))
    return paths


def _check_clean(text):
    from rgm.compiler.check import check
    from rgm.compiler.parser import parse

    program, diags = parse(text, "pin.rgm")
    errors = [d for d in diags if d.is_error] + [d for d in check(program).diagnostics if d.is_error]
    assert errors == []


@pytest.fixture(scope="module")
def fitted_pin(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("pin")
    pose = np.eye(4)
    pose[:3, :3] = random_rotation(np.random.default_rng(7))
    pose[:3, 3] = [40.0, -25.0, 310.0]
    views = _write_views(tmp, pin_views(chamfer=0.0, noise=0.03, outliers=0.05, seed=1, pose=pose))
    out, report = tmp / "pin.rgm", tmp / "fit.json"
    assert main(["fit", *views, "--tol", "0.1", "-o", str(out), "--report", str(report)]) == 0
    return tmp, views, out, pose, json.loads(report.read_text())


def test_pin_dimensions_within_0_05mm(fitted_pin):
    _, _, out, _, report = fitted_pin
    text = out.read_text()
    assert "revolve(profile, axis" in text
    assert abs(_param(text, "radius") - PIN_RADIUS) < 0.05
    assert abs(_param(text, "length") - PIN_LENGTH) < 0.05
    part = report["parts"][0]
    assert part["category"] == "cylinder" and part["certificate"]["holds"]
    assert set(report["timings"]) >= {"intake", "filter", "split", "classify", "build", "certify", "emit"}


def test_pin_file_checks_and_evaluates_to_the_posed_axis(fitted_pin):
    _, _, out, pose, _ = fitted_pin
    text = out.read_text()
    _check_clean(text)
    model = rgm.loads(text)
    pin = model.objects["pin"]
    # the evaluated revolution's axis is the scan's cylinder axis (pose of the y axis)
    assert abs(abs(np.asarray(pin.axis_dir) @ pose[:3, 1]) - 1) < 1e-6
    off = np.asarray(pin.axis_point) - pose[:3, 3]
    assert np.linalg.norm(off - (off @ pose[:3, 1]) * pose[:3, 1]) < 0.05
    assert "@fit(points:" in text and '@classified(as: "cylinder"' in text and "@source(scans:" in text


def test_verify_holds_then_fails_after_a_hand_edit(fitted_pin, tmp_path):
    _, views, out, _, _ = fitted_pin
    assert main(["verify", str(out), *views]) == 0
    edited = tmp_path / "edited.rgm"
    edited.write_text(re.sub(r"param radius := [0-9.]+mm;", "param radius := 27.6500mm;", out.read_text()))
    assert main(["verify", str(edited), *views]) == 1


def test_chamfered_pin_gets_a_chamfer_param(tmp_path):
    views = _write_views(tmp_path, pin_views(chamfer=2.0, noise=0.03, outliers=0.05, seed=2))
    out = tmp_path / "pin.rgm"
    assert main(["fit", *views, "--tol", "0.1", "-o", str(out)]) == 0
    text = out.read_text()
    assert abs(_param(text, "radius") - PIN_RADIUS) < 0.05
    assert abs(_param(text, "length") - PIN_LENGTH) < 0.05
    assert abs(_param(text, "chamfer") - 2.0) < 0.05
    assert "radius - chamfer" in text
    _check_clean(text)
    rgm.loads(text)


def test_fit_refuses_to_overwrite_without_force(fitted_pin, capsys):
    _, views, out, _, _ = fitted_pin
    assert main(["fit", *views, "--tol", "0.1", "-o", str(out)]) == 1
    assert "--force" in capsys.readouterr().err
    assert main(["fit", views[0], "--tol", "0.1", "-o", views[0], "--force"]) == 1


def test_fit_reports_a_missing_scan_without_traceback(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "nope.ply"), "--tol", "0.1", "-o", str(tmp_path / "x.rgm")]) == 1
    err = capsys.readouterr().err
    assert "nope.ply" in err and "Traceback" not in err


def test_pin_compiles_to_iges_with_a_surface_of_revolution(fitted_pin, tmp_path):
    _, _, out, _, _ = fitted_pin
    igs = tmp_path / "pin.igs"
    assert main(["compile", str(out), "-t", "iges", "-o", str(igs)]) == 0
    directory = [line for line in igs.read_text().splitlines() if line[72:73] == "D"]
    types = {int(line[:8]) for line in directory[::2]}
    assert 120 in types                                    # IGES surface of revolution


@pytest.mark.occ
def test_pin_compiles_to_step(fitted_pin, tmp_path):
    pytest.importorskip("OCP")
    _, _, out, _, _ = fitted_pin
    step = tmp_path / "pin.step"
    assert main(["compile", str(out), "-t", "step", "-o", str(step)]) == 0
    assert step.read_text().startswith("ISO-10303-21;")


def test_grooved_pin_gets_groove_params(tmp_path):
    r, length = PIN_RADIUS, PIN_LENGTH
    profile = np.array([[0, 0], [r, 0], [r, 40], [r - 4, 40], [r - 4, 52], [r, 52], [r, length], [0, length]])
    views = _write_views(tmp_path, pin_views(profile=profile, seed=3))
    out = tmp_path / "grooved.rgm"
    assert main(["fit", *views, "--tol", "0.1", "-o", str(out)]) == 0
    text = out.read_text()
    for name, value in (("radius", r), ("length", length), ("groove1_at", 40.0), ("groove1_width", 12.0),
                        ("groove1_depth", 4.0)):
        assert abs(_param(text, name) - value) < 0.05, name
    _check_clean(text)
    assert main(["verify", str(out), *views]) == 0
