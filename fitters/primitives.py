"""Exact primitives from classified parts: boxes (oriented, from six robust plane fits) and the shared
surface sampling used for coverage.

Box: start from the superellipsoid's (or PCA) axes; every point whose normal lies within ~18 deg of a
local axis is assigned to that face; the orientation is refined by orthogonal Procrustes on the face
normals (the rotation R minimising sum |R s_i e_k(i) - n_i|^2, Schönemann 1966 / Kabsch 1976), then each
face's offset is a robust mean (median, then the mean of the points within 3 MADs) of the coordinates of
its points (`faces="mean"`: the least-squares plane) or their 99th percentile outwards (`faces="envelope"`,
the default: the supporting plane a designer measures with callipers, which also bounds a carton whose
faces bulge; noise moves it outwards by about one noise sigma).  Opposite faces give the dimensions.  A face without data (never seen) falls back to the
99.5 percentile of all points along its axis, and is reported.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.errors import GeometryError

__all__ = ["BoxFit", "fit_box"]


@dataclass(frozen=True)
class BoxFit:
    """frame : (4, 4) box frame (columns: axes, centre) -> cloud frame.  half : (3,) half extents.
    unseen : names of faces without data ("+x", "-z", ...)."""

    frame: np.ndarray
    half: np.ndarray
    unseen: tuple = ()

    @property
    def dimensions(self) -> np.ndarray:
        return 2.0 * self.half

    def distance(self, points) -> np.ndarray:
        """(n,) exact distance of cloud-frame points to the box surface (|signed distance|)."""
        p = (np.asarray(points, float) - self.frame[:3, 3]) @ self.frame[:3, :3]
        q = np.abs(p) - self.half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        return np.abs(outside + np.minimum(q.max(axis=1), 0.0))

    def sample_surface(self, spacing: float) -> np.ndarray:
        """(m, 3) points on the six faces on a grid of about `spacing` (cloud frame)."""
        out = []
        for k in range(3):
            i, j = [a for a in range(3) if a != k]
            u = np.linspace(-self.half[i], self.half[i], max(2, int(2 * self.half[i] / spacing) + 1))
            v = np.linspace(-self.half[j], self.half[j], max(2, int(2 * self.half[j] / spacing) + 1))
            gu, gv = (g.ravel() for g in np.meshgrid(u, v))
            for s in (-1, 1):
                p = np.zeros((len(gu), 3))
                p[:, i], p[:, j], p[:, k] = gu, gv, s * self.half[k]
                out.append(p)
        return np.vstack(out) @ self.frame[:3, :3].T + self.frame[:3, 3]


def _robust_mean(x):
    med = np.median(x)
    mad = 1.4826 * np.median(np.abs(x - med)) + 1e-12
    return float(np.mean(x[np.abs(x - med) < 3 * mad]))


def fit_box(points, normals, rotation=None, *, faces: str = "envelope", min_face_points: int = 30) -> BoxFit:
    """Oriented box from points and unit normals (n, 3); `rotation` (3, 3) is a start (columns = axes)."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    if len(points) < 6 * min_face_points:
        raise GeometryError(f"a box needs at least {6 * min_face_points} points, got {len(points)}")
    centre = np.median(points, axis=0)
    rot = np.linalg.eigh(np.cov((points - centre).T))[1] if rotation is None else np.asarray(rotation, float)
    for _ in range(3):
        local = normals @ rot
        k = np.argmax(np.abs(local), axis=1)
        ok = np.abs(local[np.arange(len(k)), k]) > 0.95
        target = np.zeros_like(local)
        target[np.arange(len(k)), k] = np.sign(local[np.arange(len(k)), k])
        u, _, vt = np.linalg.svd(normals[ok].T @ target[ok])
        rot = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    local_p = (points - centre) @ rot
    side = np.sign(local_p[np.arange(len(k)), k])
    lo, hi, unseen = np.empty(3), np.empty(3), []
    for axis in range(3):
        for sgn, store in ((1, hi), (-1, lo)):
            face = ok & (k == axis) & (side == sgn)
            if face.sum() >= min_face_points:
                x = local_p[face, axis]
                store[axis] = _robust_mean(x) if faces == "mean" else np.percentile(x, 50 + 49 * sgn)
            else:
                unseen.append(("+" if sgn > 0 else "-") + "xyz"[axis])
                store[axis] = np.percentile(local_p[:, axis], 99.5 if sgn > 0 else 0.5)
    frame = np.eye(4)
    frame[:3, :3] = rot
    frame[:3, 3] = centre + rot @ ((lo + hi) / 2.0)
    return BoxFit(frame, (hi - lo) / 2.0, tuple(unseen))
