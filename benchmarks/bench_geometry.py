"""Surface evaluation: rgm's NurbsSurface beside scipy's NdBSpline, geomdl and OpenCASCADE.

Workload: a bicubic surface with a 50 x 50 control net (clamped, non-uniform interior knots on
[0, 1]^2, a 100 x 100 mm bumpy sheet), evaluated at 1,000,000 random paired parameters (u_i, v_i)
plus the four corners and edge midpoints, so the domain ends are exercised. Three cases: points of
the polynomial surface, points of the same net with random weights (rational), and the point plus
first partials Su, Sv of the polynomial surface.

How each peer is timed, all in this one process (time.perf_counter, wall clock):
- rgm `NurbsSurface.evaluate` / `.derivatives(order=1)` and scipy's compiled
  `scipy.interpolate.NdBSpline` on all 1,000,000 points, best of REPEATS runs taken alternately
  (rgm, scipy, rgm, ...) so that both see the same load. NdBSpline is polynomial only: the rational
  case evaluates the homogeneous net (w*P, w) and divides, which is exact; scipy's first partials
  are two more NdBSpline calls with nu = (1, 0) and (0, 1) (plus the quotient rule when rational).
- geomdl (pure Python) on the first GEOMDL_POINTS points with `evaluate_list` (derivatives: one
  `derivatives(u, v, 1)` call per point on GEOMDL_DERIV_POINTS); its per-point time is extrapolated
  linearly to 1,000,000 points, and printed as extrapolated. rgm on the same subset is shown too.
- OpenCASCADE `Geom_BSplineSurface.D0` / `D1` (OCP 7.9 has no batch evaluator) in a Python loop
  over the first OCC_POINTS points: that time includes one pybind11 call per point, so the
  loop of a trivial call of the same arity (`gp_Pnt.SetCoord(u, v, 0)`) is timed as well and the
  difference printed as an estimate of OpenCASCADE's own cost. Its per-point rate is extrapolated.

Max differences are between rgm's points (or partials) and each peer's on the same parameters,
also relative to the control net's diagonal (for partials, to the largest partial if that is bigger:
Su, Sv are in mm per unit parameter). PASS/FAIL: rgm time / NdBSpline time <= 2 and
geomdl time / rgm time >= 100 (issue 3's targets, for points of the polynomial surface; the same bars
are applied to the rational and derivative cases), and agreement within 1e-12 x size.

    .venv/bin/python benchmarks/bench_geometry.py
"""
from __future__ import annotations

import importlib.util
import os
import time

import numpy as np

from rgm.geometry import NurbsSurface

POINTS = 1_000_000
NET = 50
DEGREE = 3
REPEATS = 5
GEOMDL_POINTS = 10_000
GEOMDL_DERIV_POINTS = 2_000
OCC_POINTS = 100_000
SCIPY_BAR = 2.0        # rgm time / NdBSpline time must not exceed this
GEOMDL_BAR = 100.0     # geomdl time / rgm time must reach this
AGREE = 1e-12          # max difference / size


def make_surface(rational: bool) -> NurbsSurface:
    """Bicubic 50 x 50 sheet over 100 x 100 mm with bumps; random weights in [0.5, 2] if rational."""
    rng = np.random.default_rng(7)
    inner = np.sort(rng.uniform(0.0, 1.0, NET - DEGREE - 1))
    knots = np.r_[np.zeros(DEGREE + 1), inner, np.ones(DEGREE + 1)]
    x, y = np.meshgrid(np.linspace(0, 100, NET), np.linspace(0, 100, NET), indexing="ij")
    z = 10 * np.sin(x / 13) * np.cos(y / 17) + rng.normal(0, 0.5, x.shape)
    weights = rng.uniform(0.5, 2.0, (NET, NET)) if rational else None
    return NurbsSurface(DEGREE, DEGREE, knots, knots, np.stack([x, y, z], axis=-1), weights)


