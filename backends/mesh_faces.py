"""The faces the mesher works on: each model surface or trimmed face as a parameter-space patch
(`rgm.backends.mesh_surface`) with its boundary loops as pieces uv(s), s in [0, 1].

An untrimmed surface is bounded by its domain rectangle (sides broken at the knots); a trimmed face by
its trimming curves: 2-D curves as given, 3-D curves by projection onto the surface, lazy intersections
approximated at the tolerance the caller passes (a tenth of the mesh tolerance). A plane's patch box is
the bounding box of its loops' plane coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.errors import BackendError
from rgm.geometry.power_form import power_form

from .mesh_edges import Piece
from .mesh_surface import Patch, closest_together, evaluate_together, surface_patch


@dataclass
class Face:
    """A patch, its boundary loops (list of lists of `Piece`) and, once meshed, its triangles."""

    patch: Patch
    loops: list
    trimmed: bool
    grid: tuple | None = None                      # initial grid lines (gu, gv) in (u, v)
    tri: np.ndarray | None = None                  # (t, 3) global vertex ids
    tri_uv: np.ndarray | None = None               # (t, 3, 2) parameters of the triangle corners


def _points_of(nurbs):
    """t (m,) -> points (m, d) of a NurbsCurve, from its per-span power form (`rgm.geometry.power_form`:
    edge sampling evaluates the trimming curves in many small calls) where it has one."""
    power = power_form(nurbs)
    return nurbs.evaluate if power is None else (lambda t: power.d(t, 0)[0])


def _knot_breaks(nurbs, a, b) -> np.ndarray:
    """The knots of a NurbsCurve inside (a, b) as piece parameters in [0, 1], with the ends: the
    pieces between them are smooth, so edge sampling sizes its steps on each separately."""
    inner = ((k - a) / (b - a) for k in set(nurbs.knots.tolist()))   # a few knots: Python sets beat np.unique
    return np.array(sorted({0.0, 1.0, *(t for t in inner if 0 < t < 1)}))


def _curve_piece(patch, nurbs, a=None, b=None):
    """Piece following a 2-D NurbsCurve from parameter a to b (default: its whole domain)."""
    t0, t1 = nurbs.domain
    a = t0 if a is None else a
    b = t1 if b is None else b
    at = _points_of(nurbs)
    return Piece(patch, lambda s: at(np.clip(a + s * (b - a), t0, t1)), _knot_breaks(nurbs, a, b))


def _line_piece(patch, p, q):
    p, q = np.asarray(p, float), np.asarray(q, float)
    return Piece(patch, lambda s: p + np.asarray(s)[:, None] * (q - p))


def _intersection_pieces(patch, inter, surface, prev_end, next_start, tol):
    """The part of a lazy intersection's uv branch running from `prev_end` to `next_start` (uv, or None
    when the loop is this one closed branch): `IntersectionCurve.stretch`, as every back end takes it."""
    if prev_end is None:
        branches = inter.uv_curves(surface, tol)
        closed = [c for c in branches if np.linalg.norm(c.evaluate(np.array(c.domain))[0]
                                                        - c.evaluate(np.array(c.domain))[1]) < 1e-6]
        if len(closed) != 1:
            raise BackendError(f"the intersection gives {len(closed)} closed branches; a loop needs exactly one")
        return _curve_piece(patch, closed[0])
    ends = patch.evaluate(*np.array([prev_end, next_start], float).T)
    uv, _ = inter.stretch(surface, ends[0], ends[1], tol)
    return _curve_piece(patch, uv)


def _loop_start(loop, surface, patch) -> list:
    """A trimming loop's pieces as far as they need no projection: 3-D curves (off a plane) left as
    NurbsCurves for `_project_onto`, lazy intersections for `_loop_finish`."""
    from rgm.model import IntersectionCurve, Plane

    out = []
    for piece in loop.pieces:
        if isinstance(piece, IntersectionCurve):
            out.append(piece)
        elif piece.dim == 2:
            out.append(_curve_piece(patch, piece.nurbs()))
        elif isinstance(surface, Plane):   # plane coordinates: an exact affine image of the curve
            c = piece.nurbs()
            at, (t0, t1) = _points_of(c), c.domain
            out.append(Piece(patch, lambda s, at=at, t0=t0, t1=t1: surface.coordinates(at(t0 + s * (t1 - t0))),
                             _knot_breaks(c, t0, t1)))
        else:
            out.append(piece.nurbs())
    return out


def _loop_finish(out, surface, patch, tol) -> list:
    """The loop's lazy intersections (in `out`, in place) as the stretches joining their neighbours."""
    for k, p in enumerate(out):
        if not isinstance(p, Piece):
            closed = len(out) == 1
            prev_end = None if closed else out[k - 1].uv(np.array([1.0]))[0]
            next_start = None if closed else out[(k + 1) % len(out)].uv(np.array([0.0]))[0]
            out[k] = _intersection_pieces(patch, p, surface, prev_end, next_start, tol)
    return out


