"""Geometric validity checks on an evaluated model, reported as diagnostics on the offending expression.

Codes:
    E0501  degenerate curve: a line, polyline segment, circle or B-spline of (near) zero length
    E0502  a revolution profile crosses its axis (the surface would pass through itself)
    W0503  coincident consecutive rows/columns in a B-spline control net (a self-overlapping net)
    E0504  a trimming loop is not closed within the model tolerance
    W0505  a loop piece runs backwards (its end meets the next piece's end); back ends reverse it
    E0506  a parameter-space loop piece leaves the surface's domain
    E0507  a 3-D loop piece does not lie on the trimmed surface (farther than the tolerance)
    E0508  an intersection used as a loop piece has no branch, or several where nothing picks one (a
           piece between two curves is the stretch of the branch nearest their ends, as back ends take it)
    E0509  an intersection used as a loop piece is not an intersection *of* the trimmed surface

Lazy pieces (`intersect(...)`) are not computed by `validate`: `rgmc check` and `rgm.load` never
march an intersection. Loops that contain one are checked by `validate_lazy(model, tol)` once the
intersections are approximated (`rgmc compile` calls it before handing the model to a back end;
the approximations are cached, so the back end reuses them at the same tolerance).
"""
from __future__ import annotations

import numpy as np

from rgm.compiler.diagnostics import Diagnostic, error, warning
from rgm.errors import GeometryError
from rgm.model import objects as O
from rgm.model.lazy import IntersectionCurve

_SAMPLES = 64


def validate(model: O.Model) -> list[Diagnostic]:
    """Every validity diagnostic of the model's objects (each object checked once)."""
    out: list[Diagnostic] = []
    seen: set[int] = set()
    for obj in model.objects.values():
        try:
            # numbers near the float limit overflow in the measures (lengths, distances): the object is
            # then reported (E0510, or the check the infinite measure fails), not warned about
            with np.errstate(over="ignore", invalid="ignore"):
                _visit(obj, model.tolerance, out, seen)
        except GeometryError as exc:   # a form made on demand that cannot be (a net whose numbers overflow)
            out.append(error("E0510", str(exc), _span(obj), "cannot be built"))
    return out


def validate_lazy(model: O.Model, tol: float | None = None) -> list[Diagnostic]:
    """Closure of the loops that contain intersections, approximated at `tol` (default: the model
    tolerance); the gap allowed is the model tolerance plus `tol`. Intersection pieces may run
    either way (a marched branch has no preferred direction). An intersection piece between two curves
    is the stretch of its branch between the previous piece's end and the next one's start (the points
    of the branch nearest them), as the back ends and `rgm.fitters.freeform_measure` take it: the loop
    closes when those ends lie on the branch."""
    tol = model.tolerance if tol is None else float(tol)
    out: list[Diagnostic] = []
    faces = _faces(model)
    for face in faces:
        for lp in face.loops():
            if lp.is_lazy:
                _lazy_loop(face, lp, tol, model.tolerance + tol, out)
    return out


def _faces(model: O.Model) -> list:
    seen, faces = set(), []
    stack = list(model.objects.values())
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, O.TrimmedFace):
            faces.append(obj)
        elif isinstance(obj, O.Shell):
            stack.extend(obj.faces)
    return faces


