"""Transforms as values: 4x4 homogeneous similarity matrices (model units) and the `Transform` object.

The matrix builders below are what the language's transforms evaluate to, both those applied to
geometry directly (`translate`, `rotate`, `scale`, `mirror`) and the transform values
(`translation`, `rotation`, `scaling`, `mirroring`, `frame`). Every matrix acts on column vectors,
p' = M p, so `a @ b` applies `b` first: the language writes that composition `a * b`. All of them
are similarities (rotation, translation, uniform scale, reflection), the transforms that map circles
to circles and that every model object's `.transform(matrix)` accepts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rgm.compiler.diagnostics import Span
from rgm.errors import GeometryError
from rgm.model.base import ModelObject, _unit, frozen_array

#: `frame` axes count as parallel when the sine of their angle is below this
PARALLEL_SINE = 1e-9


def translation(by) -> np.ndarray:
    """p -> p + by."""
    m = np.eye(4)
    m[:3, 3] = by
    return m


def rotation(axis, angle: float, about) -> np.ndarray:
    """Right-handed rotation by `angle` (radians) about the line through `about` along `axis` (Rodrigues)."""
    k = np.asarray(axis, float)
    norm = np.linalg.norm(k)
    if norm == 0:
        raise GeometryError("rotation axis has zero length")
    k = k / norm
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    r = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
    return _about(r, about)


def scaling(factor: float, about) -> np.ndarray:
    """Uniform scale by `factor` about the point `about` (a negative factor also reflects through it)."""
    if factor == 0:
        raise GeometryError("scale factor is zero")
    return _about(np.eye(3) * factor, about)


def mirroring(plane) -> np.ndarray:
    """Reflection in a plane (Householder): x -> x - 2 ((x - o) . n) n for its origin o and unit normal n."""
    n = plane.normal
    return _about(np.eye(3) - 2 * np.outer(n, n), plane.origin)


def frame(origin, z, x) -> np.ndarray:
    """The placement of a part-aligned frame: maps the part's local axes to the world.

    Local (1, 0, 0), (0, 1, 0), (0, 0, 1) go to the unit vectors X, Y, Z and the local origin to
    `origin`, where Z = z / |z|, X is `x` with its component along Z removed (Gram-Schmidt), normalised,
    and Y = Z x X (right-handed). A rigid motion; `x` only needs to be not parallel to `z`.
    """
    zu = _unit(np.asarray(z, float), "the frame's z axis")
    xv = np.asarray(x, float)
    xn = float(np.linalg.norm(xv))
    if xn == 0.0:
        raise GeometryError("the frame's x axis has zero length")
    xo = xv - (xv @ zu) * zu
    if np.linalg.norm(xo) <= PARALLEL_SINE * xn:
        raise GeometryError("the frame's x axis is parallel to its z axis")
    xu = xo / np.linalg.norm(xo)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = xu, np.cross(zu, xu), zu, origin
    return m


def _about(linear: np.ndarray, center) -> np.ndarray:
    """The affine map p -> center + linear (p - center)."""
    m = np.eye(4)
    m[:3, :3] = linear
    c = np.asarray(center, float)
    m[:3, 3] = c - linear @ c
    return m


@dataclass(frozen=True, eq=False)
class Transform(ModelObject):
    """A transform value of the language: the 4x4 similarity `matrix` (model units, read-only).

    `after(first)` is the composition "apply `first`, then this one" (the language's `self * first`),
    `inverse()` undoes it, and `apply(g)` moves any model object with its `.transform(matrix)`, which
    keeps the object's kind (a placed revolution is still a `Revolution`).
    """

    matrix: np.ndarray
    name: str | None = field(default=None, kw_only=True)
    span: Span | None = field(default=None, kw_only=True, repr=False)

    def __post_init__(self):
        m = frozen_array(self.matrix, 2, (4,))
        if m.shape != (4, 4):
            raise GeometryError(f"a transform is a 4x4 matrix, got shape {m.shape}")
        object.__setattr__(self, "matrix", m)

    def after(self, first: "Transform") -> "Transform":
        """This transform applied after `first`: matrix self.matrix @ first.matrix (anonymous, no span)."""
        return Transform(self.matrix @ first.matrix)

    def inverse(self) -> "Transform":
        """The transform that undoes this one (similarities are always invertible; anonymous, no span)."""
        return Transform(np.linalg.inv(self.matrix))

    def apply(self, geometry):
        """`geometry` moved by this transform (same kind of object)."""
        return geometry.transform(self.matrix)
