"""Exact NURBS forms of lines, polylines, circular arcs, circles and conic arcs.

All curves are parameterised on [0, 1]. Circular arcs use the standard piecewise rational
quadratic of Piegl & Tiller A7.1: the sweep is cut into at most four equal pieces of <= 90 degrees,
each a rational Bezier arc whose middle control point sits at distance r / cos(dθ/2) from the centre
with weight cos(dθ/2). Angles are in radians; points may be 2-D or 3-D (all of one dimension).
"""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError

from .curve import NurbsCurve

__all__ = ["line_curve", "polyline_curve", "arc_curve", "circle_curve", "arc_three_points",
           "conic_arc", "unit_arc"]

_EPS = 1e-12


def _points(*arrays, what="points"):
    out = [np.asarray(a, dtype=float) for a in arrays]
    dim = out[0].shape[-1] if out[0].ndim else 0
    if dim not in (2, 3) or any(a.shape[-1:] != (dim,) for a in out):
        raise GeometryError(f"{what} must all be 2-D or all 3-D, got shapes {[a.shape for a in out]}")
    if not all(np.all(np.isfinite(a)) for a in out):
        raise GeometryError(f"{what} contain a non-finite value")
    return out


def line_curve(p0, p1) -> NurbsCurve:
    """The segment p0 -> p1 as a degree-1 B-spline on [0, 1]."""
    p0, p1 = _points(p0, p1)
    return NurbsCurve(1, [0.0, 0.0, 1.0, 1.0], np.stack([p0, p1]))


def polyline_curve(points) -> NurbsCurve:
    """The polyline through `points (k, d)`, degree 1, vertex i at parameter i / (k-1).

    Uniform vertex parameters keep the curve valid even with repeated vertices (a zero-length
    segment is a modelling error the evaluated model reports, not a reason to fail here).
    """
    (points,) = _points(points)
    if points.ndim != 2 or points.shape[0] < 2:
        raise GeometryError(f"a polyline needs at least two points, got shape {points.shape}")
    k = points.shape[0]
    params = np.linspace(0.0, 1.0, k)
    return NurbsCurve(1, np.r_[0.0, params, 1.0], points)