def _lazy_loop(face, lp, tol: float, gap_tol: float, out: list) -> None:
    pieces = lp.pieces
    lazy = [isinstance(p, IntersectionCurve) for p in pieces]
    ends, free = [], []
    for i, piece in enumerate(pieces):
        if not lazy[i]:
            ends.append(piece_ends(face.surface, piece))
            free.append(False)
            continue
        if face.surface is not piece.a and face.surface is not piece.b:
            out.append(error("E0509", f"loop piece {i + 1} is an intersection of other surfaces, not of the "
                                      "trimmed one", _span(piece, lp), "not on this face"))
            return
        try:
            branches = piece.approximate(tol)
        except GeometryError as exc:
            out.append(error("E0508", f"loop piece {i + 1}: {exc}", _span(piece, lp), "cannot be approximated"))
            return
        k = len(pieces)
        between = k > 1 and not lazy[i - 1] and not lazy[(i + 1) % k]
        if between and branches:
            # between two curves the piece is the stretch of the branch from the previous piece's end to
            # the next one's start, as the back ends take it (of the branch passing nearest to both)
            try:
                _, c = piece.stretch(face.surface, piece_ends(face.surface, pieces[i - 1])[1],
                                     piece_ends(face.surface, pieces[(i + 1) % k])[0], tol)
            except GeometryError as exc:
                out.append(error("E0508", f"loop piece {i + 1}: {exc}", _span(piece, lp), "cannot be approximated"))
                return
            ends.append((c.start, c.end))
            free.append(True)
            continue
        if len(branches) != 1:
            out.append(error("E0508", f"loop piece {i + 1} is an intersection with {len(branches)} branches; "
                                      "a loop piece needs exactly one", _span(piece, lp),
                             f"{len(branches)} branches"))
            return
        c = branches[0].curve
        ends.append(tuple(c.evaluate(np.array(c.domain))))
        free.append(True)
    _chain(face, lp, ends, free, gap_tol, out)


def loop_stretches(loop, surface, tol: float) -> dict:
    """{k: (uv, curve)} for every intersection piece k of `loop` between two other curves: its branch's
    stretch from the previous piece's end to the next one's start (`IntersectionCurve.stretch`), the
    piece as the loop takes it."""
    pieces, out = loop.pieces, {}
    for k, piece in enumerate(pieces):
        before, after = pieces[k - 1], pieces[(k + 1) % len(pieces)]
        if isinstance(piece, IntersectionCurve) and len(pieces) > 1 and \
                not isinstance(before, IntersectionCurve) and not isinstance(after, IntersectionCurve):
            out[k] = piece.stretch(surface, piece_ends(surface, before)[1], piece_ends(surface, after)[0], tol)
    return out


def _chain(face, lp, ends, free, tol, out) -> None:
    """Walk the pieces end to start; a `free` piece may be reversed silently, a fixed one with W0505."""
    k = len(ends)
    order = [list(e) for e in ends]
    if free[0] and k > 1:  # orient a free first piece towards the second
        nxt = order[1]
        if min(np.linalg.norm(order[0][0] - q) for q in nxt) < min(np.linalg.norm(order[0][1] - q) for q in nxt):
            order[0].reverse()
    for i in range(k):
        j = (i + 1) % k
        end_i = order[i][1]
        if np.linalg.norm(end_i - order[j][0]) <= tol:
            continue
        if j != 0 and np.linalg.norm(end_i - order[j][1]) <= tol:
            order[j].reverse()
            if not free[j]:
                out.append(warning("W0505", f"loop piece {j + 1} runs backwards: its end meets piece {i + 1}",
                                   _span(lp.pieces[j], lp), "reversed piece", hint="swap its end points"))
            continue
        gap = float(np.linalg.norm(end_i - order[j][0]))
        where = "its last piece and its first" if j == 0 else f"pieces {i + 1} and {j + 1}"
        out.append(error("E0504", f"trimming loop is not closed: a gap of {gap:.3g} between {where} "
                                  f"(tolerance {tol:g})", _span(lp, face), "open loop"))
        return


def _visit(obj, tol: float, out: list, seen: set) -> None:
    if id(obj) in seen or not isinstance(obj, O.ModelObject):
        return
    seen.add(id(obj))
    if isinstance(obj, IntersectionCurve):
        return
    if isinstance(obj, O.Curve):
        _curve(obj, tol, out)
        for piece in getattr(obj, "pieces", ()):
            _visit(piece, tol, out, seen)
    elif isinstance(obj, O.Revolution):
        _visit(obj.profile, tol, out, seen)
        _revolution(obj, tol, out)
    elif isinstance(obj, O.Extrusion):
        _visit(obj.profile, tol, out, seen)
    elif isinstance(obj, O.RuledSurface):
        _visit(obj.a, tol, out, seen)
        _visit(obj.b, tol, out, seen)
    elif isinstance(obj, O.BSplineSurface):
        _net(obj, tol, out)
    elif isinstance(obj, O.TrimmedFace):
        _visit(obj.surface, tol, out, seen)
        for lp in obj.loops():
            for piece in lp.pieces:
                _visit(piece, tol, out, seen)
            _loop(obj, lp, tol, out)
    elif isinstance(obj, O.Shell):
        for face in obj.faces:
            _visit(face, tol, out, seen)


