"""OpenCASCADE back end: model objects → TopoDS shapes, STEP/BREP files and CadQuery objects.

This is the only module of rgm that imports OCP or cadquery, and only inside functions (``import OCP``
costs ~2 s). Lowering keeps exact geometry (model units throughout):

- B-spline, extrusion and ruled surfaces become ``Geom_BSplineSurface`` faces of their exact NURBS form;
  planes become ``Geom_Plane`` with rgm's plane coordinates as (u, v).
- A revolution is swept by ``BRepPrimAPI_MakeRevol``, so each line piece of the profile becomes an
  analytic cylinder (parallel to the axis), cone (inclined) or plane (perpendicular), and other pieces a
  true ``Geom_SurfaceOfRevolution``; profile ends on the axis close the shell, which becomes a solid.
- A trimmed face is built on the surface of its exact NURBS form (rgm's (u, v), so trimming curves are
  exact ``Geom2d_BSplineCurve`` pcurves); 3-D edges are derived with ``BRepLib.BuildCurves3d``, wires and
  face orientation repaired with ``ShapeFix_Wire``/``ShapeFix_Face``. Lazy intersections are computed here
  by OpenCASCADE's own intersector (``GeomInt_IntSS``) at the file's precision, with pcurves on both faces.
- Shells are sewn (``BRepBuilderAPI_Sewing``); a closed shell becomes a solid oriented outwards.

Every shape is checked with ``BRepCheck_Analyzer``; tolerances are capped (``ShapeFix_ShapeTolerance``)
so a fix-up never bloats the file precision. ``write_step(..., verify=True)`` reads the file back and
measures its deviation from rgm's own evaluation before the file is renamed into place.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from rgm.errors import BackendError, GeometryError

#: STEP schema option → OpenCASCADE ``write.step.schema`` value.
SCHEMAS = {"AP214": "AP214IS", "AP203": "AP203", "AP242": "AP242DIS"}
#: model units → STEP/OpenCASCADE length unit names.
UNITS = {"mm": "MM", "cm": "CM", "m": "M", "in": "INCH"}
#: Precision written into the file (model units): edge/vertex tolerances are kept at or below this.
PRECISION = 1e-7
#: 3-D trimming curves are projected onto their surface to this share of the tolerance: at the tolerance
#: itself the pcurve of a seam curve across a densely knotted fitted surface (39 x 35 control points)
#: looped back on itself and OpenCASCADE refused the wire, and it took 25 times longer
_PROJECTION = 0.01


def _quiet():
    """Silence OpenCASCADE's transfer statistics on stdout (only failures are printed)."""
    from OCP.Message import Message, Message_Gravity

    for printer in Message.DefaultMessenger_s().Printers():
        printer.SetTraceLevel(Message_Gravity.Message_Fail)


# --- geometry: numpy NURBS → Geom ---------------------------------------------------------------

def _knots_mults(knots):
    """Distinct knots and multiplicities (OpenCASCADE and STEP store knot vectors this way)."""
    from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal

    k = np.asarray(knots, float)
    tol = 1e-12 * max(1.0, float(np.abs(k).max()))
    starts = np.flatnonzero(np.concatenate([[True], np.diff(k) > tol]))
    mults = np.diff(np.concatenate([starts, [k.size]]))
    ak, am = TColStd_Array1OfReal(1, starts.size), TColStd_Array1OfInteger(1, starts.size)
    for i, (value, m) in enumerate(zip(k[starts], mults), 1):
        ak.SetValue(i, float(value))
        am.SetValue(i, int(m))
    return ak, am


def geom_surface(nurbs):
    """``Geom_BSplineSurface`` with the same degrees, knots, control net (nu, nv, 3) and weights."""
    from OCP.Geom import Geom_BSplineSurface
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array2OfPnt
    from OCP.TColStd import TColStd_Array2OfReal

    ctrl = np.asarray(nurbs.ctrl, float)
    nu, nv = ctrl.shape[:2]
    poles = TColgp_Array2OfPnt(1, nu, 1, nv)
    weights = TColStd_Array2OfReal(1, nu, 1, nv)
    w = np.asarray(nurbs.weights, float) if nurbs.is_rational else np.ones((nu, nv))
    for i in range(nu):
        for j in range(nv):
            poles.SetValue(i + 1, j + 1, gp_Pnt(*ctrl[i, j]))
            weights.SetValue(i + 1, j + 1, float(w[i, j]))
    uk, um = _knots_mults(nurbs.knots_u)
    vk, vm = _knots_mults(nurbs.knots_v)
    try:
        return Geom_BSplineSurface(poles, weights, uk, vk, um, vm, nurbs.degree_u, nurbs.degree_v, False, False)
    except Exception as exc:  # Standard_ConstructionError
        raise BackendError(f"OpenCASCADE rejected a B-spline surface: {exc}") from None


