"""OpenCASCADE's reading of an IGES file measured against rgm's own evaluation of the model.

`measure(model, occ)` takes the shapes `IGESControl_Reader` transferred (one per root, in the order of
the model's exports) and, per exported object:

- faces: points of the OCC surface on a grid over the face's (u, v) bounds against rgm's evaluation
  **at the same (u, v)** when the file keeps the parametrisation (128 B-spline surfaces, planes in
  plane coordinates); a surface of revolution (120) at the same angle from the generatrix, the profile
  point located by rgm's inversion of the generatrix;
- edges: every OCC edge (on its face: surface ∘ pcurve, the geometry OCC read from the file; free
  curves: the 3-D curve) against rgm's trimming curves (parameter-space pieces S(B(t)) evaluated by rgm)
  or the surface's natural boundary; B-spline curves at the same parameter;
- `edges_3d`: OCC's 3-D edge curves against the same (with PREF = 1 OpenCASCADE rebuilds them from the
  pcurves itself, within its edge tolerance, reported as `edge_tolerance`);
- cover: the other direction, points of rgm's curves and trimming curves against OCC's edges
  (`Extrema_ExtPC` on surface ∘ pcurve), so a missing or wrong trim fails.

Distances are in model units (OpenCASCADE reads IGES in mm). OCP is imported inside functions (like
`iges_occ_check`, this module belongs with `rgm.backends.occ` by the architecture rule).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rgm.model import (
    CompositeCurve, Curve, IntersectionCurve, Line, Plane, Revolution, Shell, Surface, TrimmedFace,
)

from .iges_curves import surface_points

__all__ = ["Measured", "measure", "model_size", "MM"]

#: millimetres per model unit (OpenCASCADE reads IGES in mm)
MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}


@dataclass
class Measured:
    """Deviations (model units) of one exported object as OpenCASCADE read it (see the module doc)."""

    name: str
    faces: list = field(default_factory=list)   # (OCC surface type, wire count, edges_3d) per face
    surface: float = 0.0
    edges: float = 0.0
    edges_3d: float = 0.0
    cover: float = 0.0
    edge_tolerance: float = 0.0

    @property
    def worst(self) -> float:
        """The largest deviation of the file's geometry (surfaces, edges on their faces, cover)."""
        return max(self.surface, self.edges, self.cover)


def model_size(model, tol: float | None = None) -> float:
    """Largest extent of the exported objects' bounding box (control nets and sampled curves)."""
    from .iges_verify import sample_object

    tol = model.tolerance if tol is None else tol
    pts = np.concatenate([sample_object(o, tol) for o in model.exported()])
    return float(np.ptp(pts, axis=0).max()) or 1.0


def _xyz(points) -> np.ndarray:
    return np.array([[p.X(), p.Y(), p.Z()] for p in points]).reshape(-1, 3)


def _explore(shape, kind):
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    what, cast = {"face": (TopAbs_FACE, TopoDS.Face_s), "edge": (TopAbs_EDGE, TopoDS.Edge_s),
                  "wire": (TopAbs_WIRE, TopoDS.Wire_s)}[kind]
    exp, out = TopExp_Explorer(shape, what), []
    while exp.More():
        out.append(cast(exp.Current()))
        exp.Next()
    return out


def _edges(shape) -> list:
    from OCP.BRep import BRep_Tool

    return [e for e in _explore(shape, "edge") if not BRep_Tool.Degenerated_s(e)]


def _type(adaptor) -> str:
    return str(adaptor.GetType()).split("_")[-1].split(".")[-1]


# --- rgm side: curves and boundaries --------------------------------------------------------------

def _pieces(curve) -> list:
    return [q for p in curve.pieces for q in _pieces(p)] if isinstance(curve, CompositeCurve) else [curve]


def _nurbs(curve, tol):
    return curve.nurbs(tol) if isinstance(curve, IntersectionCurve) else curve.nurbs()


def _invert(surface, pts) -> np.ndarray:
    """(k, 2) rgm parameters of points on `surface` (plane coordinates for a plane)."""
    if isinstance(surface, Plane):
        return surface.coordinates(pts)
    u, v, _p, _d = surface.nurbs().closest_point(pts)
    return np.column_stack([u, v])


