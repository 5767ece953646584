"""Points and curves of the evaluated model (2-D parameter-space or 3-D, model units).

Each keeps the kind the language gave it; `.nurbs()` is its exact (rational) NURBS form, built by
`rgm.geometry.conics` (Piegl & Tiller A7.1 arcs and circles) and cached.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError
from rgm.model.base import ModelObject, _apply_direction, _apply_normal, _apply_points, _scale_of, _unit, frozen_array

@dataclass(frozen=True, eq=False)
class Point(ModelObject):
    """A point: `xyz` (3,) in model units, or (2,) for a parameter-space `uv` point."""

    xyz: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "xyz", frozen_array(self.xyz, 1, (2, 3)))

    @property
    def dim(self) -> int:
        return self.xyz.shape[0]

    def transform(self, matrix):
        return replace(self, xyz=_apply_points(matrix, self.xyz))


@dataclass(frozen=True, eq=False)
class Vector(ModelObject):
    """A free vector (3,) in model units; transforms by the linear part only."""

    xyz: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "xyz", frozen_array(self.xyz, 1, (3,)))

    def transform(self, matrix):
        return replace(self, xyz=_apply_direction(matrix, self.xyz))


@dataclass(frozen=True, eq=False)
class HPoint(ModelObject):
    """A weighted control point: Euclidean `xyz` (3,) and weight `w` (rgm's convention, see docs)."""

    xyz: np.ndarray
    w: float
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "xyz", frozen_array(self.xyz, 1, (3,)))
        object.__setattr__(self, "w", float(self.w))

    def transform(self, matrix):
        return replace(self, xyz=_apply_points(matrix, self.xyz))


# --- curves --------------------------------------------------------------------------------------

def _drop_to(curve, dim: int):
    """A 3-D NurbsCurve lying in z = 0 as a `dim`-D one (parameter-space curves are built in 3-D)."""
    if dim == 3:
        return curve
    from rgm.geometry import NurbsCurve

    weights = curve.weights if curve.is_rational else None
    return NurbsCurve(curve.degree, curve.knots, np.asarray(curve.ctrl)[:, :dim], weights)


def _lift(p: np.ndarray) -> np.ndarray:
    return p if p.shape[0] == 3 else np.concatenate([p, [0.0]])


class Curve(ModelObject):
    """Common behaviour of curves: `.dim`, cached `.nurbs()`, `start`/`end` points."""

    @property
    def start(self) -> np.ndarray:
        n = self.nurbs()
        return n.evaluate(np.array([n.domain[0]]))[0]

    @property
    def end(self) -> np.ndarray:
        n = self.nurbs()
        return n.evaluate(np.array([n.domain[1]]))[0]


@dataclass(frozen=True, eq=False)
class Line(Curve):
    """The segment from `p0` to `p1`, (d,) each, d = 2 (uv) or 3."""

    p0: np.ndarray
    p1: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "p0", frozen_array(self.p0, 1, (2, 3)))
        object.__setattr__(self, "p1", frozen_array(self.p1, 1, (self.p0.shape[0],)))

    @property
    def dim(self) -> int:
        return self.p0.shape[0]

    @property
    def start(self):
        return self.p0

    @property
    def end(self):
        return self.p1

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.conics import line_curve

        return _drop_to(line_curve(_lift(self.p0), _lift(self.p1)), self.dim)

    def transform(self, matrix):
        return replace(self, p0=_apply_points(matrix, self.p0), p1=_apply_points(matrix, self.p1))


@dataclass(frozen=True, eq=False)
class Polyline(Curve):
    """Straight segments through `points` (k, d), k >= 2, as a degree-1 B-spline."""

    points: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        pts = frozen_array(self.points, 2, (2, 3))
        if pts.shape[0] < 2:
            raise GeometryError("a polyline needs at least two points")
        object.__setattr__(self, "points", pts)

    @property
    def dim(self) -> int:
        return self.points.shape[1]

    @property
    def start(self):
        return self.points[0]

    @property
    def end(self):
        return self.points[-1]

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.conics import polyline_curve

        pts = self.points if self.dim == 3 else np.column_stack([self.points, np.zeros(len(self.points))])
        return _drop_to(polyline_curve(pts), self.dim)

    def transform(self, matrix):
        return replace(self, points=_apply_points(matrix, self.points))


