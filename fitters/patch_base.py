"""The base surface a patch is parameterised over (`rgm.fitters.patches`, step 2): the best-fit plane
when the patch is disc-like, otherwise a cylinder (axis from the normals), a full wrap round it, or the
patch split where neither projects it one-to-one; and the margins that make its fitted surface reach
past its data (`reach_past`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rgm.errors import GeometryError
from rgm.fitters.creases import checked_points, linked_components, median_spacing, unit_rows

__all__ = ["Base", "Wrap", "base_parameters", "cylinder_frame", "goes_round", "reach_past", "reach_margins",
           "turn_start", "unit_box"]


@dataclass(frozen=True)
class Base:
    """The base surface a patch was projected onto: kind "plane" or "cylinder"; `agreement` is the 1st
    percentile of |n . d| over the patch (d: the projection direction), the cosine of its worst angle."""

    kind: str
    agreement: float
    closed: bool = False   # a cylinder's full wrap, u its angle over 2 pi (`rgm.fitters.wrap`)
    wrap: object = field(default=None, compare=False, repr=False)   # a closed wrap's faces: their `Wrap`


@dataclass(frozen=True)
class Wrap:
    """The closed wrap two faces were cut from (`rgm.fitters.wrap`): its points' indices in the input, their
    parameters (u its angle over 2 pi, v its height, both in [0, 1]), and the faces' margin past each
    seam (a share of the turn), which maps a face's u to the wrap's."""

    indices: np.ndarray
    u: np.ndarray
    v: np.ndarray
    delta: float

    def closed_u(self, s: np.ndarray, start: float) -> np.ndarray:
        """The wrap's u of parameters s (k,) of its face from u = `start` (0 or 1/2)."""
        return np.mod(np.asarray(s, float) * (0.5 + 2 * self.delta) - self.delta + start, 1.0)

    def start(self, indices: np.ndarray) -> float:
        """Where the face holding points `indices` (of the input) starts: 0 or 1/2."""
        return 0.0 if self.u[np.flatnonzero(self.indices == indices[0])[0]] < 0.5 else 0.5


def _plane(points, normals):
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    uv = (points - c) @ vt[:2].T
    return uv, float(np.quantile(np.abs(normals @ vt[2]), 0.01))


def cylinder_frame(points, normals):
    """(centre (2,) in the basis, basis (3, 2), axis (3,), agreement) of a cylinder-like patch: the axis the
    direction most nearly perpendicular to all `normals`, the centre the normal lines' least-squares meeting
    point across it, the agreement the 1st percentile of |n . radial|."""
    vec = np.linalg.eigh(normals.T @ normals)[1]
    axis, e1, e2 = vec[:, 0], vec[:, 1], vec[:, 2]
    p2 = points @ np.c_[e1, e2]
    n2 = normals @ np.c_[e1, e2]                  # normals across the axis, length |n x axis|
    w = np.sum(n2 * n2, axis=1)
    A = np.eye(2) * w.sum() - n2.T @ n2           # sum (|n|² I - n n^T): the normal lines' meeting point
    b = w @ p2 - np.einsum("ni,n->i", n2, np.einsum("ni,ni->n", n2, p2))
    centre2 = np.linalg.solve(A + 1e-9 * np.trace(A) * np.eye(2), b)
    agree = float(np.quantile(np.abs(np.einsum("ni,ni->n", n2, unit_rows(p2 - centre2))), 0.01))
    return centre2, np.c_[e1, e2], axis, agree


