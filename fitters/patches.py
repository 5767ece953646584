"""Scattered free-form data split into patches at its sharp edges, each fitted as a trimmed NURBS surface.

The paper: "B-splines are subdivided where discontinuities take place". For a range grid that is
`rgm.fitters.freeform_part.split_patches`; this module does it for scattered points (n, 3), such as the
merged views of a closed or wrapped part:

1. Creases (`rgm.fitters.creases`). Robust PCA normals (`rgm.fitters.normals.pca_normals`, Hoppe et al.
   1992); a point is a crease point when at least two of its k nearest neighbours have normals more than
   `angle_deg` away from its own (unoriented normals: |n_i . n_j| is compared). Crease points are set aside, the rest
   joined by a k-nearest graph (8 neighbours within a few point spacings, normals agreeing) into components
   (`scipy.sparse.csgraph.connected_components`); small components are dropped and each crease point then
   joins the patch on whose local tangent plane it lies, so neighbouring patches meet at the crease
   itself and no point of one face is pulled into its neighbour. A group whose fits (3.) hold their
   statistic yet miss some points by `_MISSED_EDGE` tolerances has an edge rounded too softly for
   `angle_deg` (the YCB cracker box's four long faces, 13.5 mm off at the edges): it is split again at
   `_SOFT_CREASE` degrees, kept if every piece holds and the worst miss shrinks.
2. Parameterisation by projection onto a base surface (`rgm.fitters.patch_base`): the best-fit plane when
   the patch is disc-like (every normal within `max_angle` of the plane normal: the projection is then
   one-to-one), otherwise a
   cylinder whose axis is the direction most nearly perpendicular to all normals (the smallest
   eigenvector of sum n n^T) through the least-squares meeting point of the normal lines; u is the angle
   about the axis cut at the largest angular gap, v the height. A patch that wraps fully round (no gap)
   is one surface closed round the axis, cut into two faces along two of its iso-lines, so their seams
   are the same curve on both (`rgm.fitters.wrap`; refitted together, `_refit_wrap`); a patch that fits
   neither base (a crease too soft to be found, such as a rounded bottom edge) is split into its mantle
   and its ends (normals across or along the cylinder axis), or failing that across its longest extent.
   Both parameters are scaled to [0, 1]², then into [m, 1 - m] (`reach_past`) so that the surface
   reaches 5 point spacings past its data on every side.
3. Each patch is fitted by `fit_freeform` with those parameters (least squares, knot insertion to the
   tolerance, trimming loops from the occupied cells of (u, v)). A piece whose fit stops at a limit
   (approximation or control net) with the tolerance unmet (its projection folds, or it spans faces a
   crease too soft to find divides) is split in two across its longest extent, each half parameterised
   again, to `_RESPLIT` splits; the halves are kept if every one holds (`_fit_piece`). YCB meat can,
   views with seeds 2-4: every patch now holds (before, pieces of the lid's corner did not), and 29-33
   seams of 40-53 are within 1 mm (20-24 of 34-44 before). Neighbouring patches that one surface serves
   (it holds on each side's points, with no more control points than both, twice as many for a closed
   wrap) are then merged (`rgm.fitters.patch_merge`): a seam between surfaces that part cannot be closed
   by any trim. A closed wrap takes such a neighbour too (the can's mantle, slivers of its rolled rim),
   and a rim its profile rolls over into, parameterised along that profile (`rgm.fitters.patch_sweep`),
   all the rim's pieces at once; a swept wrap then claims the points of other patches its surface runs
   through on its profile (`rgm.fitters.patch_merge.claim_rims`).
4. Neighbouring patches share their boundary curve (`rgm.fitters.shared_edges`): the piece of each face's
   trimming loop along the crease with a neighbour becomes the same described intersection,
   `intersect(surface_i, surface_j)`, one binding used by both loops, joined to the rest of each loop
   (from its data, re-fitted from join to join) at two points on both surfaces. The least-squares surfaces
   reach past their data (2.), so near a crease they usually cross. G0 then holds by construction to
   the intersection's approximation; it is measured, not assumed: along the shared edge as the back ends
   take it. Where nothing is shared (surfaces meeting nearly tangentially; surfaces that do not reach
   past the crease; seams of a few samples; a rebuilt loop that would not be valid) the faces keep their
   own trims and the gap is measured (`g0_gaps`): samples of one patch's trimming loop as written
   (`as_written`: a face with shared edges has its data loop re-fitted between their joins) whose nearest
   other data belong to the other patch, measured to the nearest other *face* as written (trimmed: its
   surface reaches past its data, and a trim that stops short leaves a hole however near the surfaces
   pass), every sample about 0.1 mm apart (as a check of the written `.rgm` finds them), reported with
   the reason. Where three patches share an edge pairwise, the three edges run to the point all three
   surfaces share (`rgm.fitters.shared_edges`, corner joins), so the faces meet at the corner.
   Seams still over the tolerance get a common boundary curve by constrained refit (`_share_and_refit`):
   the patches of those seams are fitted again with anchors (`seam_anchors`, `rgm.fitters.freeform.Anchors`)
   along every seam of theirs not shared (both faces' loop samples near the other face, their closest
   points on the other surface and the midpoints), at half the tolerance where that holds, each patch
   still meeting its own certificate; a patch with a shared edge is held to it. The set is shared and
   measured again, and kept by groups, by patch and as a whole only where it brings more seams within the
   tolerance, for up to `_ROUNDS` rounds. Last, seams whose surfaces do not cross along them may share
   one curve midway between the two surfaces (`rgm.fitters.seam_curves`), and so may a shared seam left
   open beyond its intersection's ends (where the intersection follows only part of it: the YCB meat
   can's mantle meets its bottom along a fillet), a closed wrap's two faces are
   refitted as one surface, and each shared intersection is checked as the file reads back (`_unclosed`:
   where surfaces nearly touch, marching at the tolerance is sensitive to the last printed digit) and
   unshared where it does not close. Every surface is held, where it reaches past its data, to bend no
   more than over them (`rgm.fitters.freeform.Extension`), so neighbours that must cross do not run off.
   Seams still over the tolerance that share nothing, where the surfaces pass within it, are closed by
   growing one face's trim to the other's edge (`rgm.fitters.seam_cover`): first on the plain faces, the
   set then shared again and kept if it scores better; last on the faces as shared (a face with shared
   edges grows the data stretches between them, `grown_outline`), kept if every sample scores better.
   Each choice above scores a set of seams (`_score`) at each seam's worst as written: along a shared
   edge and beyond its ends, where the faces' data pieces run on (`Gap.rest`); a shared seam open there
   is grown like one that shares nothing. A face of a closed wrap grows too, its loop held along the
   seams it shares with the wrap's other face, and the seams are measured along holes as well as outer
   loops. YCB views at 1.5 mm (the tests' six views), seams within 1 mm as the file reads back
   (`rgm.fitters.seam_check`, as `rgmc verify` measures them): mustard bottle, noise seeds 1 and 4:
   13/13, 9/12 (worst 0.70, 1.10 mm); cracker box, seed 1: 12/12 (0.45 mm); potted meat can, seeds
   1-4: 16/35, 45/63, 60/72, 40/52 (worst 2.7-4.0 mm); 227 of 319 seams over these and three 1 mm view
   sets of the can (227 of 328 before the wraps grew, 169 of 322 when the score took a shared seam along
   its edge alone: the counts reported until 2026-12-07 did too, and read every seam of the bottle and
   the box within).
   What stays over: seams "too short on one side to share" at three-patch corners, near-tangent surfaces
   that part by more than the tolerance before they reach the other face, slivers, the meat can's rolled
   rim. The figures move with the machine (floating-point differences steer the discrete choices). Their
   history, and what was tried, is in docs/fitting.md and the commit log.
5. `rgmc fit` writes the patches (`rgm.fitters.freeform_build`, `rgm.fitters.pipeline`), each with its
   certificate measured on the printed trimmed surface.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from rgm.errors import GeometryError
from rgm.fitters.creases import checked_points, median_spacing, split_scattered, unit_rows
from rgm.fitters.freeform import Anchors, design_matrix
from rgm.fitters.freeform_measure import TrimmedNurbs
from rgm.fitters.freeform_part import FreeformShape, fit_freeform, retrimmed, trim_parameters
from rgm.fitters.normals import pca_normals
from rgm.fitters.patch_base import Base, Wrap, base_parameters, reach_past
from rgm.fitters.patch_merge import claim_rims, merge_neighbours, take_rims
from rgm.fitters.patch_sweep import on_profile, rims, swept_parameters
from rgm.fitters.trimloops import check_loops

__all__ = ["PatchFit", "Gap", "PatchSet", "fit_patches", "seam_anchors", "boundary_samples", "as_written",
           "g0_gaps"]

_ANCHOR_WEIGHT = 10.0   # weight of a seam anchor relative to a data point's (`seam_anchors`)
_GROWTH = 4             # a refitted net has at most this many times the control points (`fit_patches`)
_FIRST = 0.5            # the first refit is at this share of the tolerance (`fit_patches`)
_CLOSED = ("the two faces of one surface closed round its axis: their seams are iso-parameter lines of both "
           "(`rgm.fitters.wrap`), G0 by construction")
_WITHIN = ("refitted through a common boundary curve with its neighbour: the separate trims are measured (surfaces "
           "pulled together along a band are not intersected)")
_ANCHOR_TOL = 0.25      # anchors are met within this share of the seam tolerance (`seam_anchors`)
_ROUNDS = 3              # anchored refit rounds at most (`_share_and_refit`)
_RESPLIT = 2             # a piece no surface fits is split in halves at most this deep (`_fit_piece`)
_DENSE = 8               # a fit with a control point per fewer data points than this tries halves too (`_fit_piece`)
_MISSED_EDGE = 10        # a group whose fits miss a point by this many tolerances is split again (`fit_patches`)
_SOFT_CREASE = 20.0      # at this crease angle (degrees)


# ---------------------------------------------------------------------------------------- fitting
@dataclass
class PatchFit:
    """One patch: the indices of its points in the input, its base surface, the trimmed fit, seconds, and
    the parameters it was fitted over."""

    indices: np.ndarray
    base: Base
    shape: FreeformShape
    seconds: float
    params: tuple = ()     # the (u, v) it was fitted over (`reach_past`), (n,) each


@dataclass
class Gap:
    """The measured G0 gap between patches i and j (model units): max and 95th percentile of `samples`
    distances. `shared`: the faces share their boundary there, one `intersect(surface_i, surface_j)` in
    both loops (`rgm.fitters.shared_edges`), and the figures are measured along it as the back ends see it
    (`length` mm long; `before`: the max with separate trims; `rest`: the largest gap of the loops' data
    pieces near the other patch beyond the edge's ends, face to face, as `g0_gaps` measures: at a corner
    the edge does not reach, or where the seam ends at a free border); `curve`: the shared edge is one 3-D
    curve midway between the surfaces (`rgm.fitters.seam_curves`) instead. Otherwise the distances of
    boundary samples of each patch (near the other) to the nearest other face as written (`g0_gaps`), and
    `why` says why nothing is shared."""

    i: int
    j: int
    max: float
    p95: float
    samples: int
    shared: bool = False
    length: float = 0.0
    before: float | None = None
    why: str = ""
    curve: bool = False
    rest: float = 0.0

    @property
    def worst(self) -> float:
        """The seam's largest gap as written: along a shared edge and beyond its ends (`rest`)."""
        return max(self.max, self.rest)


