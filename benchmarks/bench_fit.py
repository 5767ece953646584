"""Surface approximation: rgm's least squares + knot insertion beside its peers, same data, same measure.

Workloads (units mm), all with Gaussian noise of sigma 0.05 mm on the height of a 100 x 100 mm part (a
gentle dome with a nose-like local feature, `truth`):
- a 500 x 500 grid; a 60 x 60 grid for geomdl (pure Python); 200,000 scattered points;
- a 1000 x 1000 range image fitted to 0.1 % of its size (0.1 mm), target under 5 s.

Every method's result becomes an `rgm.geometry.NurbsSurface`, and every one is measured the same way:
the height of the surface above each data point's (x, y) (the surface's (u, v) found there by Newton
steps on its x, y) against the noise-free height (max, RMS), and each noisy data point's distance to the
surface (max, RMS, p95: the closest-point distance that rgm's certificates bound).

- equal net size (bicubic): against peers given uniform knots, rgm's solve on the same knots: a plain
  separable least-squares solve with scipy `BSpline.design_matrix`, splipy's `least_square_fit` (grid),
  a plain sparse Kronecker least-squares solve and scipy `LSQBivariateSpline` (scattered); against
  geomdl's `approximate_surface` (small grid), which places its own knots, rgm's knot insertion within
  the same number of control points (its solve on uniform knots is shown for reference);
- equal achieved error: every method must bring the max vs the data to at most TOL (5 sigma). rgm is
  given TOL; each peer's own knob is searched for the smallest net that meets it: the uniform net size
  (bisection, checked at n - 1) for the least-squares peers and geomdl, OpenCASCADE's tolerance for
  `GeomAPI_PointsToBSplineSurface` on the full 500 x 500 grid (its height-grid form, bicubic; the
  loosest tolerance in 5 % steps down from TOL whose result meets TOL: it does not keep its own
  tolerance exactly). OpenCASCADE has no scattered-point fitter.

Targets (PASS/FAIL lines): at equal net size rgm at least as accurate as the best peer (max and RMS vs
the truth, within 0.5 %); at equal error fewer control points than every peer; the range image fitted
with its certificate (p95 of the residuals, which the benchmark re-measures) within 0.1 mm in under
5 s. The p95 is the only statistic 0.1 mm can bound with this noise (its own p95 is 0.098 mm, its
max about 0.25 mm); the max vs the truth is printed beside it, not bounded by it. Times are wall
clock (best of 3 for single solves), on a shared machine: the load average is printed.

Run: python benchmarks/bench_fit.py   (peers that are not installed are skipped with a message)
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg
from scipy.interpolate import BSpline, LSQBivariateSpline

from rgm.fitters.freeform import fit_surface, solve_grid, solve_scattered, uniform_knots
from rgm.fitters.freeform_measure import foot_distances
from rgm.geometry import NurbsSurface

SIZE = 100.0
NOISE = 0.05
TOL = 0.25                 # equal-error target: max distance of the data to the surface (mm), about 5 sigma
NET = 30                   # equal net size, per direction
SMALL, SMALL_NET = 60, 20  # geomdl's grid and net
MEGA, MEGA_TOL = 1000, 0.001 * SIZE


def truth(x, y):
    """Height (mm) of the test part at (x, y) mm: a gentle dome with a nose-like local feature."""
    return (8 * np.exp(-((x - 50) ** 2 + (y - 50) ** 2) / 1800.0)
            + 4 * np.exp(-((x - 62) ** 2 + (y - 45) ** 2) / 30.0)
            + 0.02 * (x - 50))


def grid_data(n, rng):
    """An n x n grid (n, n, 3) over the part with noisy heights, and the noise-free heights (n, n)."""
    x, y = np.meshgrid(np.linspace(0, SIZE, n), np.linspace(0, SIZE, n), indexing="ij")
    z = truth(x, y)
    return np.stack([x, y, z + rng.normal(0, NOISE, z.shape)], -1), z


def timed(fn, repeat=3):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


# --------------------------------------------------------------------------------------------- measure
def heights(s: NurbsSurface, x, y, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Heights (m,) of surface s above the points (x, y) (m,) mm, and their parameters (m, 2): (u, v) with
    S_xy(u, v) = (x, y) by Newton steps from the linear guess (exact at once for a surface whose x, y are
    linear in u, v)."""
    (u0, u1), (v0, v1) = s.domain
    u, v = u0 + x / SIZE * (u1 - u0), v0 + y / SIZE * (v1 - v0)
    for _ in range(iterations):
        p = s.evaluate(u, v)
        fx, fy = p[:, 0] - x, p[:, 1] - y
        miss = max(np.abs(fx).max(), np.abs(fy).max())
        if miss < 1e-9:
            break
        d = s.derivatives(u, v, 1)
        a, b, c, e = d[1, 0][:, 0], d[0, 1][:, 0], d[1, 0][:, 1], d[0, 1][:, 1]
        det = a * e - b * c
        u = np.clip(u - (e * fx - b * fy) / det, u0, u1)
        v = np.clip(v - (a * fy - c * fx) / det, v0, v1)
    if miss > 1e-3:   # (x, y) the surface does not reach (clamped at its edge): more than 1 um off
        raise RuntimeError(f"the surface's x, y could not be inverted (off by {miss:.2g} mm)")
    return p[:, 2], np.c_[u, v]


