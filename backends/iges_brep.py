"""IGES 5.3 manifold solid B-rep objects (`trim_entity=186`) for closed shells and solids.

186 manifold solid (form 0) → 514 closed shell (form 1) → 510 faces (form 1) → 508 loops (form 1) →
one 504 edge list and one 502 vertex list per solid (form 1), as IGES 5.3 §4.7x lays them out
(research notes §2.4; OpenCASCADE's "BRep" mode writes the same structure):

- a `Revolution` that sweeps 2 pi with both profile ends on the axis becomes one face per profile
  piece (a line, arc or B-spline of the profile; a polyline's segments), each on a 120 of that piece
  about the axis, bounded by the piece itself (the seam, used twice), the circles (100) its ends sweep
  and, where an end lies on the axis, a vertex use (a pole). Pcurves are lines in the 120's (u, v) =
  (piece parameter, angle); the profile is first turned to start at angle 0.
- a `Shell` of trimmed faces and B-spline surfaces becomes one face per member on the 128 the 144
  would use (a plane's in plane coordinates), its loops' pieces edges: model-space pieces as their own
  entities (lines 110, others 126) with the pcurve fitted to them, parameter-space pieces as the pcurve
  with the model-space curve (exact on planes); a B-spline surface without an outer loop is bounded by
  its domain. Pieces shared by two faces (within the file's tolerance) are one edge.

Loops are oriented for the surface's own normal (outer counter-clockwise in (u, v), holes clockwise);
each face's 514 flag says whether that normal points out: faces are made consistent across their
shared edges and the solid's signed volume (divergence theorem, per face by quadrature) decides the
sense. An object that is not a closed, connected, orientable shell raises `NotClosed` (the writer then
uses 144). OCP is not used here.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from rgm.geometry import NurbsCurve
from rgm.geometry.conics import line_curve
from rgm.model import CircularArc, CompositeCurve, IntersectionCurve, Line, Plane, Polyline, Revolution, Shell, TrimmedFace

from .iges_curves import model_curve, parameter_curve, parametrisation
from .iges_format import Entity

__all__ = ["NotClosed", "write_msbo"]

_TWO_PI = 2.0 * np.pi


class NotClosed(Exception):
    """The object is not a closed shell or solid; it is written as with 144."""


@dataclass
class _Use:
    """One use of an edge in a loop: `curve` (3-D, a model curve written as its own entity or a
    NurbsCurve written as a 126), `pcurve` (2-D NurbsCurve in the face's surface parameters, in the
    direction of the use), whether the use runs along `curve`, and its 3-D end points."""

    curve: object
    pcurve: NurbsCurve
    forward: bool
    start: np.ndarray
    end: np.ndarray
    degenerate: bool = False

    def reversed(self) -> "_Use":
        return replace(self, pcurve=self.pcurve.reverse(), forward=not self.forward, start=self.end, end=self.start)

    def point(self, fraction: float) -> np.ndarray:
        """The 3-D point a `fraction` of the way along the use."""
        c = _nurbs(self.curve)
        a, b = c.domain
        f = fraction if self.forward else 1.0 - fraction
        return c.evaluate([a + f * (b - a)])[0]


@dataclass
class _Face:
    surface: object        # () -> DE of the face's surface (written when the solid is)
    loops: list            # lists of _Use, the outer loop first
    volume: float          # (1/3) of the flux of S through the face, for its surface's own normal


def _nurbs(curve) -> NurbsCurve:
    return curve if isinstance(curve, NurbsCurve) else curve.nurbs()


def _uv_line(a, b) -> NurbsCurve:
    return line_curve(np.asarray(a, float), np.asarray(b, float))


def _segments(curve) -> list:
    """The smooth pieces of a curve: a composite's pieces, a polyline's segments, else the curve."""
    if isinstance(curve, CompositeCurve):
        return [q for p in curve.pieces for q in _segments(p)]
    if isinstance(curve, Polyline):
        pts = curve.points
        return [Line(p, q) for p, q in zip(pts[:-1], pts[1:]) if not np.array_equal(p, q)]
    return [curve]


def _signed_area(loop) -> float:
    """Shoelace area of the loop's pcurves sampled in (u, v) (positive: counter-clockwise)."""
    pts = np.concatenate([u.pcurve.evaluate(np.linspace(*u.pcurve.domain, 33)) for u in loop])
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _oriented(loops) -> list:
    """The outer loop counter-clockwise and the holes clockwise in (u, v) (reversed where needed)."""
    out = []
    for i, loop in enumerate(loops):
        area = _signed_area(loop)
        out.append(loop if (area > 0) == (i == 0) else [u.reversed() for u in reversed(loop)])
    return out