def unit_arc(start: float, end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rational quadratic arc of the unit circle from angle `start` to `end` (A7.1).

    0 < end - start <= 2π. Returns (knots (2k+4,), ctrl (2k+1, 2), weights (2k+1,)) for k <= 4
    Bezier pieces of equal sweep.
    """
    sweep = float(end) - float(start)
    if not np.isfinite(sweep) or sweep <= _EPS or sweep > 2 * np.pi + 1e-9:
        raise GeometryError(f"arc sweep must be in (0, 360] degrees, got {np.degrees(sweep):g} degrees")
    sweep = min(sweep, 2 * np.pi)
    pieces = int(np.clip(np.ceil(sweep / (np.pi / 2) - 1e-9), 1, 4))
    half = sweep / pieces / 2
    angles = start + half * np.arange(2 * pieces + 1)
    radius = np.where(np.arange(2 * pieces + 1) % 2 == 1, 1.0 / np.cos(half), 1.0)
    ctrl = radius[:, None] * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    weights = np.where(np.arange(2 * pieces + 1) % 2 == 1, np.cos(half), 1.0)
    inner = np.repeat(np.arange(1, pieces) / pieces, 2)
    knots = np.r_[0.0, 0.0, 0.0, inner, 1.0, 1.0, 1.0]
    return knots, ctrl, weights


def _frame(x_axis, y_axis):
    """Orthonormal (x, y) from two directions (y made perpendicular to x)."""
    x = np.asarray(x_axis, dtype=float)
    y = np.asarray(y_axis, dtype=float)
    nx = np.linalg.norm(x)
    if nx < _EPS:
        raise GeometryError("arc x axis has zero length")
    x = x / nx
    y = y - np.dot(y, x) * x
    ny = np.linalg.norm(y)
    if ny < _EPS * max(1.0, np.linalg.norm(y_axis)):
        raise GeometryError("arc x and y axes are parallel")
    return x, y / ny


def arc_curve(center, x_axis, y_axis, radius: float, a0: float, a1: float) -> NurbsCurve:
    """Exact circular arc: center + r (cos a x + sin a y) for a from a0 to a1 (radians, a0 < a1,
    sweep up to 2π). The axes are orthonormalised (y made perpendicular to x)."""
    (center,) = _points(center, what="center")
    if not np.isfinite(radius) or radius <= 0:
        raise GeometryError(f"arc radius must be > 0, got {radius!r}")
    x, y = _frame(x_axis, y_axis)
    if x.shape != center.shape:
        raise GeometryError("arc axes must have the dimension of the center")
    knots, unit, weights = unit_arc(a0, a1)
    ctrl = center[None, :] + radius * (unit[:, :1] * x[None, :] + unit[:, 1:] * y[None, :])
    return NurbsCurve(2, knots, ctrl, weights)


def perpendicular(normal) -> np.ndarray:
    """A unit vector perpendicular to the 3-D `normal`: the coordinate axis least aligned with it,
    projected onto the plane (so a circle about +z starts on +x)."""
    normal = np.asarray(normal, dtype=float)
    length = np.linalg.norm(normal)
    if not np.isfinite(length) or length < _EPS:
        raise GeometryError("normal / axis direction has zero length")
    n = normal / length
    # components within round-off of zero count as zero, so a normal a hair off an axis (a circle read back
    # from its points) gets the same start axis as the axis itself (ties go to the first: +x about +z)
    helper = np.eye(3)[int(np.argmin(np.where(np.abs(n) < 1e-12, 0.0, np.abs(n))))]
    x = helper - np.dot(helper, n) * n
    return x / np.linalg.norm(x)


def circle_curve(center, normal, radius: float) -> NurbsCurve:
    """Full circle of `radius` about `center`, counter-clockwise seen from the tip of `normal`.

    For a 2-D center the normal is ignored and the circle starts at center + (r, 0).
    """
    (center,) = _points(center, what="center")
    if center.shape[0] == 2:
        return arc_curve(center, [1.0, 0.0], [0.0, 1.0], radius, 0.0, 2 * np.pi)
    x = perpendicular(normal)
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    return arc_curve(center, x, np.cross(n, x), radius, 0.0, 2 * np.pi)


def arc_three_points(p0, p1, p2) -> NurbsCurve:
    """The circular arc from p0 through p1 to p2 (exact, any sweep below 360 degrees)."""
    p0, p1, p2 = _points(p0, p1, p2)
    dim = p0.shape[0]
    if dim == 2:
        p0, p1, p2 = (np.r_[p, 0.0] for p in (p0, p1, p2))
    a, b = p1 - p0, p2 - p0
    normal = np.cross(a, b)
    nn = float(np.dot(normal, normal))
    scale = max(np.dot(a, a), np.dot(b, b))
    if nn <= (1e-12 * scale) ** 2 or scale == 0:
        raise GeometryError("arc through three points: the points are collinear or coincide")
    # circumcentre of the triangle (standard vector formula)
    center = p0 + (np.dot(a, a) * np.cross(b, normal) + np.dot(b, b) * np.cross(normal, a)) / (2 * nn)
    radius = float(np.linalg.norm(p0 - center))
    x = (p0 - center) / radius
    y = np.cross(normal / np.sqrt(nn), x)
    v = p2 - center
    sweep = float(np.arctan2(np.dot(v, y), np.dot(v, x))) % (2 * np.pi)
    curve = arc_curve(center, x, y, radius, 0.0, sweep)
    if dim == 2:
        return NurbsCurve(2, curve.knots, curve.ctrl[:, :2], curve.weights)
    return curve


def _intersect_lines(p, s, q, t):
    """Parameters (a, b) with p + a s ≈ q + b t (least squares); None when the lines are parallel."""
    m = np.array([[np.dot(s, s), -np.dot(s, t)], [np.dot(s, t), -np.dot(t, t)]])
    rhs = np.array([np.dot(q - p, s), np.dot(q - p, t)])
    det = np.linalg.det(m)
    if abs(det) <= 1e-14 * np.dot(s, s) * np.dot(t, t):
        return None
    return np.linalg.solve(m, rhs)


def conic_arc(p0, t0, p2, t2, p) -> NurbsCurve:
    """The conic arc from p0 (tangent t0) to p2 (tangent t2) through p (Piegl & Tiller A7.3).

    One rational quadratic Bezier segment: the middle control point is where the end tangents
    meet, and its weight w1 makes the curve pass through p (w1 < 1 ellipse, = 1 parabola,
    > 1 hyperbola). Raises GeometryError for parallel tangents or a point p the arc cannot reach.
    """
    p0, t0, p2, t2, p = _points(p0, t0, p2, t2, p)
    hit = _intersect_lines(p0, t0, p2, t2)
    if hit is None:
        raise GeometryError("conic arc: the end tangents are parallel (the middle control point is at infinity)")
    p1 = p0 + hit[0] * t0
    if np.linalg.norm(p0 + hit[0] * t0 - (p2 + hit[1] * t2)) > 1e-9 * (1 + np.linalg.norm(p2 - p0)):
        raise GeometryError("conic arc: the end tangent lines do not meet (not coplanar)")
    chord = _intersect_lines(p1, p - p1, p0, p2 - p0)
    if chord is None or not 0 < chord[1] < 1:
        raise GeometryError("conic arc: the point p does not lie between the end tangents")
    alf2 = chord[1]
    a = np.sqrt(alf2 / (1.0 - alf2))
    u = a / (1.0 + a)
    num = (1 - u) ** 2 * np.dot(p - p0, p1 - p) + u * u * np.dot(p - p2, p1 - p)
    den = 2 * u * (1 - u) * np.dot(p1 - p, p1 - p)
    w1 = num / den if den != 0 else -1.0
    if not np.isfinite(w1) or w1 <= 0:
        raise GeometryError("conic arc: no conic with these end tangents passes through p")
    return NurbsCurve(2, [0, 0, 0, 1, 1, 1], np.stack([p0, p1, p2]), [1.0, w1, 1.0])
