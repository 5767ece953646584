"""Exact surface constructions: revolutions, extrusions, ruled surfaces, planes; composite curves.

Parameter conventions (documented because trims and back ends depend on them):

- `revolution_surface`: u runs around the axis (rational quadratic, domain [0, 1], angle from
  `start` to `end` but not linearly in u), v is the profile's own parameter.
- `extrusion_surface`: u is the curve's parameter, v in [0, 1] along the extrusion vector.
- `ruled_surface`: u is the (shared) curve parameter, v in [0, 1] from c0 to c1 (homogeneous blend).
- `plane_surface`: u, v are lengths along the orthonormalised x_dir, y_dir, centred on origin.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError

from .conics import unit_arc
from .curve import NurbsCurve
from .surface import NurbsSurface

__all__ = ["revolution_surface", "evaluate_revolution", "extrusion_surface", "ruled_surface",
           "plane_surface", "composite_curve", "compatible_curves"]


def _axis(axis_point, axis_dir):
    point = np.asarray(axis_point, dtype=float).reshape(3)
    direction = np.asarray(axis_dir, dtype=float).reshape(3)
    length = np.linalg.norm(direction)
    if not np.isfinite(length) or length == 0 or not np.all(np.isfinite(point)):
        raise GeometryError("revolution axis needs a finite point and a non-zero direction")
    return point, direction / length


def _check_curve3(curve, what="profile"):
    if not isinstance(curve, NurbsCurve) or curve.dim != 3:
        raise GeometryError(f"{what} must be a 3-D NurbsCurve")


def revolution_surface(profile: NurbsCurve, axis_point, axis_dir, start: float = 0.0,
                       end: float = 2 * np.pi) -> NurbsSurface:
    """Exact rational surface sweeping `profile` about the axis from angle `start` to `end`
    (radians, right-handed about `axis_dir`, 0 < end - start <= 2π) (Piegl & Tiller A8.1).

    Each profile control point P_j (weight w_j) travels on its circle: centre O_j its projection
    on the axis, radius r_j, frame X_j = (P_j - O_j)/r_j, Y_j = axis x X_j. The circle's rational
    quadratic control points (`conics.unit_arc`) give row i of the net; weights multiply.
    Returns a surface with net (2k+1, n_profile, 3), degree (2, profile.degree).
    """
    _check_curve3(profile)
    point, axis = _axis(axis_point, axis_dir)
    knots_u, unit, arc_w = unit_arc(start, end)
    with np.errstate(over="ignore", invalid="ignore"):   # coordinates near the float limit: said below
        rel = profile.ctrl - point
        centers = point + np.outer(rel @ axis, axis)                      # (n, 3)
        radial = profile.ctrl - centers
        radius = np.linalg.norm(radial, axis=1)
        x = np.divide(radial, radius[:, None], out=np.zeros_like(radial), where=radius[:, None] > 0)
        y = np.cross(axis, x)
        net = (centers[None] + radius[None, :, None] *
               (unit[:, None, :1] * x[None] + unit[:, None, 1:] * y[None]))  # (2k+1, n, 3)
    if not np.isfinite(net).all():
        raise GeometryError("the revolution's control net overflows: the profile's coordinates are too large")
    w_profile = profile.weights if profile.is_rational else np.ones(profile.n)
    weights = arc_w[:, None] * w_profile[None, :]
    return NurbsSurface(2, profile.degree, knots_u, profile.knots, net, weights)


def evaluate_revolution(profile: NurbsCurve, axis_point, axis_dir, angle, v) -> np.ndarray:
    """Points of the revolution evaluated directly: the profile point at parameter v (m,) rotated
    by `angle` (m,) radians about the axis (Rodrigues' formula). Returns (m, 3).

    This is the analytic surface the exact NURBS form must reproduce, and a cheap evaluator when
    the true angle (not the rational u parameter) is what a consumer has.
    """
    _check_curve3(profile)
    point, k = _axis(axis_point, axis_dir)
    angle = np.atleast_1d(np.asarray(angle, dtype=float))
    p = profile.evaluate(v) - point
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    along = (p @ k)[:, None] * k
    return point + p * cos + np.cross(k, p) * sin + along * (1 - cos)


def extrusion_surface(curve: NurbsCurve, vector) -> NurbsSurface:
    """The curve swept along `vector (3,)`: S(u, v) = C(u) + v * vector, v in [0, 1]."""
    _check_curve3(curve, "extruded curve")
    vector = np.asarray(vector, dtype=float).reshape(3)
    if not np.all(np.isfinite(vector)) or np.linalg.norm(vector) == 0:
        raise GeometryError("extrusion vector must be finite and non-zero")
    net = np.stack([curve.ctrl, curve.ctrl + vector], axis=1)
    weights = None if not curve.is_rational else np.stack([curve.weights] * 2, axis=1)
    return NurbsSurface(curve.degree, 1, curve.knots, [0, 0, 1, 1], net, weights)


def compatible_curves(curves) -> list[NurbsCurve]:
    """The curves rewritten on one degree, one domain (the first curve's) and one knot vector, by
    degree elevation, reparameterisation and knot refinement; none changes shape."""
    if not curves:
        raise GeometryError("no curves to make compatible")
    from .knots import multiplicity
    degree = max(c.degree for c in curves)
    lo, hi = curves[0].domain
    curves = [c.elevate(degree - c.degree) if c.degree < degree else c for c in curves]
    curves = [c.reparameterize(lo, hi) if c.domain != (lo, hi) else c for c in curves]
    values = np.unique(np.concatenate([c.knots[degree:c.n + 1] for c in curves]))
    values = values[(values > lo) & (values < hi)]
    out = []
    for c in curves:
        # a knot of the union not already in c is inserted up to the largest multiplicity
        need = [np.full(max(multiplicity(o.knots, t) for o in curves) - multiplicity(c.knots, t), t)
                for t in values]
        extra = np.concatenate(need) if need else np.empty(0)
        out.append(c.refine(extra) if extra.size else c)
    return out


def ruled_surface(c0: NurbsCurve, c1: NurbsCurve) -> NurbsSurface:
    """The ruled surface between two curves (Piegl & Tiller 8.3): S(u, .) is the straight segment
    from C0(u) to C1(u'), u' being c1's parameter mapped affinely onto c0's domain. v in [0, 1]
    interpolates the homogeneous points, so it is linear along the segment for polynomial rails
    and rational (same segment, different speed) when the rails' weights differ."""
    _check_curve3(c0, "first rail")
    _check_curve3(c1, "second rail")
    a, b = compatible_curves([c0, c1])
    rational = a.is_rational or b.is_rational
    pw = np.stack([a.homogeneous, b.homogeneous], axis=1)
    return NurbsSurface.from_homogeneous(a.degree, 1, a.knots, [0, 0, 1, 1], pw, rational)


def plane_surface(origin, x_dir, y_dir, size) -> NurbsSurface:
    """A bounded plane: the rectangle origin + s x + t y, |s| <= sx/2, |t| <= sy/2, as a bilinear
    patch whose parameters (u, v) = (s, t) are lengths. `size` is a side length or (sx, sy);
    x is x_dir normalised, y is y_dir made perpendicular to x and normalised."""
    from .conics import _frame
    origin = np.asarray(origin, dtype=float).reshape(3)
    x, y = _frame(x_dir, y_dir)
    sx, sy = np.broadcast_to(np.asarray(size, dtype=float), (2,))
    if not (np.isfinite(sx) and np.isfinite(sy) and sx > 0 and sy > 0):
        raise GeometryError(f"plane size must be positive, got {size!r}")
    s = np.array([-sx / 2, sx / 2])
    t = np.array([-sy / 2, sy / 2])
    net = origin + s[:, None, None] * x + t[None, :, None] * y
    return NurbsSurface(1, 1, np.r_[s[0], s, s[1]], np.r_[t[0], t, t[1]], net)


def composite_curve(pieces, tol: float | None = None) -> NurbsCurve:
    """One curve joining `pieces` end to start, with C0 knots (multiplicity p) at the joins.

    Piece i occupies the parameter interval [i, i+1], then the whole domain is scaled to [0, 1].
    Degrees are raised to the largest; rational pieces are rescaled (all weights of a piece times
    one constant, which leaves it unchanged) so that the shared control point at each join has one
    weight. Ends must meet within `tol` (default 1e-9 x the size of the pieces), else GeometryError.
    """
    from .knots import clamp, is_clamped
    pieces = list(pieces)
    if not pieces or not all(isinstance(c, NurbsCurve) for c in pieces):
        raise GeometryError("a composite curve needs one or more NurbsCurve pieces")
    if len({c.dim for c in pieces}) != 1:
        raise GeometryError("composite curve pieces must all be 2-D or all 3-D")
    if len(pieces) == 1:
        return pieces[0].reparameterize(0.0, 1.0)
    degree = max(c.degree for c in pieces)
    pieces = [c.elevate(degree - c.degree) if c.degree < degree else c for c in pieces]
    boxes = np.concatenate([c.bbox() for c in pieces])
    size = float(np.linalg.norm(boxes.max(axis=0) - boxes.min(axis=0)))
    tol = 1e-9 * max(size, 1.0) if tol is None else tol
    knots, rows = [np.zeros(degree + 1)], []
    for i, c in enumerate(pieces):
        k, pw = c.knots, c.homogeneous
        if not is_clamped(k, degree):
            k, pw = clamp(k, degree, pw)
        k = (k - k[0]) / (k[-1] - k[0]) + i
        if rows:
            gap = np.linalg.norm(rows[-1][-1, :-1] / rows[-1][-1, -1] - pw[0, :-1] / pw[0, -1])
            if gap > tol:
                raise GeometryError(f"composite curve: piece {i} starts {gap:g} away from the end of "
                                    f"piece {i - 1} (tolerance {tol:g})")
            pw = (pw * (rows[-1][-1, -1] / pw[0, -1]))[1:]    # the shared point is kept once
        rows.append(pw)
        knots.append(k[degree + 1:-degree - 1])
        knots.append(np.full(degree if i < len(pieces) - 1 else degree + 1, i + 1.0))
    all_knots = np.concatenate(knots) / len(pieces)
    rational = any(c.is_rational for c in pieces)
    return NurbsCurve.from_homogeneous(degree, all_knots, np.concatenate(rows), rational)