def errors(s: NurbsSurface, data: np.ndarray, z_true: np.ndarray) -> dict:
    """Errors (mm) of s against the noise-free heights z_true (m,) (the height difference) and against
    the data (m, 3): each point's distance to the surface, as rgm's certificates measure it (Gauss-Newton
    from the point of the surface above it to the foot point, `foot_distances`)."""
    z, uv = heights(s, data[:, 0], data[:, 1])
    et = np.abs(z - z_true)
    ed = foot_distances(s, uv, data, np.abs(z - data[:, 2]), lambda q: np.ones(len(q), bool))
    return {"true_max": et.max(), "true_rms": np.sqrt(np.mean(et**2)), "data_max": ed.max(),
            "data_rms": np.sqrt(np.mean(ed**2)), "data_p95": np.percentile(ed, 95)}


@dataclass
class Result:
    name: str
    seconds: float
    net: tuple          # control points per direction
    err: dict
    note: str = ""

    @property
    def n_ctrl(self) -> int:
        return int(np.prod(self.net))


def run(name, fn, data, z_true, repeat=3, note="") -> Result:
    """Time fn() -> NurbsSurface (best of `repeat`) and measure it."""
    t, s = timed(fn, repeat)
    return Result(name, t, (s.nu, s.nv), errors(s, data, z_true), note)


def show(r: Result, ref: Result | None = None):
    e = r.err
    ratio = (f"  rgm/peer time {ref.seconds / r.seconds:.2f}, truth rms {ref.err['true_rms'] / e['true_rms']:.2f}"
             if ref is not None and ref is not r else "")
    print(f"  {r.name:<40s} {r.seconds * 1e3:9.1f} ms  net {r.net[0]:>3}x{r.net[1]:<3} = {r.n_ctrl:>6}  "
          f"truth max {e['true_max']:.4f} rms {e['true_rms']:.4f}  data max {e['data_max']:.4f} "
          f"p95 {e['data_p95']:.4f}{ratio}  {r.note}")


def verdict(ok: bool, what: str) -> bool:
    print(f"{'PASS' if ok else 'FAIL'}: {what}")
    return ok


def equal_net_verdict(rgm: Result, peers: list[Result], workload: str) -> bool:
    if not peers:
        return verdict(False, f"{workload}, equal net size: no peer ran")
    best_max = min(p.err["true_max"] for p in peers)
    best_rms = min(p.err["true_rms"] for p in peers)
    ok = rgm.err["true_max"] <= 1.005 * best_max and rgm.err["true_rms"] <= 1.005 * best_rms
    return verdict(ok, f"{workload}, equal net size: rgm truth max {rgm.err['true_max']:.4f} / rms "
                       f"{rgm.err['true_rms']:.4f} vs the best peer's {best_max:.4f} / {best_rms:.4f}")