@dataclass
class PatchSet:
    """The fitted patches (largest first), the measured gaps between neighbours, and the points that
    belong to no patch (creases without a neighbouring patch, specks, slivers that could not be fitted,
    each said in `skipped`, as is what was done to keep a patch's trimming loops valid:
    `rgm.fitters.trimloops.TrimLoops.notes`)."""

    patches: list[PatchFit]
    gaps: list[Gap] = field(default_factory=list)
    unassigned: int = 0
    skipped: list[str] = field(default_factory=list)

    @property
    def shapes(self) -> list[FreeformShape]:
        return [p.shape for p in self.patches]

    def __len__(self):
        return len(self.patches)


def fit_patches(points, tol: float, *, statistic: str = "p95", normals=None, angle_deg: float = 35.0,
                k: int = 16, max_ctrl: int = 4000, share: bool = True) -> PatchSet:
    """Split scattered points (n, 3) at their creases and fit each patch with a trimmed NURBS surface
    whose `statistic` of the residuals is within `tol` (model units); with `share`, neighbouring patches
    share their boundary (the intersection of their surfaces) where they can; measure the G0 gaps.

    Each surface reaches 5 point spacings past its data (`reach_past`), so that neighbours cross at their
    crease. With `share`, the patches of the seams still over `tol` are fitted again (at tol / 2 where
    that holds) through the common boundary curves of their seams (`seam_anchors`), shared and measured
    again; the refit is kept where it brings more seams within `tol` (module docstring, 4.)."""
    points = checked_points(points)
    tree = cKDTree(points)
    spacing = median_spacing(tree)
    if normals is None:
        normals = pca_normals(points, k, tree=tree)[0]
    normals = unit_rows(np.asarray(normals, float))
    groups = split_scattered(points, normals, angle_deg=angle_deg, k=k)
    patches, skipped = [], []

    def fitted(groups):   # (fits, notes) of groups of points, each parameterised and fitted (3.)
        fits, notes = [], []
        for group in groups:
            # normals from the patch's own points: the crease band's normals no longer mix both sides
            own = pca_normals(points[group], k)[0]
            for sub, u, v, base in base_parameters(points[group], own, spacing=spacing):
                fits += _fit_piece(points, group[sub], base, (u, v), tol, statistic, max_ctrl, k, spacing, notes)
        return fits, notes

    for group in groups:
        fits, notes = fitted([group])
        worst = max((f.shape.fit.stats.max for f in fits), default=0.0)
        if worst > _MISSED_EDGE * tol and angle_deg > _SOFT_CREASE:
            # a fit that holds its statistic yet misses points by _MISSED_EDGE tolerances has rounded off an
            # edge too soft for the crease angle: the group split again at _SOFT_CREASE, kept if every piece
            # holds and the worst miss shrinks (the notes are those of the fits kept)
            finer = split_scattered(points[group], normals[group], angle_deg=_SOFT_CREASE, k=k)
            again, said = fitted([group[sub] for sub in finer]) if len(finer) > 1 else ([], [])
            if again and all(f.shape.fit.stats.holds for f in again) and \
                    max(f.shape.fit.stats.max for f in again) < worst:
                notes = said + [f"{len(group)} points fitted {worst:.3g} mm off at worst as {len(fits)} patch(es) "
                                f"(an edge softer than {angle_deg:g} degrees): split at {_SOFT_CREASE:g} degrees "
                                f"into {len(again)}, {max(f.shape.fit.stats.max for f in again):.3g} mm off at worst"]
                fits = again
        patches += fits
        skipped += notes
    patches.sort(key=lambda p: -len(p.indices))

    def fit_union(idx, sides=None):
        return fit_one_piece(points, idx, tol, statistic, max_ctrl, k, spacing, sides)

    patches, taken = take_rims(points, patches, fit_union,
                               lambda idx, sides: rims(points[idx], pca_normals(points[idx], k)[0], spacing, sides),
                               spacing, tol, statistic)
    patches, claimed = claim_rims(points, patches, fit_union, lambda idx, sides: on_profile(
        points[idx], pca_normals(points[idx], k)[0], spacing, sides), tol)
    patches, merged = merge_neighbours(points, patches, fit_union, spacing, tol, statistic)
    skipped += taken + claimed + merged
    assigned = sum(len(p.indices) for p in patches)
    gaps = g0_gaps(points, patches, 5 * spacing)
    if share:
        patches, gaps = _share_and_refit(points, patches, gaps, tol, statistic, max_ctrl, spacing)
        patches, gaps = _covered(points, patches, gaps, tol, statistic, 5 * spacing)
    for r, p in enumerate(patches, 1):   # what was done to keep a trim valid (pinches, narrow necks)
        skipped += [f"patch {r} trim: {note}" for note in p.shape.loops.notes]
    return PatchSet(patches, gaps, len(points) - assigned, skipped)