# --- faces of a revolution ------------------------------------------------------------------------

def _revolution_pieces(low, rev: Revolution):
    """(axis point, axis direction, the smooth pieces of the profile turned to angle 0); NotClosed
    unless the revolution sweeps 2 pi and both ends of the profile lie on the axis."""
    from .iges import _rotation

    if abs(rev.end - rev.start - _TWO_PI) > 1e-12:
        raise NotClosed
    a, k = np.asarray(rev.axis_point, float), np.asarray(rev.axis_dir, float)
    profile = rev.profile if rev.start == 0.0 else rev.profile.transform(_rotation(a, k, rev.start))
    pieces = _segments(profile)
    if max(_radius(pieces[0].start, a, k), _radius(pieces[-1].end, a, k)) > low.tol:
        raise NotClosed
    return a, k, pieces


def _radius(p, a, k) -> float:
    return float(np.linalg.norm(np.cross(np.asarray(p, float) - a, k)))


def _revolution_faces(low, rev: Revolution) -> list:
    a, k, pieces = _revolution_pieces(low, rev)
    if low.nurbs_only:   # each piece's exact rational surface (a 128) bounded by its domain
        return _shell_faces(low, Shell(tuple(Revolution(p, a, k, 0.0, _TWO_PI) for p in pieces)))

    def radius(p):
        return _radius(p, a, k)

    axis = []   # one 110 for every face's 120, written with the first

    def surface(piece):
        def write():
            if not axis:
                axis.append(low._add(None, Entity(110, [low._points(np.stack([a, a + k])).ravel()]), False))
            return low._add(None, Entity(120, [axis[0], low.child(piece), 0.0, _TWO_PI]), False)
        return write

    faces = []
    for piece in pieces:
        _f, breaks, _c = parametrisation(piece)
        t0, t1 = float(breaks[0]), float(breaks[-1])
        s, e = np.asarray(piece.start, float), np.asarray(piece.end, float)

        def circle(p, forward, t):
            centre = a + ((p - a) @ k) * k
            line = _uv_line((t, 0.0), (t, _TWO_PI))
            if radius(p) <= low.tol:
                return _Use(None, line if forward else line.reverse(), True, p, p, degenerate=True)
            use = _Use(CircularArc(centre, k, radius(p), p, p), line, True, p, p)
            return use if forward else use.reversed()

        uses = [_Use(piece, _uv_line((t0, 0.0), (t1, 0.0)), True, s, e), circle(e, True, t1),
                _Use(piece, _uv_line((t1, _TWO_PI), (t0, _TWO_PI)), False, e, s), circle(s, False, t0)]
        faces.append(_Face(surface(piece), [uses], _revolution_flux(piece, a, k)))
    return faces


def _revolution_flux(piece, a, k, nt: int = 8, na: int = 64) -> float:
    """(1/3) of the flux of S - 0 through the surface swept by `piece`, normal S_t x S_angle: Gauss nodes
    on each knot span of the piece, the trapezoid rule (exact for trigonometric integrands) in angle."""
    c = piece.nurbs()
    knots = np.unique(c.knots)
    g, w = np.polynomial.legendre.leggauss(nt)
    t = np.concatenate([0.5 * (lo + hi) + 0.5 * (hi - lo) * g for lo, hi in zip(knots[:-1], knots[1:])])
    wt = np.concatenate([0.5 * (hi - lo) * w for lo, hi in zip(knots[:-1], knots[1:])])
    d = c.derivatives(t, 1)
    p, dp = d[0] - a, d[1]
    theta = np.linspace(0.0, _TWO_PI, na, endpoint=False)
    cos, sin = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]

    def rot(v, along):    # Rodrigues, angles (na, 1, 1) x vectors (nt, 3)
        return v * cos + np.cross(k, v) * sin + along * (1 - cos)

    s = a + rot(p, np.outer(p @ k, k))
    st = rot(dp, np.outer(dp @ k, k))
    sa = np.cross(k, s - a)
    f = np.einsum("ijk,ijk->ij", s, np.cross(st, sa))
    return float((f * wt).sum() * (_TWO_PI / na) / 3.0)


# --- faces of a shell -----------------------------------------------------------------------------