class _Boundary:
    """rgm's curves bounding a face (or a free curve): parameter-space NURBS on `surface`, model-space NURBS."""

    def __init__(self, surface=None, uv=(), xyz=()):
        self.surface, self.uv, self.xyz = surface, list(uv), list(xyz)

    def samples(self, count: int = 9) -> np.ndarray:
        """Points (k, 3) of every curve at `count` parameters each (parameter-space ones mapped by rgm)."""
        out = [c.evaluate(np.linspace(*c.domain, count)) for c in self.xyz]
        for c in self.uv:
            q = c.evaluate(np.linspace(*c.domain, count))
            out.append(surface_points(self.surface, q[:, 0], q[:, 1]))
        return np.concatenate(out)

    def distance(self, pts, uv=None) -> np.ndarray:
        """(k,) distance bound of points (k, 3) to the curves: model-space ones by rgm's curve inversion;
        parameter-space ones as |S(B(t*)) - p| with t* the parameter of B closest to p's (u, v) (given,
        or found by rgm's surface inversion)."""
        best = np.full(len(pts), np.inf)
        for c in self.xyz:
            best = np.minimum(best, c.closest_point(pts)[2])
        if self.uv:
            uv = _invert(self.surface, pts) if uv is None else uv
            for c in self.uv:
                q = c.evaluate(c.closest_point(uv)[0])
                best = np.minimum(best, np.linalg.norm(surface_points(self.surface, q[:, 0], q[:, 1]) - pts, axis=1))
        return best


def _rectangle(u0, u1, v0, v1) -> list:
    from rgm.geometry.conics import line_curve

    c = [(u0, v0), (u1, v0), (u1, v1), (u0, v1), (u0, v0)]
    return [line_curve(np.array(p, float), np.array(q, float)) for p, q in zip(c, c[1:])]


def _face_boundary(obj, tol, occ_bounds, preference: str = "auto") -> _Boundary:
    """The rgm curves bounding a face: its loops (plus the domain when it has no outer loop), or the
    natural domain of a bare surface (a plane's: the extent the file gave it, OCC's `occ_bounds`). A
    lazy intersection piece is the curve of it the receiver takes (`pcurve_preference` as written):
    its approximation in this surface's (u, v), or in model space under PREF = 2."""
    surface = obj.surface if isinstance(obj, TrimmedFace) else obj
    b = _Boundary(surface)
    loops = obj.loops() if isinstance(obj, TrimmedFace) else ()
    for loop in loops:
        model_space = preference == "3d" or (preference == "auto" and all(
            p.dim == 3 and not isinstance(p, IntersectionCurve) for p in loop.pieces))
        for piece in (q for p in loop.pieces for q in _pieces(p)):
            if isinstance(piece, IntersectionCurve) and not model_space:
                b.uv.append(piece.uv_curves(surface, tol)[0])
            else:
                (b.uv if piece.dim == 2 else b.xyz).append(_nurbs(piece, tol))
    if not (isinstance(obj, TrimmedFace) and obj.outer is not None):
        (u0, u1), (v0, v1) = surface.domain if not isinstance(surface, Plane) else (occ_bounds[:2], occ_bounds[2:])
        b.uv += _rectangle(u0, u1, v0, v1)
    return b


# --- OCC side -------------------------------------------------------------------------------------

