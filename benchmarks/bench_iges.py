"""Benchmark: IGES writing and reading, rgm beside OpenCASCADE (IGESControl_Writer / IGESControl_Reader).

The model: 100 bicubic B-spline surfaces with 50 x 50 control nets (random smooth heights, some
rational). rgm writes it with `write_iges` and reads it back with `read_iges_file`; OpenCASCADE
writes the same surfaces (as Geom_BSplineSurface faces, Faces mode) and reads its file back with
every root transferred. Printed: times (best of `--repeat` runs, the peers taking turns; wall clock,
and CPU time of this process beside it; rgm's write includes the fsync of its atomic output), ratios (OpenCASCADE time / rgm time: above 1 means rgm is faster),
PASS/FAIL against the target (rgm's writer at least as fast as OpenCASCADE's), the load average
(the machine may be shared), file sizes with the mean length of a real in each file (rgm writes
shortest round-trip reprs, which read back bit-exact; OpenCASCADE about 10 significant digits), and
the accuracy of both read-backs (max deviation of the control points).

rgm formats each distinct real once, and this model repeats values (grid coordinates, polynomial
weights of 1); `--all-distinct` jitters the grid and makes every surface rational, so that no real
repeats (rgm's worst case).

    .venv/bin/python benchmarks/bench_iges.py [--surfaces 100] [--net 50] [--repeat 3] [--all-distinct]
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rgm.backends.iges import write_iges
from rgm.backends.iges_read import read_iges_file
from rgm.geometry import NurbsSurface
from rgm.geometry.knots import uniform_knots
from rgm.model import BSplineSurface, Model


def make_model(count: int, net: int, seed: int = 0, all_distinct: bool = False) -> Model:
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 100.0, net)
    objects = {}
    for k in range(count):
        ctrl = np.zeros((net, net, 3))
        ctrl[..., 0] = g[:, None] + 120.0 * (k % 10)
        ctrl[..., 1] = g[None, :] + 120.0 * (k // 10)
        ctrl[..., 2] = np.cumsum(np.cumsum(rng.normal(0, 0.05, (net, net)), 0), 1)
        if all_distinct:
            ctrl[..., :2] += rng.uniform(-1e-3, 1e-3, (net, net, 2))
        w = rng.uniform(0.8, 1.2, (net, net)) if k % 4 == 0 or all_distinct else None
        knots = uniform_knots(3, net)
        objects[f"s{k}"] = BSplineSurface(NurbsSurface(3, 3, knots, knots, ctrl, w), name=f"s{k}")
    return Model("mm", 1e-3, objects, tuple(objects))


def race(runs: dict, repeat: int) -> dict:
    """{name: (best wall time, best CPU time, last result)} of the callables `runs`, run in turn
    `repeat` times (interleaved, so that every peer sees the same load on a shared machine)."""
    best = {name: [np.inf, np.inf, None] for name in runs}
    for _ in range(repeat):
        for name, fn in runs.items():
            wall, cpu = time.perf_counter(), time.process_time()
            out = fn()
            b = best[name]
            b[0], b[1], b[2] = min(b[0], time.perf_counter() - wall), min(b[1], time.process_time() - cpu), out
    return {name: tuple(b) for name, b in best.items()}


def real_lengths(path: Path) -> tuple[int, float, float]:
    """(number of reals in the P section, their mean length in characters, mean number of characters
    of data per P record) of an IGES file."""
    rows = [line[:64].rstrip() for line in path.read_text(encoding="latin-1").splitlines() if line[72:73] == "P"]
    reals = [t for t in re.split(r"[,;]", "".join(rows)) if "." in t and "H" not in t]
    return len(reals), sum(map(len, reals)) / max(len(reals), 1), sum(map(len, rows)) / max(len(rows), 1)


def rgm_peer(model, folder: Path):
    """(write, read, deviation of a read-back's control points from the model) for rgm."""
    path = folder / "rgm.igs"

    def deviation(back) -> float:
        assert back.ok, back.messages()
        return max(float(np.abs(model.objects[k].surface.ctrl - back.model.objects[k].surface.ctrl).max())
                   for k in model.exports)

    return (lambda: write_iges(model, path)), (lambda: read_iges_file(path)), deviation


def occ_peer(model, folder: Path):
    """The same for OpenCASCADE (Faces mode, every root transferred), or None without OCP."""
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

    def deviation(shape) -> float:
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
        assert k == len(model.exports), f"{k} faces of {len(model.exports)}"
        return dev

    return write, read, deviation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surfaces", type=int, default=100)
    parser.add_argument("--net", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--all-distinct", action="store_true", help="no real repeats (rgm's worst case)")
    args = parser.parse_args()
    model = make_model(args.surfaces, args.net, all_distinct=args.all_distinct)
    reals = np.concatenate([np.concatenate([s.ctrl.ravel(), s.weights.ravel() if s.is_rational else
                                            np.ones(s.nu * s.nv), s.knots_u, s.knots_v])
                            for s in (model.objects[k].surface for k in model.exports)])
    print(f"model: {args.surfaces} bicubic surfaces, {args.net}x{args.net} control nets "
          f"({args.surfaces * args.net ** 2} control points; {reals.size} reals in the nets, weights and knots, "
          f"{np.unique(reals).size} distinct)")
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        peers = {"rgm": rgm_peer(model, folder)}
        occ = occ_peer(model, folder)
        if occ is not None:
            peers["OCC"] = occ
        writes = race({name: peer[0] for name, peer in peers.items()}, args.repeat)
        reads = race({name: peer[1] for name, peer in peers.items()}, args.repeat)
        sizes = {name: (folder / f"{name.lower()}.igs").stat().st_size for name in peers}
        for name, (_write, _read, deviation) in peers.items():
            w, r = writes[name], reads[name]
            print(f"{name:5} write {w[0]:7.3f} s (cpu {w[1]:6.3f})   read {r[0]:7.3f} s (cpu {r[1]:6.3f})   "
                  f"file {sizes[name] / 1e6:6.2f} MB   control-point deviation after read-back {deviation(r[2]):.3g}")
        if occ is not None:
            w, r = writes["rgm"][0], reads["rgm"][0]
            print(f"ratio (OCC time / rgm time): write {writes['OCC'][0] / w:.2f}x   read {reads['OCC'][0] / r:.2f}x   "
                  f"size rgm/OCC {sizes['rgm'] / sizes['OCC']:.2f}")
            (nr, lr, fill), (no, lo, _) = real_lengths(folder / "rgm.igs"), real_lengths(folder / "occ.igs")
            print(f"file size: rgm writes {nr} reals of {lr:.1f} characters on average (shortest round-trip, "
                  f"bit-exact), OCC {no} of {lo:.1f} (about 10 significant digits); with OCC's lengths rgm's "
                  f"file would be about {(sizes['rgm'] - nr * (lr - lo) / fill * 81) / 1e6:.2f} MB (records "
                  f"hold {fill:.1f} characters on average), so the difference is the digits")
            verdict = "PASS" if w <= writes["OCC"][0] else "FAIL"
            print(f"target: rgm's writer at least as fast as OpenCASCADE's: {verdict} "
                  f"(rgm {w:.3f} s, OCC {writes['OCC'][0]:.3f} s, wall clock)")
    after = os.getloadavg()
    print(f"load average (1, 5, 15 min) before {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, "
          f"after {after[0]:.2f} {after[1]:.2f} {after[2]:.2f} on {os.cpu_count()} cores")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
