"""A full wrap parameterised along its meridian profile: u its angle about the axis, v the arc length of the
profile, so that a profile that rolls over (a can's rim) is still one surface over one parameterisation.

A closed wrap is parameterised by angle and height (`rgm.fitters.patch_base`), which folds where the
surface turns past horizontal: the YCB potted meat can's mantle flares out below its lid and rolls over
into a bead about 3 mm across, whose top is horizontal and whose inner wall runs down again. Fitted over
the height, the rim's points lie on both sides of any one surface (1.8 mm at p95 at a 1 mm tolerance);
fitted as a face of its own, over a plane, its seams with the mantle and the lid are near-tangent
intersections that change between approximations. Swept along the profile, mantle and rim are one
surface and the seam between them is gone.

The profile is common to the whole turn, measured across the mantle's cross-section:

1. the cross-section: the median distance from the axis per angle bin (a closed polygon, resampled at a
   quarter point spacing); each point's offset w is its signed distance to that polygon in its own
   plane across the axis (outside positive), its height z along the axis. On a rounded-rectangle
   section the radial offset would stretch the profile by up to 1 / cos of the angle between the radial
   and the normal; the distance does not;
2. the (w, z) points of the whole turn lie along one curve: binned in cells of half a point spacing, the
   cells' centroids joined by their minimum spanning tree, whose heaviest path (each edge weighing the
   points of its two cells) is the profile's order (after Lee 2000, curve reconstruction from unorganised
   points, which takes the longest: at 1.5 mm views the can's roll is a blob of points beside which a
   sparse branch of the lid's points runs farther), smoothed by a running mean over two point spacings
   of its length either way;
3. v is the arc length of each point's closest point on that path.

`swept_parameters` refuses (None) points that do not go round their axis or do not lie along one profile
(the 95th percentile of the distance to it over three point spacings), and a merge's side that is no
rim (`rims`): one that runs in towards the axis (a sweep takes a wrap's rim, not its ends, a lid or a
bottom across a crease, which stay faces of their own) or lies off the profile.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path
from scipy.spatial import cKDTree

from rgm.fitters.patch_base import Base, cylinder_frame, goes_round, turn_start, unit_box

__all__ = ["on_profile", "rims", "swept_parameters"]

#: how far a side a sweep takes may lie from the wrap's cross-section, as a share of its distance from the axis:
#: a rim keeps near the section, an end (a lid, a bottom) runs in towards the axis
_RIM = 0.25
#: the 95th percentile of the points' distance to their common profile, in point spacings, beyond which
#: they are no sweep of one profile
_OFF_PROFILE = 3.0


def swept_parameters(points, normals, spacing: float, sides=None):
    """(u, v, Base) of `points` (n, 3) as one wrap swept along its meridian profile (module docstring): u
    its angle over 2 pi in [0, 1), v the profile's arc length scaled to [0, 1]; None where the points do
    not go round their axis (from the largest side's `normals` (n, 3), as for a cylinder), do not lie
    along one profile, or where a side but the largest (labels `sides` (n,)) is no rim (`rims`).
    `spacing`: the point spacing (model units)."""
    frame = _Section(points, normals, spacing, sides)
    taken, path = _rims(frame, spacing)       # with every side a rim, the path is all the points' profile
    if len(taken) < len(frame.rest) or path is None:
        return None
    if path[0, 1] > path[-1, 1]:                      # v runs up the axis
        path = path[::-1]
    s, off = _along(path, frame.q)
    if np.quantile(off, 0.95) > _OFF_PROFILE * spacing:
        return None
    u = np.mod(frame.theta - turn_start(frame.theta), 2 * np.pi) / (2 * np.pi)
    return u, unit_box(np.c_[u, s])[1], Base("swept", frame.agree, closed=True)


def rims(points, normals, spacing: float, sides) -> np.ndarray:
    """The labels (sorted) of the sides of `points` (labels `sides` (n,)) but the largest, a closed wrap,
    that keep to its rim: each runs in from the wrap's cross-section by at most _RIM of the points'
    median distance from the axis (the 95th percentile of its |offset|: a roll, a bead, a flange as
    narrow, not an end such as a lid or a bottom across a crease, which stays a face of its own) and
    lies along the profile of the wrap and those sides (its points' 95th percentile distance to it within
    _OFF_PROFILE point spacings: not a few of the lid's points along the rim); none where the wrap does
    not go round."""
    return _rims(_Section(points, normals, spacing, sides), spacing)[0]


def _rims(frame, spacing: float):
    """(the labels `rims` returns, the profile path of the wrap and its shallow sides, None if none) of a
    `_Section`."""
    if not frame.round:
        return frame.rest[:0], None
    w = np.abs(frame.q[:, 0])
    shallow = [side for side in frame.rest if np.quantile(w[frame.sides == side], 0.95) <= _RIM * frame.radius]
    path = _profile_path(frame.q[frame.main | np.isin(frame.sides, shallow)], spacing / 2)
    if path is None or len(frame.rest) == 0:
        return frame.rest[:0], path
    off = _along(path, frame.q)[1]
    return np.array([side for side in shallow
                     if np.quantile(off[frame.sides == side], 0.95) <= _OFF_PROFILE * spacing],
                    dtype=frame.rest.dtype), path


def on_profile(points, normals, spacing: float, sides) -> np.ndarray:
    """(n,) bool: the points of the sides but the largest, a swept wrap (labels `sides` (n,)), that lie on
    the wrap's own profile (within a point `spacing` of the profile of its points alone, and more than a
    spacing from either end of it, where the wrap meets its ends across their creases) and keep to its
    rim (within _RIM of the section): where the wrap's surface runs through another patch's points."""
    frame = _Section(points, normals, spacing, sides)
    path = _profile_path(frame.q[frame.main], spacing / 2) if frame.round else None
    if path is None:
        return np.zeros(len(frame.q), bool)
    s, off = _along(path, frame.q)
    length = np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))
    return ~frame.main & (off <= spacing) & (s > spacing) & (s < length - spacing) & \
        (np.abs(frame.q[:, 0]) <= _RIM * frame.radius)


class _Section:
    """The points of a wrap and its sides across the wrap's axis: `theta` (n,) the angle about it, `q`
    (n, 2) the offset from the wrap's cross-section (`_offset`) and the height; `round` whether the wrap
    goes all the way round, `radius` the points' median distance from the axis, `agree` the cylinder's
    agreement (`rgm.fitters.patch_base.cylinder_frame`), `main` the wrap's points (the largest side),
    `rest` the other sides' labels."""

    def __init__(self, points, normals, spacing: float, sides):
        points, normals = np.asarray(points, float), np.asarray(normals, float)
        self.sides = np.zeros(len(points), int) if sides is None else np.asarray(sides)
        labels, count = np.unique(self.sides, return_counts=True)
        self.main = self.sides == labels[np.argmax(count)]
        self.rest = np.delete(labels, np.argmax(count))
        centre2, basis, axis, self.agree = cylinder_frame(points[self.main], normals[self.main])  # not the rim's
        d2 = points @ basis - centre2
        self.theta = np.arctan2(d2[:, 1], d2[:, 0])
        rho = np.linalg.norm(d2, axis=1)
        self.radius = float(np.median(rho))
        self.round = goes_round(self.theta[self.main], rho[self.main], spacing)
        self.q = np.c_[_offset(d2, self.theta, rho, spacing), points @ axis]


def _offset(d2, theta, rho, spacing: float) -> np.ndarray:
    """(n,) each point's signed distance (outside positive) to the cross-section: the closed polygon of
    the median distance from the axis per angle bin; points `d2` (n, 2) across the axis, at angles
    `theta` and distances `rho` from it."""
    bins = int(np.clip(2 * np.pi * np.median(rho) / (4 * spacing), 16, 720))
    b = np.minimum(((theta + np.pi) / (2 * np.pi) * bins).astype(int), bins - 1)
    order = np.argsort(b, kind="stable")
    cuts = np.searchsorted(b[order], np.arange(bins + 1))
    held = np.flatnonzero(np.diff(cuts) > 0)
    radius = np.array([np.median(rho[order[cuts[i]:cuts[i + 1]]]) for i in held])
    angle = -np.pi + (held + 0.5) * 2 * np.pi / bins
    ring = np.c_[radius * np.cos(angle), radius * np.sin(angle)]
    ring = np.r_[ring, ring[:1]]
    length = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))]
    at = np.linspace(0.0, length[-1], int(length[-1] / (spacing / 4)) + 2)
    dense = np.c_[np.interp(at, length, ring[:, 0]), np.interp(at, length, ring[:, 1])]
    section = np.interp(theta, np.r_[angle - 2 * np.pi, angle, angle + 2 * np.pi], np.tile(radius, 3))
    dist = cKDTree(dense).query(d2)[0]
    return np.where(rho >= section, dist, -dist)