def geom_curve(nurbs):
    """``Geom_BSplineCurve`` (3-D) or ``Geom2d_BSplineCurve`` (2-D, parameter space) of a NurbsCurve."""
    from OCP.TColStd import TColStd_Array1OfReal

    ctrl = np.asarray(nurbs.ctrl, float)
    w = np.asarray(nurbs.weights, float) if nurbs.is_rational else np.ones(len(ctrl))
    weights = TColStd_Array1OfReal(1, len(ctrl))
    for i, wi in enumerate(w, 1):
        weights.SetValue(i, float(wi))
    knots, mults = _knots_mults(nurbs.knots)
    if ctrl.shape[1] == 2:
        from OCP.Geom2d import Geom2d_BSplineCurve
        from OCP.gp import gp_Pnt2d
        from OCP.TColgp import TColgp_Array1OfPnt2d

        poles = TColgp_Array1OfPnt2d(1, len(ctrl))
        for i, p in enumerate(ctrl, 1):
            poles.SetValue(i, gp_Pnt2d(*p))
        return Geom2d_BSplineCurve(poles, weights, knots, mults, nurbs.degree)
    from OCP.Geom import Geom_BSplineCurve
    from OCP.gp import gp_Pnt
    from OCP.TColgp import TColgp_Array1OfPnt

    poles = TColgp_Array1OfPnt(1, len(ctrl))
    for i, p in enumerate(ctrl, 1):
        poles.SetValue(i, gp_Pnt(*p))
    return Geom_BSplineCurve(poles, weights, knots, mults, nurbs.degree)


def _pnt(p):
    from OCP.gp import gp_Pnt

    return gp_Pnt(*map(float, p))


def _dir(v):
    from OCP.gp import gp_Dir

    return gp_Dir(*map(float, v))


def surface_geom(surface):
    """The ``Geom_Surface`` whose (u, v) are rgm's own for `surface` (used for faces and pcurves)."""
    from rgm.model import Plane

    if isinstance(surface, Plane):
        from OCP.Geom import Geom_Plane
        from OCP.gp import gp_Ax3

        return Geom_Plane(gp_Ax3(_pnt(surface.origin), _dir(surface.normal), _dir(surface.x_dir)))
    return geom_surface(surface.nurbs())


# --- curves → edges and wires --------------------------------------------------------------------

