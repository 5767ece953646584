"""Trims that reach their neighbours: a seam closed where the surfaces already pass within the tolerance.

Each patch is trimmed to its own data (`rgm.fitters.trimloops`), so two patches meeting at a crease, a
corner or a sliver's edge stop short of each other by up to a few point spacings, while their surfaces,
which reach past the data (`rgm.fitters.patch_base.reach_past`), pass within the tolerance of each other
there. Where no common edge is shared (`rgm.fitters.shared_edges`), `cover_seams` closes the seam by
moving one face's trim out to the other's: the samples of face a's trimming loop on the seam with b are
projected onto b's surface; where the foot lies within the tolerance and inside b's domain, b's trim is
grown to cover it, with the band between its data and the foot (`rgm.fitters.freeform_part.fit_freeform`,
`cover`). Face a's edge then lies on face b within the tolerance: G0 as the written model has it, the
faces overlapping by at most half a trimming raster cell. The surfaces are not changed, so the
certificates stand; a grown trim is kept only when the seams it touches score better.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rgm.geometry.inversion import closest_point_surface

__all__ = ["cover_seams"]


def _feet(shape_b, xyz, tol: float) -> np.ndarray:
    """(k, 2) the parameters on b's surface of the points xyz (k, 3) whose closest point lies within
    `tol` of them, strictly inside its domain (a foot on the domain's edge means the surface stops there)."""
    surface = shape_b.nurbs()
    u, v, _, dist = closest_point_surface(surface, xyz)
    (u0, u1), (v0, v1) = surface.domain
    inside = (u > u0 + 1e-9) & (u < u1 - 1e-9) & (v > v0 + 1e-9) & (v < v1 - 1e-9)
    return np.c_[u, v][(dist <= tol) & inside]


def cover_seams(points, patches, gaps, tol: float, near: float, retrim, measure, score):
    """Patches with the trims of the seams over `tol` that share nothing grown to their neighbours (module
    docstring), and their gaps. `retrim(patch, feet)` -> the patch trimmed to its data and the
    surface parameters `feet` (k, 2) (`rgm.fitters.freeform_part.retrimmed`), or None if no valid trim
    results; `measure(patches)` -> gaps;
    `score(gaps)` orders sets of seams. Each seam is tried both ways (the face of fewer points grown
    first); a grown face is kept only if its seams then score better."""
    from rgm.fitters.patches import _twins, boundary_samples

    patches = list(patches)
    step = near / 10
    for g in sorted(gaps, key=lambda g: -g.max):
        if g.max <= tol or g.shared or _twins(patches, g.i, g.j):
            continue
        current = {(h.i, h.j): h for h in gaps}.get((g.i, g.j))
        if current is None or current.max <= tol:
            continue
        order = sorted((g.i, g.j), key=lambda k: len(patches[k].indices))
        for b in order:
            a = g.i + g.j - b
            if patches[b].shape.outline is not None:   # its loop has shared edges: not re-trimmed
                continue
            xyz, shared = boundary_samples(patches[a].shape, step)
            d = cKDTree(points[patches[b].indices]).query(xyz, distance_upper_bound=2 * near)[0]
            feet = _feet(patches[b].shape, xyz[np.isfinite(d) & (shared < 0)], tol)
            if not len(feet):
                continue
            grown = retrim(patches[b], feet)
            if grown is None:
                continue
            trial = patches[:b] + [grown] + patches[b + 1:]
            new = measure(trial)
            touched = lambda gs: [h for h in gs if b in (h.i, h.j)]   # noqa: E731
            if score(touched(new)) > score(touched(gaps)):
                patches, gaps = trial, new
                break
    return patches, gaps
