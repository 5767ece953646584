"""Fit certificates: how far the filtered scan points lie from the model, measured, never estimated.

Every figure comes from exact closest-point distances of the points used to the built surface (the
shape's own `distance`: the meridian-plane distance for a full surface of revolution, the box's exact
distance function, a trimmed NURBS face's closest point restricted to its trim,
`rgm.fitters.freeform_measure`).  Each filtered point counts for the part nearest to it
(`nearest_part`), both when `rgmc fit` certifies and when `rgmc verify` re-measures.  `coverage` is the
share of the model's surface that has data: surface samples (spacing ~ the scan's point spacing) with a
scan point within a few spacings.

Which statistic does the tolerance bound?  On real scans the maximum includes the scanner's noise and
the few outliers that survive filtering, so by default the tolerance bounds the 95th percentile
(`statistic="p95"`); `"max"` and `"p99"` may be asked for.  The certificate states its statistic, and rgm
never chases noise to meet it: a certificate that does not hold is reported, not forced.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Certificate", "certify", "STATISTICS", "nearest_part", "surface_coverage", "shape_from_model"]

STATISTICS = ("max", "p99", "p95")


@dataclass(frozen=True)
class Certificate:
    """points: count used; max, rms, p95, p99: deviations (model units); coverage in [0, 1];
    tol: the tolerance asked for; statistic: the figure that tol bounds."""

    points: int
    max: float
    rms: float
    p95: float
    p99: float
    coverage: float
    tol: float
    statistic: str

    @property
    def value(self) -> float:
        """The bounded statistic's value."""
        return {"max": self.max, "p99": self.p99, "p95": self.p95}[self.statistic]

    @property
    def holds(self) -> bool:
        return self.value <= self.tol

    def as_dict(self) -> dict:
        return {**asdict(self), "holds": self.holds}


def certify(distances, tol: float, *, statistic: str = "p95", coverage: float = float("nan")) -> Certificate:
    """Certificate from the points' closest-point distances (n,) to the model (model units)."""
    if statistic not in STATISTICS:
        raise ValueError(f"statistic must be one of {', '.join(STATISTICS)}, not {statistic!r}")
    d = np.abs(np.asarray(distances, float))
    if d.size == 0:
        raise ValueError("a certificate needs at least one point")
    p95, p99 = np.percentile(d, [95, 99])
    return Certificate(int(d.size), float(d.max()), float(np.sqrt(np.mean(d * d))), float(p95), float(p99),
                       float(coverage), float(tol), statistic)