def _edges_of(curve):
    """List of TopoDS_Edge for a 3-D model curve, keeping lines and circles analytic."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.gp import gp_Ax2, gp_Circ

    from rgm.model import BSplineCurve, Circle, CircularArc, CompositeCurve, IntersectionCurve, Line, Polyline

    if curve.dim != 3:
        raise BackendError(f"{_label(curve)} is a parameter-space curve; only 3-D curves have a shape of their own")
    if isinstance(curve, Line):
        return [BRepBuilderAPI_MakeEdge(_pnt(curve.p0), _pnt(curve.p1)).Edge()]
    if isinstance(curve, Polyline) or (isinstance(curve, BSplineCurve) and curve.curve.degree == 1
                                       and not curve.curve.is_rational):
        pts = curve.points if isinstance(curve, Polyline) else np.asarray(curve.curve.ctrl)
        return [BRepBuilderAPI_MakeEdge(_pnt(a), _pnt(b)).Edge() for a, b in zip(pts[:-1], pts[1:])
                if np.linalg.norm(b - a) > PRECISION]
    if isinstance(curve, Circle):   # starting where rgm's circle starts, so loops stay joined
        from rgm.geometry.conics import perpendicular

        circ = gp_Circ(gp_Ax2(_pnt(curve.center), _dir(curve.normal), _dir(perpendicular(curve.normal))),
                       curve.radius)
        return [BRepBuilderAPI_MakeEdge(circ).Edge()]
    if isinstance(curve, CircularArc):
        x, _ = curve.frame
        circ = gp_Circ(gp_Ax2(_pnt(curve.center), _dir(curve.normal), _dir(x)), curve.radius)
        return [BRepBuilderAPI_MakeEdge(circ, 0.0, curve.sweep).Edge()]
    if isinstance(curve, CompositeCurve):
        return [e for piece in curve.pieces for e in _edges_of(piece)]
    if isinstance(curve, IntersectionCurve):
        return [BRepBuilderAPI_MakeEdge(c3).Edge() for c3, _, _ in _occ_intersection(curve)]
    return [BRepBuilderAPI_MakeEdge(geom_curve(curve.nurbs())).Edge()]


def _wire(edges):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeWire

    mk = BRepBuilderAPI_MakeWire()
    for e in edges:
        mk.Add(e)
    if not mk.IsDone():
        raise BackendError("curve pieces do not join end to start")
    return mk.Wire()


# --- intersections by OpenCASCADE ------------------------------------------------------------------

def _occ_intersection(curve):
    """Branches of ``curve.a ∩ curve.b`` by ``GeomInt_IntSS`` at the file precision (PRECISION, not the
    model's tolerance: the lazy intersection is approximated here, as finely as the file can hold), or
    at 10 or 100 times it where OpenCASCADE's approximation fails at that (two YCB meat can patches whose
    surfaces nearly touch): list of (3-D curve, pcurve on a, on b)."""
    from OCP.GeomInt import GeomInt_IntSS

    a, b = surface_geom(curve.a), surface_geom(curve.b)
    for k in range(3):
        try:
            inter = GeomInt_IntSS(a, b, PRECISION * 10**k, True, True, True)
            break
        except Exception:   # OCP raises OpenCASCADE's Standard_* errors as plain exceptions: here its
            # approximation failing ("BSpline curve: Knots interval values too close")
            if k == 2:
                raise BackendError(f"OpenCASCADE's intersector failed on {_label(curve)}") from None
    if not inter.IsDone() or inter.NbLines() == 0:
        raise BackendError(f"OpenCASCADE found no intersection for {_label(curve)}")
    return [(inter.Line(i), inter.LineOnS1(i), inter.LineOnS2(i)) for i in range(1, inter.NbLines() + 1)]


def _project2d(curve2d, p):
    """(distance, parameter) of the closest point of a bounded Geom2d curve to the 2-D point p: the
    nearest orthogonal foot or, when p lies beyond the curve (no foot, or a nearer end), an end."""
    from OCP.Geom2dAPI import Geom2dAPI_ProjectPointOnCurve
    from OCP.gp import gp_Pnt2d

    point = gp_Pnt2d(*map(float, p))
    ends = [(point.Distance(curve2d.Value(t)), t) for t in (curve2d.FirstParameter(), curve2d.LastParameter())]
    proj = Geom2dAPI_ProjectPointOnCurve(point, curve2d)
    feet = [(proj.LowerDistance(), proj.LowerDistanceParameter())] if proj.NbPoints() else []
    return min(feet + ends)


# --- trimmed faces -------------------------------------------------------------------------------

def _geom2d_pieces(curve):
    """[(Geom2d_Curve, t0, t1)] of a 2-D model curve; lines, polylines, circles and arcs stay analytic."""
    from OCP.GCE2d import GCE2d_MakeSegment
    from OCP.Geom2d import Geom2d_Circle
    from OCP.gp import gp_Ax22d, gp_Dir2d, gp_Pnt2d

    from rgm.model import BSplineCurve, Circle, CircularArc, CompositeCurve, Line, Polyline

    def segment(a, b):
        c = GCE2d_MakeSegment(gp_Pnt2d(*map(float, a)), gp_Pnt2d(*map(float, b))).Value()
        return c, c.FirstParameter(), c.LastParameter()

    if isinstance(curve, Line):
        return [segment(curve.p0, curve.p1)]
    if isinstance(curve, Polyline) or (isinstance(curve, BSplineCurve) and curve.curve.degree == 1
                                       and not curve.curve.is_rational):
        pts = curve.points if isinstance(curve, Polyline) else np.asarray(curve.curve.ctrl)
        return [segment(a, b) for a, b in zip(pts[:-1], pts[1:]) if np.linalg.norm(b - a) > 0]
    if isinstance(curve, (Circle, CircularArc)):
        x = np.array([1.0, 0.0]) if isinstance(curve, Circle) else curve.frame[0][:2]
        axes = gp_Ax22d(gp_Pnt2d(*map(float, curve.center)), gp_Dir2d(*map(float, x)), bool(curve.normal[2] > 0))
        sweep = 2 * np.pi if isinstance(curve, Circle) else curve.sweep
        return [(Geom2d_Circle(axes, curve.radius), 0.0, sweep)]
    if isinstance(curve, CompositeCurve):
        return [p for piece in curve.pieces for p in _geom2d_pieces(piece)]
    c = geom_curve(curve.nurbs())
    return [(c, c.FirstParameter(), c.LastParameter())]


def _pcurve_pieces(loop, surface, tol):
    """Pcurves (Geom2d_Curve, t0, t1) of a loop in `surface`'s (u, v), joined end to start."""
    from OCP.BRep import BRep_Tool
    from OCP.Geom2d import Geom2d_TrimmedCurve
    from OCP.GeomProjLib import GeomProjLib
    from OCP.TopExp import TopExp

    from rgm.geometry import NurbsCurve
    from rgm.model import BSplineCurve, IntersectionCurve, Plane

    pieces = []  # (geom2d or None, t0, t1, intersection piece or None)
    for piece in loop.pieces:
        if isinstance(piece, IntersectionCurve):
            pieces.append((None, 0.0, 0.0, piece))
        elif piece.dim == 2:
            pieces += [(c, t0, t1, None) for c, t0, t1 in _geom2d_pieces(piece)]
        elif isinstance(surface, Plane):  # plane coordinates are an exact affine image of the curve
            c = piece.nurbs()
            image = NurbsCurve(c.degree, c.knots, surface.coordinates(np.asarray(c.ctrl)),
                               c.weights if c.is_rational else None)
            pieces += [(g, t0, t1, None) for g, t0, t1 in _geom2d_pieces(BSplineCurve(image))]
        else:  # each smooth 3-D edge (line, arc, spline) projected onto the surface
            for edge in _edges_of(piece):
                c3, t0, t1 = BRep_Tool.Curve_s(edge, 0.0, 1.0), BRep_Tool.Parameter_s(
                    TopExp.FirstVertex_s(edge), edge), BRep_Tool.Parameter_s(TopExp.LastVertex_s(edge), edge)
                c2 = GeomProjLib.Curve2d_s(c3, t0, t1, surface_geom(surface), _PROJECTION * tol)
                pieces.append((c2, c2.FirstParameter(), c2.LastParameter(), None))
    out = []
    for k, (c, t0, t1, inter) in enumerate(pieces):
        if inter is None:
            out.append((c, t0, t1))
            continue
        side = 1 if inter.a is surface else 2 if inter.b is surface else 0
        if side == 0:
            raise BackendError(f"{_label(inter)} is not an intersection with this face's surface")
        branches = [b[side] for b in _occ_intersection(inter)]
        if len(pieces) == 1:  # the whole loop is one closed branch
            closed = [b for b in branches if b.Value(b.FirstParameter()).Distance(b.Value(b.LastParameter())) < 1e-6]
            if len(closed) != 1:
                raise BackendError(f"{_label(inter)} gives {len(closed)} closed branches; a loop needs exactly one")
            out.append((closed[0], closed[0].FirstParameter(), closed[0].LastParameter()))
            continue
        prev, nxt = pieces[k - 1], pieces[(k + 1) % len(pieces)]
        if prev[3] is not None or nxt[3] is not None:
            raise BackendError("two intersection pieces in a row in one loop are not supported; put a curve between")
        best, ta, tb = _stretch_between(inter, branches, surface, prev[0].Value(prev[2]), nxt[0].Value(nxt[1]), tol)
        # the neighbours end where this piece's approximation starts and ends (they met it within the
        # tolerance, but a wire closes at PRECISION): their last / first point moved onto it
        if k == 0:
            pieces[-1] = (*_moved_end(pieces[-1][:3], best.Value(ta), True), None)
        else:
            out[-1] = _moved_end(out[-1], best.Value(ta), True)
        if k + 1 < len(pieces):
            pieces[k + 1] = (*_moved_end(pieces[k + 1][:3], best.Value(tb), False), None)
        else:
            out[0] = _moved_end(out[0], best.Value(tb), False)
        out.append((Geom2d_TrimmedCurve(best, ta, tb), ta, tb))
    return _snapped_joins(out)