def fit_one_piece(points, indices, tol: float, statistic: str, max_ctrl: int, k: int, spacing: float,
                  sides=None) -> list:
    """The PatchFits of points[indices] parameterised as one piece over its own base (`base_parameters`,
    the surface reaching 5 spacings past the data; where that splits them, a wrap swept along its profile,
    `swept_parameters`): one, or a full wrap's two faces (`_fit_wrap`, one closed surface); [] when no
    single base serves them all (a piece left out or split, and no sweep), a full wrap's closed surface
    misses `tol`, or no fit results: how two neighbours' union is tried as one patch
    (`rgm.fitters.patch_merge`), `sides` (len(indices),) labelling each neighbour's points, on each of
    which the statistic must hold on its own (`rgm.fitters.freeform_surface.fit_surface`)."""
    own = pca_normals(points[indices], k)[0]
    pieces = base_parameters(points[indices], own, spacing=spacing)
    if len(pieces) == 1 and len(pieces[0][0]) == len(indices):
        _, u, v, base = pieces[0]
    elif (swept := swept_parameters(points[indices], own, spacing, sides)) is not None:
        u, v, base = swept
    else:
        return []
    if base.closed:
        return _fit_wrap(points, indices, base, (u, v), tol, statistic, max_ctrl, k, spacing, [], 0, halves=False,
                         sides=sides)
    try:
        return [_fit_patch(points, indices, base, reach_past(points[indices], u, v, 5 * spacing), tol, statistic,
                           max_ctrl, sides=sides)]
    except GeometryError:
        return []


def _fit_piece(points, indices, base, uv, tol, statistic, max_ctrl, k, spacing, skipped, depth=_RESPLIT) -> list:
    """The PatchFits of one piece of a patch (`fit_patches`), parameterised by `uv` (u, v) over `base`:
    one, or, where no surface over those parameters meets `tol` within the limits of `fit_freeform` (the
    projection folds, or the piece spans faces that a crease too soft to find divides) or meets it only
    with a control point per fewer than `_DENSE` data points (the projection is steep), the fits of its
    two halves across its longest extent, each parameterised again, to `depth` splits, kept only if
    every one of them holds (and, for a fit that held, with fewer control points in all). Pieces under
    16 points are left out, fits that fail said in `skipped`."""
    if len(indices) < 16:
        return []
    if base.closed:
        return _fit_wrap(points, indices, base, uv, tol, statistic, max_ctrl, k, spacing, skipped, depth)
    params = reach_past(points[indices], *uv, 5 * spacing)
    try:
        fit = _fit_patch(points, indices, base, params, tol, statistic, max_ctrl)
    except GeometryError as exc:     # a sliver no surface or trim can be fitted to: said, not hidden
        skipped.append(f"{len(indices)} points not fitted: {exc}")
        return []
    whole = fit.shape.fit
    dense = whole.n_ctrl * _DENSE > len(indices)
    if (whole.stats.holds and not dense) or depth == 0 or len(indices) < 64:
        return [fit]
    x = points[indices] - points[indices].mean(axis=0)
    along = x @ np.linalg.svd(x, full_matrices=False)[2][0]
    halves, notes = [], []
    for half in (indices[along < np.median(along)], indices[along >= np.median(along)]):
        own = pca_normals(points[half], k)[0]
        for sub, u, v, b in base_parameters(points[half], own, spacing=spacing, depth=1):
            halves += _fit_piece(points, half[sub], b, (u, v), tol, statistic, max_ctrl, k, spacing, notes, depth - 1)
    if halves and all(h.shape.fit.stats.holds for h in halves) and \
            (not whole.stats.holds or sum(h.shape.fit.n_ctrl for h in halves) < whole.n_ctrl):
        why = (f"met the tolerance only with {whole.n_ctrl} control points" if whole.stats.holds else
               f"met the tolerance ({whole.stopped})")
        skipped += notes + [f"{len(indices)} points split in {len(halves)} patches: no surface over one "
                            f"parameterisation {why}"]
        return halves
    return [fit]