def equal_error_verdict(rgm: Result, peers: list[Result], workload: str) -> bool:
    met = rgm.err["data_max"] <= TOL
    beaten = [p for p in peers if p.err["data_max"] <= TOL]
    ok = met and all(rgm.n_ctrl < p.n_ctrl for p in beaten)
    ratios = ", ".join(f"{p.name.split()[0]} {rgm.n_ctrl / p.n_ctrl:.2f}" for p in beaten)
    missing = [p.name for p in peers if p not in beaten]
    return verdict(ok, f"{workload}, equal error (data max <= {TOL} mm): rgm {rgm.n_ctrl} control points "
                       f"{'meets' if met else 'MISSES'} it; rgm/peer control points: {ratios or 'no peer'}"
                       + (f"; never met by {', '.join(missing)}" if missing else ""))


def smallest_net(fit_n, data, z_true, lo=4, hi=150) -> tuple[Result | None, float]:
    """The smallest uniform net size n in [lo, hi] whose fit (fit_n(n) -> NurbsSurface) meets TOL on the
    data max, by bisection (the error falls with n) checked at n - 1; and the search's seconds."""
    t0, cache = time.perf_counter(), {}

    def meets(n):
        if n not in cache:
            t, s = timed(lambda: fit_n(n), 1)
            cache[n] = Result("", t, (s.nu, s.nv), errors(s, data, z_true))
        return cache[n].err["data_max"] <= TOL

    if not meets(hi):
        return None, time.perf_counter() - t0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if meets(mid) else (mid, hi)
    while hi > 4 and meets(hi - 1):   # bisection assumed monotone: confirm the answer's neighbour fails
        hi -= 1
    return cache[hi], time.perf_counter() - t0


def searched(result: Result | None, seconds: float, name: str) -> Result | None:
    if result is None:
        print(f"  {name:<40s} no uniform net up to 150 x 150 meets {TOL} mm")
        return None
    result.name, result.note = name, f"(search {seconds:.1f} s)"
    return result


# --------------------------------------------------------------------------------------------- peers
def rgm_net(u, grid, n) -> NurbsSurface:
    k = uniform_knots(3, n)
    return NurbsSurface(3, 3, k, k, solve_grid(u, u, grid, k, k, 3, 3)[0], None)


def plain_separable(u, grid, n) -> NurbsSurface:
    """Separable least squares with scipy's design matrices: C = (Bu'Bu)^-1 Bu' Z Bv (Bv'Bv)^-1."""
    k = uniform_knots(3, n)
    B = BSpline.design_matrix(u, k, 3).tocsc()
    M = (B.T @ B).toarray()
    rows = grid.shape[0]
    T = np.linalg.solve(M, (B.T @ grid.reshape(rows, -1)).reshape(n, -1)).reshape(n, rows, 3)
    T = (B.T @ T.transpose(1, 0, 2).reshape(rows, -1)).reshape(n, n * 3)
    C = np.linalg.solve(M, T).reshape(n, n, 3).transpose(1, 0, 2)
    return NurbsSurface(3, 3, k, k, C, None)


def splipy_fit(u, grid, n) -> NurbsSurface:
    from splipy import BSplineBasis
    from splipy.surface_factory import least_square_fit

    k = uniform_knots(3, n)
    basis = BSplineBasis(4, k)
    srf = least_square_fit(grid, [basis, basis], [u, u])
    return NurbsSurface(3, 3, k, k, np.asarray(srf.controlpoints)[..., :3], None)


def geomdl_fit(grid, n) -> NurbsSurface:
    from geomdl import fitting

    m = grid.shape[0]
    s = fitting.approximate_surface(grid.reshape(-1, 3).tolist(), m, m, 3, 3, ctrlpts_size_u=n, ctrlpts_size_v=n)
    return NurbsSurface(3, 3, np.array(s.knotvector_u), np.array(s.knotvector_v),
                        np.array(s.ctrlpts2d)[..., :3], None)


