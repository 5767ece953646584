"""Measuring trimmed NURBS faces: closest-point distances restricted to the trim, as certificates need.

`TrimmedNurbs` is a NURBS surface with its trimming loops as closed (u, v) polygons (the outer boundary
first, then the holes; none: the whole domain). It is built from an evaluated model object
(`from_model`: a `TrimmedFace` or a bare B-spline surface, as `rgmc fit` writes and `rgmc verify`
compiles), so the fitter and the verifier measure exactly the same thing.

Distance of a point to the face (model units): the closest point is searched on the face itself, never
on the untrimmed surface: the nearest of a dense sample of the face (a (u, v) grid about 1/250 of the
face's size apart, kept where it lies inside the trim by the even-odd rule over all loops) starts
Gauss-Newton steps on |S(u, v) - p| that are kept while they lower the distance and stay inside; the
distance to the face's 3-D boundary (the loops mapped onto the surface, a dense polyline) is taken
when it is smaller (a point beyond the trim's edge). Each figure is the distance to a point of the face,
so it is never below the true distance: a certificate measured with it is conservative.

Loop pieces: 2-D curves are sampled densely; a lazy `intersect(surface, plane)` piece is approximated by
`IntersectionCurve.uv_curves` at its tolerance (the file's) and the branch running from the previous
piece's end to the next piece's start is taken; 3-D curves on the surface are projected by closest points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from rgm.geometry.polygon import inside_polygons

__all__ = ["TrimmedNurbs", "foot_distances", "branch_between"]

_PER_SPAN = 16      # samples per knot span of a 2-D loop piece
_BRANCH = 4097      # samples of an intersection branch in (u, v)


def _curve_uv(curve) -> np.ndarray:
    """Dense (k, 2) samples of a 2-D model curve, ends included."""
    c = curve.nurbs()
    breaks = np.unique(c.knots)
    t = np.unique(np.concatenate([np.linspace(a, b, _PER_SPAN + 1) for a, b in zip(breaks[:-1], breaks[1:])]))
    return c.evaluate(t)[:, :2]


def branch_between(branches, start, end) -> np.ndarray:
    """The samples (k, 2) of the branch (2-D NurbsCurves) passing nearest to `start` and `end` (uv),
    from the sample nearest `start` to the one nearest `end`."""
    best = None
    for c in branches:
        pts = c.evaluate(np.linspace(*c.domain, _BRANCH))
        ia = int(np.argmin(np.linalg.norm(pts - start, axis=1)))
        ib = int(np.argmin(np.linalg.norm(pts - end, axis=1)))
        err = np.linalg.norm(pts[ia] - start) + np.linalg.norm(pts[ib] - end)
        if best is None or err < best[0]:
            best = (err, pts[ia:ib + 1] if ia <= ib else pts[ib:ia + 1][::-1])
    return best[1]


def _loop_uv(loop, surface_obj, nurbs) -> np.ndarray:
    """A closed (u, v) polygon (k, 2) of a model Loop on `surface_obj` (last point not repeated)."""
    from rgm.geometry.inversion import closest_point_surface
    from rgm.model import IntersectionCurve

    pieces = []
    for piece in loop.pieces:
        if isinstance(piece, IntersectionCurve):
            pieces.append(piece)
        elif piece.dim == 2:
            pieces.append(_curve_uv(piece))
        else:
            c = piece.nurbs()
            u, v = closest_point_surface(nurbs, c.evaluate(np.linspace(*c.domain, 513)))[:2]
            pieces.append(np.c_[u, v])
    size = float(np.ptp(np.asarray(nurbs.ctrl).reshape(-1, 3), axis=0).max())
    for k, p in enumerate(pieces):
        if not isinstance(p, IntersectionCurve):
            continue
        branches = p.uv_curves(surface_obj, p.tolerance or 1e-4 * size)
        if len(pieces) == 1:
            pieces[k] = branches[0].evaluate(np.linspace(*branches[0].domain, _BRANCH))
            continue
        before, after = pieces[k - 1], pieces[(k + 1) % len(pieces)]
        if isinstance(before, IntersectionCurve) or isinstance(after, IntersectionCurve):
            raise ValueError("a loop with two intersection pieces in a row cannot be measured; put a curve between")
        pieces[k] = branch_between(branches, before[-1], after[0])
    poly = np.vstack(pieces)
    keep = np.r_[True, np.linalg.norm(np.diff(poly, axis=0), axis=1) > 0]
    poly = poly[keep]
    return poly[:-1] if np.allclose(poly[0], poly[-1]) else poly


@dataclass
class TrimmedNurbs:
    """surface: rgm.geometry.NurbsSurface; loops: closed (u, v) polygons (k, 2), the outer one first,
    then the holes (empty: the whole domain)."""

    surface: object
    loops: tuple = ()

    @classmethod
    def from_model(cls, obj) -> "TrimmedNurbs":
        """From an evaluated model object: a TrimmedFace on a surface with an exact NURBS form, or such a
        surface itself."""
        from rgm.model import TrimmedFace

        if isinstance(obj, TrimmedFace):
            nurbs = obj.surface.nurbs()
            return cls(nurbs, tuple(_loop_uv(loop, obj.surface, nurbs) for loop in obj.loops()))
        return cls(obj.nurbs())

    def inside(self, uv: np.ndarray) -> np.ndarray:
        """(m,) bool: parameters uv (m, 2) on the face (inside the trim)."""
        if not self.loops:
            return np.ones(len(uv), bool)
        return inside_polygons(uv, self.loops)

    def bounds(self) -> np.ndarray:
        """(2, 3) box containing the face: its control net's box (the convex hull property)."""
        ctrl = np.asarray(self.surface.ctrl).reshape(-1, 3)
        return np.array([ctrl.min(axis=0), ctrl.max(axis=0)])

    def boundary_distance(self, points: np.ndarray) -> np.ndarray:
        """(n,) distances of points (n, 3) to the face's 3-D boundary polylines (model units)."""
        verts = [self.surface.evaluate(p[:, 0], p[:, 1]) for p in self.loops]
        sizes = np.array([len(v) for v in verts])
        first = np.repeat(np.r_[0, np.cumsum(sizes)[:-1]], sizes)
        local = np.arange(sizes.sum()) - first
        nxt = first + (local + 1) % np.repeat(sizes, sizes)
        v = np.vstack(verts)
        _, near = cKDTree(v).query(points, k=min(2, len(v)))
        near = near.reshape(len(points), -1)
        prv = np.empty_like(nxt)
        prv[nxt] = np.arange(len(v))
        seg_a = np.concatenate([near, near], axis=1)
        seg_b = np.concatenate([nxt[near], prv[near]], axis=1)
        a, b = v[seg_a], v[seg_b]                                   # (n, 4, 3) candidate segments
        ab = b - a
        t = np.clip(np.einsum("nkd,nkd->nk", points[:, None] - a, ab) /
                    np.maximum(np.einsum("nkd,nkd->nk", ab, ab), 1e-300), 0.0, 1.0)
        return np.linalg.norm(a + t[..., None] * ab - points[:, None], axis=2).min(axis=1)

    def inner_distance(self, points: np.ndarray, iterations: int = 10) -> np.ndarray:
        """(n,) distances of points (n, 3) to points of the face found from inside: the nearest sample
        of a dense (u, v) grid on the face, then `foot_distances` steps that stay on the face (model units)."""
        uv, xyz, tree = self._dense()
        d, j = tree.query(points)
        return foot_distances(self.surface, uv[j], points, d, self.inside, iterations)

    def _dense(self):
        """(u, v) (k, 2), points (k, 3) and their KD-tree, of a dense sample of the face (about 1/250 of
        its size apart), its boundary included; made once (a face is measured again and again)."""
        if not hasattr(self, "_dense_cache"):
            size = float(np.ptp(self.bounds(), axis=0).max())
            uv = np.vstack([self._inside_grid(size / 250), *self.loops])
            xyz = self.surface.evaluate(uv[:, 0], uv[:, 1])
            self._dense_cache = (uv, xyz, cKDTree(xyz))
        return self._dense_cache

    def distance(self, points) -> np.ndarray:
        """(n,) distances (model units) of points (n, 3) to the trimmed face (see the module docstring)."""
        points = np.asarray(points, float)
        if len(points) == 0:
            return np.zeros(0)
        d = self.inner_distance(points)
        return np.minimum(d, self.boundary_distance(points)) if self.loops else d

    def _inside_grid(self, spacing: float) -> np.ndarray:
        """(u, v) (k, 2) of a grid on the face whose steps are about `spacing` (model units) at the
        surface's speed over the data's region (the loops' bounding box; 8 to 400 steps a direction)."""
        (u0, u1), (v0, v1) = self.surface.domain
        if self.loops:
            lo, hi = np.vstack(self.loops).min(axis=0), np.vstack(self.loops).max(axis=0)
            (u0, v0), (u1, v1) = lo, hi
        probe = np.linspace(0, 1, 9)
        uu, vv = np.meshgrid(u0 + probe * (u1 - u0), v0 + probe * (v1 - v0), indexing="ij")
        grid = self.surface.evaluate(uu.ravel(), vv.ravel()).reshape(9, 9, 3)
        along_u = np.linalg.norm(np.diff(grid, axis=0), axis=2).sum(axis=0).max()
        along_v = np.linalg.norm(np.diff(grid, axis=1), axis=2).sum(axis=1).max()
        nu, nv = (int(np.clip(x / max(spacing, 1e-12), 8, 400)) for x in (along_u, along_v))
        u, v = np.meshgrid(np.linspace(u0, u1, nu), np.linspace(v0, v1, nv), indexing="ij")
        uv = np.c_[u.ravel(), v.ravel()]
        return uv[self.inside(uv)]

    def sample_surface(self, spacing: float) -> np.ndarray:
        """Points (k, 3) on the face about `spacing` (model units) apart, for coverage (a face too thin
        for the grid gives its boundary)."""
        uv = self._inside_grid(spacing)
        if len(uv) == 0 and self.loops:
            uv = np.vstack(self.loops)
        return self.surface.evaluate(uv[:, 0], uv[:, 1])