def _profile_path(q, cell: float):
    """The profile through 2-D points q (n, 2) lying along one curve: the heaviest path of the minimum
    spanning tree of their cells' centroids (cells of side `cell`, the sparsest tenth of them left out as
    strays), smoothed by a running mean over 4 cells of its length either way; (m, 2) in order, None if
    under 3 cells."""
    key = np.floor(q / cell).astype(np.int64)
    _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    centre = np.zeros((len(count), 2))
    np.add.at(centre, inverse, q)
    dense = count >= max(2.0, np.quantile(count, 0.1))
    centre, count = (centre / count[:, None])[dense], count[dense]
    if len(centre) < 3:
        return None
    k = min(9, len(centre))
    dist, nbr = cKDTree(centre).query(centre, k=k)
    rows = np.repeat(np.arange(len(centre)), k - 1)
    graph = coo_matrix((dist[:, 1:].ravel() + 1e-12 * cell, (rows, nbr[:, 1:].ravel())), shape=(len(centre),) * 2)
    tree = minimum_spanning_tree(graph).tocoo()
    # each edge weighs the points of its two cells: the heaviest path follows the profile where most points
    # lie (a rim's roll), not a sparse branch beside it (a few of the lid's points along the rim)
    mass = (count[tree.row] + count[tree.col]) / 2.0
    tree = coo_matrix((np.r_[mass, mass], (np.r_[tree.row, tree.col], np.r_[tree.col, tree.row])), shape=tree.shape)
    # the tree's heaviest path: the farthest node from any node, then the farthest from that one
    first = shortest_path(tree, indices=int(np.argmax(count)), directed=False)
    a = int(np.argmax(np.where(np.isfinite(first), first, -1.0)))
    far, pred = shortest_path(tree, indices=a, directed=False, return_predecessors=True)
    node = int(np.argmax(np.where(np.isfinite(far), far, -1.0)))
    path = [node]
    while node != a:
        node = int(pred[node])
        path.append(node)
    path = centre[path]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
    lo, hi = np.searchsorted(s, s - 4 * cell), np.searchsorted(s, s + 4 * cell, side="right")
    total = np.r_[np.zeros((1, 2)), np.cumsum(path, axis=0)]
    smooth = (total[hi] - total[lo]) / (hi - lo)[:, None]
    smooth[[0, -1]] = path[[0, -1]]
    keep = np.r_[True, np.linalg.norm(np.diff(smooth, axis=0), axis=1) > 1e-9 * cell]
    return smooth[keep] if keep.sum() >= 2 else None


def _along(path, q):
    """(arc length along `path` (m, 2) of each point's closest point on it, its distance) for q (n, 2):
    the closest of the two segments at the nearest vertex."""
    seg = np.diff(path, axis=0)
    length = np.linalg.norm(seg, axis=1)
    s0 = np.r_[0.0, np.cumsum(length)]
    nearest = cKDTree(path).query(q)[1]
    best_s, best_d = np.zeros(len(q)), np.full(len(q), np.inf)
    for j in (np.clip(nearest - 1, 0, len(seg) - 1), np.minimum(nearest, len(seg) - 1)):
        t = np.clip(np.einsum("ni,ni->n", q - path[j], seg[j]) / length[j] ** 2, 0.0, 1.0)
        d = np.linalg.norm(q - path[j] - t[:, None] * seg[j], axis=1)
        better = d < best_d
        best_d[better], best_s[better] = d[better], (s0[j] + t * length[j])[better]
    return best_s, best_d