def occ_fit(grid, tol) -> NurbsSurface:
    """OpenCASCADE's approximation of the heights of an n x n grid (its Z-points form: the surface is a
    height field over x, y), bicubic C2, to the tolerance `tol` (mm)."""
    from OCP.GeomAbs import GeomAbs_C2
    from OCP.GeomAPI import GeomAPI_PointsToBSplineSurface
    from OCP.TColStd import TColStd_Array2OfReal

    n = grid.shape[0]
    z = TColStd_Array2OfReal(1, n, 1, n)
    for i, row in enumerate(grid[..., 2].tolist()):
        for j, value in enumerate(row):
            z.SetValue(i + 1, j + 1, value)
    step = SIZE / (n - 1)
    t = time.perf_counter()
    s = GeomAPI_PointsToBSplineSurface(z, 0.0, step, 0.0, step, 3, 3, GeomAbs_C2, tol).Surface()
    t = time.perf_counter() - t
    nu, nv = s.NbUPoles(), s.NbVPoles()
    ctrl = np.array([[(p.X(), p.Y(), p.Z()) for p in (s.Pole(i, j) for j in range(1, nv + 1))]
                     for i in range(1, nu + 1)])

    def knots(value, mult, count):
        return np.repeat([value(i) for i in range(1, count + 1)], [mult(i) for i in range(1, count + 1)])

    return t, NurbsSurface(3, 3, knots(s.UKnot, s.UMultiplicity, s.NbUKnots()),
                           knots(s.VKnot, s.VMultiplicity, s.NbVKnots()), ctrl, None)


def greville_surface(tx, ty, heights_c) -> NurbsSurface:
    """The 3-D surface (x, y, z(x, y)) of a scalar spline z on knots tx, ty (mm) with coefficients
    (nx, ny): x and y are exact with the Greville abscissae as their control values."""
    gx = np.convolve(tx[1:-1], np.ones(3) / 3, "valid")
    gy = np.convolve(ty[1:-1], np.ones(3) / 3, "valid")
    X, Y = np.meshgrid(gx, gy, indexing="ij")
    return NurbsSurface(3, 3, tx, ty, np.stack([X, Y, heights_c], -1), None)


def plain_sparse(u, v, pts, n) -> NurbsSurface:
    """Scattered least squares the plain way: the row-wise Kronecker product of scipy's design matrices
    (4 x 4 non-zeros a row), normal equations A'A by sparse products, `spsolve`."""
    k = uniform_knots(3, n)
    Bu, Bv = BSpline.design_matrix(u, k, 3).tocsr(), BSpline.design_matrix(v, k, 3).tocsr()
    m = len(u)
    iu, iv = Bu.indices.reshape(m, 4), Bv.indices.reshape(m, 4)
    cols = (iu[:, :, None] * n + iv[:, None, :]).reshape(m, 16)
    vals = (Bu.data.reshape(m, 4)[:, :, None] * Bv.data.reshape(m, 4)[:, None, :]).reshape(m, 16)
    A = sp.csr_matrix((vals.ravel(), cols.ravel(), np.arange(0, 16 * m + 1, 16)), shape=(m, n * n))
    C = scipy.sparse.linalg.spsolve((A.T @ A).tocsc(), A.T @ pts)
    return NurbsSurface(3, 3, k, k, C.reshape(n, n, 3), None)


def lsq_bivariate(xy, z, n) -> NurbsSurface:
    k = uniform_knots(3, n) * SIZE
    spl = LSQBivariateSpline(xy[:, 0], xy[:, 1], z, k[4:-4], k[4:-4], bbox=[0, SIZE, 0, SIZE], kx=3, ky=3)
    tx, ty, c = spl.tck
    return greville_surface(tx, ty, c.reshape(len(tx) - 4, len(ty) - 4))


def rgm_adaptive(data, tol, statistic, params) -> NurbsSurface:
    return fit_surface(data, tol, params=params, statistic=statistic).nurbs()


def skipped(name, exc):
    print(f"  {name} not installed ({exc}): pip install {name} to compare (skipped)")