def _fit_wrap(points, indices, base, uv, tol, statistic, max_ctrl, k, spacing, skipped, depth,
              anchors=None, halves: bool = True, sides=None) -> list:
    """The two faces of a full wrap (`rgm.fitters.wrap.fit_wrap`: one closed surface, two faces sharing
    its seams exactly), their Base naming their `Wrap`; where a face misses `tol`, the two halves apart,
    each parameterised over its own angle (`_fit_piece`), as said in `skipped`. `anchors` (in the wrap's
    parameters): points the closed surface is pulled through (`_refit_round`); then, or without `halves`,
    no fallback ([]). `sides` (len(indices),): labels of points on each of which `tol` holds on its own."""
    from rgm.fitters.wrap import fit_wrap, seam_margin

    reach = 5 * spacing
    try:
        faces = fit_wrap(points[indices], *uv, tol, statistic=statistic, max_ctrl=max_ctrl, reach=reach,
                         anchors=anchors, sides=sides)
    except GeometryError as exc:
        if anchors is not None or not halves:
            return []
        skipped.append(f"a full wrap of {len(indices)} points fitted as two halves apart: {exc}")
    else:
        base = replace(base, wrap=Wrap(indices, *uv, seam_margin(points[indices], *uv, reach)))
        return [PatchFit(indices[own], base, shape, seconds, params) for own, shape, seconds, params in faces]
    out, normals = [], pca_normals(points[indices], k)[0]
    for half in (uv[0] < 0.5, uv[0] >= 0.5):
        for sub, u, v, b in base_parameters(points[indices[half]], normals[half], spacing=spacing, depth=2):
            out += _fit_piece(points, indices[half][sub], b, (u, v), tol, statistic, max_ctrl, k, spacing,
                              skipped, depth)
    return out


def _refit_wrap(points, plain, r, anchors, tol, statistic, max_ctrl, sizes, spacing) -> list:
    """The two faces of patch r's closed wrap fitted again through both faces' `anchors` ({patch: Anchors}
    in its parameters, moved to the wrap's), at tol / 2 where both faces hold, else at `tol`, the closed
    net to at most _GROWTH times the faces' first `sizes`: [(patch, PatchFit)], or [] when neither holds."""
    wrap = plain[r].base.wrap
    pair = [t for t, q in enumerate(plain) if q.base.wrap is wrap]
    own = [anchors[t] for t in pair if t in anchors]
    if not own:
        return []
    cap = min(max_ctrl, max(_GROWTH * sum(sizes[t] for t in pair), 100))
    uv = np.vstack([np.c_[wrap.closed_u(a.uv[:, 0], wrap.start(plain[t].indices)), a.uv[:, 1]]
                    for t, a in zip(pair, own)])
    joint = Anchors(uv, np.vstack([a.xyz for a in own]), own[0].weight, own[0].tol)
    for at in (_FIRST * tol, tol):
        faces = _fit_wrap(points, wrap.indices, plain[r].base, (wrap.u, wrap.v), at, statistic, cap, 0, spacing,
                          [], 0, joint)
        if faces and all(f.shape.fit.stats.holds for f in faces):
            # the new faces in the old order: the face from u = 0 first in both
            old = sorted(pair, key=lambda t: wrap.start(plain[t].indices))
            return list(zip(old, faces))
    return []


def _fit_patch(points, indices, base, params, tol, statistic, max_ctrl, anchors=None, sides=None) -> PatchFit:
    """A PatchFit of points[indices] over `params` (u, v) at `tol`: the trimmed surface, timed. `anchors`
    (`rgm.fitters.freeform.Anchors`): points the surface is pulled through; `sides`: labels of points on
    each of which `tol` holds on its own (`fit_freeform`)."""
    t0 = time.perf_counter()
    shape = fit_freeform(points[indices], tol, statistic=statistic, max_ctrl=max_ctrl, cuts=False, params=params,
                         anchors=anchors, sides=sides)
    return PatchFit(indices, base, shape, time.perf_counter() - t0, params)


def _covered(points, patches, gaps, tol, statistic, near, fresh=False):
    """The seams in `gaps` still over `tol` that share nothing, closed where the surfaces pass within it by
    growing one face's trim to the other's edge (`rgm.fitters.seam_cover`; a face with shared edges is
    grown by `rgm.fitters.seam_cover.grown_outline`). With `fresh`, a grown face gets a copy of its fit, so
    that the shared-edge candidates cached for the old loop are not reused for the new one
    (`_share_and_refit`); otherwise `gaps` are measured as `_share_and_refit` reports them, and so are the
    grown faces', kept only where they score better."""
    from rgm.fitters.seam_cover import cover_seams, grown_outline

    def retrim(patch, feet):
        if patch.shape.outline is not None:   # shared edges in its loop: the data stretches between grown
            data = trim_parameters(patch.shape, patch.params, len(patch.indices))
            shape = grown_outline(patch.shape, feet, data, tol)
            return None if shape is None else PatchFit(patch.indices, patch.base, shape, patch.seconds, patch.params)
        try:   # a closed wrap's face keeps its loop along the seams (with its twin's data past them)
            shape = retrimmed(patch.shape, points[patch.indices], patch.params, tol, statistic, feet,
                              past=None if patch.base.wrap is None else _past_seams(patch))
        except GeometryError:
            return None
        if check_loops(shape.loops.outer, shape.loops.holes):
            return None
        if fresh:
            shape = replace(shape, fit=replace(shape.fit))
        return PatchFit(patch.indices, patch.base, shape, patch.seconds, patch.params)

    before = gaps
    grown, gaps = cover_seams(points, patches, gaps, tol, near, retrim,
                              lambda trial: as_written(points, trial, before, near), lambda gs: _score(gs, tol))
    if gaps is before or fresh:
        return grown, gaps
    # the choices above take 150 samples a seam; kept only if every sample (as reported) scores better
    final = as_written(points, grown, gaps, near, per_seam=None, step=near / 40)
    return (grown, final) if _score(final, tol) > _score(before, tol) else (patches, before)


def _past_seams(patch: PatchFit) -> np.ndarray:
    """(k, 2) the parameters, in the face `patch` of a closed wrap, of its twin's data past its seams
    (within the margin it reaches past them), as `rgm.fitters.wrap.fit_wrap` trims the face."""
    wrap = patch.base.wrap
    own = np.flatnonzero(np.isin(wrap.indices, patch.indices))
    s = np.mod(wrap.u - wrap.start(patch.indices) + wrap.delta, 1.0) / (0.5 + 2 * wrap.delta)
    slope, offset = np.polyfit(wrap.v[own], patch.params[1], 1)   # the face's v: the wrap's past its margin
    past = np.setdiff1d(np.flatnonzero(s <= 1.0), own)
    return np.c_[s[past], offset + slope * wrap.v[past]]


def _score(gaps, tol):
    """How good a set of seams is: (seams within `tol`, minus the summed excess over it), each seam taken
    at its worst as written (beyond a shared edge's ends too)."""
    return sum(g.worst <= tol for g in gaps), -sum(max(g.worst - tol, 0.0) for g in gaps)