def _natural_loop(nurbs) -> list:
    """The domain boundary of a NurbsSurface: its four boundary rows (exact), poles as vertex uses."""
    (u0, u1), (v0, v1) = nurbs.domain
    w = nurbs.weights if nurbs.is_rational else None
    rows = [NurbsCurve(nurbs.degree_u, nurbs.knots_u, nurbs.ctrl[:, 0], None if w is None else w[:, 0]),
            NurbsCurve(nurbs.degree_v, nurbs.knots_v, nurbs.ctrl[-1], None if w is None else w[-1]),
            NurbsCurve(nurbs.degree_u, nurbs.knots_u, nurbs.ctrl[:, -1], None if w is None else w[:, -1]),
            NurbsCurve(nurbs.degree_v, nurbs.knots_v, nurbs.ctrl[0], None if w is None else w[0])]
    corners = [(u0, v0), (u1, v0), (u1, v1), (u0, v1), (u0, v0)]
    uses = []
    for i, row in enumerate(rows):   # the last two rows run against the loop
        forward = i < 2
        start, end = (row.start, row.end) if forward else (row.end, row.start)
        pole = np.ptp(row.ctrl, axis=0).max() == 0.0
        uses.append(_Use(None if pole else row, _uv_line(corners[i], corners[i + 1]), forward, start, end, pole))
    return uses


def _piece_use(low, piece, surface, near) -> _Use:
    ftol = min(low.tol, 1e-10 * max(1.0, _extent(surface)))
    if isinstance(piece, IntersectionCurve):
        pc, c = piece.uv_curves(surface, low.tol)[0], piece.nurbs(low.tol)
    elif piece.dim == 2:
        pc = piece.nurbs()
        c = model_curve(surface, pc, ftol)
    else:
        c = piece if isinstance(piece, Line) else piece.nurbs()
        pc = parameter_curve(surface, piece.nurbs(), ftol, near)
    c3 = _nurbs(c)
    return _Use(c, pc, True, c3.start, c3.end)


def _extent(surface) -> float:
    if isinstance(surface, Plane):
        return float(np.abs(surface.origin).max())
    return float(np.ptp(surface.nurbs().ctrl.reshape(-1, 3), axis=0).max())


def _shell_faces(low, shell: Shell) -> list:
    faces = []
    for member in shell.faces:
        face = member if isinstance(member, TrimmedFace) else TrimmedFace(member)
        surface = face.surface
        if isinstance(surface, Plane) and face.outer is None:
            raise NotClosed
        loops = []
        for loop in face.loops():
            uses, near = [], None
            for piece in (q for p in loop.pieces for q in _segments(p)):
                uses.append(_piece_use(low, piece, surface, near))
                near = uses[-1].pcurve.end
            loops.append(uses)
        if face.outer is None:
            loops.insert(0, _natural_loop(surface.nurbs()))
        loops = _oriented(loops)
        faces.append(_Face(lambda f=face: low.trim_surface(f), loops, _face_flux(surface, loops)))
    return faces


def _face_flux(surface, loops, n: int = 48) -> float:
    """(1/3) of the flux of S through the trimmed face, for its surface's own normal: exact for a plane
    (S . n is constant: times the loops' signed area), else the midpoint rule on an n x n grid over the
    outer loop's (u, v) box, counting the cells whose centre is inside (even-odd rule over all loops)."""
    if isinstance(surface, Plane):
        return float(surface.origin @ surface.normal) * sum(_signed_area(lp) for lp in loops) / 3.0
    polys = [np.concatenate([u.pcurve.evaluate(np.linspace(*u.pcurve.domain, 33)) for u in lp]) for lp in loops]
    lo, hi = polys[0].min(axis=0), polys[0].max(axis=0)
    step = (hi - lo) / n
    g = [lo[i] + step[i] * (np.arange(n) + 0.5) for i in range(2)]
    u, v = (x.ravel() for x in np.meshgrid(*g, indexing="ij"))
    inside = np.zeros(u.size, bool)
    for poly in polys:
        x0, y0, x1, y1 = poly[:-1, 0], poly[:-1, 1], poly[1:, 0], poly[1:, 1]
        crosses = ((y0[None] > v[:, None]) != (y1[None] > v[:, None]))
        xcross = x0 + (v[:, None] - y0) * (x1 - x0) / np.where(y1 == y0, 1.0, y1 - y0)
        inside ^= (crosses & (u[:, None] < xcross)).sum(axis=1) % 2 == 1
    d = surface.nurbs().derivatives(u[inside], v[inside], 1)
    s, su, sv = d[0, 0], d[1, 0], d[0, 1]
    return float(np.einsum("ij,ij->i", s, np.cross(su, sv)).sum() * step[0] * step[1] / 3.0)


# --- topology and entities ------------------------------------------------------------------------

