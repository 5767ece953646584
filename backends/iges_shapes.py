"""Exact conversions of IGES entity data into rgm geometry, for the reader (`iges_read`): parameter
sub-ranges split off exactly, a 126 form 2 recognised as the circle or arc it is, a bilinear 128 in
plane coordinates as the plane it is."""
from __future__ import annotations

import numpy as np

from rgm.model import Circle, CircularArc, Plane

__all__ = ["sub_curve", "sub_surface", "as_arc", "as_plane"]


def sub_curve(curve, v0: float, v1: float):
    """`curve` restricted to [v0, v1] when that is a proper sub-range of its domain (exact split)."""
    a, b = curve.domain
    if a < v0 < b:
        curve = curve.split(v0)[1]
    if a < v1 < b and v1 < curve.domain[1]:
        curve = curve.split(v1)[0]
    return curve


def as_arc(curve):
    """The Circle or CircularArc a 126 form 2 (circular arc) is, when its points lie on one circle to
    1e-12 of its radius (centre and normal from three points in order, so the sense is kept); else None."""
    p = curve.evaluate(np.linspace(*curve.domain, 33))
    p3 = np.column_stack([p, np.zeros(len(p))]) if p.shape[1] == 2 else p
    a, b, c = p3[0], p3[11], p3[22]
    n = np.cross(b - a, c - b)
    if not np.linalg.norm(n) > 0:
        return None
    n /= np.linalg.norm(n)
    ab, ac = b - a, c - a
    centre = a + (np.cross(n, ab) * (ac @ ac) - np.cross(n, ac) * (ab @ ab)) / (2 * np.cross(ab, ac) @ n)
    r = np.linalg.norm(p3 - centre, axis=1)
    if np.ptp(r) > 1e-12 * r[0] or np.abs((p3 - centre) @ n).max() > 1e-12 * r[0]:
        return None
    dim = p.shape[1]
    if dim == 2:
        n = np.array([0.0, 0.0, np.sign(n[2])])
    if np.linalg.norm(p3[-1] - p3[0]) <= 1e-12 * r[0]:
        # a Circle starts on its own axis (`rgm.geometry.conics.perpendicular`): only a curve that starts
        # there is one; another full circle stays the B-spline it is, its parameterisation kept
        circle = Circle(centre[:dim], n, float(r.mean()))
        start = circle.nurbs().evaluate(np.array([0.0]))[0]
        return circle if np.linalg.norm(start - p[0]) <= 1e-9 * r[0] else None
    return CircularArc(centre[:dim], n, float(np.linalg.norm(p3[0] - centre)), p[0], p[-1])


def sub_surface(s, u0, u1, v0, v1):
    (a, b), (c, e) = s.domain
    for direction, t0, t1, lo, hi in (("u", u0, u1, a, b), ("v", v0, v1, c, e)):
        if lo < t0 < hi:
            s = s.split(direction, t0)[1]
        dom = s.domain[0 if direction == "u" else 1]
        if dom[0] < t1 < dom[1]:
            s = s.split(direction, t1)[0]
    return s


def as_plane(s):
    """A Plane when the bilinear 128 is parametrised by plane coordinates (isometric, orthogonal);
    trimming curves then keep their meaning. None otherwise."""
    if (s.degree_u, s.degree_v, s.nu, s.nv) != (1, 1, 2, 2) or s.is_rational:
        return None
    (u0, u1), (v0, v1) = s.domain
    c = s.ctrl
    x = (c[1, 0] - c[0, 0]) / (u1 - u0)
    y = (c[0, 1] - c[0, 0]) / (v1 - v0)
    size = max(float(np.abs(c).max()), 1.0)
    if (abs(np.linalg.norm(x) - 1) > 1e-12 or abs(np.linalg.norm(y) - 1) > 1e-12 or abs(x @ y) > 1e-12
            or np.abs(c[1, 1] - c[0, 1] - c[1, 0] + c[0, 0]).max() > 1e-12 * size):
        return None
    origin = c[0, 0] - u0 * x - v0 * y
    return Plane(origin, np.cross(x, y), x)
