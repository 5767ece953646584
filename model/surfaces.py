"""Surfaces of the evaluated model, in model units; `.domain` is that of the exact `.nurbs()` form
(`rgm.geometry.revolve`: rational revolutions by Piegl & Tiller A8.1, extrusions, ruled surfaces).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError
from rgm.model.base import ModelObject, _apply_direction, _apply_points, _is_mirror, _unit, frozen_array
from rgm.model.curves import Curve

class Surface(ModelObject):
    """Common behaviour: `.domain` ((u0, u1), (v0, v1)) is that of the exact `.nurbs()` form."""

    @property
    def domain(self):
        return self.nurbs().domain


@dataclass(frozen=True, eq=False)
class Plane(Surface):
    """The infinite plane through `origin` with unit `normal`; `x_dir` (unit, in the plane) and
    `y_dir = normal x x_dir` give plane coordinates (u, v) in model units: P = origin + u x + v y."""

    origin: np.ndarray
    normal: np.ndarray
    x_dir: np.ndarray | None = None
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        n = _unit(np.asarray(self.normal, float), "plane normal")
        x = self.x_dir
        if x is None:  # any unit vector perpendicular to n, chosen stably
            helper = np.eye(3)[int(np.argmin(np.abs(n)))]
            x = np.cross(helper, n)
        x = np.asarray(x, float)
        x = _unit(x - (x @ n) * n, "plane x direction")
        object.__setattr__(self, "origin", frozen_array(self.origin, 1, (3,)))
        object.__setattr__(self, "normal", frozen_array(n, 1, (3,)))
        object.__setattr__(self, "x_dir", frozen_array(x, 1, (3,)))

    @property
    def y_dir(self) -> np.ndarray:
        return np.cross(self.normal, self.x_dir)

    @property
    def domain(self):
        return ((-np.inf, np.inf), (-np.inf, np.inf))

    def signed_distance(self, points) -> np.ndarray:
        """(k,) signed distances of points (k, 3) along the normal."""
        return (np.asarray(points, float) - self.origin) @ self.normal

    def coordinates(self, points) -> np.ndarray:
        """(k, 2) plane coordinates (u, v) of points (k, 3) (their projections)."""
        axes = self.__dict__.get("_axes")
        if axes is None:   # (3, 2): x_dir, y_dir as columns, kept (meshing maps many small batches)
            axes = np.column_stack([self.x_dir, self.y_dir])
            object.__setattr__(self, "_axes", axes)
        return (np.asarray(points, float) - self.origin) @ axes

    def nurbs(self, size: float | None = None, center=(0.0, 0.0)):
        """Bilinear NurbsSurface over the square [cu - size, cu + size] x [cv - size, cv + size] of
        plane coordinates, so its (u, v) are the plane's own; `size` (model units) is required."""
        if size is None:
            raise GeometryError("an infinite plane has no NURBS form without a size")
        from rgm.geometry import NurbsSurface

        s = float(size)
        cu, cv = center
        us, vs = np.array([cu - s, cu + s]), np.array([cv - s, cv + s])
        ctrl = self.origin + us[:, None, None] * self.x_dir + vs[None, :, None] * self.y_dir
        return NurbsSurface(1, 1, np.repeat(us, 2), np.repeat(vs, 2), ctrl, None)

    def transform(self, matrix):
        x = _unit(_apply_direction(matrix, self.x_dir), "x direction")
        y = _unit(_apply_direction(matrix, self.y_dir), "y direction")
        return replace(self, origin=_apply_points(matrix, self.origin), normal=np.cross(x, y), x_dir=x)


@dataclass(frozen=True, eq=False)
class BSplineSurface(Surface):
    """A free-form surface given by its NurbsSurface (`bsurface(...)`)."""

    surface: object  # rgm.geometry.NurbsSurface
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def nurbs(self):
        return self.surface

    def transform(self, matrix):
        return replace(self, surface=self.surface.transform(matrix))


@dataclass(frozen=True, eq=False)
class Revolution(Surface):
    """`profile` (a 3-D model curve) swept about the axis through `axis_point` along unit `axis_dir`,
    counter-clockwise (right-hand rule) from angle `start` to `end` (radians)."""

    profile: Curve
    axis_point: np.ndarray
    axis_dir: np.ndarray
    start: float = 0.0
    end: float = 2 * np.pi
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "axis_point", frozen_array(self.axis_point, 1, (3,)))
        object.__setattr__(self, "axis_dir", frozen_array(_unit(np.asarray(self.axis_dir, float), "axis"), 1, (3,)))
        object.__setattr__(self, "start", float(self.start))
        object.__setattr__(self, "end", float(self.end))

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.revolve import revolution_surface

        return revolution_surface(self.profile.nurbs(), self.axis_point, self.axis_dir, self.start, self.end)

    def transform(self, matrix):
        # A mirror reverses the sense of rotation: flip the axis so the swept angles stay the same.
        d = _unit(_apply_direction(matrix, self.axis_dir), "axis") * (-1.0 if _is_mirror(matrix) else 1.0)
        return replace(self, profile=self.profile.transform(matrix),
                       axis_point=_apply_points(matrix, self.axis_point), axis_dir=d)


@dataclass(frozen=True, eq=False)
class Extrusion(Surface):
    """`profile` (3-D curve) swept along `direction` (3,), model units: S(u, v) = C(u) + v * direction."""

    profile: Curve
    direction: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "direction", frozen_array(self.direction, 1, (3,)))

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.revolve import extrusion_surface

        return extrusion_surface(self.profile.nurbs(), self.direction)

    def transform(self, matrix):
        return replace(self, profile=self.profile.transform(matrix), direction=_apply_direction(matrix, self.direction))


@dataclass(frozen=True, eq=False)
class RuledSurface(Surface):
    """Straight lines between corresponding points of 3-D curves `a` and `b`."""

    a: Curve
    b: Curve
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.revolve import ruled_surface

        return ruled_surface(self.a.nurbs(), self.b.nurbs())

    def transform(self, matrix):
        return replace(self, a=self.a.transform(matrix), b=self.b.transform(matrix))
