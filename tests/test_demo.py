"""`make demo`, the README's first command, end to end: simulated scans of the paper's pin are fitted,
checked, compiled to IGES/STEP (both verified) and STL, and re-measured; the recovered dimensions are
the pin's own (radius 27.15 mm, length 129.88 mm) within 0.05 mm."""
import json

import pytest

pytest.importorskip("OCP")


def test_demo_runs_end_to_end(tmp_path, monkeypatch, capsys):
    from rgm import demo

    monkeypatch.setattr(demo, "OUT", tmp_path / "demo")
    monkeypatch.chdir(demo.ROOT)
    assert demo.main() == 0
    for name in ("pin.rgm", "pin.igs", "pin.step", "pin.stl", "fit.json"):
        assert (tmp_path / "demo" / name).stat().st_size > 0
    part = json.loads((tmp_path / "demo" / "fit.json").read_text())["parts"][0]
    assert part["params"]["radius"] == pytest.approx(27.15, abs=0.05)
    assert part["params"]["length"] == pytest.approx(129.88, abs=0.05)
    assert part["certificate"]["holds"]
