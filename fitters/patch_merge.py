"""Neighbouring patches that one surface fits as well: merged, so that no seam is left between them.

The crease finder and the splitting of pieces no single base projects one-to-one
(`rgm.fitters.patches`) can cut a smooth face in two: the flat ring under the YCB mustard bottle's cap
came out as two patches (307 and 153 points, noise seed 4) whose surfaces part by 1-2 mm where they
meet, and a seam where two surfaces part cannot be closed by any trim. Every seam costs a shared edge
or a measured gap, so two neighbours are one patch wherever one surface serves both:

- the union of their points is parameterised again as one piece (`fit(indices)`: its own base, as a
  patch is, or for a closed wrap and a rim it rolls over into, a sweep along their common profile,
  `rgm.fitters.patch_sweep`) and fitted to the tolerance;
- the fit holds the certificate's statistic on *each* side's points separately (a sliver across a real
  crease would otherwise hide among the larger patch's points: 5 % of them may lie anywhere at p95);
- it needs no more control points than the two had together (a crease fitted round by a dense net is
  not one face), or twice as many where one of the two is a closed wrap (`rgm.fitters.wrap`), whose net
  grows by whole rows round its turn.

Pairs are tried smallest first; a merged patch is tried again with its neighbours, until no pair merges.
Before the pairs, each closed wrap is offered all the neighbours that keep to its rim at once
(`take_rims`): a rolled rim the crease finder left in a string of pieces is one roll all the way round;
a wrap so swept then claims the points of other patches that its surface runs through (`claim_rims`).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rgm.fitters.freeform import statistic_value

__all__ = ["claim_rims", "neighbour_pairs", "merge_neighbours", "take_rims"]

#: two patches are neighbours when at least this many of their points lie within _REACH spacings of each other
_CONTACTS = 4
_REACH = 2.5
#: a closed wrap taking a neighbour may have this many times the control points the two had: its net grows by
#: whole rows round the turn (the knot lines a strip of rim along a sixth of the turn needs cost control points
#: all the way round)
_WRAP_GROWTH = 2


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


def _unit(patches: list, i: int) -> tuple[int, ...]:
    """The patches that merge as one with patch i: i alone, or both faces of its closed wrap."""
    wrap = patches[i].base.wrap
    return (i,) if wrap is None else tuple(t for t, q in enumerate(patches) if q.base.wrap is wrap)


def _one_surface(faces: list, sides: list[np.ndarray], n_ctrl: int, tol: float, statistic: str) -> bool:
    """Whether the fits `faces` of two units' points (one patch, or a closed wrap's two faces) serve both
    (module docstring): each holds, within `n_ctrl` control points in all, and each side's points (indices
    into the input) meet `tol` at `statistic` on their own."""
    if not faces or sum(f.shape.fit.n_ctrl for f in faces) > n_ctrl or \
            any(not f.shape.fit.stats.holds or len(f.shape.fit.residuals) != len(f.indices) for f in faces):
        return False
    indices = np.concatenate([f.indices for f in faces])
    residuals = np.concatenate([f.shape.fit.residuals for f in faces])
    return all(statistic_value(residuals[np.isin(indices, side)], statistic) <= tol for side in sides)


def merge_neighbours(points: np.ndarray, patches: list, fit, spacing: float, tol: float, statistic: str):
    """(patches, notes): `patches` (PatchFits) with every pair of neighbours that one surface serves
    merged (module docstring). `fit(indices, sides)` -> the PatchFits of points[indices] parameterised as
    one piece (one, or a full wrap's two faces), the statistic holding on each side's points (labels
    `sides`) on its own, [] when it is not one piece or no fit results. A closed wrap's two faces count
    as one patch and take a neighbour that is no closed wrap (the YCB meat can's mantle takes slivers of
    its rolled rim, whose own surfaces part from it by 1-2 mm); two closed wraps are not merged."""
    patches, notes, failed = list(patches), [], set()
    while True:
        units = {tuple(sorted((_unit(patches, i), _unit(patches, j)))) for i, j in
                 neighbour_pairs(points, patches, spacing)}
        units = [(a, b) for a, b in units if a != b and min(len(a), len(b)) == 1]
        units.sort(key=lambda ab: sorted(sum(len(patches[k].indices) for k in u) for u in ab))
        merged = False
        for a, b in units:
            sides = [np.concatenate([patches[k].indices for k in u]) for u in (a, b)]
            key = tuple(side.tobytes() for side in sides)
            if key in failed:
                continue
            faces = fit(np.concatenate(sides), _labels(sides))
            old = [patches[k].shape.fit.n_ctrl for k in a + b]
            growth = _WRAP_GROWTH if max(len(a), len(b)) > 1 else 1    # one of the two is a closed wrap
            if not _one_surface(faces, sides, growth * sum(old), tol, statistic):
                failed.add(key)
                continue
            notes.append(f"patches of {' and '.join(str(len(side)) for side in sides)} points merged: one "
                         f"surface of {sum(f.shape.fit.n_ctrl for f in faces)} control points fits both "
                         f"(they had {sum(old[:len(a)])} and {sum(old[len(a):])})")
            patches = [p for k, p in enumerate(patches) if k not in a + b] + faces
            merged = True
            break
        if not merged:
            patches.sort(key=lambda p: -len(p.indices))
            return patches, notes


def take_rims(points: np.ndarray, patches: list, fit, rims, spacing: float, tol: float, statistic: str):
    """(patches, notes): each closed wrap with all the neighbours that keep to its rim taken at once.

    A rolled rim comes out of the crease finder as one ring or as a string of pieces (the YCB meat can at
    1.5 mm views, seed 3: thirteen pieces of 16-264 points). Taken one at a time, a piece along part of
    the turn makes the wrap's closed surface grow whole rows and columns to place the roll only there
    (4,700 control points from 1,000, refused); taken together they are the roll all the way round, one
    sweep along the profile (`rgm.fitters.patch_sweep`): 910 control points from 608. `rims(indices,
    sides)` -> the labels of the sides (each neighbour's points; label 0 the wrap's) that keep to its rim;
    `fit` as for `merge_neighbours`. The wrap takes them where its fit holds on every side on its own,
    within twice the control points they had; otherwise the pairwise merge still tries each."""
    notes, tried = [], set()
    while True:
        for wrap in _untried_wraps(patches, tried):
            near = sorted({b if a in wrap else a for a, b in neighbour_pairs(points, patches, spacing)
                           if (a in wrap) != (b in wrap) and len(_unit(patches, b if a in wrap else a)) == 1})
            sides = [np.concatenate([patches[r].indices for r in wrap])] + [patches[r].indices for r in near]
            taken = [near[t - 1] for t in rims(np.concatenate(sides), _labels(sides))] if len(near) > 1 else []
            if len(taken) < 2:
                continue
            sides = sides[:1] + [patches[r].indices for r in taken]
            faces = fit(np.concatenate(sides), _labels(sides))
            old = sum(patches[r].shape.fit.n_ctrl for r in wrap + tuple(taken))
            if not _one_surface(faces, sides, _WRAP_GROWTH * old, tol, statistic):
                continue
            notes.append(f"a closed wrap of {len(sides[0])} points took {len(taken)} patches along its rim "
                         f"({', '.join(str(len(side)) for side in sides[1:])} points): one surface of "
                         f"{sum(f.shape.fit.n_ctrl for f in faces)} control points (they had {old})")
            patches = [p for r, p in enumerate(patches) if r not in wrap + tuple(taken)] + faces
            break
        else:
            return patches, notes


def claim_rims(points: np.ndarray, patches: list, fit, on_profile, tol: float):
    """(patches, notes): the points of other patches that a swept wrap's surface runs through, handed to it.

    The crease finder sets the points of a tight roll's creases by their tangent planes, and on the YCB
    meat can a few hundred of the flare's and the inner wall's points went to the lid's pieces: fitted over
    planes, these bent down to pass them and met the swept rim along no clean intersection. Once the wrap
    is swept along its profile (`take_rims`), a point of another patch goes to it where it lies on the
    wrap's profile (`on_profile(indices, sides)` -> mask, label 0 the wrap's points) and within `tol` / 2
    of its surface. The wrap is fitted again with them (at most twice its control points), each patch
    that gave points with the rest (left out under 16), and the hand-over is kept where every fit holds.
    `fit(indices, sides)` as for `merge_neighbours`."""
    notes, tried = [], set()
    while True:
        for wrap in _untried_wraps(patches, tried):
            if patches[wrap[0]].base.kind != "swept":
                continue
            mine = np.concatenate([patches[r].indices for r in wrap])
            others = [r for r in range(len(patches)) if r not in wrap and patches[r].base.wrap is None]
            theirs = np.concatenate([patches[r].indices for r in others] + [np.zeros(0, int)])
            on = on_profile(np.r_[mine, theirs], _labels([mine, theirs]))[len(mine):] if len(theirs) else theirs
            if not np.any(on):
                continue
            near = np.min([patches[r].shape.distance(points[theirs[on]]) for r in wrap], axis=0)
            take = theirs[np.flatnonzero(on)[near <= tol / 2]]
            donors = [r for r in others if np.isin(patches[r].indices, take).any()]
            faces = fit(np.r_[mine, take], _labels([mine, take])) if len(take) >= 4 else []
            most = _WRAP_GROWTH * sum(patches[r].shape.fit.n_ctrl for r in wrap)
            if not faces or not all(f.shape.fit.stats.holds for f in faces) or \
                    sum(f.shape.fit.n_ctrl for f in faces) > most:
                continue
            rest = [np.setdiff1d(patches[r].indices, take) for r in donors]
            refits = [fit(left, None) if len(left) >= 16 else [] for left in rest]
            if any(len(left) >= 16 and not (got and all(f.shape.fit.stats.holds for f in got))
                   for left, got in zip(rest, refits)):
                continue
            notes.append(f"a swept wrap took {len(take)} points of {len(donors)} patches that its surface runs "
                         f"through on its profile ({sum(len(left) < 16 for left in rest)} of them left out)")
            tried.add(_key(faces))      # claimed once
            patches = [p for r, p in enumerate(patches) if r not in set(wrap) | set(donors)] + faces + \
                [f for got in refits for f in got]
            break
        else:
            return patches, notes


def _key(faces: list) -> bytes:
    """What a closed wrap's faces (PatchFits) hold, as one key: the same points, the same wrap."""
    return b"".join(f.indices.tobytes() for f in faces)


def _untried_wraps(patches: list, tried: set):
    """The closed wraps among `patches` (their faces' indices) not in `tried` (keys, `_key`), each added
    to it as it is given: a wrap that took or claimed nothing is not offered the same again."""
    for wrap in sorted({_unit(patches, i) for i in range(len(patches))}):
        key = _key([patches[r] for r in wrap])
        if len(wrap) > 1 and key not in tried:
            tried.add(key)
            yield wrap


def _labels(sides: list[np.ndarray]) -> np.ndarray:
    """(sum of lengths,) the index of the side each of the concatenated `sides`' points comes from."""
    return np.repeat(np.arange(len(sides)), [len(side) for side in sides])