def _stretch_between(inter, branches, surface, a, b, tol):
    """(Geom2d curve, ta, tb), ta < tb: the stretch of the lazy intersection `inter` on `surface` from the
    2-D point `a` (the loop's previous piece's end) to `b` (the next one's start). OpenCASCADE's branch
    (`branches`, its pcurves on `surface`) passing nearest both is taken if it passes within `tol` (mm) of
    both; where the surfaces meet at a small angle GeomInt_IntSS can break one curve into fragments none of
    which reaches both (a fitted mustard bottle's shoulder: 5.5 mm), and rgm's own marched intersection
    (`IntersectionCurve.stretch`) at tol / 10 is taken instead. Neither within `tol`: an error."""
    geom = surface_geom(surface)

    def gap(curve, ta, tb):
        return max(geom.Value(p.X(), p.Y()).Distance(geom.Value(q.X(), q.Y()))
                   for p, q in ((a, curve.Value(ta)), (b, curve.Value(tb))))

    best = min(branches, key=lambda br: _project2d(br, (a.X(), a.Y()))[0] + _project2d(br, (b.X(), b.Y()))[0])
    (_, ta), (_, tb) = _project2d(best, (a.X(), a.Y())), _project2d(best, (b.X(), b.Y()))
    miss = gap(best, ta, tb)
    if miss > tol:
        from rgm.model import BSplineCurve

        ends = [np.array([p.X(), p.Y(), p.Z()]) for p in (geom.Value(a.X(), a.Y()), geom.Value(b.X(), b.Y()))]
        try:
            uv, _ = inter.stretch(surface, ends[0], ends[1], tol / 10)
        except GeometryError:
            uv = None
        if uv is not None:
            [(best, ta, tb)] = _geom2d_pieces(BSplineCurve(uv))
        own = np.inf if uv is None else gap(best, ta, tb)
        if own > tol:
            raise BackendError(f"{_label(inter)}: the loop's neighbouring pieces end {min(miss, own):.3g} away "
                               f"from the intersection (more than the tolerance {tol:g}); they must meet it")
    if ta > tb:
        best = best.Reversed()
        ta, tb = best.ReversedParameter(ta), best.ReversedParameter(tb)
    return best, ta, tb


def _snapped_joins(pieces, gap: float = 1e-6):
    """Pcurve pieces (Geom2d_Curve, t0, t1) of a closed loop with each join closer than `gap` (in (u, v))
    made exact: a piece's end moved onto the next one's start, or that start onto the end where the end
    cannot move (`_moved_end`). Projected 3-D pieces meet their neighbours to about 1e-9 in (u, v), which
    on a surface a few hundred millimetres across is over the wire's PRECISION: OpenCASCADE then joined the
    edges but found the face unorientable."""
    out = list(pieces)
    for k in range(len(out)):
        nxt = (k + 1) % len(out)
        end, start = out[k][0].Value(out[k][2]), out[nxt][0].Value(out[nxt][1])
        if 0.0 < end.Distance(start) < gap:
            moved = _moved_end(out[k], start, True)
            if moved is out[k]:
                out[nxt] = _moved_end(out[nxt], end, False)
            else:
                out[k] = moved
    return out