def _share_and_refit(points, patches, gaps, tol, statistic, max_ctrl, spacing):
    """Share the boundaries (`rgm.fitters.shared_edges.share_boundaries`); then refit the patches of the
    seams still over `tol` with their common boundary curves as anchors (`seam_anchors`), at tol / 2
    where that holds (each surface then nearer the crease's data that both approximate, so nearer each
    other, or crossing where they did not), else at `tol`. The refitted set is shared and measured
    again; each group of patches linked by seams over `tol` keeps its refit only if the seams it
    touches score better (`_score`), then each refitted patch whose own seams score worse goes back to its
    plain fit (kept if the set then scores better), and the whole set is kept when it scores better;
    rounds go on from the set kept while one scores better, at most _ROUNDS (`_refit_round`). Last,
    the seams still over `tol` may share one curve midway between their surfaces (`with_curves`, kept if
    it scores better). Returns (patches with their shared loops, gaps)."""
    from rgm.fitters.shared_edges import share_boundaries

    near = 5 * spacing
    cache = {}

    def share(fits, before):
        # intersected again: the seams shared before and those still over the tolerance; a seam the refit
        # brought within it keeps its separate trims, measured (intersections are most of the cost, and
        # surfaces pulled together along a band meet ill-conditioned)
        copy = [PatchFit(q.indices, q.base, q.shape, q.seconds, q.params) for q in fits]
        was = {(g.i, g.j) for g in before if g.shared}
        measured = g0_gaps(points, fits, near)
        tried = [g for g in measured if (g.max > tol or (g.i, g.j) in was) and not _twins(fits, g.i, g.j)]
        done = {(g.i, g.j): g for g in share_boundaries(points, copy, tried, tol, near, spacing, cache)}
        out = [done.get((g.i, g.j)) or replace(g, why=g.why or _WITHIN) for g in measured]
        return as_written(points, copy, out, near), copy

    def with_curves(fits, result, gaps):
        # the seams still over the tolerance whose intersection cannot be shared, and the shared ones left
        # open beyond their edge's ends: one curve midway between the surfaces, in both loops, where one lies
        # within the tolerance of both; the other pairs shared before are shared again as they were (their
        # candidates cached), the rest kept as measured
        if not any(g.worst > tol for g in gaps):
            return result, gaps
        copy = [PatchFit(q.indices, q.base, q.shape, q.seconds, q.params) for q in fits]
        tried = [replace(g, max=g.before, shared=False) if g.shared else g for g in gaps
                 if (g.shared or g.max > tol) and not _twins(fits, g.i, g.j)]
        open_ends = {(g.i, g.j) for g in gaps if g.shared and not g.curve and g.rest > tol}
        done = {(g.i, g.j): g for g in share_boundaries(points, copy, tried, tol, near, spacing, cache, curves=True,
                                                         open_ends=open_ends)}
        out = as_written(points, copy, [done.get((g.i, g.j), g) for g in gaps], near)
        if _score(out, tol) > _score(gaps, tol):
            return copy, out
        # kept as they were, with the reasons no curve was shared either
        return result, [replace(g, why=done[(g.i, g.j)].why) if not g.shared and (g.i, g.j) in done
                        and not done[(g.i, g.j)].shared else g for g in gaps]

    plain = [PatchFit(q.indices, q.base, q.shape, q.seconds, q.params) for q in patches]
    # the faces of a closed wrap meet along iso-lines of one surface: nothing to intersect there
    closed = [g for g in gaps if _twins(patches, g.i, g.j)]
    old_gaps = share_boundaries(points, patches, [g for g in gaps if g not in closed], tol, near, spacing, cache)
    old_gaps = as_written(points, patches, sorted(old_gaps + closed, key=lambda g: (g.i, g.j)), near)
    sizes = [q.shape.fit.n_ctrl for q in plain]
    fits, result, gaps = plain, patches, old_gaps
    for _ in range(_ROUNDS):
        if not any(g.worst > tol for g in gaps):
            break
        better = _refit_round(points, fits, gaps, share, cache, sizes, tol, statistic, max_ctrl, near, spacing)
        if better is None and _wrap_pairs(fits):   # again with the closed wraps as fixed neighbours
            better = _refit_round(points, fits, gaps, share, cache, sizes, tol, statistic, max_ctrl, near, spacing,
                                  hold_wraps=True)
        if better is None:
            break
        fits, result, gaps = better
    result, gaps = with_curves(fits, result, gaps)
    # the seams still over the tolerance that share nothing: the plain faces' trims grown to each other
    # where the surfaces pass within it (`_covered`), and the set shared again; kept if it scores better
    over = {(g.i, g.j) for g in gaps if g.max > tol and not g.shared}
    if over:
        grown, _ = _covered(points, fits, [g for g in g0_gaps(points, fits, near) if (g.i, g.j) in over], tol,
                            statistic, near, fresh=True)
        if any(a is not b for a, b in zip(grown, fits)):
            grown_gaps, grown_result = share(grown, gaps)
            grown_result, grown_gaps = with_curves(grown, grown_result, grown_gaps)
            if _score(grown_gaps, tol) > _score(gaps, tol):
                fits, result, gaps = grown, grown_result, grown_gaps
    for _ in range(_ROUNDS):
        # as the file is read back: a shared intersection of the printed surfaces that does not run between
        # its joins is not shared (the pair's candidate for these fits becomes the reason), the set shared again
        unclosed = _unclosed(result, gaps, tol)
        if not unclosed:
            break
        for (i, j), why in unclosed.items():
            cache[(i, j)] = [(fits[i].shape.fit, fits[j].shape.fit, why)] + cache.get((i, j), [])
        gaps, result = share(fits, gaps)
        result, gaps = with_curves(fits, result, gaps)
    # the figures reported: every sample, a fortieth of `near` apart (about 0.1 mm at the YCB views'
    # spacing), as a check of the written file at that density finds them (the choices above take 150 a seam)
    return result, as_written(points, result, gaps, near, per_seam=None, step=near / 40)


def _unclosed(patches: list[PatchFit], gaps: list[Gap], tol: float) -> dict:
    """{(i, j): why} for the shared intersections whose faces' loops would not close as the file reads
    back: the intersection of the printed surfaces (`rgm.fitters.freeform_part.printed_surface`, numbers
    as written) approximated at `tol` (as `rgmc compile`'s closure check takes it) and at tol / _FINER (as
    the STEP back end does where OpenCASCADE's own branch misses the joins), each face's stretch of it
    between its neighbouring pieces' ends must reach both within `tol`. Where two surfaces nearly touch,
    marching at the tolerance is sensitive to the last printed digit (the YCB meat can: an open branch in
    memory, a closed loop from the file, and a loop left open by 29.6 mm), and marching finer may split
    a branch that the coarser march ran through (a crease whose finer stretch missed its joins by 10.3 mm,
    which the STEP back end refused)."""
    from rgm.fitters.freeform_part import printed_surface
    from rgm.fitters.shared_edges import _FINER
    from rgm.model import IntersectionCurve

    surfaces, out = {}, {}
    for g in gaps:
        if not g.shared or g.curve:
            continue
        for k in (g.i, g.j):
            if k not in surfaces:
                surfaces[k] = printed_surface(patches[k].shape)
        for at in (tol, tol / _FINER):
            crease = IntersectionCurve(surfaces[g.i], surfaces[g.j], at)
            miss = max(_join_miss(patches[k].shape, surfaces[k], crease, other) for k, other in ((g.i, g.j), (g.j, g.i)))
            if miss > tol:
                out[(g.i, g.j)] = (f"on the printed surfaces their intersection, approximated at {at:g} mm, misses "
                                   f"a join by {miss:.2f} mm (the surfaces nearly touch: marching is sensitive to "
                                   f"the last digit written)")
                break
    return out