def _span(*objs):
    return next((o.span for o in objs if getattr(o, "span", None) is not None), None)


def _what(obj) -> str:
    return f"`{obj.name}`" if obj.name else f"this {type(obj).__name__}"


# --- curves and surfaces -------------------------------------------------------------------------

def _curve(c, tol: float, out: list) -> None:
    if getattr(c, "dim", 3) == 2:
        tol = 1e-12  # parameter-space curves: the model tolerance (a length) does not apply
    if isinstance(c, O.Polyline):
        seg = np.linalg.norm(np.diff(c.points, axis=0), axis=1)
        bad = np.flatnonzero(seg <= tol)
        if bad.size:
            i = int(bad[0])
            out.append(error("E0501", f"polyline {_what(c)} has a zero-length segment between its points "
                                      f"{i + 1} and {i + 2} ({seg[i]:.3g} <= tolerance {tol:g})", c.span,
                             "degenerate segment", hint="remove the repeated point"))
        return
    if isinstance(c, (O.Circle, O.CircularArc)):
        length = c.radius
    elif isinstance(c, O.CompositeCurve):
        return  # its pieces are checked one by one
    elif isinstance(c, O.Line):
        length = float(np.linalg.norm(c.p1 - c.p0))
    elif isinstance(c, O.BSplineCurve):
        length = float(np.linalg.norm(np.diff(np.asarray(c.curve.ctrl), axis=0), axis=1).sum())
    else:
        return
    if length <= tol:
        out.append(error("E0501", f"{_what(c)} is degenerate: its size {length:.3g} is within the tolerance {tol:g}",
                         c.span, "zero-length curve"))


def _revolution(r: O.Revolution, tol: float, out: list) -> None:
    """The profile must stay on one side of the axis (it may touch it, as closed solids do)."""
    try:
        n = r.profile.nurbs()
        pts = n.evaluate(np.linspace(*n.domain, _SAMPLES * max(1, len(np.unique(n.knots)))))
    except GeometryError:
        return
    rel = pts - r.axis_point
    radial = rel - np.outer(rel @ r.axis_dir, r.axis_dir)
    dist = np.linalg.norm(radial, axis=1)
    if dist.max() <= tol:
        out.append(error("E0502", f"the profile of {_what(r)} lies on its axis", _span(r.profile, r),
                         "zero-radius profile"))
        return
    side = radial @ (radial[int(np.argmax(dist))] / dist.max())
    if side.min() < -tol:
        out.append(error("E0502", f"the profile of {_what(r)} crosses its axis (it reaches {-side.min():.3g} "
                                  f"past it); the revolved surface would pass through itself",
                         _span(r.profile, r), "crosses the axis",
                         hint="keep the profile on one side of the axis; it may end on it"))


def _net(s: O.BSplineSurface, tol: float, out: list) -> None:
    net = np.asarray(s.surface.ctrl)
    for axis, word in ((0, "rows"), (1, "columns")):
        gap = np.linalg.norm(np.diff(net, axis=axis), axis=2).max(axis=1 - axis)
        bad = np.flatnonzero(gap <= tol * 1e-3)
        if bad.size:
            i = int(bad[0])
            out.append(warning("W0503", f"control net of {_what(s)} has coincident {word} {i + 1} and {i + 2}: "
                                        f"the surface overlaps itself there (zero-speed parameter lines)",
                               s.span, "self-overlapping net"))


# --- loops ---------------------------------------------------------------------------------------

def _on_surface(surface, pts2: np.ndarray) -> np.ndarray:
    """Points (k, 3) of parameter points (k, 2) on a model surface."""
    if isinstance(surface, O.Plane):
        return surface.origin + pts2[:, :1] * surface.x_dir + pts2[:, 1:] * surface.y_dir
    return surface.nurbs().evaluate(pts2[:, 0], pts2[:, 1])


