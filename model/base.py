"""Shared pieces of the model objects: read-only arrays, the `ModelObject` mixin, and the action of
4x4 homogeneous similarity transforms (rotation, translation, uniform scale, mirror) on points,
directions and oriented normals.
"""
from __future__ import annotations

from dataclasses import replace

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