def _moved_end(piece, point, at_end: bool):
    """A pcurve piece (Geom2d_Curve, t0, t1) with its end (`at_end`) or start moved to the 2-D point:
    a B-spline's end pole, or a segment rebuilt; other curves are kept (their ends are exact)."""
    from OCP.Geom2d import Geom2d_BSplineCurve
    from OCP.GCE2d import GCE2d_MakeSegment

    c, t0, t1 = piece
    here = c.Value(t1 if at_end else t0)
    if here.Distance(point) == 0.0:
        return piece
    if isinstance(c, Geom2d_BSplineCurve) and (t1 if at_end else t0) == (c.LastParameter() if at_end else c.FirstParameter()):
        c = c.Copy()
        c.SetPole(c.NbPoles() if at_end else 1, point)
        return c, t0, t1
    if type(c).__name__ == "Geom2d_TrimmedCurve" and type(c.BasisCurve()).__name__ == "Geom2d_Line":
        a, b = (c.Value(t0), point) if at_end else (point, c.Value(t1))
        seg = GCE2d_MakeSegment(a, b).Value()
        return seg, seg.FirstParameter(), seg.LastParameter()
    return piece


def _face_from_loops(face, tol):
    """TopoDS_Face of a TrimmedFace: edges from pcurves, 3-D curves derived (`_edge_on_surface`), wires and
    orientation fixed."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge, BRepBuilderAPI_MakeFace
    from OCP.ShapeFix import ShapeFix_Face, ShapeFix_Wire

    surf = surface_geom(face.surface)
    if face.outer is None:
        if not hasattr(face.surface, "nurbs") or face.surface.domain[0][0] == -np.inf:
            raise BackendError(f"{_label(face)}: an infinite plane needs an outer loop")
        return BRepBuilderAPI_MakeFace(surf, PRECISION).Face()
    wires = []
    for loop in face.loops():
        edges = []
        for c2, t0, t1 in _pcurve_pieces(loop, face.surface, tol):
            mk = BRepBuilderAPI_MakeEdge(c2, surf, t0, t1)
            if not mk.IsDone():
                raise BackendError(f"{_label(face)}: could not build an edge from a trimming curve")
            edges.append(_edge_on_surface(mk.Edge(), c2, surf, t0, t1))
        wires.append(_wire(edges))
    mk = BRepBuilderAPI_MakeFace(surf, wires[0], True)
    for w in wires[1:]:
        mk.Add(w)
    result = mk.Face()
    for w in _wires_of(result):
        fix_wire = ShapeFix_Wire(w, result, PRECISION)
        fix_wire.Perform()
    fix = ShapeFix_Face(result)
    fix.SetPrecision(PRECISION)
    fix.FixOrientationMode = 1
    fix.Perform()
    return fix.Face()


def _off_surface(edge, c2, surf, t0: float, t1: float, m: int) -> float:
    """Largest distance (model units) at m parameters between an edge's 3-D curve and its pcurve on `surf`."""
    from OCP.BRep import BRep_Tool

    c3 = BRep_Tool.Curve_s(edge, 0.0, 0.0)
    worst = 0.0
    for t in np.linspace(t0, t1, m):
        uv = c2.Value(float(t))
        worst = max(worst, surf.Value(uv.X(), uv.Y()).Distance(c3.Value(float(t))))
    return worst


def _edge_on_surface(edge, c2, surf, t0: float, t1: float):
    """The edge of pcurve c2 on `surf` with its 3-D curve derived (``BRepLib::BuildCurves3d``). Across a
    densely knotted B-spline surface (a fitted patch) OpenCASCADE's default approximation can leave that
    curve far off the surface, silently (0.4 mm on an 80 x 80 net; the face is then refused, or written with
    a bloated tolerance): there it is measured at a few points per knot span, and approximated again in
    more segments, up to 8 per knot line it may cross, until it lies within 10 x the precision."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
    from OCP.BRepLib import BRepLib
    from OCP.GeomAbs import GeomAbs_C1

    BRepLib.BuildCurves3d_s(edge, PRECISION)
    if not hasattr(surf, "NbUKnots"):
        return edge
    lines = surf.NbUKnots() + surf.NbVKnots()
    m = 4 * lines + 33
    best, off = edge, _off_surface(edge, c2, surf, t0, t1, m)
    for segments in (2 * lines, 4 * lines, 8 * lines):
        if off <= 10 * PRECISION:
            break
        again = BRepBuilderAPI_MakeEdge(c2, surf, t0, t1).Edge()
        BRepLib.BuildCurves3d_s(again, PRECISION, GeomAbs_C1, 14, segments)
        d = _off_surface(again, c2, surf, t0, t1, m)
        if d < off:
            best, off = again, d
    return best


def _wires_of(shape):
    from OCP.TopAbs import TopAbs_WIRE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    exp = TopExp_Explorer(shape, TopAbs_WIRE)
    out = []
    while exp.More():
        out.append(TopoDS.Wire_s(exp.Current()))
        exp.Next()
    return out


# --- revolutions, shells, solids -----------------------------------------------------------------

def _revolution(rev, tol):
    """Shape swept by ``BRepPrimAPI_MakeRevol``: analytic cylinders/cones/planes for line pieces."""
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeRevol
    from OCP.gp import gp_Ax1, gp_Trsf

    axis = gp_Ax1(_pnt(rev.axis_point), _dir(rev.axis_dir))
    profile = _wire(_edges_of(rev.profile))
    if rev.start != 0.0:
        rot = gp_Trsf()
        rot.SetRotation(axis, rev.start)
        profile = BRepBuilderAPI_Transform(profile, rot, True).Shape()
    sweep = rev.end - rev.start
    full = abs(sweep - 2 * np.pi) < 1e-12
    mk = BRepPrimAPI_MakeRevol(profile, axis) if full else BRepPrimAPI_MakeRevol(profile, axis, sweep)
    if not mk.IsDone():
        raise BackendError(f"{_label(rev)}: OpenCASCADE could not sweep the profile")
    return _close_up(mk.Shape())


def _close_up(shape):
    """A shell that closes up becomes a solid oriented outwards; otherwise the shape is kept."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeSolid
    from OCP.ShapeFix import ShapeFix_Solid
    from OCP.TopAbs import TopAbs_SHELL
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    exp = TopExp_Explorer(shape, TopAbs_SHELL)
    shells = []
    while exp.More():
        shells.append(TopoDS.Shell_s(exp.Current()))
        exp.Next()
    if len(shells) != 1 or not BRep_Tool.IsClosed_s(shells[0]):
        return shape
    solid = BRepBuilderAPI_MakeSolid(shells[0]).Solid()
    fix = ShapeFix_Solid(solid)
    fix.Perform()
    return fix.Solid()


