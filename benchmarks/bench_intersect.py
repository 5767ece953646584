"""Surface-surface and surface-plane intersection: rgm's marcher beside OpenCASCADE's GeomAPI_IntSS.

Same random bicubic patches (5 x 5 nets over [0, 10]^2, one rational), same process. For each
tolerance it prints the time of both and the accuracy of both, measured the same way: 400 samples
of every returned 3-D curve, distance to each surface by rgm's closest point. OpenCASCADE is
skipped with a message when cadquery/OCP is not installed.

    python benchmarks/bench_intersect.py
"""
from __future__ import annotations

import importlib.util
import time

import numpy as np

from rgm.geometry import NurbsSurface
from rgm.geometry.intersect import intersect_surface_plane, intersect_surfaces

KNOTS = np.array([0, 0, 0, 0, 0.5, 1, 1, 1, 1.0])


def patch(seed: int, tilt: float, rational: bool) -> NurbsSurface:
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.linspace(0, 10, 5), np.linspace(0, 10, 5), indexing="ij"), axis=2)
    z = tilt * (g[..., :1] - 5) + rng.normal(0, 1.2, (5, 5, 1))
    return NurbsSurface(3, 3, KNOTS, KNOTS, np.concatenate([g, z], axis=2),
                        rng.uniform(0.6, 1.6, (5, 5)) if rational else None)


def accuracy(curves_points, surfaces) -> float:
    if not curves_points:
        return float("nan")
    pts = np.concatenate(curves_points)
    return float(max(s.closest_point(pts)[-1].max() for s in surfaces))


def rgm_run(sa, sb, plane, tol):
    t = time.perf_counter()
    if plane is None:
        branches = intersect_surfaces(sa, sb, tol)
    else:
        branches = intersect_surface_plane(sa, plane[0], plane[1], tol)
    dt = time.perf_counter() - t
    pts = [br.curve.evaluate(np.linspace(*br.curve.domain, 400)) for br in branches]
    return dt, len(branches), pts


def _occ_surface(s: NurbsSurface):
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal, TColStd_Array2OfReal

    def knots(k):
        values, mults = np.unique(k, return_counts=True)
        a, m = TColStd_Array1OfReal(1, len(values)), TColStd_Array1OfInteger(1, len(values))
        for i, (v, c) in enumerate(zip(values, mults), 1):
            a.SetValue(i, float(v))
            m.SetValue(i, int(c))
        return a, m

    nu, nv = s.ctrl.shape[:2]
    poles = TColgp_Array2OfPnt(1, nu, 1, nv)
    weights = TColStd_Array2OfReal(1, nu, 1, nv)
    w = s.weights if s.is_rational else np.ones((nu, nv))
    for i in range(nu):
        for j in range(nv):
            poles.SetValue(i + 1, j + 1, gp_Pnt(*map(float, s.ctrl[i, j])))
            weights.SetValue(i + 1, j + 1, float(w[i, j]))
    (ku, mu), (kv, mv) = knots(s.knots_u), knots(s.knots_v)
    return Geom_BSplineSurface(poles, weights, ku, kv, mu, mv, s.degree_u, s.degree_v)


def occ_run(sa, sb, plane, tol):
    from OCP.Geom import Geom_Plane
    from OCP.GeomAPI import GeomAPI_IntSS
    from OCP.gp import gp_Dir, gp_Pnt

    a = _occ_surface(sa)
    b = _occ_surface(sb) if plane is None else Geom_Plane(gp_Pnt(*map(float, plane[0])), gp_Dir(*map(float, plane[1])))
    t = time.perf_counter()
    inter = GeomAPI_IntSS(a, b, tol)
    n = inter.NbLines() if inter.IsDone() else 0
    curves = [inter.Line(i) for i in range(1, n + 1)]
    dt = time.perf_counter() - t
    pts = []
    for c in curves:
        u0, u1 = c.FirstParameter(), c.LastParameter()
        pts.append(np.array([[p.X(), p.Y(), p.Z()] for p in (c.Value(u) for u in np.linspace(u0, u1, 400))]))
    return dt, n, pts


def main() -> None:
    have_occ = importlib.util.find_spec("OCP") is not None
    if not have_occ:
        print("OpenCASCADE (OCP) not installed: printing rgm alone (pip install cadquery to compare)")
    cases = [("surface-surface", patch(1, 0.0, False), patch(2, 0.9, True).swap_uv(), None),
             ("surface-plane", patch(3, 0.0, True), None, (np.array([5.0, 5.0, 0.0]), np.array([0.3, -0.2, 1.0])))]
    rgm_run(cases[0][1], cases[0][2], None, 1e-1)  # warm up imports and caches on both sides
    if have_occ:
        occ_run(cases[0][1], cases[0][2], None, 1e-1)
    print(f"{'case':16} {'tol':>7} {'rgm s':>8} {'rgm err':>9} {'br':>3} | {'occ s':>8} {'occ err':>9} {'br':>3} | ratio")
    for name, sa, sb, plane in cases:
        surfaces = [sa] if sb is None else [sa, sb]
        for tol in (1e-2, 1e-4, 1e-6):
            dt, nb, pts = rgm_run(sa, sb, plane, tol)
            err = accuracy(pts, surfaces)
            if plane is not None:
                n = plane[1] / np.linalg.norm(plane[1])
                err = max(err, float(np.abs((np.concatenate(pts) - plane[0]) @ n).max()))
            row = f"{name:16} {tol:7.0e} {dt:8.3f} {err:9.2e} {nb:3d} |"
            if have_occ:
                odt, onb, opts = occ_run(sa, sb, plane, tol)
                oerr = accuracy(opts, surfaces)
                if plane is not None and opts:
                    oerr = max(oerr, float(np.abs((np.concatenate(opts) - plane[0]) @ n).max()))
                row += f" {odt:8.3f} {oerr:9.2e} {onb:3d} | {dt / odt:6.1f}x"
            print(row)


if __name__ == "__main__":
    main()
