"""Benchmark: pairwise registration of full-resolution bunny views, rgm vs Open3D point-to-plane ICP.

Each pair of views 45 degrees apart starts from the same pose: the bun.conf ground truth disturbed by a
fixed rotation (6 degrees about a random axis) and translation (6 mm).  Both sides get the same target
normals (rgm's robust PCA, oriented to the sensor), so the timings compare the ICP loops alone.  Open3D
runs twice: plain point-to-plane ICP with a 5 mm correspondence distance, and with its Tukey kernel.
Printed: time (best of 3), iterations, rotation error, RMS displacement of the view's points against
bun.conf, and rgm's time ratio to the faster Open3D variant.  Open3D is optional (pip install open3d;
it needs `apt-get install -y libusb-1.0-0`; `pip uninstall dash` afterwards keeps dash's pytest plugin out
of the test runs); without it only rgm runs.
Run: python benchmarks/bench_register.py [--data /work/shared/data/stanford-bunny]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from rgm.fitters.io import read_conf
from rgm.fitters.normals import orient_normals, pca_normals
from rgm.fitters.register import _rodrigues, icp, pose_error

PAIRS = [("bun000.ply", "bun045.ply"), ("bun045.ply", "bun090.ply"), ("bun000.ply", "bun315.ply"),
         ("bun315.ply", "bun270.ply")]


def _open3d():
    """Open3D, or None. Its import pulls in its plotly/dash viewer; when dash is absent (it is kept out of
    the venv because it registers a pytest plugin) an empty stand-in is enough for the registration API."""
    import sys
    import types

    if "dash" not in sys.modules:
        try:
            import dash  # noqa: F401
        except ImportError:
            stub = types.ModuleType("dash")
            stub.html = stub.dcc = types.ModuleType("dash.sub")
            stub.Dash = object
            sys.modules["dash"] = stub
    try:
        import open3d
        return open3d
    except (ImportError, OSError) as exc:
        print(f"Open3D: skipped ({exc}); pip install open3d and apt-get install -y libusb-1.0-0")
        return None


def _o3d_icp(o3d, src, tgt, tgt_n, init, robust):
    """Open3D point-to-plane ICP; iterations counted from its debug log (fd 1 captured)."""
    s, t = o3d.geometry.PointCloud(), o3d.geometry.PointCloud()
    s.points = o3d.utility.Vector3dVector(src)
    t.points = o3d.utility.Vector3dVector(tgt)
    t.normals = o3d.utility.Vector3dVector(tgt_n)
    reg = o3d.pipelines.registration
    est = (reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=0.0005)) if robust
           else reg.TransformationEstimationPointToPlane())
    crit = reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=100)
    best, res = np.inf, None
    for _ in range(3):
        t0 = time.perf_counter()
        res = reg.registration_icp(s, t, 0.005, init, est, crit)
        best = min(best, time.perf_counter() - t0)
    with tempfile.TemporaryFile() as log:  # one more run with the debug log to count iterations
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Debug)
        saved = os.dup(1)
        os.dup2(log.fileno(), 1)
        try:
            reg.registration_icp(s, t, 0.005, init, est, crit)
        finally:
            os.dup2(saved, 1)
            os.close(saved)
            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Warning)
        log.seek(0)
        iterations = log.read().decode(errors="replace").count("ICP Iteration #")
    return best, iterations, np.asarray(res.transformation)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data/stanford-bunny", help="folder with bun.conf")
    args = ap.parse_args()
    views = {Path(v.source).name: v for v in read_conf(Path(args.data) / "bun.conf")}
    o3d = _open3d()
    rng = np.random.default_rng(7)
    print(f"{'pair':24s} {'method':16s} {'time s':>7s} {'iter':>5s} {'rot err deg':>11s} {'rms err mm':>10s}")
    ratios, acc = [], []
    for a, b in PAIRS:
        A, B = views[a], views[b]
        truth = np.linalg.inv(A.pose) @ B.pose
        axis = rng.normal(size=3)
        init = truth.copy()
        init[:3, :3] = _rodrigues(axis / np.linalg.norm(axis) * np.radians(6)) @ truth[:3, :3]
        init[:3, 3] += rng.normal(size=3) / np.sqrt(3) * 0.006
        na, _ = pca_normals(A.points, 16)
        na = orient_normals(na, A.points, A)
        nb, _ = pca_normals(B.points, 16)
        nb = orient_normals(nb, B.points, B)
        rows = {}
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            res = icp(B.points, A.points, na, init, source_normals=nb)
            best = min(best, time.perf_counter() - t0)
        rows["rgm"] = (best, res.iterations, res.transform)
        if o3d is not None:
            rows["open3d"] = _o3d_icp(o3d, B.points, A.points, na, init, robust=False)
            rows["open3d+tukey"] = _o3d_icp(o3d, B.points, A.points, na, init, robust=True)
        errs = {}
        for name, (dt, it, T) in rows.items():
            ang, _, rms = pose_error(T, truth, B.points)
            errs[name] = rms
            print(f"{a[:-4] + ' <- ' + b[:-4]:24s} {name:16s} {dt:7.3f} {it:5d} {np.degrees(ang):11.4f} {rms * 1000:10.4f}")
        if o3d is not None:
            fastest = min(rows["open3d"][0], rows["open3d+tukey"][0])
            ratios.append(rows["rgm"][0] / fastest)
            acc.append(errs["rgm"] <= min(errs["open3d"], errs["open3d+tukey"]) + 1e-6)
    if ratios:
        print(f"rgm time / fastest Open3D: median {np.median(ratios):.2f} (per pair {', '.join(f'{r:.2f}' for r in ratios)}); "
              f"rgm at least as accurate on {sum(acc)}/{len(acc)} pairs")


if __name__ == "__main__":
    main()