def _sew(shapes, tol):
    from OCP.BRepBuilderAPI import BRepBuilderAPI_Sewing

    sewing = BRepBuilderAPI_Sewing(tol)
    for s in shapes:
        sewing.Add(s)
    sewing.Perform()
    return _close_up(sewing.SewedShape())


# --- public API ----------------------------------------------------------------------------------

def _label(obj) -> str:
    name = getattr(obj, "name", None)
    return f"`{name}`" if name else type(obj).__name__


def to_shape(obj, tol: float | None = None):
    """The OpenCASCADE ``TopoDS_Shape`` of one model object (curve, surface, face or shell).

    `tol` (model units) is the precision for intersections and sewing (default 1e-6). Raises
    BackendError when the object cannot be lowered or the result fails ``BRepCheck_Analyzer``.
    """
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace

    from rgm.model import Curve, Plane, Revolution, Shell, Surface, TrimmedFace

    tol = 1e-6 if tol is None else float(tol)
    if isinstance(obj, Revolution):
        shape = _revolution(obj, tol)
    elif isinstance(obj, Plane):
        raise BackendError(f"{_label(obj)} is an infinite plane; trim it with a loop to export it")
    elif isinstance(obj, Surface):
        shape = BRepBuilderAPI_MakeFace(surface_geom(obj), PRECISION).Face()
    elif isinstance(obj, TrimmedFace):
        shape = _face_from_loops(obj, tol)
    elif isinstance(obj, Shell):
        shape = _sew([to_shape(f, tol) for f in obj.faces], tol)
    elif isinstance(obj, Curve):
        edges = _edges_of(obj)
        shape = edges[0] if len(edges) == 1 else _wire(edges)
    else:
        raise BackendError(f"{_label(obj)} ({type(obj).__name__}) has no OpenCASCADE shape")
    return _checked(shape, obj)


def _checked(shape, obj):
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepLib import BRepLib
    from OCP.ShapeFix import ShapeFix_Shape, ShapeFix_ShapeTolerance

    BRepLib.BuildCurves3d_s(shape, PRECISION)
    if not BRepCheck_Analyzer(shape).IsValid():
        fix = ShapeFix_Shape(shape)
        fix.SetPrecision(PRECISION)
        fix.SetMaxTolerance(1e3 * PRECISION)
        fix.Perform()
        shape = fix.Shape()
    ShapeFix_ShapeTolerance().LimitTolerance(shape, PRECISION, 1e3 * PRECISION)
    if not BRepCheck_Analyzer(shape).IsValid():
        raise BackendError(f"{_label(obj)}: OpenCASCADE finds the lowered shape invalid (BRepCheck_Analyzer)")
    return shape


def named_shapes(model, tol: float | None = None) -> list:
    """[(binding name, TopoDS_Shape)] for every exported object of the model."""
    tol = model.tolerance if tol is None else tol
    names = model.exports or tuple(n for n, o in model.objects.items() if any(o is e for e in model.exported()))
    return [(name, to_shape(model.objects[name], tol)) for name in names]


def to_cadquery(model):
    """CadQuery objects for a model (or one model object): a ``cq.Shape`` (Solid, Shell, Face, Edge) per
    exported binding, combined into a ``cq.Compound`` when there are several. Users can fillet,
    boolean and export them with CadQuery as usual."""
    import cadquery as cq

    from rgm.model import Model

    pairs = named_shapes(model) if isinstance(model, Model) else [(getattr(model, "name", None), to_shape(model))]
    shapes = [cq.Shape.cast(s) for _, s in pairs]
    for (name, _), s in zip(pairs, shapes):
        s.label = name or ""
    return shapes[0] if len(shapes) == 1 else cq.Compound.makeCompound(shapes)


