"""Reading IGES manifold solid B-reps (186 → 514 → 510 → 508 → 504/502, IGES 5.3 §4.7x) into the model:
a mixin of the IGES reader (`iges_read._Reader`).

A 186 becomes the model object of its shell (void shells are reported as unsupported); a 514 becomes
a `Shell` of `TrimmedFace`s, or, when its faces are the pieces of one revolution (every face on a 120
sweeping 2 pi about the same axis, generatrices joined end to start, as rgm's writer makes them), that
`Revolution` (of a `Polyline` when every generatrix is a line). A 510's loops are built from the
pcurves of its edge uses, or, on a 120 (whose IGES (u, v) is not rgm's) or where a use has no pcurve,
from the edges' model-space curves in the sense of the use; vertex uses (poles) add nothing then.
Face and shell orientation flags are not kept: rgm's shells carry no orientation. 190 plane surfaces
(OpenCASCADE's BRep mode puts planar faces on them) are read as planes.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from rgm.errors import GeometryError
from rgm.model import (
    BSplineCurve, Circle, CircularArc, CompositeCurve, Line, Loop, Plane, Polyline, Revolution, Shell, TrimmedFace,
)
from rgm.model.curves import _lift

__all__ = ["BrepReading", "BREP_TYPES", "circles_started_at_vertices", "reversed_curve", "started_at_joins"]

#: entity types of the manifold solid B-rep (and 190, the plane surface OpenCASCADE's faces use)
BREP_TYPES = {186, 190, 502, 504, 508, 510, 514}


def reversed_curve(curve):
    """The same model curve traversed the other way (same kind where the kind can say so)."""
    if isinstance(curve, Line):
        return Line(curve.p1, curve.p0)
    if isinstance(curve, Polyline):
        return Polyline(curve.points[::-1])
    if isinstance(curve, Circle):
        return Circle(curve.center, -np.asarray(curve.normal), curve.radius)
    if isinstance(curve, CircularArc):
        return CircularArc(curve.center, -np.asarray(curve.normal), curve.radius, curve.end_point, curve.start_point)
    if isinstance(curve, CompositeCurve):
        return CompositeCurve(tuple(reversed_curve(p) for p in reversed(curve.pieces)))
    return BSplineCurve(curve.nurbs().reverse())


def started_at_joins(pieces) -> tuple:
    """A loop's pieces with every full `Circle` among several pieces made a full-turn `CircularArc` from
    the previous piece's end: a circle has no start point of its own (rgm's starts on a reference
    direction of its normal), but in a loop it must start at the vertex where its neighbours join it
    (a hole's seam line and rims, say), or the loop would not close."""
    pieces = list(pieces)
    if len(pieces) < 2:
        return tuple(pieces)
    for k, c in enumerate(pieces):
        if isinstance(c, Circle):
            prev = pieces[k - 1].nurbs()
            pieces[k] = _from(c, prev.evaluate(np.array([prev.domain[1]]))[0])
    return tuple(pieces)


def circles_started_at_vertices(faces, tol: float) -> tuple:
    """Faces whose single-circle loops (a hole's rim) start at a loop vertex of the faces lying on the
    circle (within `tol`), such as the end of the hole's seam line on the neighbouring face, so both
    faces describe their common edge from the same point (the mesher then samples it once)."""
    ends = [p.nurbs().evaluate(np.array(p.nurbs().domain)) for f in faces if isinstance(f, TrimmedFace)
            for lp in f.loops() for p in lp.pieces if len(lp.pieces) > 1 and p.dim == 3]
    if not ends:
        return tuple(faces)
    ends = np.concatenate(ends)

    def started(loop):
        c = loop.pieces[0] if len(loop.pieces) == 1 else None
        if not isinstance(c, Circle) or c.dim != 3:
            return loop
        d = ends - c.center
        axial = d @ c.normal
        off = np.hypot(np.linalg.norm(d - axial[:, None] * c.normal, axis=1) - c.radius, axial)
        return replace(loop, pieces=(_from(c, ends[np.argmin(off)]),)) if off.min() <= tol else loop

    return tuple(replace(f, outer=f.outer and started(f.outer), holes=tuple(started(h) for h in f.holes))
                 if isinstance(f, TrimmedFace) else f for f in faces)


def _from(circle, point):
    """The full turn of `circle` from the point of it nearest to `point` (a `CircularArc` with start =
    end), or the circle itself where it starts there already."""
    n = np.asarray(circle.normal, float)
    radial = _lift(np.asarray(point, float)) - _lift(circle.center)
    radial -= (radial @ n) * n
    if not np.linalg.norm(radial) > 0:
        return circle
    start = (_lift(circle.center) + circle.radius * radial / np.linalg.norm(radial))[:circle.dim]
    own = circle.nurbs().evaluate(np.array([circle.nurbs().domain[0]]))[0]
    if np.linalg.norm(own - start) <= 1e-12 * circle.radius:
        return circle
    return CircularArc(circle.center, circle.normal, circle.radius, start, start)


class BrepReading:
    """186/514/510 conversion and the structure (parameter counts, references) of the B-rep entities."""

    def brep_uses(self, de: int) -> list:
        """The edge uses of a 508: (type, list DE, index, orientation, [pcurve DEs]) each."""
        d, out, i = self.d, [], 2
        for _ in range(d.int(de, 1)):
            kind, lst, index, sense, count = d.ints(de, i, 5)
            out.append((kind, lst, index, sense, d.ints(de, i + 6, count)[::2] if count else []))
            i += 5 + 2 * count
        return out

    def brep_own_count(self, de: int, t: int) -> int:
        d = self.d
        if t == 186:
            return 3 + 2 * d.int(de, 3)
        if t == 514:
            return 1 + 2 * d.int(de, 1)
        if t == 510:
            return 3 + d.int(de, 2)
        if t == 508:
            return 1 + sum(5 + 2 * len(u[4]) for u in self.brep_uses(de))
        if t == 190:
            return 3 if self.d.entries[de].form == 1 else 2
        return 1 + (5 if t == 504 else 3) * d.int(de, 1)

    def brep_children(self, de: int, t: int) -> list[int]:
        d = self.d
        if t == 186:
            return [d.int(de, 1)] + d.ints(de, 4, d.int(de, 3))[::2]
        if t == 514:
            return d.ints(de, 2, 2 * d.int(de, 1))[::2]
        if t == 510:
            return [d.int(de, 1)] + d.ints(de, 4, d.int(de, 2))
        if t == 508:
            return [x for u in self.brep_uses(de) for x in [u[1], *u[4]]]
        if t == 504:
            rows = np.array(d.ints(de, 2, 5 * d.int(de, 1)), int).reshape(-1, 5)
            return sorted(set(rows[:, [0, 1, 3]].ravel().tolist()))
        if t == 190:
            return d.ints(de, 1, self.brep_own_count(de, t))
        return []

    # -- conversion ---------------------------------------------------------------------------------
    def _e186(self, de, dim):
        if self.d.int(de, 3):
            raise GeometryError("a manifold solid with void shells is not supported")
        return self.get(self.d.int(de, 1))

    def _e514(self, de, dim):
        faces = tuple(self.get(f) for f in self.d.ints(de, 2, 2 * self.d.int(de, 1))[::2])
        return _as_revolution(faces) or Shell(faces)

    def _e510(self, de, dim):
        d = self.d
        surface = self.get(d.int(de, 1))
        loops = [Loop(started_at_joins(self._brep_loop(lp, surface)), name=self.name(lp))
                 for lp in d.ints(de, 4, d.int(de, 2))]
        outer = d.int(de, 3) == 1
        return TrimmedFace(surface, loops[0] if outer else None, tuple(loops[1:] if outer else loops))

    def _e190(self, de, dim):
        """Plane surface: location (116), normal (123) and, form 1 (parametrised), the reference
        direction (123) of u; v along normal x reference, as rgm's plane coordinates."""
        ptrs = self.d.ints(de, 1, self.brep_own_count(de, 190))
        point = self.get(ptrs[0])
        normal, *ref = (self.d.reals(p, 1, 3) for p in ptrs[1:])
        return Plane(point.xyz, normal, ref[0] if ref else None)

    def _brep_loop(self, de: int, surface) -> list:
        if self.d.entries[de].type != 508:
            raise GeometryError(f"a face's loop (DE {de}) must be a 508")
        uses = self.brep_uses(de)
        if not isinstance(surface, Revolution) and all(u[4] for u in uses):
            return [self.get(u[4][0], 2) for u in uses]
        pieces = []
        for kind, lst, index, sense, _p in uses:
            if kind == 1:       # a vertex (a pole): nothing in model space
                continue
            if self.d.entries[lst].type != 504:
                raise GeometryError(f"an edge use points to DE {lst}, which is not a 504 edge list")
            curve = self.get(self.d.int(lst, 2 + 5 * (index - 1)))
            if isinstance(curve, Circle):   # a full circle starts at its edge's start vertex
                start = self._vertex(*self.d.ints(lst, 3 + 5 * (index - 1), 2))
                curve = _from(curve, start)
            pieces.append(curve if sense == 1 else reversed_curve(curve))
        return pieces

    def _vertex(self, vlist: int, index: int) -> np.ndarray:
        """Point `index` (1-based) of the 502 vertex list at DE `vlist`."""
        if self.d.entries[vlist].type != 502:
            raise GeometryError(f"an edge's vertex (DE {vlist}) must be in a 502 vertex list")
        return self.d.reals(vlist, 2 + 3 * (index - 1), 3)


def _as_revolution(faces):
    """The Revolution a shell's faces are the pieces of (see the module docstring), else None."""
    revs = [f.surface for f in faces if isinstance(f, TrimmedFace) and isinstance(f.surface, Revolution)]
    if len(revs) != len(faces) or not revs:
        return None
    first = revs[0]
    for r in revs:
        if (r.start, r.end) != (0.0, 2 * np.pi) or not (np.array_equal(r.axis_point, first.axis_point)
                                                       and np.array_equal(r.axis_dir, first.axis_dir)):
            return None
    pieces = [r.profile for r in revs]
    if any(not np.array_equal(p.end, q.start) for p, q in zip(pieces[:-1], pieces[1:])):
        return None
    if all(isinstance(p, Line) for p in pieces):
        profile = Polyline(np.vstack([pieces[0].p0] + [p.p1 for p in pieces]))
    else:
        profile = pieces[0] if len(pieces) == 1 else CompositeCurve(tuple(pieces))
    return Revolution(profile, first.axis_point, first.axis_dir, 0.0, 2 * np.pi)