def parameters(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n paired parameters: corners and edge midpoints first, then uniform random ones."""
    ends = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0], [0.5, 1], [0, 0.5], [1, 0.5]])
    uv = np.vstack([ends, np.random.default_rng(11).uniform(0, 1, (n - len(ends), 2))])
    return uv[:, 0].copy(), uv[:, 1].copy()


def size(s: NurbsSurface) -> float:
    box = s.bbox()
    return float(np.linalg.norm(box[1] - box[0]))


# -- the evaluators: each returns (m, 3) points or (3, m, 3) = point, Su, Sv --------------------
def rgm_points(s, u, v):
    return s.evaluate(u, v)


def rgm_partials(s, u, v):
    d = s.derivatives(u, v, 1)
    return np.stack([d[0, 0], d[1, 0], d[0, 1]])


def scipy_evaluator(s: NurbsSurface, partials: bool):
    """NdBSpline on the Euclidean net (polynomial) or the homogeneous net (rational, exact)."""
    from scipy.interpolate import NdBSpline

    net = s.homogeneous if s.is_rational else s.ctrl
    spline = NdBSpline((s.knots_u, s.knots_v), net, (s.degree_u, s.degree_v))

    def run(u, v):
        xi = np.column_stack([u, v])
        h = [spline(xi)] + ([spline(xi, nu=(1, 0)), spline(xi, nu=(0, 1))] if partials else [])
        if not s.is_rational:
            return np.stack(h) if partials else h[0]
        w = [a[:, 3:] for a in h]
        pt = h[0][:, :3] / w[0]
        if not partials:
            return pt
        return np.stack([pt] + [(a[:, :3] - wa * pt) / w[0] for a, wa in zip(h[1:], w[1:])])
    return run


def geomdl_evaluator(s: NurbsSurface, partials: bool):
    from geomdl import NURBS, BSpline

    g = NURBS.Surface() if s.is_rational else BSpline.Surface()
    g.degree_u, g.degree_v = s.degree_u, s.degree_v
    g.ctrlpts_size_u, g.ctrlpts_size_v = s.nu, s.nv
    if s.is_rational:
        g.ctrlptsw = s.homogeneous.reshape(-1, 4).tolist()     # geomdl: v runs fastest, like rgm
    else:
        g.ctrlpts = s.ctrl.reshape(-1, 3).tolist()
    g.knotvector_u, g.knotvector_v = s.knots_u.tolist(), s.knots_v.tolist()

    def run(u, v):
        if not partials:
            return np.array(g.evaluate_list(np.column_stack([u, v]).tolist()))
        d = [g.derivatives(a, b, 1) for a, b in zip(u.tolist(), v.tolist())]
        return np.array([[x[0][0] for x in d], [x[1][0] for x in d], [x[0][1] for x in d]])
    return run


def occ_surface(s: NurbsSurface):
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal, TColStd_Array2OfReal

    def knots(k):
        values, mults = np.unique(k, return_counts=True)
        a, m = TColStd_Array1OfReal(1, len(values)), TColStd_Array1OfInteger(1, len(values))
        for i, (x, c) in enumerate(zip(values, mults), 1):
            a.SetValue(i, float(x))
            m.SetValue(i, int(c))
        return a, m

    poles = TColgp_Array2OfPnt(1, s.nu, 1, s.nv)
    weights = TColStd_Array2OfReal(1, s.nu, 1, s.nv)
    w = s.weights if s.is_rational else np.ones((s.nu, s.nv))
    for i in range(s.nu):
        for j in range(s.nv):
            poles.SetValue(i + 1, j + 1, gp_Pnt(*map(float, s.ctrl[i, j])))
            weights.SetValue(i + 1, j + 1, float(w[i, j]))
    (ku, mu), (kv, mv) = knots(s.knots_u), knots(s.knots_v)
    if s.is_rational:
        return Geom_BSplineSurface(poles, weights, ku, kv, mu, mv, s.degree_u, s.degree_v)
    return Geom_BSplineSurface(poles, ku, kv, mu, mv, s.degree_u, s.degree_v)


def occ_evaluator(s: NurbsSurface, partials: bool):
    """Geom_BSplineSurface.D0/D1 per point; returns (run, binding-overhead run)."""
    from OCP.gp import gp_Pnt, gp_Vec

    surface = occ_surface(s)

    def run(u, v):
        p, du, dv = gp_Pnt(), gp_Vec(), gp_Vec()
        out = np.empty((3, len(u), 3)) if partials else np.empty((len(u), 3))
        for i, (a, b) in enumerate(zip(u.tolist(), v.tolist())):
            if partials:
                surface.D1(a, b, p, du, dv)
                out[:, i] = (p.X(), p.Y(), p.Z()), (du.X(), du.Y(), du.Z()), (dv.X(), dv.Y(), dv.Z())
            else:
                surface.D0(a, b, p)
                out[i] = p.X(), p.Y(), p.Z()
        return out

    def overhead(u, v):
        """The same loop with a trivial call of the same arity in place of D0/D1."""
        p = gp_Pnt()
        out = np.empty((3, len(u), 3)) if partials else np.empty((len(u), 3))
        for i, (a, b) in enumerate(zip(u.tolist(), v.tolist())):
            p.SetCoord(a, b, 0.0)
            if partials:
                out[:, i] = (p.X(), p.Y(), p.Z()), (p.X(), p.Y(), p.Z()), (p.X(), p.Y(), p.Z())
            else:
                out[i] = p.X(), p.Y(), p.Z()
        return out
    return run, overhead


# -- timing ------------------------------------------------------------------------------------
def best_alternating(runs: dict, u, v, repeats: int) -> tuple[dict, dict]:
    """Best wall time of each callable over `repeats` rounds run alternately; also the last results."""
    times = {name: float("inf") for name in runs}
    results = {}
    for _ in range(repeats):
        for name, run in runs.items():
            t = time.perf_counter()
            results[name] = run(u, v)
            times[name] = min(times[name], time.perf_counter() - t)
    return times, results


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def main() -> None:
    print(f"load average {os.getloadavg()[0]:.2f} / {os.getloadavg()[1]:.2f} (1 / 5 min) on "
          f"{os.cpu_count()} cpus at start; wall-clock times, shared machine")
    have_geomdl = importlib.util.find_spec("geomdl") is not None
    if not have_geomdl:
        print("geomdl not installed: skipped (pip install geomdl to compare)")
    have_occ = importlib.util.find_spec("OCP") is not None
    if not have_occ:
        print("OpenCASCADE (OCP) not installed: skipped (pip install cadquery to compare)")
    u, v = parameters(POINTS)
    print(f"surface: degree {DEGREE}x{DEGREE}, net {NET}x{NET}, non-uniform clamped knots; "
          f"{POINTS:,} paired parameters incl. corners and edges; best of {REPEATS} alternating runs\n")
    verdicts = []
    cases = [("points, polynomial", make_surface(False), False),
             ("points, rational", make_surface(True), False),
             ("point + Su, Sv, polynomial", make_surface(False), True)]
    header = f"{'case':27} {'peer':22} {'points':>9} {'time s':>9} {'ns/pt':>8} {'peer/rgm':>9}  max diff (rel)"
    print(header)
    print("-" * len(header))
    for case, s, partials in cases:
        rgm = (lambda a, b: rgm_partials(s, a, b)) if partials else (lambda a, b: rgm_points(s, a, b))
        scipy_run = scipy_evaluator(s, partials)
        rgm(u[:1000], v[:1000]), scipy_run(u[:1000], v[:1000])          # warm up
        times, results = best_alternating({"rgm": rgm, "scipy": scipy_run}, u, v, REPEATS)
        t_rgm, t_sp = times["rgm"], times["scipy"]
        diff = float(np.abs(results["rgm"] - results["scipy"]).max())
        scale = max(size(s), float(np.abs(results["rgm"]).max()))
        ns = 1e9 / POINTS
        print(f"{case:27} {'rgm':22} {POINTS:9,} {t_rgm:9.3f} {t_rgm * ns:8.0f} {1.0:9.2f}")
        print(f"{'':27} {'scipy NdBSpline':22} {POINTS:9,} {t_sp:9.3f} {t_sp * ns:8.0f} {t_sp / t_rgm:9.2f}"
              f"  {diff:.1e} ({diff / scale:.1e})")
        verdicts.append((f"{case}: rgm / NdBSpline time = {t_rgm / t_sp:.2f} (bar <= {SCIPY_BAR:g})",
                         t_rgm / t_sp <= SCIPY_BAR))
        verdicts.append((f"{case}: max |rgm - NdBSpline| = {diff / scale:.1e} x size (bar {AGREE:g})",
                         diff <= AGREE * scale))
        reference = results["rgm"]
        del results
        if have_geomdl:
            n = GEOMDL_DERIV_POINTS if partials else GEOMDL_POINTS
            run = geomdl_evaluator(s, partials)
            times, res = best_alternating({"geomdl": run, "rgm": rgm}, u[:n], v[:n], 1)
            tg = times["geomdl"]
            diff = float(np.abs(res["geomdl"] - res["rgm"]).max())
            extrapolated = tg / n * POINTS / t_rgm
            print(f"{'':27} {'geomdl':22} {n:9,} {tg:9.3f} {tg / n * 1e9:8.0f} {extrapolated:9.0f}"
                  f"  {diff:.1e} ({diff / scale:.1e})   ratio extrapolated to {POINTS:,} points")
            print(f"{'':27} {'  (rgm, same subset)':22} {n:9,} {times['rgm']:9.4f} "
                  f"{times['rgm'] / n * 1e9:8.0f} {tg / times['rgm']:9.0f}   ratio measured on the subset")
            verdicts.append((f"{case}: geomdl / rgm time = {extrapolated:.0f} (extrapolated from {n:,} "
                             f"points; bar >= {GEOMDL_BAR:g})", extrapolated >= GEOMDL_BAR))
        if have_occ:
            run, overhead = occ_evaluator(s, partials)
            times, res = best_alternating({"occ": run, "loop": overhead}, u[:OCC_POINTS], v[:OCC_POINTS], 2)
            to, tl = times["occ"], times["loop"]
            ref = reference[:, :OCC_POINTS] if partials else reference[:OCC_POINTS]
            diff = float(np.abs(res["occ"] - ref).max())
            name = "OCC D1 loop" if partials else "OCC D0 loop"
            print(f"{'':27} {name:22} {OCC_POINTS:9,} {to:9.3f} {to / OCC_POINTS * 1e9:8.0f} "
                  f"{to / OCC_POINTS * POINTS / t_rgm:9.1f}  {diff:.1e} ({diff / scale:.1e})   "
                  f"extrapolated; incl. one Python call per point")
            kernel = max(to - tl, 0.0)
            print(f"{'':27} {'  (minus call overhead)':22} {OCC_POINTS:9,} {kernel:9.3f} "
                  f"{kernel / OCC_POINTS * 1e9:8.0f} {kernel / OCC_POINTS * POINTS / t_rgm:9.1f}   "
                  f"estimate: loop of gp_Pnt.SetCoord took {tl:.3f} s")
            verdicts.append((f"{case}: max |rgm - OCC| = {diff / scale:.1e} x size (bar {AGREE:g})",
                             diff <= AGREE * scale))
        print()
    for text, ok in verdicts:
        print(f"{verdict(ok)}  {text}")
    print(f"\nload average {os.getloadavg()[0]:.2f} / {os.getloadavg()[1]:.2f} (1 / 5 min) at end")


if __name__ == "__main__":
    main()