def _compound(shapes):
    from OCP.BRep import BRep_Builder
    from OCP.TopoDS import TopoDS_Compound

    comp, builder = TopoDS_Compound(), BRep_Builder()
    builder.MakeCompound(comp)
    for s in shapes:
        builder.Add(comp, s)
    return comp


def _step_statics_ready() -> None:
    """Initialise OpenCASCADE's STEP controllers before setting their static parameters: the first
    writer or reader a process makes initialises them and resets the statics to their defaults, so the
    first STEP file written used to come out in AP214 and millimetres whatever was asked."""
    from OCP.STEPCAFControl import STEPCAFControl_Controller
    from OCP.STEPControl import STEPControl_Controller

    STEPControl_Controller.Init_s()
    STEPCAFControl_Controller.Init_s()


def _write_step_file(pairs, path, schema, units):
    """STEP through ``STEPCAFControl_Writer``: one XCAF label per binding, named after it."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_StepModelType
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFApp import XCAFApp_Application
    from OCP.XCAFDoc import XCAFDoc_DocumentTool
    from OCP.XSControl import XSControl_WorkSession

    _quiet()
    doc = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
    XCAFApp_Application.GetApplication_s().InitDocument(doc)
    tool = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
    for name, shape in pairs:
        label = tool.AddShape(shape, False)
        TDataStd_Name.Set_s(label, TCollection_ExtendedString(name or "rgm"))
    _step_statics_ready()
    Interface_Static.SetCVal_s("write.step.schema", SCHEMAS[schema])
    Interface_Static.SetCVal_s("xstep.cascade.unit", units)
    Interface_Static.SetCVal_s("write.step.unit", units)
    Interface_Static.SetIVal_s("write.surfacecurve.mode", 1)
    Interface_Static.SetIVal_s("write.precision.mode", 0)
    writer = STEPCAFControl_Writer(XSControl_WorkSession(), False)
    writer.SetNameMode(True)
    if not writer.Transfer(doc, STEPControl_StepModelType.STEPControl_AsIs):
        raise BackendError("OpenCASCADE could not transfer the shapes to STEP")
    if writer.Write(str(path)) != IFSelect_RetDone:
        raise BackendError(f"OpenCASCADE could not write {path}")


def write_step(model, path, *, schema: str = "AP214", verify: bool = False, tol: float | None = None,
               report=None, **ignored):
    """Write the exported objects of `model` as STEP (AP214 by default; AP203, AP242) in model units,
    binding names as product names. With `verify`, the temporary file is read back, checked and its
    deviation measured (`verify_step`); a failing file is removed and BackendError raised, a passing
    one's figures are given to `report` (a callable taking one line of text) when there is one."""
    from rgm.atomic import temp_path_beside

    schema = schema.upper()
    if schema not in SCHEMAS:
        raise BackendError(f"unknown STEP schema {schema!r}; choose one of {', '.join(SCHEMAS)}")
    if model.units not in UNITS:
        raise BackendError(f"units {model.units!r} cannot be written to STEP")
    pairs = named_shapes(model, tol)
    tmp = temp_path_beside(path)
    try:
        _write_step_file(pairs, tmp, schema, UNITS[model.units])
        if verify:
            figures = verify_step(model, tmp, tol=tol, expected=[shape for _, shape in pairs])
            if report is not None:
                report(f"verified {path}: read back by STEPControl_Reader, valid (BRepCheck_Analyzer), "
                       f"{figures['faces']} faces of the same surface types, max deviation from the model "
                       f"{figures['max']:.3g} {model.units} (limit {figures['limit']:.3g})")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return Path(path)


def write_brep(model, path, **ignored):
    """Write the exported objects as one OpenCASCADE BREP compound (native, lossless) atomically."""
    from OCP.BRepTools import BRepTools

    from rgm.atomic import temp_path_beside

    shape = _compound([s for _, s in named_shapes(model)])
    tmp = temp_path_beside(path)
    try:
        if not BRepTools.Write_s(shape, str(tmp)):
            raise BackendError(f"OpenCASCADE could not write {path}")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return Path(path)


def read_step(path, units: str = "mm"):
    """Read a STEP file: its shape (all roots transferred) in `units` (the file's own unit is converted);
    BackendError if it cannot be read."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_Reader

    _quiet()
    if units not in UNITS:
        raise BackendError(f"units {units!r} are not known to the STEP reader")
    _step_statics_ready()
    Interface_Static.SetCVal_s("xstep.cascade.unit", UNITS[units])
    reader = STEPControl_Reader()
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise BackendError(f"OpenCASCADE cannot read the STEP file {path}")
    reader.TransferRoots()
    return reader.OneShape()


def read_iges(path):
    """Read an IGES file with ``IGESControl_Reader``: (shape of all roots, list of fail messages)."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.IGESControl import IGESControl_Reader

    _quiet()
    reader = IGESControl_Reader()
    status = reader.ReadFile(str(path))
    fails = []
    if status != IFSelect_RetDone:
        fails.append(f"ReadFile status {int(status)}")
    check = reader.Model().GlobalCheck() if reader.Model() is not None else None
    if check is not None:
        fails += [_text(check.CFail(i)) for i in range(1, check.NbFails() + 1)]
    if status != IFSelect_RetDone:
        return None, fails
    reader.TransferRoots()
    if reader.NbShapes() == 0 or reader.OneShape().IsNull():   # OpenCASCADE reads any text as 0 entities
        return None, fails + [f"no entity of {path} could be transferred (is it an IGES file?)"]
    return reader.OneShape(), fails