def _topology(faces, tol: float):
    """(vertices (m, 3), edges [(curve, start vertex, end vertex)], per use (edge index or -vertex - 1,
    agrees with the edge's curve), face senses (+1: the surface's normal points out)); NotClosed unless
    every edge has exactly two uses and the faces can be oriented consistently into one shell."""
    vertices: list = []

    def vertex(p) -> int:
        if vertices:
            d = np.linalg.norm(np.asarray(vertices) - p, axis=1)
            if d.min() <= tol:
                return int(d.argmin())
        vertices.append(np.asarray(p, float))
        return len(vertices) - 1

    edges, uses_of, refs = [], [], {}
    for fi, face in enumerate(faces):
        for li, loop in enumerate(face.loops):
            for ui, use in enumerate(loop):
                vs, ve = vertex(use.start), vertex(use.end)
                if use.degenerate:
                    refs[fi, li, ui] = (-vs - 1, True)
                    continue
                mid = use.point(0.5)
                for ei, (curve, a, b, emid) in enumerate(edges):
                    if {a, b} == {vs, ve} and np.linalg.norm(emid - mid) <= 10 * tol:
                        break
                else:
                    c = _nurbs(use.curve)
                    a, b = (vs, ve) if use.forward else (ve, vs)
                    edges.append((use.curve, a, b, c.evaluate([np.mean(c.domain)])[0]))
                    uses_of.append([])
                    ei = len(edges) - 1
                e = _nurbs(edges[ei][0])
                e25, e75 = e.evaluate([np.interp(f, [0, 1], e.domain) for f in (0.25, 0.75)])
                q = use.point(0.25)
                agrees = np.linalg.norm(q - e25) < np.linalg.norm(q - e75)
                refs[fi, li, ui] = (ei, agrees)
                uses_of[ei].append((fi, 1 if agrees else -1))
    if any(len(u) != 2 for u in uses_of):
        raise NotClosed
    sense = np.zeros(len(faces), int)
    sense[0] = 1
    queue, neighbours = deque([0]), [[] for _ in faces]
    for (fi, ai), (fj, aj) in uses_of:
        neighbours[fi].append((fj, -ai * aj))
        neighbours[fj].append((fi, -ai * aj))
    while queue:
        fi = queue.popleft()
        for fj, rel in neighbours[fi]:
            if sense[fj] == 0:
                sense[fj] = sense[fi] * rel
                queue.append(fj)
            elif sense[fj] != sense[fi] * rel:
                raise NotClosed
    if not sense.all():
        raise NotClosed
    if sum(s * f.volume for s, f in zip(sense, faces)) < 0:
        sense = -sense
    return np.asarray(vertices), [e[:3] for e in edges], refs, sense


def write_msbo(low, obj, root: bool) -> int:
    """Write the closed `obj` (Revolution or Shell) as a 186 through the IGES lowering `low`; its DE.
    NotClosed (before anything is written) when it is not a closed solid."""
    faces = _revolution_faces(low, obj) if isinstance(obj, Revolution) else \
        _shell_faces(low, obj) if isinstance(obj, Shell) else None
    if not faces:
        raise NotClosed
    vertices, edges, refs, sense = _topology(faces, low.tol)
    vde = low._add(None, Entity(502, [len(vertices), low._points(vertices).ravel()], form=1), False)

    def curve_de(curve):
        return low._piece(curve, 3) if isinstance(curve, NurbsCurve) else low.child(curve)

    edge_rows = [[curve_de(c), vde, a + 1, vde, b + 1] for c, a, b in edges]
    ede = low._add(None, Entity(504, [len(edges), *[x for row in edge_rows for x in row]], form=1), False)
    face_des = []
    for fi, face in enumerate(faces):
        sde = face.surface()
        loop_des = []
        for li, loop in enumerate(face.loops):
            items = []
            for ui, use in enumerate(loop):
                index, agrees = refs[fi, li, ui]
                pde = low._piece(use.pcurve, 2)
                items += ([1, vde, -index] if index < 0 else [0, ede, index + 1]) + [int(agrees), 1, 0, pde]
            loop_des.append(low._add(None, Entity(508, [len(loop), *items], form=1, use=0), False))
        face_des.append(low._add(None, Entity(510, [sde, len(loop_des), 1, *loop_des], form=1), False))
    shell = low._add(None, Entity(514, [len(faces), *[x for f, s in zip(face_des, sense) for x in (f, int(s > 0))]],
                                  form=1), False)
    return low._add(obj, Entity(186, [shell, 1, 0]), root)

