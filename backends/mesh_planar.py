"""Planar faces: triangulated in their plane from the boundary samples alone, with no interior points.

A face whose surface lies in a plane (a `Plane`; a NURBS patch whose control points over the face's
domain are coplanar; a revolution whose profile over the face's domain is perpendicular to the axis,
such as the end disks of a pin) is exactly flat, so no interior point is needed for any chordal
tolerance: its boundary polygon, sampled by the shared edges to the tolerance, is triangulated in the
plane (constrained Delaunay), n - 2 triangles for a disk where meshing in (u, v) would fan them around
the pole. The bound is exact rather than measured: by the convex-hull property the surface lies within
`flatness` of the plane (taken as 1e-3 of the tolerance), so every triangle point is within that of the
plane and within the boundary chords' certified deviation of the face.

In (u, v) a face's loops pass through its poles (degenerate edges, one vertex) and along its seams (the
same edge both ways); in the plane these are not boundary: a loop's vertex ids are cut at every vertex it
visits twice into simple loops, and the ones enclosing nothing (a seam there and back) are dropped.
"""
from __future__ import annotations

import numpy as np

from .mesh_surface import NurbsPatch, PlanePatch, RevolutionPatch

__all__ = ["plane_frame", "simple_loops"]

#: the surface must lie within FLATNESS * tol of its plane to be meshed as planar
FLATNESS = 1e-3


def _support(knots, degree, lo, hi) -> np.ndarray:
    """Mask of the control points whose basis functions are non-zero somewhere in (lo, hi)."""
    knots = np.asarray(knots, float)
    n = len(knots) - degree - 1
    return (knots[:n] < hi) & (knots[degree + 1:degree + 1 + n] > lo)


def _fit_plane(points):
    """(centroid, unit normal, max distance of the points from that plane) by SVD."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    n = vt[-1]
    return c, n, float(np.abs((points - c) @ n).max())


def _plane(patch, flatness):
    """(origin, normal) of the plane the patch lies in within `flatness`, or None."""
    (u0, u1), (v0, v1) = patch.domain
    if isinstance(patch, PlanePatch):
        return patch.o, np.cross(patch.x, patch.y)
    if isinstance(patch, RevolutionPatch):   # the profile in the axis frame: constant axial coordinate
        prof = patch.local
        z = prof.ctrl[_support(prof.knots, prof.degree, v0, v1), 2]
        if len(z) == 0 or z.max() - z.min() > flatness:
            return None
        return patch.a + 0.5 * (z.max() + z.min()) * patch.k, patch.k
    if isinstance(patch, NurbsPatch):
        s = patch.nurbs
        net = s.ctrl[_support(s.knots_u, s.degree_u, u0, u1)][:, _support(s.knots_v, s.degree_v, v0, v1)]
        pts = net.reshape(-1, 3)
        if len(pts) < 3:
            return None
        c, n, off = _fit_plane(pts)
        return (c, n) if off <= flatness else None
    return None


def plane_frame(patch, tol):
    """(origin (3,), e1 (3,), e2 (3,)) of the plane a patch lies in within FLATNESS * tol, e1 x e2 along
    the surface normal Su x Sv (so counter-clockwise in the plane is counter-clockwise in (u, v)); None
    for a patch that is not planar."""
    plane = _plane(patch, FLATNESS * tol)
    if plane is None:
        return None
    origin, normal = np.asarray(plane[0], float), np.asarray(plane[1], float)
    (u0, u1), (v0, v1) = patch.domain
    t = np.array([0.5, 0.3, 0.7, 0.2, 0.8])
    _, su, sv = patch.d1(u0 + t * (u1 - u0), v0 + t[::-1] * (v1 - v0))
    sn = np.cross(su, sv)
    k = int(np.argmax(np.linalg.norm(sn, axis=1)))
    if not np.linalg.norm(sn[k]) > 0:
        return None
    normal = normal / np.linalg.norm(normal) * np.sign(sn[k] @ normal)
    e1 = np.cross(normal, np.eye(3)[int(np.argmin(np.abs(normal)))])
    e1 /= np.linalg.norm(e1)
    return origin, e1, np.cross(normal, e1)


def simple_loops(ids) -> list:
    """Positions (into `ids`) of the simple loops of a closed loop of vertex ids (first not repeated):
    consecutive repeats (a pole) merged, the loop cut at every id it visits twice, pieces of fewer than
    three vertices (a seam walked there and back) dropped."""
    ids = np.asarray(ids)
    pos = np.flatnonzero(ids != np.roll(ids, 1)) if len(ids) > 1 else np.arange(len(ids))
    stack, out = [pos], []
    while stack:
        loop = stack.pop()
        if len(loop) < 3:
            continue
        values, first, counts = np.unique(ids[loop], return_index=True, return_counts=True)
        if counts.max() == 1:
            out.append(loop)
            continue
        d = values[np.argmax(counts > 1)]
        a, b = np.flatnonzero(ids[loop] == d)[:2]
        stack += [loop[a:b], np.concatenate([loop[b:], loop[:a]])]
    return out
