"""`rgmc compile`: diagnostics and exit codes, lazy per-target dispatch, options reaching the writer,
failed writers leaving no file, and the input file never overwritten."""
from __future__ import annotations

import math
import sys
import types

import pytest

from rgm.cli import main
from rgm.commands import compile as compile_cmd
from rgm.errors import BackendError

PIN = """units mm;
tolerance 0.01;
param radius := 27.15mm;
axis := line(pt(0, 0, 0), pt(0, 1, 0));
profile := polyline([pt(0, 0, 0), pt(radius, 0, 0), pt(radius, 50, 0), pt(0, 50, 0)]);
pin := revolve(profile, axis);
export pin;
"""


@pytest.fixture
def pin(tmp_path):
    path = tmp_path / "pin.rgm"
    path.write_text(PIN)
    return path


@pytest.fixture
def fake_backend(monkeypatch):
    """A back end module `rgm.backends._fake` whose writer records its call or fails on request."""
    module = types.ModuleType("rgm.backends._fake")
    module.calls = []
    module.fail = False

    def write_fake(model, path, *, fmt=None, tol=None, angle_tol=None, verify=False, schema=None, n=None, flat=None):
        opts = {k: v for k, v in dict(fmt=fmt, tol=tol, angle_tol=angle_tol, verify=verify, schema=schema, n=n,
                                      flat=flat).items() if v is not None and v is not False}
        module.calls.append((model, path, opts))
        path.write_text("partial")
        if module.fail:
            raise module.fail

    module.write_fake = write_fake
    monkeypatch.setitem(sys.modules, "rgm.backends._fake", module)
    monkeypatch.setitem(compile_cmd.TARGETS, "iges", ("rgm.backends._fake", "write_fake", {}))
    monkeypatch.setitem(compile_cmd.TARGETS, "stl", ("rgm.backends._fake", "write_fake", {"fmt": "stl"}))
    return module


def test_options_defines_and_tolerances_reach_the_writer(pin, tmp_path, fake_backend, capsys):
    out = tmp_path / "out" / "pin.igs"
    rc = main(["compile", str(pin), "-t", "iges", "-o", str(out), "-D", "radius=30", "--tol", "0.05",
               "--verify", "--option", "schema=AP214", "--option", "n=3", "--option", "flat=true"])
    assert rc == 0 and out.exists()
    (model, path, opts) = fake_backend.calls[0]
    assert model.params["radius"] == 30 and path == out
    assert opts == {"tol": 0.05, "verify": True, "schema": "AP214", "n": 3, "flat": True}


def test_mesh_targets_get_format_and_angle_in_radians(pin, tmp_path, fake_backend):
    rc = main(["compile", str(pin), "-t", "stl", "-o", str(tmp_path / "p.stl"), "--angle", "10"])
    assert rc == 0
    opts = fake_backend.calls[0][2]
    assert opts["fmt"] == "stl" and "tol" not in opts and opts["angle_tol"] == pytest.approx(math.radians(10))


def test_backend_error_leaves_no_file(pin, tmp_path, fake_backend, capsys):
    fake_backend.fail = BackendError("cannot lower this model (test)")
    out = tmp_path / "pin.igs"
    assert main(["compile", str(pin), "-t", "iges", "-o", str(out)]) == 1
    assert not out.exists()
    assert "cannot lower this model (test)" in capsys.readouterr().err


def test_a_back_end_bug_is_reported_as_one_and_leaves_no_file(pin, tmp_path, fake_backend, capsys):
    fake_backend.fail = ZeroDivisionError("float division by zero")
    out = tmp_path / "pin.igs"
    assert main(["compile", str(pin), "-t", "iges", "-o", str(out)]) == 1
    err = capsys.readouterr().err
    assert "internal error in the iges back end" in err and "Traceback" not in err and not out.exists()


def test_unknown_options_and_flags_a_target_does_not_take_are_usage_errors(pin, tmp_path, fake_backend,
                                                                             monkeypatch, capsys):
    assert main(["compile", str(pin), "-t", "iges", "-o", str(tmp_path / "p.igs"), "--option", "bogus=1"]) == 2
    assert "has no option bogus (its options: flat, n, schema)" in capsys.readouterr().err
    fake_backend.write_plain = lambda model, path: path.write_text("x")
    monkeypatch.setitem(compile_cmd.TARGETS, "alpha1", ("rgm.backends._fake", "write_plain", {}))
    assert main(["compile", str(pin), "-t", "alpha1", "-o", str(tmp_path / "p.a1"), "--verify"]) == 2
    assert "-t alpha1 does not take --verify" in capsys.readouterr().err
    assert not fake_backend.calls and not (tmp_path / "p.a1").exists()


def test_missing_backend_is_a_clear_error(pin, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(compile_cmd.TARGETS, "alpha1", ("rgm.backends._not_written_yet", "write_alpha1", {}))
    assert main(["compile", str(pin), "-t", "alpha1", "-o", str(tmp_path / "p.a1")]) == 1
    err = capsys.readouterr().err
    assert "alpha1 back end" in err and "Traceback" not in err


def test_input_is_never_overwritten(pin, fake_backend, capsys):
    assert main(["compile", str(pin), "-t", "iges", "-o", str(pin)]) == 1
    assert pin.read_text() == PIN and not fake_backend.calls
    assert "refusing to overwrite the input" in capsys.readouterr().err


def test_existing_output_is_replaced(pin, tmp_path, fake_backend):
    out = tmp_path / "old.igs"
    out.write_text("old")
    assert main(["compile", str(pin), "-t", "iges", "-o", str(out)]) == 0 and fake_backend.calls


def test_errors_in_the_file_stop_before_the_backend(tmp_path, fake_backend, capsys):
    bad = tmp_path / "bad.rgm"
    bad.write_text("units mm;\nr := revolve(polyline([pt(-2, 0, 0), pt(5, 0, 0), pt(5, 4, 0)]), "
                   "line(pt(0, 0, 0), pt(0, 1, 0)));\n")
    assert main(["compile", str(bad), "-t", "iges", "-o", str(tmp_path / "bad.igs")]) == 1
    out = capsys.readouterr()
    assert "E0502" in out.out and not fake_backend.calls and not (tmp_path / "bad.igs").exists()


def test_usage_errors_exit_2(pin, tmp_path, capsys):
    assert main(["compile", str(pin), "-t", "iges", "-o", str(tmp_path / "x"), "-D", "radius"]) == 2
    assert main(["compile", str(pin), "-t", "nope", "-o", str(tmp_path / "x")]) == 2
    assert main(["compile", str(tmp_path / "missing.rgm"), "-t", "iges", "-o", str(tmp_path / "x")]) == 2
