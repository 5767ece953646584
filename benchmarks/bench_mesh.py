"""Tessellation benchmark: rgm's certified mesher beside OpenCASCADE's BRepMesh_IncrementalMesh.

The same models (the pin revolution, a fitted bicubic patch, a trimmed patch with a hole) are meshed by
both at the same deflection; both meshes' deviation is measured the same way (every triangle sampled on
a 6-step barycentric lattice, closest point on rgm's exact surface from a global KD-tree seed + Newton).
Prints triangle counts, times, measured deviations and ratios. OpenCASCADE is skipped when absent.

    .venv/bin/python benchmarks/bench_mesh.py
"""
from __future__ import annotations

import time

import numpy as np

from rgm.backends.mesh import collect_faces, tessellate_mesh
from rgm.geometry import NurbsSurface
from rgm.model import BSplineSurface, Circle, Loop, Polyline, Revolution, TrimmedFace

PIN = np.array([[0, 0, 0], [25.95, 0, 0], [27.15, 1.2, 0], [27.15, 128.68, 0], [25.95, 129.88, 0], [0, 129.88, 0]])


def models():
    n = 8
    k = np.concatenate([np.zeros(4), np.linspace(0, 1, n - 2)[1:-1], np.ones(4)])
    g = np.linspace(0, 100, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    patch = BSplineSurface(NurbsSurface(3, 3, k, k, np.stack([x, y, 8 * np.sin(x / 18) * np.cos(y / 25)], axis=-1)))
    trimmed = TrimmedFace(patch, Loop((Polyline([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.1, 0.1]]),)),
                          (Loop((Circle([0.5, 0.5], [0, 0, -1], 0.2),)),))
    return {"pin (revolution)": Revolution(Polyline(PIN), [0, 0, 0], [0, 1, 0]), "bicubic patch": patch,
            "trimmed patch": trimmed}


def lattice(steps=6):
    i, j = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1), indexing="ij")
    keep = i + j <= steps
    a, b = i[keep] / steps, j[keep] / steps
    return np.column_stack([1 - a - b, a, b])


def deviation(obj, vertices, triangles) -> float:
    """Max distance of lattice samples of every triangle to the closest of the object's exact patches."""
    pts = np.einsum("sk,tkd->tsd", lattice(), vertices[triangles]).reshape(-1, 3)
    patches = [f.patch for f in collect_faces([obj], tol=None)]
    return float(np.min([p.closest(pts)[1] for p in patches], axis=0).max())


def occ_mesh(obj, tol):
    """(vertices, triangles, seconds) from BRepMesh_IncrementalMesh at deflection `tol` (absolute)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopLoc import TopLoc_Location

    from rgm.backends import occ

    shape = occ.to_shape(obj)
    t0 = time.perf_counter()
    BRepMesh_IncrementalMesh(shape, tol, False, 0.5, False)
    seconds = time.perf_counter() - t0
    verts, tris, base = [], [], 0
    for face in occ.faces_of(shape):
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        trsf = loc.Transformation()
        nodes = [tri.Node(i).Transformed(trsf) for i in range(1, tri.NbNodes() + 1)]
        verts.append(np.array([[p.X(), p.Y(), p.Z()] for p in nodes]))
        tris.append(np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)]) - 1 + base)
        base += tri.NbNodes()
    return np.concatenate(verts), np.concatenate(tris), seconds


def main():
    try:
        import OCP  # noqa: F401
        have_occ = True
    except ImportError:
        have_occ = False
        print("OpenCASCADE (OCP) is not installed: printing rgm's figures only")
    print(f"{'model':18} {'tol':>6} | {'rgm tris':>8} {'time s':>7} {'max dev':>9} | "
          f"{'occ tris':>8} {'time s':>7} {'max dev':>9} | {'tris ratio':>10} {'time ratio':>10}")
    for name, obj in models().items():
        for tol in (0.1, 0.01):
            t0 = time.perf_counter()
            mesh = tessellate_mesh(obj, tol)
            t_rgm = time.perf_counter() - t0
            d_rgm = deviation(obj, mesh.vertices, mesh.triangles)
            row = f"{name:18} {tol:6.3g} | {len(mesh.triangles):8d} {t_rgm:7.3f} {d_rgm:9.4g} | "
            if have_occ:
                v, t, t_occ = occ_mesh(obj, tol)
                d_occ = deviation(obj, v, t)
                row += (f"{len(t):8d} {t_occ:7.3f} {d_occ:9.4g} | {len(mesh.triangles) / len(t):10.2f} "
                        f"{t_rgm / t_occ:10.1f}")
            print(row, flush=True)


if __name__ == "__main__":
    main()