# --------------------------------------------------------------------------------------------- workloads
def bench_grid(rng) -> list[bool]:
    grid, z_true = grid_data(500, rng)
    data, zt = grid.reshape(-1, 3), z_true.ravel()
    u = np.linspace(0, 1, 500)
    print(f"\n500 x 500 grid; equal net size {NET} x {NET} bicubic:")
    rgm = run("rgm separable solve", lambda: rgm_net(u, grid, NET), data, zt)
    peers = [run("plain separable (scipy design_matrix)", lambda: plain_separable(u, grid, NET), data, zt)]
    if _has("splipy"):
        peers.append(run("splipy least_square_fit", lambda: splipy_fit(u, grid, NET), data, zt))
    for r in [rgm, *peers]:
        show(r, rgm)
    verdicts = [equal_net_verdict(rgm, peers, "500 x 500 grid")]

    print(f"\n500 x 500 grid; equal achieved error, max vs the data <= {TOL} mm:")
    ad = run("rgm knot insertion", lambda: rgm_adaptive(grid, TOL, "max", (u, u)), data, zt, repeat=1)
    show(ad)
    peers = [searched(*smallest_net(lambda n: plain_separable(u, grid, n), data, zt), "plain separable, smallest net")]
    if _has("splipy"):
        hi = peers[0].net[0] + 8 if peers[0] is not None else 150
        peers.append(searched(*smallest_net(lambda n: splipy_fit(u, grid, n), data, zt, hi=hi), "splipy, smallest net"))
    peers.append(occ_search(grid, data, zt))
    peers = [p for p in peers if p is not None]
    for p in peers:
        show(p, ad)
    return verdicts + [equal_error_verdict(ad, peers, "500 x 500 grid")]


def _has(module) -> bool:
    try:
        __import__(module)
        return True
    except ImportError as exc:
        skipped(module, exc)
        return False


def occ_search(grid, data, zt) -> Result | None:
    """OpenCASCADE on the full grid: the loosest tolerance, in 5 % steps down from TOL, whose result meets
    TOL on the data max (at most 6 tries; each try is printed)."""
    if not _has("OCP"):
        return None
    t0 = time.perf_counter()
    for k in range(6):
        tol = TOL * (1 - 0.05 * k)
        t, s = occ_fit(grid, tol)
        r = Result(f"OpenCASCADE PointsToBSplineSurface tol {tol:.4f}", t, (s.nu, s.nv), errors(s, data, zt))
        print(f"    OCC tol {tol:.4f}: {t:6.1f} s, net {s.nu} x {s.nv}, data max {r.err['data_max']:.4f}")
        if r.err["data_max"] <= TOL:
            r.note = f"(search {time.perf_counter() - t0:.1f} s)"
            return r
    print(f"  OpenCASCADE did not meet {TOL} mm at tolerances down to {tol:.4f}")
    return None


def bench_small(rng) -> list[bool]:
    if not _has("geomdl"):
        return []
    grid, z_true = grid_data(SMALL, rng)
    data, zt = grid.reshape(-1, 3), z_true.ravel()
    u = np.linspace(0, 1, SMALL)
    print(f"\n{SMALL} x {SMALL} grid; equal net size {SMALL_NET} x {SMALL_NET} bicubic (geomdl places its own knots, "
          f"so rgm places its own: knot insertion within {SMALL_NET ** 2} control points):")
    rgm = run(f"rgm knot insertion, <= {SMALL_NET ** 2} points", lambda: fit_surface(
        grid, 0.0, params=(u, u), statistic="max", max_ctrl=SMALL_NET ** 2).nurbs(), data, zt)
    peer = run("geomdl approximate_surface", lambda: geomdl_fit(grid, SMALL_NET), data, zt, repeat=1)
    show(rgm)
    show(run("(rgm solve on uniform knots, for reference)", lambda: rgm_net(u, grid, SMALL_NET), data, zt))
    show(peer, rgm)
    verdicts = [equal_net_verdict(rgm, [peer], f"{SMALL} x {SMALL} grid")]
    print(f"\n{SMALL} x {SMALL} grid; equal achieved error, max vs the data <= {TOL} mm:")
    ad = run("rgm knot insertion", lambda: rgm_adaptive(grid, TOL, "max", (u, u)), data, zt, repeat=1)
    peer = searched(*smallest_net(lambda n: geomdl_fit(grid, n), data, zt, hi=SMALL - 1), "geomdl, smallest net")
    show(ad)
    if peer is not None:
        show(peer, ad)
    return verdicts + [equal_error_verdict(ad, [p for p in [peer] if p is not None], f"{SMALL} x {SMALL} grid")]


