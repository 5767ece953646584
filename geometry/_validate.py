"""Input checks shared by the curve and surface constructors; every failure is a GeometryError."""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError


def frozen(array) -> np.ndarray:
    """A read-only float64 copy, so that NURBS objects are immutable."""
    out = np.array(array, dtype=float, copy=True)
    out.setflags(write=False)
    return out


def check_degree(degree, what: str = "degree") -> int:
    if isinstance(degree, (bool, np.bool_)) or not isinstance(degree, (int, np.integer)) or degree < 1:
        raise GeometryError(f"{what} must be an integer >= 1, not {degree!r}")
    return int(degree)


def check_knots(knots, degree: int, n: int, what: str = "knot vector") -> np.ndarray:
    """Validate a knot vector for `n` control points of degree `degree`; return it frozen.

    Rules: length n + p + 1, finite, non-decreasing, a non-empty domain [knots[p], knots[n]], no
    knot repeated more than p + 1 times and none inside the domain more than p times (so curves
    are continuous, which splitting and degree elevation rely on).
    """
    try:
        knots = np.asarray(knots, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(f"{what} must be a sequence of numbers") from None
    if knots.ndim != 1:
        raise GeometryError(f"{what} must be one-dimensional, got shape {knots.shape}")
    if n < degree + 1:
        raise GeometryError(f"degree {degree} needs at least {degree + 1} control points, got {n}")
    if knots.shape[0] != n + degree + 1:
        raise GeometryError(
            f"{what} has {knots.shape[0]} knots but {n} control points of degree {degree} "
            f"need n + p + 1 = {n + degree + 1}")
    if not np.all(np.isfinite(knots)):
        raise GeometryError(f"{what} contains a non-finite value")
    steps = np.diff(knots)
    if np.any(steps < 0):
        i = int(np.argmax(steps < 0))
        raise GeometryError(f"{what} must be non-decreasing, but knot {i + 1} ({knots[i + 1]:g}) "
                            f"is below knot {i} ({knots[i]:g})")
    if not knots[degree] < knots[n]:
        raise GeometryError(f"{what} has an empty domain [{knots[degree]:g}, {knots[n]:g}]")
    values, counts = np.unique(knots, return_counts=True)
    if counts.max() > degree + 1:
        raise GeometryError(f"{what}: a knot is repeated {counts.max()} times, more than degree + 1 "
                            f"= {degree + 1}")
    inside = (values > knots[degree]) & (values < knots[n])
    if np.any(counts[inside] > degree):
        bad = values[inside][np.argmax(counts[inside] > degree)]
        raise GeometryError(f"{what}: interior knot {bad:g} is repeated more than degree = {degree} "
                            f"times, which would make the curve discontinuous")
    return frozen(knots)


def check_points(ctrl, shape_hint: str, dims: tuple[int, ...], ndim: int) -> np.ndarray:
    try:
        ctrl = np.asarray(ctrl, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(f"control points must be numbers shaped {shape_hint}") from None
    if ctrl.ndim != ndim or ctrl.shape[-1] not in dims:
        raise GeometryError(f"control points must have shape {shape_hint}, got {ctrl.shape}")
    if not np.all(np.isfinite(ctrl)):
        raise GeometryError("control points contain a non-finite value")
    return frozen(ctrl)


def check_weights(weights, shape: tuple[int, ...]) -> np.ndarray | None:
    if weights is None:
        return None
    try:
        weights = np.asarray(weights, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError("weights must be numbers") from None
    if weights.shape != shape:
        raise GeometryError(f"weights must have shape {shape} (one per control point), got {weights.shape}")
    if not np.all(np.isfinite(weights)) or np.any(weights <= 0):
        raise GeometryError(f"weights must be finite and > 0, got minimum {np.nanmin(weights):g}")
    return frozen(weights)


def check_params(u, domain: tuple[float, float], what: str = "u") -> np.ndarray:
    """Parameters as a 1-D float array inside `domain` (round-off beyond the ends is clipped)."""
    try:
        u = np.atleast_1d(np.asarray(u, dtype=float))
    except (TypeError, ValueError):
        raise GeometryError(f"parameter {what} must be numbers") from None
    if u.ndim != 1:
        raise GeometryError(f"parameter {what} must be one-dimensional, got shape {u.shape}")
    lo, hi = domain
    slack = 1e-9 * max(hi - lo, 1.0)
    if u.size and (not np.all(np.isfinite(u)) or u.min() < lo - slack or u.max() > hi + slack):
        raise GeometryError(f"parameter {what} outside the domain [{lo:g}, {hi:g}]: "
                            f"range [{np.nanmin(u):g}, {np.nanmax(u):g}]")
    return np.clip(u, lo, hi)


def check_matrix(matrix, dim: int) -> np.ndarray:
    """A (d+1, d+1) homogeneous transform for d-dimensional points."""
    matrix = np.asarray(matrix, dtype=float)
    if matrix.shape != (dim + 1, dim + 1) or not np.all(np.isfinite(matrix)):
        raise GeometryError(f"transform must be a finite {dim + 1}x{dim + 1} matrix, got shape {matrix.shape}")
    return matrix
