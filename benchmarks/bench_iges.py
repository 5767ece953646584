"""Benchmark: IGES writing and reading, rgm beside OpenCASCADE (IGESControl_Writer / IGESControl_Reader).

The model: 100 bicubic B-spline surfaces with 50 x 50 control nets (random smooth heights, some
rational). rgm writes it with `write_iges` and reads it back with `read_iges_file`; OpenCASCADE
writes the same surfaces (as Geom_BSplineSurface faces, Faces mode) and reads its file back with
every root transferred. Printed: times, ratios (OpenCASCADE time / rgm time: above 1 means rgm is
faster), file sizes, and the accuracy of both read-backs (max deviation of the control points).

    .venv/bin/python benchmarks/bench_iges.py [--surfaces 100] [--net 50]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from rgm.backends.iges import write_iges
from rgm.backends.iges_read import read_iges_file
from rgm.geometry import NurbsSurface
from rgm.geometry.knots import uniform_knots
from rgm.model import BSplineSurface, Model


def make_model(count: int, net: int, seed: int = 0) -> Model:
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 100.0, net)
    objects = {}
    for k in range(count):
        ctrl = np.zeros((net, net, 3))
        ctrl[..., 0] = g[:, None] + 120.0 * (k % 10)
        ctrl[..., 1] = g[None, :] + 120.0 * (k // 10)
        ctrl[..., 2] = np.cumsum(np.cumsum(rng.normal(0, 0.05, (net, net)), 0), 1)
        w = rng.uniform(0.8, 1.2, (net, net)) if k % 4 == 0 else None
        knots = uniform_knots(3, net)
        objects[f"s{k}"] = BSplineSurface(NurbsSurface(3, 3, knots, knots, ctrl, w), name=f"s{k}")
    return Model("mm", 1e-3, objects, tuple(objects))


def timed(fn, repeat: int = 3):
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def bench_rgm(model, folder: Path):
    path = folder / "rgm.igs"
    t_write, _ = timed(lambda: write_iges(model, path))
    t_read, back = timed(lambda: read_iges_file(path))
    dev = max(float(np.abs(model.objects[k].surface.ctrl - back.model.objects[k].surface.ctrl).max())
              for k in model.exports)
    return t_write, t_read, path.stat().st_size, dev, back.ok


def bench_occ(model, folder: Path):
    try:
        from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace
    except ImportError:
        print("OpenCASCADE (OCP) is not installed: skipping the peer")
        return None
    from OCP.BRep import BRep_Tool
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.IGESControl import IGESControl_Reader, IGESControl_Writer
    from OCP.Interface import Interface_Static
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from rgm.backends.occ import _quiet, geom_surface

    _quiet()
    faces = [BRepBuilderAPI_MakeFace(geom_surface(model.objects[k].surface), 1e-7).Face() for k in model.exports]
    path = folder / "occ.igs"

    def write():
        Interface_Static.SetIVal_s("write.iges.brep.mode", 0)
        writer = IGESControl_Writer("MM", 0)
        for f in faces:
            writer.AddShape(f)
        writer.ComputeModel()
        assert writer.Write(str(path))

    def read():
        reader = IGESControl_Reader()
        assert reader.ReadFile(str(path)) == IFSelect_RetDone
        reader.TransferRoots()
        return reader.OneShape()

    t_write, _ = timed(write)
    t_read, shape = timed(read)
    exp, dev, k = TopExp_Explorer(shape, TopAbs_FACE), 0.0, 0
    while exp.More():
        s = BRep_Tool.Surface_s(TopoDS.Face_s(exp.Current()))  # OCP returns the derived type
        poles = s.Poles()
        ctrl = model.objects[model.exports[k]].surface.ctrl
        got = np.array([[[poles.Value(i, j).X(), poles.Value(i, j).Y(), poles.Value(i, j).Z()]
                         for j in range(1, poles.ColLength() + 1)] for i in range(1, poles.RowLength() + 1)])
        dev = max(dev, float(np.abs(got - ctrl).max()) if got.shape == ctrl.shape else np.inf)
        k += 1
        exp.Next()
    return t_write, t_read, path.stat().st_size, dev, k == len(model.exports)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surfaces", type=int, default=100)
    parser.add_argument("--net", type=int, default=50)
    args = parser.parse_args()
    model = make_model(args.surfaces, args.net)
    print(f"model: {args.surfaces} bicubic surfaces, {args.net}x{args.net} control nets "
          f"({args.surfaces * args.net ** 2} control points)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        r = bench_rgm(model, folder)
        print(f"rgm   write {r[0]:7.3f} s   read {r[1]:7.3f} s   file {r[2] / 1e6:6.2f} MB   "
              f"control-point deviation after read-back {r[3]:.3g}   reader ok: {r[4]}")
        o = bench_occ(model, folder)
        if o is not None:
            print(f"OCC   write {o[0]:7.3f} s   read {o[1]:7.3f} s   file {o[2] / 1e6:6.2f} MB   "
                  f"control-point deviation after read-back {o[3]:.3g}   all faces: {o[4]}")
            print(f"ratio (OCC time / rgm time): write {o[0] / r[0]:.2f}x   read {o[1] / r[1]:.2f}x   "
                  f"size rgm/OCC {r[2] / o[2]:.2f}")
    os.sys.stdout.flush()


if __name__ == "__main__":
    main()