def bench_scattered(rng) -> list[bool]:
    n = 200_000
    xy = rng.uniform(0, SIZE, (n, 2))
    zt = truth(xy[:, 0], xy[:, 1])
    pts = np.c_[xy, zt + rng.normal(0, NOISE, n)]
    u, v = xy[:, 0] / SIZE, xy[:, 1] / SIZE
    k = uniform_knots(3, NET)
    print(f"\n200,000 scattered points; equal net size {NET} x {NET} bicubic:")
    rgm = run("rgm sparse normal equations",
              lambda: NurbsSurface(3, 3, k, k, solve_scattered(u, v, pts, k, k, 3, 3)[0], None), pts, zt)
    peers = [run("plain sparse Kronecker + spsolve", lambda: plain_sparse(u, v, pts, NET), pts, zt, repeat=1),
             run("scipy LSQBivariateSpline", lambda: lsq_bivariate(xy, pts[:, 2], NET), pts, zt, repeat=1)]
    for r in [rgm, *peers]:
        show(r, rgm)
    verdicts = [equal_net_verdict(rgm, peers, "scattered")]
    print(f"\n200,000 scattered points; equal achieved error, max vs the data <= {TOL} mm:")
    ad = run("rgm knot insertion", lambda: rgm_adaptive(pts, TOL, "max", (u, v)), pts, zt, repeat=1)
    show(ad)
    plain = searched(*smallest_net(lambda m: plain_sparse(u, v, pts, m), pts, zt, hi=60), "plain sparse, smallest net")
    hi = plain.net[0] + 4 if plain is not None else 60
    lsq = searched(*smallest_net(lambda m: lsq_bivariate(xy, pts[:, 2], m), pts, zt, lo=max(4, hi - 9), hi=hi),
                   "LSQBivariateSpline, smallest net")
    peers = [p for p in (plain, lsq) if p is not None]
    for p in peers:
        show(p, ad)
    print("  OpenCASCADE: no scattered-point surface fitter (GeomPlate takes a few thousand points)")
    return verdicts + [equal_error_verdict(ad, peers, "scattered")]


def bench_megapixel(rng) -> list[bool]:
    grid, z_true = grid_data(MEGA, rng)
    u = np.linspace(0, 1, MEGA)
    t, fit = timed(lambda: fit_surface(grid, MEGA_TOL, params=(u, u), statistic="p95"), repeat=1)
    r = Result("rgm knot insertion", t, fit.ctrl.shape[:2], errors(fit.nurbs(), grid.reshape(-1, 3), z_true.ravel()),
               f"certificate p95 {fit.stats.p95:.4f} holds={fit.stats.holds}")
    print(f"\n{MEGA} x {MEGA} range image to 0.1 % of its size ({MEGA_TOL:g} mm on the p95 vs the data; the "
          f"noise alone has p95 {1.96 * NOISE:.3f} mm and max ~{4.9 * NOISE:.2f} mm):")
    show(r)
    ok = fit.stats.holds and r.err["data_p95"] <= MEGA_TOL and t < 5
    return [verdict(ok, f"range image {MEGA} x {MEGA}: p95 vs data {r.err['data_p95']:.4f} mm (<= {MEGA_TOL:g}), "
                        f"{t:.2f} s (< 5 s), {r.n_ctrl} control points ({r.n_ctrl / MEGA**2:.4%} of the points); "
                        f"vs the truth max {r.err['true_max']:.4f}, rms {r.err['true_rms']:.4f} mm")]


def main():
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (1, 5, 15 min); noise sigma {NOISE} mm; "
          f"errors in mm: heights above the data's (x, y) vs the truth and vs the data")
    fit_surface(grid_data(40, np.random.default_rng(1))[0], 1.0)   # warm the imports rgm uses on first call
    # each workload its own seeded data: the same whichever peers are installed (geomdl's grid is skipped
    # without it, and a shared stream would then give the later workloads other points)
    workloads = (bench_grid, bench_small, bench_scattered, bench_megapixel)
    verdicts = [v for seed, bench in enumerate(workloads) for v in bench(np.random.default_rng(seed))]
    print(f"\n{sum(verdicts)}/{len(verdicts)} targets met; load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