def _seams(patches, tol) -> list:
    """For each patch, [(axis, lo, hi)] for each parameter direction in which it closes up: S(lo, t) =
    S(hi, t) within `tol` (default 1e-7 x the patch's size) along the whole seam (a full revolution, a
    closed B-spline surface); the probes of all patches evaluated together (`evaluate_together`)."""
    t = np.linspace(0.0, 1.0, 9)
    probes, limits = [], []
    for patch in patches:
        (u0, u1), (v0, v1) = patch.domain
        limit = tol
        if not limit:
            uu, vv = np.meshgrid(u0 + t * (u1 - u0), v0 + t * (v1 - v0), indexing="ij")
            probe = patch.evaluate(uu.ravel(), vv.ravel())
            limit = 1e-7 * float(np.linalg.norm(probe.max(axis=0) - probe.min(axis=0)))
        limits.append(limit)
        for axis, (lo, hi), (a, b) in ((0, (u0, u1), (v0, v1)), (1, (v0, v1), (u0, u1))):
            other = a + t * (b - a)
            probes += [np.column_stack([np.full(9, x), other])[:, ::1 if axis == 0 else -1] for x in (lo, hi)]
    xyz = evaluate_together([p for p in patches for _ in range(4)], probes)
    out = []
    for k, (patch, limit) in enumerate(zip(patches, limits)):
        (u0, u1), (v0, v1) = patch.domain
        seams = []
        for n, (axis, lo, hi) in enumerate(((0, u0, u1), (1, v0, v1))):
            gap = np.linalg.norm(xyz[4 * k + 2 * n] - xyz[4 * k + 2 * n + 1], axis=1)
            if gap.max() <= limit:
                seams.append((axis, lo, hi))
        out.append(seams)
    return out


def _project_onto(loops, patches, tol):
    """Replace the 3-D curves (NurbsCurve) among the pieces of each loop (in place) by Pieces following
    their closest points on the loop's patch, the closest-point searches of all loops together
    (`closest_together`). On a seam the closest point is ambiguous (lo or hi): each piece keeps the
    side its own off-seam samples lie on at either end, and a piece running along the seam takes the side
    of its neighbours' ends, so the loop stays connected in (u, v)."""
    from rgm.geometry import NurbsCurve

    probe = np.linspace(0.0, 1.0, 33)
    jobs = [(pieces, patch, [k for k, c in enumerate(pieces) if isinstance(c, NurbsCurve)])
            for pieces, patch in zip(loops, patches)]
    jobs = [j for j in jobs if j[2]]
    if not jobs:
        return
    xs = [np.concatenate([pieces[k].evaluate(pieces[k].domain[0] + probe * np.ptp(pieces[k].domain)) for k in curves])
          for pieces, _, curves in jobs]
    # one search for all the loops' curves: they lie on the surface, so the nearest node of a coarse grid
    # (16 x 16 and the knots) starts in the closest point's basin nearly always; the points not found on
    # the surface get four starts from a 32 x 32 grid (the 46-face plate: 52 -> 46 ms to collect its faces)
    found = closest_together([patch for _, patch, _ in jobs], xs, grid=16, starts=1)
    seams = _seams([patch for _, patch, _ in jobs], tol)
    for (pieces, patch, curves), x, (uv, dist), closes in zip(jobs, xs, found, seams):
        redo = dist > 1e-9 * float(np.ptp(x, axis=0).max())
        if redo.any():
            uv[redo], dist[redo] = patch.closest(x[redo], grid=32)
        _follow(pieces, patch, curves, x, uv, dist, probe, closes)