def foot_distances(surface, uv: np.ndarray, points: np.ndarray, bound: np.ndarray, inside,
                   steps: int = 10) -> np.ndarray:
    """(k,) distances of points (k, 3) to `surface` from start parameters uv (k, 2) whose distances are
    `bound` (k,): Gauss-Newton steps on |S(u, v) - p| towards the foot point, clipped to the domain,
    shortened (to a half, a quarter) where the full step does not come closer or leaves where `inside`
    ((k, 2) -> (k,) bool) says, and kept only when one does; a point stops when no step helps or the
    last gained less than 1e-9 of the distance. Each result is the distance to a point of the surface
    there, so never below the true distance, and at most `bound` (model units)."""
    (u0, u1), (v0, v1) = surface.domain
    x, d = np.array(uv, float), np.asarray(bound, float).copy()
    active = np.arange(len(x))
    for _ in range(steps):
        if not len(active):
            break
        xa, pa = x[active], points[active]
        der = surface.derivatives(xa[:, 0], xa[:, 1], 1)
        J = np.stack([der[1, 0], der[0, 1]], axis=-1)                                   # (k, 3, 2)
        JtJ = np.einsum("kai,kaj->kij", J, J) + 1e-12 * np.eye(2)
        step = np.linalg.solve(JtJ, -np.einsum("kai,ka->ki", J, der[0, 0] - pa)[..., None])[..., 0]
        gain = np.zeros(len(active))
        todo = np.arange(len(active))
        for scale in (1.0, 0.5, 0.25):
            y = xa[todo] + scale * step[todo]
            y = np.c_[np.clip(y[:, 0], u0, u1), np.clip(y[:, 1], v0, v1)]
            dy = np.linalg.norm(surface.evaluate(y[:, 0], y[:, 1]) - pa[todo], axis=1)
            closer = (dy < d[active[todo]]) & inside(y)
            hit = todo[closer]
            gain[hit] = d[active[hit]] - dy[closer]
            x[active[hit]], d[active[hit]] = y[closer], dy[closer]
            todo = todo[~closer]
            if not len(todo):
                break
        active = active[gain > 1e-9 * np.maximum(d[active], 1e-300)]
    return d
