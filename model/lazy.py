"""Lazy intersection curves: `intersect(a, b)` in the language.

An `IntersectionCurve` holds its two operand surfaces and computes nothing until a consumer (a back
end, a validity check at export) calls `approximate(tol)`. The marching itself is
`rgm.geometry.intersect`; results are cached per tolerance, and a smaller `tol` gives a more
accurate curve (each branch reports its measured `max_error` <= tol against both surfaces).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError
from rgm.model.objects import Curve, Plane, Surface


@dataclass(frozen=True, eq=False)
class IntersectionCurve(Curve):
    """The intersection of surfaces `a` and `b` (either may be a `Plane`), computed on demand.

    `tolerance` (model units) is the default for `approximate`/`nurbs` (the evaluator sets the model
    tolerance). `computed` lists the tolerances approximated so far: empty after `rgmc check`.
    """

    a: Surface
    b: Surface
    tolerance: float | None = None
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "_cache", {})

    @property
    def dim(self) -> int:
        return 3

    @property
    def computed(self) -> tuple[float, ...]:
        return tuple(self._cache)

    def _tol(self, tol) -> float:
        tol = self.tolerance if tol is None else tol
        if tol is None or not tol > 0:
            raise GeometryError("an intersection curve needs a positive tolerance to be approximated")
        return float(tol)

    def approximate(self, tol: float | None = None) -> list:
        """Branches (`rgm.geometry.intersect.IntersectionBranch`) of a ∩ b within `tol`, cached per tol.

        `uv_a`/`uv_b` are the branch's images in the parameter spaces of `a`/`b`; for a `Plane`
        operand they are plane coordinates (an exact affine image of the 3-D curve).
        """
        tol = self._tol(tol)
        if tol not in self._cache:
            self._cache[tol] = _approximate(self.a, self.b, tol)
        return self._cache[tol]

    def nurbs(self, tol: float | None = None):
        """The single branch's 3-D NurbsCurve; an error if the surfaces meet in several branches."""
        branches = self.approximate(tol)
        if len(branches) != 1:
            raise GeometryError(f"the intersection{_of(self)} has {len(branches)} branches; expected one")
        return branches[0].curve

    def uv_curves(self, surface, tol: float | None = None) -> list:
        """2-D NurbsCurves of every branch in the parameter space of `surface` (operand a or b)."""
        if surface is self.a:
            return [br.uv_a for br in self.approximate(tol)]
        if surface is self.b:
            return [br.uv_b for br in self.approximate(tol)]
        raise GeometryError(f"the intersection{_of(self)} does not lie on that surface (not one of its operands)")

    def stretch(self, surface, start, end, tol: float | None = None):
        """(uv, curve): the stretch of the branch passing nearest to `start` and `end` (3-D points: a
        loop's previous piece's end and next piece's start) from the point nearest `start` to the one
        nearest `end`, as 2-D NurbsCurve on `surface` (operand a or b) and 3-D NurbsCurve, sharing their
        parameter. A marched branch has no preferred direction: this is how a loop takes an intersection
        piece between two curves (`rgm.model.validate`, the back ends)."""
        ends = np.array([start, end], float)
        best = None
        for br, uv in zip(self.approximate(tol), self.uv_curves(surface, tol)):
            t, _, dist = br.curve.closest_point(ends)
            if best is None or dist.sum() < best[0]:
                best = (dist.sum(), t, uv, br.curve)
        if best is None:
            raise GeometryError(f"the intersection{_of(self)} is empty")
        (ta, tb), uv, curve = best[1], best[2], best[3]
        lo, hi = curve.domain
        eps = 1e-12 * (hi - lo)
        a, b = min(ta, tb), max(ta, tb)
        if b - a <= eps:
            raise GeometryError(f"the intersection{_of(self)} meets both neighbouring pieces at one point")
        cut = []
        for c in (uv, curve):
            c = c.split(b)[0] if b < hi - eps else c
            c = c.split(a)[1] if a > lo + eps else c
            cut.append(c.reverse() if ta > tb else c)
        return cut[0], cut[1]

    def transform(self, matrix, memo: dict | None = None):
        """A new lazy intersection of the transformed operands (`memo` keeps operand identity)."""
        memo = {} if memo is None else memo
        a = memo.setdefault(id(self.a), self.a.transform(matrix))
        b = memo.setdefault(id(self.b), self.b.transform(matrix))
        return replace(self, a=a, b=b)


def _of(curve) -> str:
    return f" `{curve.name}`" if curve.name else ""


def _plane_image(plane: Plane, curve):
    """The plane coordinates of a 3-D NurbsCurve lying in `plane`: affine map of its control points."""
    from rgm.geometry import NurbsCurve

    return NurbsCurve(curve.degree, curve.knots, plane.coordinates(np.asarray(curve.ctrl)),
                      curve.weights if curve.is_rational else None)


def _approximate(a, b, tol: float) -> list:
    from rgm.geometry import intersect

    if isinstance(a, Plane) and isinstance(b, Plane):
        raise GeometryError("two planes meet in an infinite line; intersect a bounded surface instead")
    if isinstance(b, Plane) or isinstance(a, Plane):
        surface, plane = (a, b) if isinstance(b, Plane) else (b, a)
        branches = intersect.intersect_surface_plane(surface.nurbs(), plane.origin, plane.normal, tol)
        out = []
        for br in branches:
            on_plane = _plane_image(plane, br.curve)
            uv_a, uv_b = (br.uv_a, on_plane) if surface is a else (on_plane, br.uv_a)
            out.append(replace(br, uv_a=uv_a, uv_b=uv_b))
        return out
    return intersect.intersect_surfaces(a.nurbs(), b.nurbs(), tol)