def _surface_deviation(face, obj, mm: float, n: int) -> float:
    """Max |OCC surface - rgm surface| on an n x n grid over the face's (u, v) bounds, same parameters
    (a surface of revolution: same angle from the generatrix, the profile parameter found by rgm)."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface
    from OCP.BRepTools import BRepTools

    surface = obj.surface if isinstance(obj, TrimmedFace) else obj
    adaptor = BRepAdaptor_Surface(face, False)
    u0, u1, v0, v1 = BRepTools.UVBounds_s(face)
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij"))
    occ = _xyz(adaptor.Value(a, b) for a, b in zip(u, v)) / mm
    if _type(adaptor) == "SurfaceOfRevolution" and isinstance(surface, Revolution):
        from rgm.geometry.revolve import evaluate_revolution

        # OpenCASCADE's angle turns about its own axis direction (IGES 120 (t, angle) becomes (2 pi - angle,
        # t), so its axis is rgm's reversed and u = 0 is rgm's `end`): rgm's angle is theta0 + sign (u - u0)
        d = adaptor.AxeOfRevolution().Direction()
        sign = 1.0 if np.dot([d.X(), d.Y(), d.Z()], surface.axis_dir) > 0 else -1.0
        theta0 = surface.start if sign > 0 else surface.end
        prof = surface.profile.nurbs()
        generatrix = _rotate(occ.reshape(n, n, 3)[0], surface.axis_point, surface.axis_dir, -theta0)
        t = prof.closest_point(generatrix)[0]                      # the profile parameter, by rgm's inversion
        rgm = evaluate_revolution(prof, surface.axis_point, surface.axis_dir, theta0 + sign * (u - u0), np.tile(t, n))
    else:
        rgm = surface_points(surface, u, v)
    return float(np.linalg.norm(occ - rgm, axis=1).max())


def _rotate(pts, point, axis, angle) -> np.ndarray:
    """Points rotated by `angle` about the line through `point` along unit `axis` (Rodrigues)."""
    p = np.asarray(pts, float) - point
    c, s = np.cos(angle), np.sin(angle)
    return point + p * c + np.cross(axis, p) * s + np.outer(p @ axis, axis) * (1 - c)


def _edge_samples(edge, face, count: int):
    """Points (count, 3) mm of an edge: on its face (surface ∘ pcurve, with the pcurve's (u, v)) or
    free (its 3-D curve, uv None), and of its 3-D curve at the same parameters."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Curve

    c3 = BRepAdaptor_Curve(edge)
    if face is None:
        t = np.linspace(c3.FirstParameter(), c3.LastParameter(), count)
        p = _xyz(c3.Value(x) for x in t)
        return p, None, p, t, c3
    pcurve = BRep_Tool.CurveOnSurface_s(edge, face, 0.0, 0.0)
    on = BRepAdaptor_Curve(edge, face)
    t = np.linspace(on.FirstParameter(), on.LastParameter(), count)
    uv = np.array([[q.X(), q.Y()] for q in (pcurve.Value(x) for x in t)])
    t3 = t if BRep_Tool.SameParameter_s(edge) else np.linspace(c3.FirstParameter(), c3.LastParameter(), count)
    return _xyz(on.Value(x) for x in t), uv, _xyz(c3.Value(x) for x in t3), t, c3


def _cover(points_mm, edges, face, candidates: int = 2) -> np.ndarray:
    """(k,) distance (mm) of points to the nearest of `edges` (on `face`: surface ∘ pcurve): the least of
    the end points, Extrema_ExtPC's extrema and a local search (Extrema_LocateExtPC) from the nearest of
    33 samples, on the `candidates` edges nearest by those samples. The local search is needed: on a
    looping rational curve Extrema_ExtPC can miss the minimum of a point lying on the curve (0.48 mm
    instead of 1e-15 on a 10 mm cubic)."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.Extrema import Extrema_ExtPC, Extrema_LocateExtPC
    from OCP.gp import gp_Pnt

    curves = [BRepAdaptor_Curve(e, face) if face is not None else BRepAdaptor_Curve(e) for e in edges]
    params = [np.linspace(c.FirstParameter(), c.LastParameter(), 33) for c in curves]
    polys = [_xyz(c.Value(x) for x in t) for c, t in zip(curves, params)]
    near = np.stack([np.linalg.norm(points_mm[:, None] - q[None], axis=2) for q in polys])   # (edges, k, 33)
    coarse = near.min(axis=2)
    best = np.full(len(points_mm), np.inf)
    for i, p in enumerate(points_mm):
        point = gp_Pnt(*p)
        for k in np.argsort(coarse[:, i])[:candidates]:
            d = min(np.linalg.norm(polys[k][[0, -1]] - p, axis=1))
            ext = Extrema_ExtPC(point, curves[k], 1e-12)
            if ext.IsDone() and ext.NbExt():
                d = min(d, min(ext.SquareDistance(j) for j in range(1, ext.NbExt() + 1)) ** 0.5)
            local = Extrema_LocateExtPC(point, curves[k], float(params[k][np.argmin(near[k, i])]), 1e-12)
            if local.IsDone():
                d = min(d, local.SquareDistance() ** 0.5)
            best[i] = min(best[i], d)
    return best


def _measure_face(face, obj, tol, mm, out: Measured, preference: str, n: int = 7, count: int = 9):
    from OCP.BRep import BRep_Tool
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    s = BRepAdaptor_Surface(face, False)
    kind = _type(s)
    out.surface = max(out.surface, _surface_deviation(face, obj, mm, n))
    boundary = _face_boundary(obj, tol, (s.FirstUParameter(), s.LastUParameter(),
                                         s.FirstVParameter(), s.LastVParameter()), preference)
    edges = _edges(face)
    face_3d = 0.0
    if edges:
        samples = [_edge_samples(e, face, count) for e in edges]
        on, uv, p3 = (np.concatenate([sample[i] for sample in samples]) for i in range(3))
        # a B-spline face has rgm's (u, v) (checked above), so OCC's pcurve gives each edge point's (u, v)
        d = boundary.distance(on / mm, uv if kind == "BSplineSurface" else None)
        out.edges = max(out.edges, float(d.max()))
        face_3d = float((np.linalg.norm(p3 - on, axis=1) / mm + d).max())   # OCC's 3-D curve: a bound
        out.edges_3d = max(out.edges_3d, face_3d)
    out.faces.append((kind, len(_explore(face, "wire")), face_3d))
    out.edge_tolerance = max([out.edge_tolerance] + [BRep_Tool.Tolerance_s(e) / mm for e in edges])
    out.cover = max(out.cover, float(_cover(boundary.samples() * mm, edges, face).max()) / mm)


def _measure_curve(shape, obj, tol, mm, out: Measured, count: int = 9):
    from OCP.BRep import BRep_Tool

    pieces = [_nurbs(p, tol) for p in _pieces(obj)]
    boundary = _Boundary(xyz=pieces)
    whole = pieces[0] if len(pieces) == 1 and not isinstance(obj, Line) else None
    edges = _edges(shape)
    for edge in edges:
        p3, _uv, _p, t, c3 = _edge_samples(edge, None, count)
        p3 = p3 / mm
        if whole is not None and _type(c3) == "BSplineCurve" and whole.domain[0] <= t[0] and t[-1] <= whole.domain[1]:
            d = np.linalg.norm(whole.evaluate(t) - p3, axis=1)              # same parameter
        else:
            d = boundary.distance(p3)
        out.edges = out.edges_3d = max(out.edges, float(d.max()))
        out.edge_tolerance = max(out.edge_tolerance, BRep_Tool.Tolerance_s(edge) / mm)
    out.cover = float(_cover(boundary.samples(17) * mm, edges, None).max()) / mm


def measure(model, shapes, tol: float | None = None, pcurve_preference: str = "auto") -> list[Measured]:
    """One `Measured` per exported object, against the OCC shape transferred from its root (`shapes`
    in export order), for a file written with `tol` (default the model's) and `pcurve_preference`.
    Faces of a shell are matched to the shell's faces in order."""
    tol = model.tolerance if tol is None else tol
    mm = MM.get(model.units, 1.0)
    out = []
    for obj, shape in zip(model.exported(), shapes):
        m = Measured(getattr(obj, "name", "") or type(obj).__name__)
        if isinstance(obj, Curve):
            _measure_curve(shape, obj, tol, mm, m)
        else:
            faces = list(obj.faces) if isinstance(obj, Shell) else [obj]
            occ_faces = _explore(shape, "face")
            if len(occ_faces) != len(faces) and not isinstance(obj, Surface):
                m.surface = np.inf
            for i, face in enumerate(occ_faces):
                _measure_face(face, faces[min(i, len(faces) - 1)], tol, mm, m, pcurve_preference)
        out.append(m)
    return out
