"""The evaluated model: immutable geometric objects with the binding name and source span they came from.

Every object is a frozen dataclass whose arrays are read-only float64 copies, in the model's units
(angles in radians). Each keeps the *kind* the language gave it (a translated revolution is still a
`Revolution`), so back ends can emit exact entities (IGES 120 surface of revolution, STEP circles);
`.nurbs()` gives the exact rational NURBS form of any curve or surface (Piegl & Tiller ch. 7-8).

`transform(matrix)` applies a 4x4 homogeneous similarity (rotation, translation, uniform scale,
mirror): the only transforms the language has, and the ones that map circles to circles.
The lazy surface-surface intersection lives in `rgm.model.lazy` (`IntersectionCurve`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError
from rgm.model.base import ModelObject, frozen_array
from rgm.model.curves import (BSplineCurve, Circle, CircularArc, CompositeCurve, Curve, HPoint, Line, Point,
                              Polyline, Vector)
from rgm.model.surfaces import BSplineSurface, Extrusion, Plane, Revolution, RuledSurface, Surface

__all__ = ["BSplineCurve", "BSplineSurface", "Circle", "CircularArc", "CompositeCurve", "Curve", "Extrusion",
           "GEOMETRY", "HPoint", "Line", "Loop", "Model", "ModelObject", "Plane", "Point", "Polyline", "Revolution",
           "RuledSurface", "Shell", "Surface", "TrimmedFace", "Vector", "frozen_array"]

# --- topology ------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Loop(ModelObject):
    """A closed trimming loop: `pieces` joined end to start, each a 2-D curve in the face surface's
    parameter space, a 3-D curve on the surface, or a lazy `IntersectionCurve`."""

    pieces: tuple
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "pieces", tuple(self.pieces))
        if not self.pieces:
            raise GeometryError("a loop needs at least one piece")

    @property
    def is_lazy(self) -> bool:
        """True when a piece is an intersection that is only computed on `approximate(tol)`."""
        from rgm.model.lazy import IntersectionCurve

        return any(isinstance(p, IntersectionCurve) for p in self.pieces)

    def transform(self, matrix, memo: dict | None = None, uv_matrix=None):
        """The loop moved with its face: 3-D pieces by `matrix`; parameter-space pieces stay (the
        surface's parameterisation moves with it) unless `uv_matrix` (4x4 acting on (u, v, 0)) says how
        the face's (u, v) change, as a plane's metric coordinates do under a scaling."""
        from rgm.model.lazy import IntersectionCurve

        out = []
        for p in self.pieces:
            if isinstance(p, IntersectionCurve):
                out.append(p.transform(matrix, memo))
            elif p.dim == 2:
                out.append(p if uv_matrix is None else p.transform(uv_matrix))
            else:
                out.append(p.transform(matrix))
        return replace(self, pieces=tuple(out))


@dataclass(frozen=True, eq=False)
class TrimmedFace(ModelObject):
    """The part of `surface` inside `outer` (None: the whole surface domain) and outside `holes`."""

    surface: Surface
    outer: Loop | None = None
    holes: tuple = ()
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "holes", tuple(self.holes))

    def loops(self) -> tuple:
        return ((self.outer,) if self.outer is not None else ()) + self.holes

    def transform(self, matrix, memo: dict | None = None):
        # The memo keeps operand identity, so an intersection piece still knows it lies on this surface.
        # A plane's (u, v) are lengths along its unit axes, which a transform keeps unit: a scaling by s
        # scales the plane coordinates of every point by s (rotations and mirrors keep them).
        from rgm.model.base import _scale_of
        from rgm.model.surfaces import Plane

        memo = {} if memo is None else memo
        surface = memo.setdefault(id(self.surface), self.surface.transform(matrix))
        s = _scale_of(matrix)
        # (scaled in z too, which 2-D pieces lack, so that the matrix is a similarity by s: an arc's radius
        # takes its uniform scale, s, as its points do; diag(s, s, 1) gave it s^(2/3))
        uv = np.diag([s, s, s, 1.0]) if isinstance(self.surface, Plane) and s != 1.0 else None
        return replace(self, surface=surface,
                       outer=None if self.outer is None else self.outer.transform(matrix, memo, uv),
                       holes=tuple(h.transform(matrix, memo, uv) for h in self.holes))


@dataclass(frozen=True, eq=False)
class Shell(ModelObject):
    """Faces (TrimmedFace or bare surfaces) meant to share edges."""

    faces: tuple
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "faces", tuple(self.faces))

    def transform(self, matrix):
        memo: dict = {}
        return replace(self, faces=tuple(f.transform(matrix, memo) if isinstance(f, TrimmedFace)
                                         else memo.setdefault(id(f), f.transform(matrix)) for f in self.faces))


# --- the model -----------------------------------------------------------------------------------

GEOMETRY = (Curve, Surface, TrimmedFace, Shell)


@dataclass(frozen=True, eq=False)
class Model:
    """An evaluated `.rgm` file: every binding by name, in `units`, with the model `tolerance`.

    `params` are the final values of the `param` bindings (after -D overrides), as plain numbers in
    model units (radians for angles); `source` is the file path the model came from; `diagnostics`
    the warnings found while compiling it.
    """

    units: str
    tolerance: float
    objects: dict
    exports: tuple = ()
    params: dict = field(default_factory=dict)
    source: str | None = None
    diagnostics: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "exports", tuple(self.exports))
        object.__setattr__(self, "tolerance", float(self.tolerance))

    def exported(self) -> list:
        """Objects to emit: the `export`ed bindings in order; with no `export`, every surface, face and
        shell binding (or, if there are none, every curve)."""
        if self.exports:
            return [self.objects[n] for n in self.exports]
        solids = [o for o in self.objects.values() if isinstance(o, (Surface, TrimmedFace, Shell))]
        return solids or [o for o in self.objects.values() if isinstance(o, Curve)]

    def __getitem__(self, name: str):
        return self.objects[name]
