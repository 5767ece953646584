"""`make demo`: rgm's main job on the bundled example.

The bundled example is the paper's pin (Figure 7: radius 27.15 mm, length 129.88 mm, 1.2 mm chamfers)
seen by a simulated laser range finder: five orthographic range views from fixed directions, 0.03 mm
noise along the rays and 5 % gross outliers, from fixed seeds (`rgm.fitters.synthetic`, part "pin"),
written as PLY point clouds in the part's frame to build/demo/scans/. They are fitted into a procedural
model (`rgmc fit`), checked, compiled to IGES 5.3 and STEP (each read back and verified) and to an STL
mesh at 0.05 mm, and the model is re-measured against the scans (`rgmc verify`). Everything goes to
build/demo/. Each step after the scan is the same `rgmc` command a user would type; a failing step
stops the demo with its exit code.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from rgm.cli import main as rgmc

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "build" / "demo"
#: viewing directions of the simulated scanner (part frame: the pin's axis is y)
VIEWS = ((1, 0.35, 0), (-0.5, -0.35, 0.87), (-0.5, 0.3, -0.87), (0.3, 1.2, 0.2), (-0.2, -1.2, -0.3))


def simulate_scans(folder: Path) -> list[Path]:
    """Range views of the pin (see the module docstring) as PLY files in `folder`; their paths."""
    from rgm.fitters.io import write_ply
    from rgm.fitters.synthetic import render

    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, direction in enumerate(VIEWS):
        view = render("pin", direction, shape=(200, 200), noise=0.03 / 140, outliers=0.05, seed=i)
        rot, shift = view.scan.pose[:3, :3], view.scan.pose[:3, 3]
        paths.append(write_ply(folder / f"pin_view{i}.ply", view.scan.points @ rot.T + shift))
    return paths


def step(title: str, *argv: str) -> None:
    print(f"\n== {title}\n$ rgmc {' '.join(argv)}", flush=True)
    t = time.perf_counter()
    code = rgmc(list(argv))
    print(f"   ({time.perf_counter() - t:.2f} s, exit {code})", flush=True)
    if code != 0:
        sys.exit(code)


def main() -> int:
    print("== simulate the scanner: five range views of the paper's pin, 0.03 mm noise, 5 % outliers")
    views = [os.path.relpath(p) for p in simulate_scans(OUT / "scans")]
    print("   " + ", ".join(views))
    rgm_file, report = OUT / "pin.rgm", OUT / "fit.json"
    step("fit the scans: filter, classify, recover the revolution, certify, write .rgm",
         "fit", *views, "--tol", "0.1", "-o", str(rgm_file), "--report", str(report), "--force")
    step("check the written procedure", "check", str(rgm_file))
    step("compile to IGES 5.3 and verify it through OpenCASCADE and rgm's own reader",
         "compile", str(rgm_file), "-t", "iges", "-o", str(OUT / "pin.igs"), "--verify", "--force")
    step("compile to STEP AP214 and verify it", "compile", str(rgm_file), "-t", "step", "-o",
         str(OUT / "pin.step"), "--verify", "--force")
    step("tessellate at a chordal deviation of 0.05 mm", "compile", str(rgm_file), "-t", "stl", "--tol", "0.05",
         "-o", str(OUT / "pin.stl"), "--force")
    step("re-measure the model against the scans", "verify", str(rgm_file), *views)
    fit = json.loads(report.read_text())
    print("\n== result")
    for part in fit.get("parts", []):
        params = ", ".join(f"{k} = {v:.3f} mm" for k, v in part.get("params", {}).items())
        cert = part.get("certificate", {})
        print(f"   {part['name']}: {part['category']} (confidence {part['confidence']:.2f}); {params}")
        if cert:
            print(f"   certificate: {cert['points']} points, max {cert['max']:.3f} mm, rms {cert['rms']:.3f} mm, "
                  f"{cert['statistic']} {cert[cert['statistic']]:.3f} mm <= tol {cert['tol']} mm: {cert['holds']}")
    print("   files: " + ", ".join(f"{p.name} ({p.stat().st_size // 1024} KiB)" for p in sorted(OUT.iterdir()) if p.is_file()))
    print("\n" + rgm_file.read_text())
    return 0


if __name__ == "__main__":
    sys.exit(main())
