"""OpenCASCADE's view of an IGES file, for `write_iges(verify=True)`, the tests and the benchmark.

OCP is imported only inside these functions. (Architecture rule: OpenCASCADE belongs in
`rgm.backends.occ`; this module is meant to move there. It is separate only so that the IGES work
did not have to wait on that file's owner.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["OccIges", "occ_read_iges", "occ_write_iges", "sample_shape"]


@dataclass
class OccIges:
    """What IGESControl_Reader made of a file: the shape of all roots, counts, fail messages, and per
    face its surface type, number of wires and sample points."""

    shape: object
    roots: int
    transferred: int
    fails: list
    faces: list      # (surface type name, wire count, points (k, 3), (u, v) params (k, 2))
    edges: list      # points (k, 3) on each edge's 3-D curve


def _messages(check_list) -> list[str]:
    out = []
    it = check_list
    for i in range(1, it.NbChecks() + 1) if hasattr(it, "NbChecks") else []:
        check = it.Value(i)
        out += [check.CFail(j).ToCString() for j in range(1, check.NbFails() + 1)]
    return out


def occ_read_iges(path, samples: int = 7) -> OccIges:
    """Read `path` with IGESControl_Reader, transfer every root, and sample each face (a
    samples x samples grid over its UV bounds) and edge (samples points over its range)."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.IGESControl import IGESControl_Reader

    from rgm.backends.occ import _quiet

    _quiet()
    reader = IGESControl_Reader()
    status = reader.ReadFile(str(path))
    fails = [] if status == IFSelect_RetDone else [f"ReadFile status {int(status)}"]
    model = reader.Model()
    if model is not None:
        check = model.GlobalCheck()
        fails += [check.CFail(i).ToCString() for i in range(1, check.NbFails() + 1)]
    if status != IFSelect_RetDone:
        return OccIges(None, 0, 0, fails, [], [])
    roots = reader.NbRootsForTransfer()
    transferred = reader.TransferRoots()
    try:
        checks = reader.WS().TransferReader().LastCheckList()
        for i in range(1, checks.NbChecks() + 1) if hasattr(checks, "NbChecks") else []:
            c = checks.Value(i)
            fails += [c.CFail(j).ToCString() for j in range(1, c.NbFails() + 1)]
    except AttributeError:
        pass
    shape = reader.OneShape()
    faces, edges = sample_shape(shape, samples)
    return OccIges(shape, roots, transferred, fails, faces, edges)


def occ_write_iges(shapes, path, units: str = "MM", brep_mode: int = 0) -> None:
    """Write TopoDS shapes with IGESControl_Writer (Faces mode by default), for tests and benchmarks."""
    from OCP.IGESControl import IGESControl_Writer
    from OCP.Interface import Interface_Static

    Interface_Static.SetIVal_s("write.iges.brep.mode", brep_mode)
    writer = IGESControl_Writer(units, brep_mode)
    for s in shapes:
        writer.AddShape(s)
    writer.ComputeModel()
    if not writer.Write(str(path)):
        raise OSError(f"OpenCASCADE could not write {path}")


def sample_shape(shape, samples: int = 7):
    """(faces, edges) of a TopoDS shape: per face (surface type, wire count, points (k, 3) on a
    samples x samples grid over its UV bounds, the (u, v) (k, 2)); per edge points (samples, 3)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    faces, edges = [], []
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        face = TopoDS.Face_s(exp.Current())
        adaptor = BRepAdaptor_Surface(face, False)
        umin, umax, vmin, vmax = BRepTools.UVBounds_s(face)
        us, vs = np.linspace(umin, umax, samples), np.linspace(vmin, vmax, samples)
        uv = np.array([(u, v) for u in us for v in vs])
        pts = np.array([[p.X(), p.Y(), p.Z()] for p in (adaptor.Value(u, v) for u, v in uv)])
        wires = TopExp_Explorer(face, TopAbs_WIRE)
        count = 0
        while wires.More():
            count += 1
            wires.Next()
        kind = str(adaptor.GetType()).split("_")[-1].split(".")[-1]
        faces.append((kind, count, pts, uv))
        exp.Next()
    exp = TopExp_Explorer(shape, TopAbs_EDGE)
    while exp.More():
        edge = TopoDS.Edge_s(exp.Current())
        if BRep_Tool.Degenerated_s(edge):
            exp.Next()
            continue
        curve = BRepAdaptor_Curve(edge)
        ts = np.linspace(curve.FirstParameter(), curve.LastParameter(), samples)
        edges.append(np.array([[p.X(), p.Y(), p.Z()] for p in (curve.Value(t) for t in ts)]))
        exp.Next()
    return faces, edges
