"""OpenCASCADE's view of an IGES file, for `write_iges(verify=True)`, the tests and the benchmark.

OCP is imported only inside these functions. (Architecture rule: OpenCASCADE belongs in
`rgm.backends.occ`; this module is meant to move there. It is separate only so that the IGES work
did not have to wait on that file's owner.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["OccIges", "occ_read_iges", "occ_write_iges", "shape_points"]


@dataclass
class OccIges:
    """What IGESControl_Reader made of a file: the shape of all roots, counts, fail messages, and the
    shape transferred from each root (in root order: rgm writes roots in export order)."""

    shape: object
    roots: int
    transferred: int
    fails: list
    shapes: list


def _fails(check_iterator) -> list[str]:
    """Fail messages of every check in an Interface_CheckIterator."""
    from rgm.backends.occ import _text

    out = []
    check_iterator.Start()
    while check_iterator.More():
        check = check_iterator.Value()
        out += [_text(check.CFail(j)) for j in range(1, check.NbFails() + 1)]
        check_iterator.Next()
    return out


def occ_read_iges(path) -> OccIges:
    """Read `path` with IGESControl_Reader and transfer every root."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.IGESControl import IGESControl_Reader

    from rgm.backends.occ import _quiet, _text

    _quiet()
    reader = IGESControl_Reader()
    status = reader.ReadFile(str(path))
    fails = [] if status == IFSelect_RetDone else [f"ReadFile status {int(status)}"]
    model = reader.Model()
    if model is not None:
        check = model.GlobalCheck()
        fails += [_text(check.CFail(i)) for i in range(1, check.NbFails() + 1)]
    if status != IFSelect_RetDone:
        return OccIges(None, 0, 0, fails, [])
    roots = reader.NbRootsForTransfer()
    transferred = reader.TransferRoots()
    fails += _fails(reader.WS().TransferReader().TransientProcess().CheckList(False))
    shapes = [reader.Shape(i) for i in range(1, reader.NbShapes() + 1)]
    return OccIges(reader.OneShape(), roots, transferred, fails, shapes)


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


def shape_points(shape, samples: int = 7) -> np.ndarray:
    """Points (k, 3) on a TopoDS shape's own geometry: per face the nodes of a samples x samples grid over
    its (u, v) bounds that lie inside the face (BRepClass_FaceClassifier), evaluated on its surface; per
    edge `samples` points of surface ∘ pcurve on its first face (the 3-D curve of a free edge)."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.BRepTools import BRepTools
    from OCP.gp import gp_Pnt2d
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_IN
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    out = []
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        face = TopoDS.Face_s(exp.Current())
        surface = BRepAdaptor_Surface(face)
        u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
        for u in np.linspace(u0, u1, samples):
            for v in np.linspace(v0, v1, samples):
                if BRepClass_FaceClassifier(face, gp_Pnt2d(u, v), 1e-9).State() == TopAbs_IN:
                    p = surface.Value(u, v)
                    out.append((p.X(), p.Y(), p.Z()))
        edges = TopExp_Explorer(face, TopAbs_EDGE)
        while edges.More():
            edge = TopoDS.Edge_s(edges.Current())
            if not BRep_Tool.Degenerated_s(edge):
                c = BRepAdaptor_Curve(edge, face)
                out += [(p.X(), p.Y(), p.Z()) for p in (c.Value(t) for t in np.linspace(c.FirstParameter(),
                                                                                       c.LastParameter(), samples))]
            edges.Next()
        exp.Next()
    exp = TopExp_Explorer(shape, TopAbs_EDGE, TopAbs_FACE)     # free edges (curves)
    while exp.More():
        c = BRepAdaptor_Curve(TopoDS.Edge_s(exp.Current()))
        out += [(p.X(), p.Y(), p.Z()) for p in (c.Value(t) for t in np.linspace(c.FirstParameter(),
                                                                               c.LastParameter(), samples))]
        exp.Next()
    return np.array(out).reshape(-1, 3)