def _join_miss(shape, surface, crease, other: int) -> float:
    """How far (model units) a face's stretch of its shared intersection `crease` with patch `other` ends
    from the joins it runs between (`rgm.fitters.shared_edges.face_stretch`), on its printed `surface`."""
    from rgm.fitters.shared_edges import face_stretch

    uv, ends = face_stretch(shape, surface, crease, other)
    s = surface.nurbs()
    return float(np.max(np.linalg.norm(s.evaluate(uv[[0, -1], 0], uv[[0, -1], 1]) - s.evaluate(ends[:, 0], ends[:, 1]),
                                       axis=1)))


def _refit_round(points, plain, old_gaps, share, cache, sizes, tol, statistic, max_ctrl, near, spacing,
                 hold_wraps: bool = False):
    """One anchored refit of the patches of the seams over `tol` (`_share_and_refit`): `plain` the fits
    (their own data loops), `old_gaps` their shared gaps, `share(fits, before)` shares and measures a set;
    nets grow to at most _GROWTH times `sizes` (the first fits'). The two faces of a closed wrap are
    refitted together (`_refit_wrap`), or with `hold_wraps` kept as fixed neighbours. Returns (fits,
    shared patches, gaps) when the refit scores better, else None."""
    over = [(g.i, g.j) for g in old_gaps if g.max > tol]
    loose = {r for pair in over for r in pair}
    if hold_wraps:   # the closed wraps' faces stay as they are, fixed neighbours of the rest
        loose = sorted(r for r in loose if plain[r].base.wrap is None)
    else:
        loose = sorted(_with_twins(plain, loose))
    # a shared edge is kept where it is: the refitted surface is held to it too (unheld, pulled along a band
    # at its other seams, its re-intersected edge came out where OpenCASCADE's exact intersection would not
    # close its face)
    edges = {(g.i, g.j): _shared_stretch(cache, (g.i, g.j), (plain[g.i].shape.fit, plain[g.j].shape.fit), spacing)
             for g in old_gaps if g.shared}
    anchors = seam_anchors(points, plain, old_gaps, loose, near, spacing, _ANCHOR_TOL * tol,
                           edges={pair: e for pair, e in edges.items() if e is not None})
    again, wraps = list(plain), set()
    for r in loose:
        q = plain[r]
        if q.base.wrap is not None:   # both faces at once, on the first one's turn
            if id(q.base.wrap) not in wraps:
                wraps.add(id(q.base.wrap))
                for t, fit in _refit_wrap(points, plain, r, anchors, tol, statistic, max_ctrl, sizes, spacing):
                    again[t] = fit
            continue
        # the net may grow to meet the anchors, to _GROWTH times its first size (no net as dense as the
        # data, wiggling between anchors it cannot all meet)
        cap = min(max_ctrl, max(_GROWTH * sizes[r], 100))
        for at in (_FIRST * tol, tol):   # tighter first, the tolerance if not
            try:
                fit = _fit_patch(points, q.indices, q.base, q.params, at, statistic, cap, anchors.get(r))
            except GeometryError:
                continue
            if fit.shape.fit.stats.holds:
                again[r] = fit
                break
    if all(a is b for a, b in zip(again, plain)):
        return None
    new_gaps, shared = share(again, old_gaps)
    # each group of patches linked by seams over the tolerance keeps its refit if its seams do better
    pairs = np.array(over).T
    group = connected_components(coo_matrix((np.ones(len(over)), pairs), shape=(len(plain),) * 2),
                                 directed=False)[1]
    keep = list(again)
    for c in np.unique(group[loose]):
        mine = set(np.nonzero(group == c)[0])
        # the refit may add or lose a seam: each set is scored on its own seams of the group
        if _score(_touching(new_gaps, mine), tol) <= _score(_touching(old_gaps, mine), tol):
            for r in mine:
                keep[r] = plain[r]
    # a wrap's two faces are one surface: both keep their refit or neither, as the seams of both their
    # groups say
    for a, b in _wrap_pairs(plain):
        if (keep[a] is plain[a]) != (keep[b] is plain[b]):
            mine = set(np.nonzero((group == group[a]) | (group == group[b]))[0])
            ok = _score(_touching(new_gaps, mine), tol) > _score(_touching(old_gaps, mine), tol)
            keep[a], keep[b] = (again[a], again[b]) if ok else (plain[a], plain[b])
    if any(a is not b for a, b in zip(keep, again)):
        if all(a is b for a, b in zip(keep, plain)):
            return None
        new_gaps, shared = share(keep, old_gaps)
    # within the set, a refitted patch whose own seams do worse than before goes back to its plain fit (a
    # group spans most patches of a part: its verdict is coarse)
    worse = _with_twins(plain, {r for r in loose if keep[r] is not plain[r]
                                and _score(_touching(new_gaps, {r}), tol) < _score(_touching(old_gaps, {r}), tol)})
    if worse and len(worse) < sum(a is not b for a, b in zip(keep, plain)):
        finer = [plain[r] if r in worse else q for r, q in enumerate(keep)]
        finer_gaps, finer_shared = share(finer, old_gaps)
        if _score(finer_gaps, tol) > _score(new_gaps, tol):
            keep, new_gaps, shared = finer, finer_gaps, finer_shared
    if _score(new_gaps, tol) <= _score(old_gaps, tol):
        return None
    return keep, shared, new_gaps


def _touching(gaps, patches: set) -> list:
    """The gaps of seams with a patch in `patches`."""
    return [g for g in gaps if g.i in patches or g.j in patches]


def _shared_stretch(cache, pair, fits, spacing: float):
    """The shared edge of `pair` (i, j) that `rgm.fitters.shared_edges.share_boundaries` found for `fits`
    (its two faces' fits), from its cache: ({face: (k, 2) its parameters}, (k, 3) points), samples of the
    intersection branch's stretch about half a point spacing apart; None when that pair of fits has none."""
    c = next((c for a, b, c in cache.get(pair, []) if a is fits[0] and b is fits[1]), None)
    if c is None or isinstance(c, str):
        return None
    xyz = c.xyz[c.lo:c.hi + 1]
    length = float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())
    k = np.unique(np.linspace(0, len(xyz) - 1, int(np.clip(2 * length / spacing, 16, len(xyz)))).astype(int))
    return {f: c.uv[f][c.lo:c.hi + 1][k] for f in pair}, xyz[k]