@dataclass(frozen=True, eq=False)
class Circle(Curve):
    """Full circle: `center` (d,), unit `normal` (3,) (counter-clockwise about it), `radius` > 0."""

    center: np.ndarray
    normal: np.ndarray
    radius: float
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "center", frozen_array(self.center, 1, (2, 3)))
        object.__setattr__(self, "normal", frozen_array(_unit(np.asarray(self.normal, float), "circle normal"), 1, (3,)))
        object.__setattr__(self, "radius", float(self.radius))

    @property
    def dim(self) -> int:
        return self.center.shape[0]

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.conics import circle_curve

        return _drop_to(circle_curve(_lift(self.center), self.normal, self.radius), self.dim)

    def transform(self, matrix):
        return replace(self, center=_apply_points(matrix, self.center), normal=_apply_normal(matrix, self.normal),
                       radius=self.radius * _scale_of(matrix))


@dataclass(frozen=True, eq=False)
class CircularArc(Curve):
    """Arc counter-clockwise about unit `normal` from `start_point` to `end_point` on the circle of
    `center`/`radius`; sweep in (0, 2*pi]. Points (d,), normal (3,)."""

    center: np.ndarray
    normal: np.ndarray
    radius: float
    start_point: np.ndarray
    end_point: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "center", frozen_array(self.center, 1, (2, 3)))
        d = (self.center.shape[0],)
        object.__setattr__(self, "normal", frozen_array(_unit(np.asarray(self.normal, float), "arc normal"), 1, (3,)))
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "start_point", frozen_array(self.start_point, 1, d))
        object.__setattr__(self, "end_point", frozen_array(self.end_point, 1, d))

    @property
    def dim(self) -> int:
        return self.center.shape[0]

    @property
    def start(self):
        return self.start_point

    @property
    def end(self):
        return self.end_point

    @property
    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(x_axis, y_axis) (3,) each: x towards the start point, y = normal x x."""
        x = _unit(_lift(self.start_point) - _lift(self.center), "arc start radius")
        return x, np.cross(self.normal, x)

    @property
    def sweep(self) -> float:
        """Swept angle in radians, in (0, 2*pi]."""
        x, y = self.frame
        e = _lift(self.end_point) - _lift(self.center)
        a = float(np.arctan2(e @ y, e @ x)) % (2 * np.pi)
        return a if a > 1e-12 else 2 * np.pi

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.conics import arc_curve

        x, y = self.frame
        return _drop_to(arc_curve(_lift(self.center), x, y, self.radius, 0.0, self.sweep), self.dim)

    def transform(self, matrix):
        return replace(self, center=_apply_points(matrix, self.center), normal=_apply_normal(matrix, self.normal),
                       radius=self.radius * _scale_of(matrix), start_point=_apply_points(matrix, self.start_point),
                       end_point=_apply_points(matrix, self.end_point))


@dataclass(frozen=True, eq=False)
class BSplineCurve(Curve):
    """A free-form curve given by its NurbsCurve (`bspline(...)` in the language)."""

    curve: object  # rgm.geometry.NurbsCurve
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    @property
    def dim(self) -> int:
        return self.curve.dim

    def nurbs(self):
        return self.curve

    def transform(self, matrix):
        if self.dim == 3:
            return replace(self, curve=self.curve.transform(matrix))
        return replace(self, curve=_drop_to(_lift_curve(self.curve).transform(matrix), 2))


def _lift_curve(curve):
    from rgm.geometry import NurbsCurve

    ctrl = np.column_stack([np.asarray(curve.ctrl), np.zeros(curve.n)])
    return NurbsCurve(curve.degree, curve.knots, ctrl, curve.weights if curve.is_rational else None)


@dataclass(frozen=True, eq=False)
class CompositeCurve(Curve):
    """Curves joined end to start (`profile(...)`); `pieces` keep their own kinds."""

    pieces: tuple
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "pieces", tuple(self.pieces))
        if not self.pieces:
            raise GeometryError("a composite curve needs at least one piece")

    @property
    def dim(self) -> int:
        return self.pieces[0].dim

    @property
    def start(self):
        return self.pieces[0].start

    @property
    def end(self):
        return self.pieces[-1].end

    def nurbs(self):
        return self._nurbs

    @cached_property
    def _nurbs(self):
        from rgm.geometry.revolve import composite_curve

        if self.dim == 3:
            return composite_curve([p.nurbs() for p in self.pieces])
        return _drop_to(composite_curve([_lift_curve(p.nurbs()) for p in self.pieces]), 2)

    def transform(self, matrix):
        return replace(self, pieces=tuple(p.transform(matrix) for p in self.pieces))