def base_parameters(points, normals, *, max_angle: float = 75.0, spacing: float | None = None,
                    depth: int = 3) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, Base]]:
    """Parameters of a patch by projection onto a base surface: a list of (indices, u, v, base), one
    entry per piece (a full wrap, or a patch no base projects one-to-one, is split; `depth` bounds the
    splitting). u, v (m,) are in [0, 1]. points (n, 3), normals (n, 3) unit, unoriented. A patch that
    fits neither base is split into its mantle (normals across the cylinder axis) and its ends (normals
    within 45 degrees of the axis), each into connected pieces; pieces under 16 points are left out."""
    points, normals = checked_points(points), np.asarray(normals, float)
    idx = np.arange(len(points))
    limit = np.cos(np.radians(max_angle))
    spacing = spacing or median_spacing(cKDTree(points))
    uv, agree_plane = _plane(points, normals)
    if agree_plane >= limit:
        return [(idx, *unit_box(uv), Base("plane", agree_plane))]
    centre2, basis, axis, agree_cyl = cylinder_frame(points, normals)
    if agree_cyl >= limit or depth == 0:
        if agree_cyl < agree_plane:
            return [(idx, *unit_box(uv), Base("plane", agree_plane))]
        d2 = points @ basis - centre2
        theta = np.arctan2(d2[:, 1], d2[:, 0])
        t = np.mod(theta - turn_start(theta), 2 * np.pi)
        if not goes_round(theta, np.linalg.norm(d2, axis=1), spacing) or depth == 0:
            return [(idx, *unit_box(np.c_[t, points @ axis]), Base("cylinder", agree_cyl))]
        # a full wrap: one surface closed round the axis (`rgm.fitters.wrap`), u its angle
        height = unit_box(np.c_[t, points @ axis])[1]
        return [(idx, t / (2 * np.pi), height, Base("cylinder", agree_cyl, closed=True))]
    else:
        ends = np.abs(normals @ axis) > np.cos(np.pi / 4)
        if min(ends.sum(), (~ends).sum()) >= 0.05 * len(points):
            pieces = []
            for group in (idx[ends], idx[~ends]):
                comp = linked_components(points[group], None, 5 * spacing, 0.0)
                pieces += [group[comp == c] for c in np.unique(comp)]
        else:                                      # split across the longest extent
            pieces = [idx[uv[:, 0] < np.median(uv[:, 0])], idx[uv[:, 0] >= np.median(uv[:, 0])]]
    out = []
    for part in (p for p in pieces if len(p) >= 16):
        for sub, u, v, base in base_parameters(points[part], normals[part], max_angle=max_angle,
                                               spacing=spacing, depth=depth - 1):
            out.append((part[sub], u, v, base))
    return out


def goes_round(theta, rho, spacing: float) -> bool:
    """Whether points at angles `theta` (n,) and distances `rho` (n,) from an axis go all the way round it:
    no gap between their angles wider than 4 point `spacing`s at their median distance."""
    s = np.sort(theta)
    return bool(np.diff(np.r_[s, s[0] + 2 * np.pi]).max() <= 4 * spacing / max(float(np.median(rho)), 1e-12))


def turn_start(theta) -> float:
    """The angle just past the widest gap between angles `theta` (n,) round the circle: where u = 0."""
    s = np.sort(theta)
    return float(s[(int(np.argmax(np.diff(np.r_[s, s[0] + 2 * np.pi]))) + 1) % len(s)])


def reach_past(points, u, v, reach: float, most: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """Parameters u, v (n,) in [0, 1] moved into [m, 1 - m] (m per direction, `reach_margins`) so that the
    surface fitted over [0, 1]² reaches about `reach` (model units) past its data on every side: two
    neighbours then extend across their crease and cross there, with no domain edge clamping their
    intersection."""
    m = reach_margins(points, u, v, reach, most)
    return m[0] + (1 - 2 * m[0]) * np.asarray(u, float), m[1] + (1 - 2 * m[1]) * np.asarray(v, float)


def reach_margins(points, u, v, reach: float, most: float = 0.2) -> np.ndarray:
    """(2,) the parameter margins along u and v that `reach` (model units) takes: `reach` over the
    surface's speed in that direction (model units per parameter unit, the median of least-squares
    Jacobians over each point's 8 nearest neighbours), at most `most`."""
    points = np.asarray(points, float)
    uv = np.c_[u, v]
    k = min(9, len(points))
    nb = cKDTree(points).query(points, k=k, workers=-1)[1][:, 1:]
    dx, duv = points[nb] - points[:, None], uv[nb] - uv[:, None]             # (n, k-1, 3), (n, k-1, 2)
    gram = np.einsum("nki,nkj->nij", duv, duv)
    ok = np.linalg.det(gram) > 1e-12 * np.einsum("nii->n", gram) ** 2
    jac = np.linalg.solve(gram[ok], np.einsum("nki,nkd->nid", duv[ok], dx[ok]))  # (m, 2, 3): dS/du, dS/dv
    speed = np.median(np.linalg.norm(jac, axis=2), axis=0) if ok.any() else np.ones(2)
    return np.minimum(reach / np.maximum(speed, 1e-300), most)


def unit_box(uv):
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    if np.any(hi - lo <= 0):
        raise GeometryError("a patch's points are collinear: no surface can be parameterised over them")
    uv = (uv - lo) / (hi - lo)
    return uv[:, 0], uv[:, 1]