def seam_anchors(points, patches: list[PatchFit], gaps: list[Gap], refit, near: float, spacing: float,
                 anchor_tol: float | None = None, weight: float | None = None, edges=None) -> dict:
    """`Anchors` per patch in `refit` (met within `anchor_tol`): a common boundary curve for each of
    its seams. A shared seam's curve is its shared edge, from `edges` ({(i, j): ({face: (k, 2)
    parameters}, (k, 3) points)}, `_shared_stretch`): the refitted surface is held to its current
    intersection with the neighbour, so that the edge stays near where it was. Along the others, the samples
    of each face's trimming loop (about half a point spacing apart, `rgm.fitters.shared_edges`) on the
    seam with the neighbour (nearest other point within `near`) and their closest points on the
    neighbour's surface; the target is their midpoint when both patches are refitted, the fixed
    neighbour's surface when only one is. Each refitted surface takes the targets at its own parameters:
    the sample's, or its closest point's. `patches` have their own (data) loops, not shared ones."""
    from rgm.fitters.shared_edges import _loop_samples, _owners
    from rgm.geometry.inversion import closest_point_surface

    weight = _ANCHOR_WEIGHT if weight is None else weight
    edges = edges or {}
    label = np.full(len(points), -1)
    for r, p in enumerate(patches):
        label[p.indices] = r
    refit = set(int(r) for r in refit)
    loose = [(g.i, g.j) for g in gaps]
    shared = {(g.i, g.j) for g in gaps if g.shared}
    out: dict[int, tuple[list, list]] = {r: ([], []) for r in refit}
    for a, p in enumerate(patches):
        partners = {j if i == a else i for i, j in loose if a in (i, j)}
        if a not in refit:
            partners &= refit
        if not partners:
            continue
        uv = _loop_samples(p.shape, spacing)
        xyz = p.shape.nurbs().evaluate(uv[:, 0], uv[:, 1])
        owner = _owners(points, label, a, xyz, near)
        for b in sorted(partners):
            pair = (min(a, b), max(a, b))
            if pair in shared:   # the surfaces cross there: held to their intersection, which stays the edge
                if a in refit and pair in edges:
                    out[a][0].append(edges[pair][0][a])
                    out[a][1].append(edges[pair][1])
                continue
            on = owner == b
            if not on.any():
                continue
            ub, vb, foot, _ = closest_point_surface(patches[b].shape.nurbs(), xyz[on])
            foot = np.asarray(foot)
            target = 0.5 * (xyz[on] + foot) if a in refit and b in refit else (foot if a in refit else xyz[on])
            if a in refit:
                out[a][0].append(uv[on])
                out[a][1].append(target)
            if b in refit:
                out[b][0].append(np.c_[ub, vb])
                out[b][1].append(target)
    return {r: Anchors(np.vstack(uv), np.vstack(xyz), weight, anchor_tol) for r, (uv, xyz) in out.items() if uv}


def _written_loops(shape: FreeformShape) -> tuple[list[np.ndarray], np.ndarray]:
    """([outer, *holes] closed (u, v) polygons (k, 2), last vertex not repeated, shared (k,)): the face's
    loops as written (the outer one is its data loop, or where it has shared edges its `outline`; 200
    samples a data piece), and for each outer vertex the patch its piece is shared with (-1: data)."""
    def polygon(pieces):
        return np.vstack([design_matrix(np.linspace(0, 1, 200), p.knots, p.degree) @ p.ctrl for p in pieces])

    if shape.outline is not None:
        outer, shared = shape.outline, shape.outline_shared
    else:
        outer = polygon(shape.loops.outer)
        shared = np.full(len(outer), -1)
    return [outer] + [polygon(h) for h in shape.holes], shared


def written_face(shape: FreeformShape) -> TrimmedNurbs:
    """The face as written, for distances to it (not to its untrimmed surface): its surface and loops
    (`_written_loops`) as a `rgm.fitters.freeform_measure.TrimmedNurbs`, made once per shape (a shape is
    not changed once made: sharing makes new ones) and kept with it, as the seams are measured again and
    again."""
    face = shape.__dict__.get("_written_face")
    if face is None:
        face = shape.__dict__["_written_face"] = TrimmedNurbs(shape.nurbs(), tuple(_written_loops(shape)[0]))
    return face


def boundary_samples(shape: FreeformShape, step: float) -> tuple[np.ndarray, np.ndarray]:
    """(points (m, 3), shared (m,)): samples on the surface along its trimming loops as written (the outer
    one its data loop, or where it has shared edges its `outline`; then the holes, as `rgmc verify`
    samples them), about `step` (model units) apart along each (the polygon of the loop, 200 samples a
    data piece, resampled by arc length, linearly in (u, v) between its vertices), and the patch each
    sample's piece is shared with (-1: a data piece); made once per shape and step, as `written_face` is."""
    return _remembered(shape, "_boundary_samples", step, lambda: _boundary_samples(shape, step))


def _remembered(shape: FreeformShape, kind: str, key, compute):
    """compute(), a tuple of arrays or an array, made once per shape and `key` and kept with the shape (a
    shape is not changed once made: sharing makes new ones), read-only."""
    memo = shape.__dict__.setdefault(kind, {})
    if key not in memo:
        value = compute()
        for a in value if isinstance(value, tuple) else (value,):
            a.setflags(write=False)
        memo[key] = value
    return memo[key]


def _boundary_samples(shape: FreeformShape, step: float) -> tuple[np.ndarray, np.ndarray]:
    from rgm.fitters.seam_check import edge_samples

    loops, shared = _written_loops(shape)
    xyz, segment, _ = edge_samples(shape.nurbs(), loops[0], step)
    holes = [edge_samples(shape.nurbs(), hole, step)[0] for hole in loops[1:]]   # their pieces share nothing
    return np.vstack([xyz, *holes]), np.r_[shared[segment], np.full(sum(map(len, holes)), -1)]


def as_written(points, patches: list[PatchFit], gaps: list[Gap], near: float, **sampling) -> list[Gap]:
    """`gaps` with each seam measured again (`g0_gaps`, with its `sampling` arguments) on the loops as
    written: a face with shared edges has its data loop re-fitted between their joins and its stretches
    along them replaced (`FreeformShape.outline`), so near its corners its edge is not where its data loop
    ran. A shared seam keeps its figures along the edge and takes its data pieces' gap beyond the edge's
    ends as its `rest`. A seam the written loops no longer border keeps its figure from the data loops, and
    so do the two faces of a closed wrap (their seams are iso-lines of one surface; the samples of their
    loops' corners nearest the other face lie on the seams with third faces)."""
    final = {(g.i, g.j): g for g in g0_gaps(points, patches, near, **sampling)}
    out = []
    for g in gaps:
        f = final.get((g.i, g.j))
        if g.shared:
            g = replace(g, rest=f.max if f is not None else 0.0)
        elif f is not None and not _twins(patches, g.i, g.j):
            g = replace(g, max=f.max, p95=f.p95, samples=f.samples)
        out.append(g)
    return out


