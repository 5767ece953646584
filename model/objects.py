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
from functools import cached_property

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError


def frozen_array(values, ndim: int | None = None, last: tuple[int, ...] | None = None) -> np.ndarray:
    """A read-only float64 copy of `values`, checked to have `ndim` axes and a last axis in `last`."""
    arr = np.array(values, dtype=np.float64)
    if ndim is not None and arr.ndim != ndim:
        raise GeometryError(f"expected a {ndim}-d array, got shape {arr.shape}")
    if last is not None and (arr.ndim == 0 or arr.shape[-1] not in last):
        raise GeometryError(f"expected coordinates of size {' or '.join(map(str, last))}, got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n == 0.0 or not np.isfinite(n):
        raise GeometryError(f"{what} has zero length")
    return v / n


# --- 4x4 similarity transforms -------------------------------------------------------------------

def _apply_points(matrix: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 4x4 matrix to points (..., 2|3); 2-D points are taken in the z = 0 plane."""
    pts = np.asarray(pts, dtype=np.float64)
    d = pts.shape[-1]
    p3 = pts if d == 3 else np.concatenate([pts, np.zeros(pts.shape[:-1] + (1,))], axis=-1)
    out = p3 @ matrix[:3, :3].T + matrix[:3, 3]
    return out[..., :d]


def _apply_direction(matrix: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear part only (vectors, axis directions); not normalised."""
    return np.asarray(v, dtype=np.float64) @ matrix[:3, :3].T


def _apply_normal(matrix: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Image of the normal of an oriented circle/plane: det(L) L^-T n, normalised (keeps right-handedness)."""
    lin = matrix[:3, :3]
    out = np.linalg.det(lin) * np.linalg.solve(lin.T, np.asarray(n, dtype=np.float64))
    return _unit(out, "transformed normal")


def _scale_of(matrix: np.ndarray) -> float:
    """The uniform scale factor of a similarity transform."""
    return float(abs(np.linalg.det(matrix[:3, :3])) ** (1.0 / 3.0))


def _is_mirror(matrix: np.ndarray) -> bool:
    return bool(np.linalg.det(matrix[:3, :3]) < 0)


class ModelObject:
    """Mixin: `named(name)` returns a copy bound to a name (the evaluator calls it per binding)."""

    name: str | None
    span: Span | None

    def named(self, name: str | None, span: Span | None = None):
        return replace(self, name=name, span=span if span is not None else self.span)


# --- points --------------------------------------------------------------------------------------

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


# --- surfaces ------------------------------------------------------------------------------------

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
        d = np.asarray(points, float) - self.origin
        return np.column_stack([d @ self.x_dir, d @ self.y_dir])

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

    def transform(self, matrix, memo: dict | None = None):
        from rgm.model.lazy import IntersectionCurve

        out = []
        for p in self.pieces:
            if isinstance(p, IntersectionCurve):
                out.append(p.transform(matrix, memo))
            elif p.dim == 2:
                out.append(p)  # parameter-space curves do not move with the surface
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
        memo = {} if memo is None else memo
        surface = memo.setdefault(id(self.surface), self.surface.transform(matrix))
        return replace(self, surface=surface,
                       outer=None if self.outer is None else self.outer.transform(matrix, memo),
                       holes=tuple(h.transform(matrix, memo) for h in self.holes))


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
