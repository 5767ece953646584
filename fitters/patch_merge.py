"""Neighbouring patches that one surface fits as well: merged, so that no seam is left between them.

The crease finder and the splitting of pieces no single base projects one-to-one
(`rgm.fitters.patches`) can cut a smooth face in two: the flat ring under the YCB mustard bottle's cap
came out as two patches (307 and 153 points, noise seed 4) whose surfaces part by 1-2 mm where they
meet, and a seam where two surfaces part cannot be closed by any trim. Every seam costs a shared edge
or a measured gap, so two neighbours are one patch wherever one surface serves both:

- the union of their points is parameterised again as one piece (`fit(indices)`: its own base, as a
  patch is) and fitted to the tolerance;
- the fit holds the certificate's statistic on *each* side's points separately (a sliver across a real
  crease would otherwise hide among the larger patch's points: 5 % of them may lie anywhere at p95);
- it needs no more control points than the two had together (a crease fitted round by a dense net is
  not one face).

Pairs are tried smallest first; a merged patch is tried again with its neighbours, until no pair merges.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rgm.fitters.freeform import statistic_value

__all__ = ["neighbour_pairs", "merge_neighbours"]

#: two patches are neighbours when at least this many of their points lie within _REACH spacings of each other
_CONTACTS = 4
_REACH = 2.5


def neighbour_pairs(points: np.ndarray, patches: list, spacing: float) -> list[tuple[int, int]]:
    """Pairs (i, j), i < j, of patches (with `indices` into points (n, 3)) that touch: at least _CONTACTS
    points of one lie within _REACH point spacings of a point of the other."""
    label = np.full(len(points), -1)
    for r, p in enumerate(patches):
        label[p.indices] = r
    mine = np.flatnonzero(label >= 0)
    tree = cKDTree(points[mine])
    dist, nbr = tree.query(points[mine], k=9, distance_upper_bound=_REACH * spacing)
    ok = np.isfinite(dist)
    a = np.broadcast_to(label[mine][:, None], nbr.shape)[ok]
    b = label[mine][np.minimum(nbr, len(mine) - 1)][ok]
    other = a != b
    pairs, count = np.unique(np.c_[np.minimum(a, b), np.maximum(a, b)][other], axis=0, return_counts=True)
    return [tuple(map(int, p)) for p in pairs[count >= _CONTACTS]]


def _one_surface(fit, na: int, n_ctrl: int, tol: float, statistic: str) -> bool:
    """Whether a fit of two patches' points (the first `na` of them the first patch's) serves both (module
    docstring): it holds, each side meets `tol` at `statistic` on its own, within `n_ctrl` control points."""
    f = fit.shape.fit
    return (f.stats.holds and f.n_ctrl <= n_ctrl and len(f.residuals) == len(fit.indices)
            and statistic_value(f.residuals[:na], statistic) <= tol
            and statistic_value(f.residuals[na:], statistic) <= tol)


def merge_neighbours(points: np.ndarray, patches: list, fit, spacing: float, tol: float, statistic: str):
    """(patches, notes): `patches` (PatchFits) with every pair of neighbours that one surface serves
    merged (module docstring). `fit(indices)` -> a PatchFit of points[indices] parameterised as one
    piece, or None when it is not one piece or no fit results. Patches of a closed wrap
    (`base.wrap`) are left as they are: their seams are iso-lines of one surface already."""
    patches, notes, failed = list(patches), [], set()
    while True:
        pairs = [(i, j) for i, j in neighbour_pairs(points, patches, spacing)
                 if patches[i].base.wrap is None and patches[j].base.wrap is None]
        pairs.sort(key=lambda ij: sorted(len(patches[k].indices) for k in ij))
        merged = False
        for i, j in pairs:
            key = (patches[i].indices.tobytes(), patches[j].indices.tobytes())
            if key in failed:
                continue
            a, b = patches[i], patches[j]
            union = fit(np.concatenate([a.indices, b.indices]))
            if union is None or not _one_surface(union, len(a.indices), a.shape.fit.n_ctrl + b.shape.fit.n_ctrl,
                                                 tol, statistic):
                failed.add(key)
                continue
            notes.append(f"patches of {len(a.indices)} and {len(b.indices)} points merged: one surface of "
                         f"{union.shape.fit.n_ctrl} control points fits both (they had {a.shape.fit.n_ctrl} and "
                         f"{b.shape.fit.n_ctrl})")
            patches = [p for k, p in enumerate(patches) if k not in (i, j)] + [union]
            merged = True
            break
        if not merged:
            patches.sort(key=lambda p: -len(p.indices))
            return patches, notes
