"""The free-form builder of `rgmc fit`: a part's points become trimmed NURBS patches.

- A part of a single range view keeps the view's grid (`grid`: the index of each pixel's point, -1 where
  the pixel holds none): the part's pixels are split at depth jumps and creases
  (`rgm.fitters.freeform_part.split_patches`; the paper: "B-splines are subdivided where discontinuities
  take place"), and each patch is a tensor-product NURBS parameterised by the grid, trimmed to its valid
  pixels; straight planar boundary pieces inside the image become described `intersect(surface, plane)`
  cuts (`fit_freeform`).
- Other data (merged views, meshes) are scattered: `rgm.fitters.patches.fit_patches` splits them at
  creases, parameterises each patch by projection onto a base surface (plane or cylinder) and fits a
  trimmed NURBS to it; neighbouring patches share their boundary where their surfaces cross (one
  `intersect(surface_i, surface_j)` in both loops, `rgm.fitters.shared_edges`), and the G0 gap between
  every pair of neighbours is measured and reported (on the shared edge, or between the separate trims
  with the reason nothing is shared).

Every patch's surface meets the tolerance's statistic, or says why it stopped short (`stopped`).
Lengths are in model units (mm).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from rgm.errors import GeometryError
from rgm.fitters.freeform_part import PlanarCut, fit_freeform, split_patches
from rgm.fitters.shared_edges import SharedEdge

__all__ = ["FreeformPart", "fit_freeform_part", "patch_part"]


@dataclass
class FreeformPart:
    """shapes: FreeformShape per patch, largest first; info: per patch, what the report says beside its
    certificate; notes: what the .rgm header and the report say about the part as a whole."""

    shapes: list = field(default_factory=list)
    info: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def _describe(shape, parameterisation: str, points: int, seconds: float) -> dict:
    f = shape.fit
    return {"parameterisation": parameterisation, "points": int(points),
            "control_net": [int(f.ctrl.shape[0]), int(f.ctrl.shape[1])], "control_points": int(f.n_ctrl),
            "refinement": [[int(n), float(v)] for n, v in f.history], "stopped": f.stopped,
            "residual": {"statistic": f.stats.statistic, "value": f.stats.value, "max": f.stats.max},
            "loops": {"outer_pieces": len(shape.outer), "holes": len(shape.holes),
                      "cuts": sum(isinstance(p, PlanarCut) for p in shape.outer),
                      "shared_edges": sum(isinstance(p, SharedEdge) for p in shape.outer)},
            "seconds": float(seconds)}


def _grid_patches(points, idx, grid, tol, statistic, min_pixels, crease_deg=None) -> FreeformPart | None:
    mask = np.isin(grid, idx)
    if mask.sum() < 16:
        return None
    xyz = np.full(grid.shape + (3,), np.nan)
    xyz[grid >= 0] = points[grid[grid >= 0]]
    masks = split_patches(xyz, mask, min_pixels=min_pixels,
                          **({} if crease_deg is None else {"crease_deg": crease_deg})) or [mask]
    out = FreeformPart()
    for m in masks:
        rows, cols = np.nonzero(m.any(axis=1))[0], np.nonzero(m.any(axis=0))[0]
        box = np.s_[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        t0 = time.perf_counter()
        try:
            shape = fit_freeform(None, tol, grid=xyz[box], mask=m[box], statistic=statistic)
        except GeometryError as exc:
            out.notes.append(f"{int(m.sum())} pixels not fitted: {exc}")
            continue
        out.shapes.append(shape)
        out.info.append(_describe(shape, "range grid", m.sum(), time.perf_counter() - t0))
        out.notes += [f"patch {len(out.shapes)} trim: {note}" for note in shape.loops.notes]
    left = int(mask.sum() - sum(m.sum() for m in masks))
    if left:
        out.notes.append(f"{left} pixels at depth jumps and creases (or in specks) belong to no patch")
    return out


def fit_freeform_part(points, idx, tol: float, *, statistic: str = "p95", grid=None,
                      min_pixels: int = 50, crease_deg: float | None = None) -> FreeformPart:
    """Trimmed NURBS patches for the part `idx` (indices into points (n, 3), mm) whose `statistic` of the
    residuals is within `tol` (mm). `grid` (rows, cols): the range image behind `points`, if they are one
    view; patches of fewer than `min_pixels` pixels are left out. Scattered data go to `fit_patches`.
    `crease_deg`: the normal change (degrees) at which the data splits into patches (None: each splitter's
    default, 40 for a range view, 35 for scattered points)."""
    from rgm.fitters.patches import fit_patches

    idx = np.asarray(idx)
    if grid is not None:
        part = _grid_patches(points, idx, grid, tol, statistic, min_pixels, crease_deg)
        if part is not None and part.shapes:
            return part
    return patch_part(fit_patches(points[idx], tol, statistic=statistic,
                                  **({} if crease_deg is None else {"angle_deg": crease_deg})))


def patch_part(result) -> FreeformPart:
    """The FreeformPart of a `rgm.fitters.patches.PatchSet`: its patches, what each is, and notes on the
    measured G0 gaps between neighbours (patches numbered from 1), unassigned and skipped points."""
    out = FreeformPart(notes=list(result.skipped))
    for p in result.patches:
        out.shapes.append(p.shape)
        how = f"projection onto a {p.base.kind}" + (", one of two faces of a surface closed round its axis"
                                                    if p.base.wrap is not None else "")
        out.info.append(_describe(p.shape, how, len(p.indices), p.seconds))
    for g in result.gaps:
        rest = f"; beyond its ends the loops' data pieces leave up to {g.rest:.4f} mm" if g.rest > g.max else ""
        if g.shared and g.curve:
            out.notes.append(f"patches {g.i + 1} | {g.j + 1}: one shared edge, a curve midway between their surfaces "
                             f"(seam_{g.i + 1}_{g.j + 1}, {g.length:.1f} mm; they do not cross along it): G0 gap "
                             f"on it max {g.max:.2g} mm, p95 {g.p95:.2g} mm ({g.samples} samples of both faces' "
                             f"edges); separate trims were {g.before:.4f} mm apart{rest}")
        elif g.shared:
            out.notes.append(f"patches {g.i + 1} | {g.j + 1}: one shared edge, the intersection of their surfaces "
                             f"({g.length:.1f} mm): G0 gap on it max {g.max:.2g} mm, p95 {g.p95:.2g} mm ({g.samples} "
                             f"samples of both faces' edges as approximated at the tolerance); separate trims "
                             f"were {g.before:.4f} mm apart{rest}")
        else:
            out.notes.append(f"patches {g.i + 1} | {g.j + 1}: G0 gap max {g.max:.4f} mm, p95 {g.p95:.4f} mm "
                             f"({g.samples} boundary samples, to the nearest other face; separate trims: "
                             f"{g.why or 'not shared'})")
    if result.unassigned:
        out.notes.append(f"{result.unassigned} points belong to no patch")
    return out
