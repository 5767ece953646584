"""Superellipsoid recovery: rgm's robust multi-start fit beside a plain Solina–Bajcsy fit, same data,
same process; then classification accuracy on generated primitives.

Peer: the plain Solina & Bajcsy (1990) least-squares fit, one start from the moments (PCA axes, eps = 1),
no robust loss, all points (`rgm.fitters.superellipsoid.fit_superellipsoid_plain`: the same residual and
analytic Jacobian, so the comparison is about the method, not the code).  No installable package
recovers superellipsoids with a comparable interface (pip packages exist only as research code).

Data: 20 random superellipsoids (semi-axes 10-100 mm, eps in [0.1, 1], random pose), 10,000 points each,
1 % Gaussian noise (of the mean semi-axis), without and with 5 % outliers (uniform in the box 20 %
larger than the cloud).  Errors against the truth:
  surface  median radial distance of the true noise-free surface to the fit / mean semi-axis;
  size     largest error of the sorted semi-axes / largest semi-axis;
  eps      largest |eps error| when the fit chose the same symmetry axis.
rgm fits on a 600-point subsample (its 12 starts on 120 of them) and measures its quality on all
10,000 points.

BLAS is set single-threaded before numpy loads (the fits are many small dense problems; on a shared
machine BLAS threads only add synchronisation).

Run: python benchmarks/bench_superellipsoid.py [--quick]
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fitters"))
from recovery_scans import random_rotation, sample_primitive, superellipsoid_cloud  # noqa: E402

from rgm.fitters.classify import classify  # noqa: E402
from rgm.fitters.superellipsoid import Superellipsoid, fit_superellipsoid, fit_superellipsoid_plain  # noqa: E402


def errors(fit, truth, rng):
    surface = np.median(fit.radial_distance(truth.surface_points(rng.normal(size=(2000, 3))))) / truth.size.mean()
    size = np.max(np.abs(np.sort(fit.size) - np.sort(truth.size))) / truth.size.max()
    same = abs(fit.rotation[:, 2] @ truth.rotation[:, 2]) > 0.95
    eps = np.max(np.abs(fit.eps - truth.eps)) if same else np.nan
    return surface, size, eps


def recovery(cases: int, n: int):
    print(f"superellipsoid recovery: {cases} random shapes x {n} points, 1 % noise "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores: times scale with it)")
    print(f"{'data':<16}{'method':<8}{'wall / cpu ms (med)':>20}{'surface % (med/max)':>22}"
          f"{'size % (med/max)':>19}{'eps (med/max)':>16}")
    for label, outliers in (("clean", 0.0), ("5 % outliers", 0.05)):
        rows = {"rgm": [], "plain": []}
        for seed in range(cases):
            rng = np.random.default_rng(seed)
            truth = Superellipsoid(rng.uniform(10, 100, 3), rng.uniform(0.1, 1.0, 2), random_rotation(rng),
                                   rng.uniform(-500, 500, 3), 0.0, 0.0)
            points, _ = superellipsoid_cloud(truth, n, noise=0.01, outliers=outliers, rng=rng)
            for name, fitter in (("rgm", fit_superellipsoid), ("plain", fit_superellipsoid_plain)):
                t0, c0 = time.perf_counter(), time.process_time()
                fit = fitter(points)
                dt, dc = time.perf_counter() - t0, time.process_time() - c0
                rows[name].append((dt, *errors(fit, truth, np.random.default_rng(seed + 10_000)), dc))
        for name, r in rows.items():
            r = np.array(r)
            print(f"{label:<16}{name:<8}{1e3 * np.median(r[:, 0]):>11.1f} /{1e3 * np.median(r[:, 4]):>6.1f}"
                  f"{100 * np.median(r[:, 1]):>11.2f} /{100 * np.max(r[:, 1]):>7.2f}"
                  f"{100 * np.median(r[:, 2]):>10.2f} /{100 * np.max(r[:, 2]):>6.1f}"
                  + (f"{np.nanmedian(r[:, 3]):>9.3f} /{np.nanmax(r[:, 3]):>5.2f}" if np.isfinite(r[:, 3]).any()
                     else f"{'n/a (other axis)':>17}"))
        ratio = np.median(np.array(rows["plain"])[:, 1]) / np.median(np.array(rows["rgm"])[:, 1])
        print(f"{'':<16}plain / rgm median surface error: {ratio:.1f}x")


def classification(per_kind: int):
    kinds = ("box", "cylinder", "sphere", "ellipsoid", "free_form")
    print(f"\nclassification: {per_kind} random shapes per category, 3000 points, 1 % noise, 5 % outliers")
    confusion = {k: {c: 0 for c in kinds + ("other_revolution",)} for k in kinds}
    times = []
    for kind in kinds:
        for seed in range(per_kind):
            pts = sample_primitive(kind, np.random.default_rng(50_000 + seed), 3000)
            t0 = time.perf_counter()
            confusion[kind][classify(pts).category] += 1
            times.append(time.perf_counter() - t0)
    cols = list(confusion["box"])
    print(f"{'true/found':<14}" + "".join(f"{c[:10]:>11}" for c in cols))
    for kind in kinds:
        print(f"{kind:<14}" + "".join(f"{confusion[kind][c]:>11}" for c in cols))
    right = sum(confusion[k][k] for k in kinds)
    print(f"accuracy {right}/{per_kind * len(kinds)} = {100 * right / (per_kind * len(kinds)):.1f} %, "
          f"median time {1e3 * np.median(times):.0f} ms per part")


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    recovery(6 if quick else 20, 10_000)
    classification(4 if quick else 20)