def _follow(pieces, patch, curves, x, uv, dist, probe, seams):
    """The Pieces of `_project_onto` for one loop: its `curves` (indices into pieces), probed at `probe`
    (points x, closest points uv at distances dist, curve after curve), on the sides of its patch's
    `seams` (`_seams`) chosen."""
    m = len(probe)
    tables = {k: (uv[i * m:(i + 1) * m], dist[i * m:(i + 1) * m]) for i, k in enumerate(curves)}
    extents = {k: float(np.ptp(x[i * m:(i + 1) * m], axis=0).max()) for i, k in enumerate(curves)}
    sides = {}
    for k, (uv, _) in tables.items():
        for axis, lo, hi in seams:
            off = np.flatnonzero(np.minimum(np.abs(uv[:, axis] - lo), np.abs(uv[:, axis] - hi)) > 1e-7 * (hi - lo))
            side = lambda i: lo if uv[i, axis] < 0.5 * (lo + hi) else hi   # noqa: E731
            sides[k, axis] = (side(off[0]), side(off[-1])) if len(off) else None
    for k, c in enumerate(pieces):   # pieces along a seam: the side where the neighbouring pieces end
        for axis, lo, hi in seams:
            if (k, axis) in sides and sides[k, axis] is None:
                near = [sides.get(((k - 1) % len(pieces), axis)), sides.get(((k + 1) % len(pieces), axis))]
                value = near[0][1] if near[0] else near[1][0] if near[1] else lo
                sides[k, axis] = (value, value)
    for k in curves:
        c = pieces[k]
        seam_sides = [(a, lo, hi, sides[k, a]) for a, lo, hi in seams]
        uv, dist = tables[k]
        pieces[k] = Piece(patch, _Projected(patch, c, seam_sides, _on_sides(uv, probe, seam_sides), dist,
                                            extents[k]), _knot_breaks(c, *c.domain))


def _on_sides(uv, s, seams):
    """uv (m, 2) at piece parameters s (m,) with the points on a seam put on the side chosen for the
    piece's start (s < 1/2) or end."""
    for axis, lo, hi, (start, end) in seams:
        on = np.minimum(np.abs(uv[:, axis] - lo), np.abs(uv[:, axis] - hi)) <= 1e-7 * (hi - lo)
        uv[on, axis] = np.where(s[on] < 0.5, start, end)
    return uv


class _Projected:
    """uv(s) of the closest points of a 3-D `curve` (s in [0, 1] over its domain) on the patch, on the
    seam sides chosen (`_on_sides`). The closest points at equally spaced parameters (`table_uv`, at
    distances `table_dist`: how far the curve lies off the surface) are interpolated as Gauss-Newton's
    guesses, so the many small calls of edge sampling are local refinements; a point that ends farther
    from the surface than twice the table's worst (plus 1e-9 of the curve's `extent`) is searched
    globally. Called as a function; `rgm.backends.mesh_edges.uv_of` runs the Gauss-Newton steps of all
    the pieces together (`start`, one `rgm.backends.mesh_surface.project_together`, `finish`)."""

    def __init__(self, patch, curve, seams, table_uv, table_dist, extent: float):
        self.patch, self.seams = patch, seams
        self.t0, self.t1 = curve.domain
        self.at = _points_of(curve)
        self.table_uv = table_uv
        self.probe = np.linspace(0.0, 1.0, len(table_uv))
        self.limit = 2 * float(table_dist.max()) + 1e-9 * extent

    def start(self, s):
        """(points (k, 3) of the curve, parameter guesses (k, 2)) at s (k,)."""
        x = self.at(self.t0 + s * (self.t1 - self.t0))
        guess = np.column_stack([np.interp(s, self.probe, self.table_uv[:, 0]),
                                 np.interp(s, self.probe, self.table_uv[:, 1])])
        return x, guess

    def finish(self, s, x, uv, dist):
        """uv (k, 2) of `project`ed points x, with the points left far off searched globally."""
        far = dist > self.limit
        if far.any():
            uv[far] = self.patch.closest(x[far])[0]
        return _on_sides(uv, s, self.seams)

    def __call__(self, s):
        s = np.asarray(s, float)
        x, guess = self.start(s)
        return self.finish(s, x, *self.patch.project(x, guess, iterations=ITERATIONS))