def g0_gaps(points, patches: list[PatchFit], near: float, per_seam: int | None = 150,
            step: float | None = None) -> list[Gap]:
    """Gaps between neighbouring patches. A sample of patch i's trimming loop (`boundary_samples`, `step`
    apart, by default a tenth of `near`: half a point spacing) on a data piece lies on the seam with patch
    j when the nearest input point outside patch i belongs to j and is within `near` (a sample of a shared
    edge lies on that edge's seam, however near a third patch's points); the seam's samples of both
    patches (at most `per_seam` each, evenly taken; None: all) are measured to the nearest other *face*
    as written (`written_face`: trimmed, not its surface, which reaches past the data, so a trim that
    stops short of the seam leaves a hole however near the surfaces pass) among the patches with points
    within `near` of the sample (j's, or a third patch's at a corner where three faces meet): the gap
    a sample would leave in the written model (samples of a free border within `near` of a seam's end
    count as well, and read a notch there: `rgm.fitters.seam_check`, which `rgmc verify` uses, leaves them
    out; taking them here, as the choices' score, brought more seams within the tolerance on the YCB
    views as written). The two faces of a closed wrap are measured to the other's surface:
    their seams are iso-lines of that one surface."""
    points = checked_points(points)
    label = np.full(len(points), -1)
    for r, p in enumerate(patches):
        label[p.indices] = r
    trees, outside = _searches(points, patches, label)
    chosen = []                     # (i, j, samples (k, 3)): the samples of seam (i, j) on face i
    for i, p in enumerate(patches):
        others = outside[i][0]
        if len(others) == 0:
            continue
        samples, shared = boundary_samples(p.shape, near / 10 if step is None else step)
        d, j = outside[i][1].query(samples, distance_upper_bound=near, workers=-1)
        hit = np.isfinite(d) & (shared < 0)   # a shared edge's samples lie on that seam (measured along it)
        owner = label[others[j[hit]]]
        for o in np.unique(owner):
            seam = samples[hit][owner == o]
            if per_seam is not None:
                seam = seam[np.linspace(0, len(seam) - 1, min(per_seam, len(seam))).astype(int)]
            chosen.append((i, int(o), seam))
    if not chosen:
        return []
    x = np.vstack([c[2] for c in chosen])
    on = np.repeat([c[0] for c in chosen], [len(c[2]) for c in chosen])
    # a closed wrap's two faces meet on an iso-line of their one surface, to its round-off: measured to it
    twin = np.repeat([_twins(patches, i, o) for i, o, _ in chosen], [len(c[2]) for c in chosen])
    gap = np.full(len(x), np.inf)
    for o, q in enumerate(patches):   # one search per face, for every sample near its points
        near_o = np.flatnonzero(np.isfinite(trees[o].query(x, distance_upper_bound=near, workers=-1)[0])
                                & (on != o) & ~twin)
        if len(near_o):
            gap[near_o] = np.minimum(gap[near_o], _face_distances(q.shape, x[near_o], on[near_o]))
    seams: dict[tuple[int, int], list[np.ndarray]] = {}
    for (i, o, seam), d in zip(chosen, np.split(gap, np.cumsum([len(c[2]) for c in chosen])[:-1])):
        if _twins(patches, i, o):   # to the other face's surface, remembered as `_face_distances` are
            d = _remembered(patches[o].shape, "_surface_distances", seam.tobytes(),
                            lambda: patches[o].shape.distance(seam))
        seams.setdefault((min(i, o), max(i, o)), []).append(d)
    return [Gap(int(i), int(j), float(np.max(np.concatenate(d))), float(np.percentile(np.concatenate(d), 95)),
                sum(map(len, d)), why=_CLOSED if _twins(patches, i, j) else "")
            for (i, j), d in sorted(seams.items())]


_SEARCH: dict = {}   # the k-d trees of the last partition `g0_gaps` measured (`_searches`)


def _searches(points: np.ndarray, patches: list[PatchFit], label: np.ndarray):
    """([tree of each patch's points], [(indices of the points outside patch r, their tree)]) for
    `patches` of points (n, 3), `label` (n,) the patch of each point: kept for the last set of patches'
    points, which every measurement of a fit after the merge shares (a few hundred of them on the YCB
    meat can, 40 ms each to build)."""
    key = (points.tobytes(), tuple(p.indices.tobytes() for p in patches))
    if key not in _SEARCH:
        _SEARCH.clear()
        outside = []
        for r in range(len(patches)):
            others = np.nonzero((label >= 0) & (label != r))[0]
            outside.append((others, cKDTree(points[others]) if len(others) else None))
        _SEARCH[key] = [cKDTree(points[p.indices]) for p in patches], outside
    return _SEARCH[key]


def _face_distances(shape: FreeformShape, x: np.ndarray, source: np.ndarray) -> np.ndarray:
    """Distances (k,) of samples x (k, 3) (of the faces `source` (k,)) to the face `shape` as written,
    remembered with the shape per source face's samples: the seams are measured again for every trial
    of `rgm.fitters.seam_cover` and refit round, and mostly only one or two faces changed (a shape is
    not changed once made; a face's samples are the same while it is). Each point's distance does not
    depend on the others measured with it, so the figures are those of one call on all of them."""
    memo = shape.__dict__.setdefault("_face_distances", {})
    groups = [np.flatnonzero(source == i) for i in np.unique(source)]
    keys = [x[rows].tobytes() for rows in groups]
    todo = [rows for rows, key in zip(groups, keys) if key not in memo]
    if todo:
        fresh = written_face(shape).distance(x[np.concatenate(todo)])
        for rows, d in zip(todo, np.split(fresh, np.cumsum([len(r) for r in todo])[:-1])):
            memo[x[rows].tobytes()] = d
            d.setflags(write=False)
    out = np.empty(len(x))
    for rows, key in zip(groups, keys):
        out[rows] = memo[key]
    return out


def _wrap_pairs(patches: list[PatchFit]) -> list[tuple[int, int]]:
    """The two faces (i, j) of each closed wrap among `patches`."""
    return [(i, j) for i in range(len(patches)) for j in range(i + 1, len(patches)) if _twins(patches, i, j)]


def _with_twins(patches: list[PatchFit], which: set) -> set:
    """`which` (patch indices) with the other face of each closed wrap it has a face of."""
    return set(which) | {t for t, q in enumerate(patches) if q.base.wrap is not None
                         and any(patches[r].base.wrap is q.base.wrap for r in which)}


def _twins(patches: list[PatchFit], i: int, j: int) -> bool:
    """Whether patches i and j are the two faces of one closed wrap (`rgm.fitters.wrap`)."""
    return patches[i].base.wrap is not None and patches[i].base.wrap is patches[j].base.wrap