def _text(message) -> str:
    return message if isinstance(message, str) else message.ToCString()


def faces_of(shape) -> list:
    """The TopoDS_Face list of a shape, in exploration order."""
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    exp = TopExp_Explorer(shape, TopAbs_FACE)
    out = []
    while exp.More():
        out.append(TopoDS.Face_s(exp.Current()))
        exp.Next()
    return out


def surface_type(face) -> str:
    """OpenCASCADE's surface type name of a face: 'Plane', 'Cylinder', 'Cone', 'BSplineSurface', ..."""
    from OCP.BRepAdaptor import BRepAdaptor_Surface

    return str(BRepAdaptor_Surface(face).GetType()).split("_")[-1].split(".")[-1]


def distances_to_shape(points, shape) -> np.ndarray:
    """(k,) distances of points (k, 3) to a shape: ``BRepExtrema_DistShapeShape`` from a vertex and, where
    that finds nothing within 1e-9 of the shape's size, also the point's nearest foot on each face's
    surface that lies inside the face (``GeomAPI_ProjectPointOnSurf``, ``BRepClass_FaceClassifier``):
    DistShapeShape can stop at a local minimum (on a surface of revolution of a B-spline generatrix it
    gave 0.058 mm for a point on the surface of an 8 mm solid, and a verified file was refused). Both
    are distances to points of the shape, so the smaller is one too."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeVertex
    from OCP.BRepClass import BRepClass_FaceClassifier
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape
    from OCP.GeomAPI import GeomAPI_ProjectPointOnSurf
    from OCP.gp import gp_Pnt2d
    from OCP.TopAbs import TopAbs_IN, TopAbs_ON

    out = np.empty(len(points))
    faces, exact = None, None
    for i, p in enumerate(np.asarray(points, float)):
        dist = BRepExtrema_DistShapeShape(BRepBuilderAPI_MakeVertex(_pnt(p)).Vertex(), shape)
        out[i] = dist.Value() if dist.IsDone() else np.inf
        if exact is None:
            exact = 1e-9 * shape_size(shape)
        if out[i] <= exact:
            continue
        if faces is None:
            faces = [(f, BRep_Tool.Surface_s(f), BRep_Tool.Tolerance_s(f)) for f in faces_of(shape)]
        for face, surface, tol in faces:
            foot = GeomAPI_ProjectPointOnSurf(_pnt(p), surface)
            if not foot.NbPoints() or foot.LowerDistance() >= out[i]:
                continue
            u, v = foot.LowerDistanceParameters()
            if BRepClass_FaceClassifier(face, gp_Pnt2d(u, v), tol).State() in (TopAbs_IN, TopAbs_ON):
                out[i] = foot.LowerDistance()
    return out


def shape_size(shape) -> float:
    """The diagonal of a shape's bounding box (model units)."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(shape, box)
    if box.IsVoid():
        return 0.0
    x0, y0, z0, x1, y1, z1 = box.Get()
    return float(np.linalg.norm([x1 - x0, y1 - y0, z1 - z0]))


def is_valid(shape) -> bool:
    from OCP.BRepCheck import BRepCheck_Analyzer

    return bool(BRepCheck_Analyzer(shape).IsValid())


def verify_step(model, path, *, tol: float | None = None, samples: int = 60, expected=None) -> dict:
    """Read `path` back and check it: valid by ``BRepCheck_Analyzer``; with `expected` (the shapes that
    were written) the same number of faces with the same surface types; and every exported face's
    points (rgm's own evaluation, `samples` per face from a coarse mesh) within `tol` (default: 1e-7 x
    model size, at least 1e-9) of the read-back shape. Returns {"faces": read-back face count, "max": the
    measured max deviation, "limit": its limit} (model units)."""
    from collections import Counter

    from rgm.backends.mesh import face_samples

    shape = read_step(path, model.units)
    if shape is None or shape.IsNull() or not is_valid(shape):
        raise BackendError(f"{path}: the STEP file read back is not a valid shape (BRepCheck_Analyzer)")
    if expected is not None:
        written = Counter(surface_type(f) for s in expected for f in faces_of(s))
        read = Counter(surface_type(f) for f in faces_of(shape))
        if written != read:
            raise BackendError(f"{path}: the STEP file read back has faces {dict(read)}, the model {dict(written)}")
    def limit_of(size):
        return max(1e-7 * size, 1e-9) if tol is None else float(tol)

    # lazy trim edges sampled at a tenth of the limit (OpenCASCADE computed them exactly in the file)
    pts, size = face_samples(model.exported(), samples, curve_tol=lambda size: limit_of(size) / 10)
    limit = limit_of(size)
    worst = float(distances_to_shape(pts, shape).max()) if len(pts) else 0.0
    if not worst <= limit:
        raise BackendError(f"{path}: the STEP file deviates {worst:.3g} from the model (limit {limit:.3g})")
    return {"faces": len(faces_of(shape)), "max": worst, "limit": limit}