def piece_ends(surface, piece) -> tuple[np.ndarray, np.ndarray]:
    """The 3-D start and end of a trimming-loop piece (a 2-D piece's through its surface)."""
    ends = np.array([piece.start, piece.end], float)
    return tuple(_on_surface(surface, ends)) if piece.dim == 2 else (ends[0], ends[1])


def _loop(face: O.TrimmedFace, lp: O.Loop, tol: float, out: list) -> None:
    if lp.is_lazy:
        return  # checked when the intersection is approximated
    surface = face.surface
    dist = _distances_3d(surface, lp.pieces, tol)
    placed = [_inside_domain(surface, p, i, tol, lp) if p.dim == 2 else _lies_on(dist.get(i), i, tol, lp)
              for i, p in enumerate(lp.pieces)]
    problems = [d for d in placed if d is not None]
    out.extend(problems)
    if problems:
        return  # closure is meaningless until the pieces are on the surface
    _chain(face, lp, [piece_ends(surface, p) for p in lp.pieces], [False] * len(lp.pieces), tol, out)


def _inside_domain(surface, piece, i: int, tol: float, lp) -> Diagnostic | None:
    if isinstance(surface, O.Plane):
        return None
    (u0, u1), (v0, v1) = surface.domain
    slack = 1e-9 * max(u1 - u0, v1 - v0)
    n = piece.nurbs()
    uv = n.evaluate(np.linspace(*n.domain, _SAMPLES))
    outside = ((uv[:, 0] < u0 - slack) | (uv[:, 0] > u1 + slack) | (uv[:, 1] < v0 - slack) | (uv[:, 1] > v1 + slack))
    if outside.any():
        p = uv[int(np.argmax(outside))]
        return error("E0506", f"loop piece {i + 1} leaves the surface's domain [{u0:g}, {u1:g}] x [{v0:g}, {v1:g}] "
                              f"(it reaches uv({p[0]:.4g}, {p[1]:.4g}))", _span(piece, lp), "outside the domain")
    return None


def _distances_3d(surface, pieces, tol: float) -> dict:
    """{i: distances (_SAMPLES,) of piece i's samples to the surface} for the model-space (3-D) pieces
    of a loop (`distances_to_surface`; {} when the surface has no NURBS form)."""
    curves = {i: p.nurbs() for i, p in enumerate(pieces) if p.dim == 3}
    try:
        return dict(zip(curves, distances_to_surface(surface, list(curves.values()), tol)))
    except GeometryError:
        return {}


def distances_to_surface(surface, curves, tol: float) -> list:
    """[distances (_SAMPLES,)] of each 3-D NurbsCurve's samples to `surface` (model units), exact where
    they exceed `tol`. All the samples are bounded in one local search (`distance_bound_surface`);
    only those it does not find within `tol` get the global search, so a curve off the surface is
    reported with its exact distance. Used for the trimming loops of a model and of an IGES import."""
    pts = [c.evaluate(np.linspace(*c.domain, _SAMPLES)) for c in curves]
    if not pts:
        return []
    if isinstance(surface, O.Plane):
        return [np.abs(surface.signed_distance(x)) for x in pts]
    from rgm.geometry.inversion import distance_bound_surface

    nurbs = surface.nurbs()
    every = np.concatenate(pts)
    dist = distance_bound_surface(nurbs, every)
    far = dist > tol
    if far.any():
        dist[far] = nurbs.closest_point(every[far])[3]
    return np.split(dist, np.cumsum([len(x) for x in pts])[:-1])


def _lies_on(dist, i: int, tol: float, lp) -> Diagnostic | None:
    """E0507 when the samples of 3-D piece i (at distances `dist`, None: not measurable) leave the surface."""
    if dist is None:
        return None
    piece = lp.pieces[i]
    if dist.max() > tol:
        return error("E0507", f"loop piece {i + 1} is {dist.max():.3g} away from the trimmed surface "
                              f"(tolerance {tol:g})", _span(piece, lp), "not on the surface",
                     hint="give the piece in the surface's parameters (uvline, uv points) or project it")
    return None