#: Gauss-Newton steps of a trimming curve's closest points from the interpolated table guesses
ITERATIONS = 3


def _rectangle(patch) -> list:
    """The four sides of the domain, counter-clockwise in (u, v), with the knots as breaks."""
    (u0, u1), (v0, v1) = patch.domain
    c = [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
    su = (patch.breaks_u - u0) / (u1 - u0)
    sv = (patch.breaks_v - v0) / (v1 - v0)
    breaks = (su, sv, 1 - su, 1 - sv)
    sides = [_with_breaks(_line_piece(patch, c[k], c[(k + 1) % 4]), breaks[k]) for k in range(4)]
    for piece in sides:
        piece.domain_side = True
    return [sides]


def _with_breaks(piece, s):
    piece.breaks = np.unique(np.concatenate([[0.0, 1.0], np.clip(s, 0, 1)]))
    return piece


def collect_faces(objs, tol) -> list:
    """Face records for model objects (surfaces, trimmed faces, shells); curves are skipped. The 3-D
    trimming curves of all faces are projected onto their surfaces together (`_project_onto`)."""
    later = []                                   # (loop pieces, surface, patch) of curved faces
    faces = _collect(objs, tol, later)
    _project_onto([out for out, _, _ in later], [patch for _, _, patch in later], tol)
    for out, surface, patch in later:
        _loop_finish(out, surface, patch, tol)
    return faces


def _collect(objs, tol, later) -> list:
    from rgm.model import Curve, Plane, Shell, Surface, TrimmedFace

    faces = []
    for obj in objs:
        if isinstance(obj, Shell):
            faces += _collect(obj.faces, tol, later)
        elif isinstance(obj, TrimmedFace):
            faces.append(_trimmed_face(obj, tol, later))
        elif isinstance(obj, Plane):
            raise BackendError(f"`{obj.name or 'plane'}` is an infinite plane; trim it with a loop to mesh it")
        elif isinstance(obj, Surface):
            faces += [Face(p, _rectangle(p), False) for p in surface_patch(obj, trimmed=False).pieces()]
        elif not isinstance(obj, Curve):
            raise BackendError(f"{type(obj).__name__} cannot be tessellated")
    return faces


def _trimmed_face(face, tol, later):
    """The Face of a TrimmedFace; the loops of a curved one are finished later (`collect_faces`), those
    of a plane here (their plane coordinates set its patch box, and need no projection)."""
    from rgm.model import Plane

    surface = face.surface
    if face.outer is None:
        if isinstance(surface, Plane):
            raise BackendError("an infinite plane needs an outer loop to be meshed")
        patch = surface_patch(surface, trimmed=bool(face.holes))   # holes live in rgm's (u, v)
        holes = [_loop_start(h, surface, patch) for h in face.holes]
        later += [(h, surface, patch) for h in holes]
        return Face(patch, _rectangle(patch) + holes, True)
    if not isinstance(surface, Plane):
        patch = surface_patch(surface, trimmed=True)
        loops = [_loop_start(loop, surface, patch) for loop in face.loops()]
        later += [(out, surface, patch) for out in loops]
        return Face(patch, loops, True)
    # a plane's patch box: the loops' plane coordinates (which do not depend on the box)
    box = PlanePatchBox(surface)
    loops = [_loop_finish(_loop_start(loop, surface, box), surface, box, tol) for loop in face.loops()]
    uv = np.concatenate([p.uv(np.linspace(0, 1, 65)) for loop in loops for p in loop])
    lo, hi = uv.min(0), uv.max(0)
    pad = 1e-9 * float(np.max(hi - lo)) + 1e-12
    patch = surface_patch(surface, trimmed=True, plane_box=((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad)))
    for piece in (p for loop in loops for p in loop):
        piece.patch = patch
    return Face(patch, loops, True)


class PlanePatchBox(Patch):
    """A stand-in patch for a plane whose box is not yet known (only loop coordinates are asked)."""

    def __init__(self, plane):
        from .mesh_surface import PlanePatch

        self.inner = PlanePatch(plane, ((-np.inf, np.inf), (-np.inf, np.inf)))
        self.domain = self.inner.domain

    def d1(self, u, v):
        return self.inner.d1(u, v)