def surface_coverage(surface_samples, points, radius: float) -> float:
    """Share of `surface_samples` (m, 3) with a point of `points` (n, 3) within `radius`."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(points).query(surface_samples, k=1, distance_upper_bound=radius)
    return float(np.mean(np.isfinite(d)))


def nearest_part(shapes, points) -> tuple[np.ndarray, np.ndarray]:
    """(owner (n,), distance (n,)): the index of the shape nearest to each point (n, 3) and its distance
    (model units). Each shape has `distance(points)`; a shape with `bounds()` ((2, 3), a box holding it)
    is measured only at points whose distance to that box, a lower bound, is below the best so far."""
    points = np.asarray(points, float)
    best = np.full(len(points), np.inf)
    owner = np.full(len(points), -1)

    def lower(k):
        if not hasattr(shapes[k], "bounds"):
            return np.zeros(len(points))
        lo, hi = shapes[k].bounds()
        return np.linalg.norm(np.maximum(np.maximum(lo - points, points - hi), 0.0), axis=1)

    bounds = [lower(k) for k in range(len(shapes))]
    for k in np.argsort([np.median(b) if len(b) else 0.0 for b in bounds], kind="stable"):
        todo = np.nonzero(bounds[k] < best)[0]
        if len(todo) == 0:
            continue
        d = np.asarray(shapes[k].distance(points[todo]), float)
        better = d < best[todo]
        best[todo[better]], owner[todo[better]] = d[better], k
    return owner, best


# ------------------------------------------------------------------------ shapes from a compiled model
def _rz(p, axis_point, axis_dir):
    d = np.asarray(p, float) - axis_point
    z = d @ axis_dir
    return np.array([np.linalg.norm(d - z * axis_dir), z])


def _profile_segments(curve, axis_point, axis_dir):
    from rgm.fitters.profile2d import Segment
    from rgm.model.objects import BSplineCurve, CircularArc, CompositeCurve, Line, Polyline

    if isinstance(curve, CompositeCurve):
        return [s for piece in curve.pieces for s in _profile_segments(piece, axis_point, axis_dir)]
    if isinstance(curve, Polyline):
        pts = [_rz(p, axis_point, axis_dir) for p in curve.points]
        return [Segment(a, b) for a, b in zip(pts, pts[1:])]
    if isinstance(curve, Line):
        return [Segment(_rz(curve.p0, axis_point, axis_dir), _rz(curve.p1, axis_point, axis_dir))]
    if isinstance(curve, CircularArc):
        from scipy.spatial.transform import Rotation

        n = np.asarray(curve.normal, float) / np.linalg.norm(curve.normal)
        u, v = curve.start_point - curve.center, curve.end_point - curve.center
        sweep = np.arctan2(np.cross(u, v) @ n, u @ v) % (2 * np.pi) or 2 * np.pi
        mid = curve.center + Rotation.from_rotvec(n * sweep / 2).apply(u)
        c = _rz(curve.center, axis_point, axis_dir)
        return [Segment(_rz(curve.start_point, axis_point, axis_dir), _rz(curve.end_point, axis_point, axis_dir),
                        c, float(curve.radius), _rz(mid, axis_point, axis_dir))]
    if isinstance(curve, BSplineCurve) and not curve.nurbs().is_rational:
        # control points in the meridian plane's own (signed r, z) coordinates: an affine map, so exact
        nurbs = curve.nurbs()
        ctrl = np.asarray(nurbs.ctrl, float) - axis_point
        z = ctrl @ axis_dir
        across = ctrl - np.outer(z, axis_dir)
        e = across.mean(axis=0) / np.linalg.norm(across.mean(axis=0))
        rz = np.column_stack([across @ e, z])
        return [Segment(rz[0], rz[-1], ctrl=rz, knots=np.asarray(nurbs.knots, float))]
    raise ValueError(f"cannot measure a profile made of {type(curve).__name__}")


def shape_from_model(obj):
    """A measurable shape (with `.distance(points)`) for an evaluated model object of the kinds `rgmc fit`
    writes: a full Revolution (RevolutionFit), a Shell whose sides are an Extrusion of a closed rectangle
    (a box: BoxFit), a TrimmedFace on a B-spline surface or such a surface (TrimmedNurbs)."""
    from rgm.fitters.freeform_measure import TrimmedNurbs
    from rgm.fitters.primitives import BoxFit
    from rgm.fitters.profile2d import Profile
    from rgm.fitters.revolution import RevolutionFit
    from rgm.model.objects import BSplineSurface, Extrusion, Polyline, Revolution, Shell, TrimmedFace

    if isinstance(obj, BSplineSurface) or isinstance(obj, TrimmedFace) and isinstance(obj.surface, BSplineSurface):
        return TrimmedNurbs.from_model(obj)

    if isinstance(obj, Revolution):
        a = np.asarray(obj.axis_point, float)
        d = np.asarray(obj.axis_dir, float) / np.linalg.norm(obj.axis_dir)
        frame = np.eye(4)
        frame[:3, 1], frame[:3, 3] = d, a
        return RevolutionFit(frame, Profile(tuple(_profile_segments(obj.profile, a, d))), float("nan"))
    if isinstance(obj, Shell):
        for face in obj.faces:
            surf = face.surface if isinstance(face, TrimmedFace) else face
            if isinstance(surf, Extrusion) and isinstance(surf.profile, Polyline) and len(surf.profile.points) == 5:
                p = np.asarray(surf.profile.points, float)
                h = np.asarray(surf.direction, float)
                e1, e2 = p[1] - p[0], p[3] - p[0]
                frame = np.eye(4)
                frame[:3, :3] = np.column_stack([e / np.linalg.norm(e) for e in (e1, e2, h)])
                frame[:3, 3] = p[0] + (e1 + e2 + h) / 2
                return BoxFit(frame, np.array([np.linalg.norm(e1), np.linalg.norm(e2), np.linalg.norm(h)]) / 2)
    raise ValueError(f"rgmc verify cannot measure a {type(obj).__name__} yet (revolutions, boxes and "
                     f"B-spline surfaces, trimmed or not, only)")
