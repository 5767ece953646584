"""Free-form parts: a trimmed tensor-product NURBS surface per part, written as `.rgm`.

The paper's face mask and hand (its Figure 5 b, c): the part's points become one least-squares bicubic
surface refined by knot insertion (`rgm.fitters.freeform`), trimmed to where data was by closed 2-D loops
in the surface's parameter space (`rgm.fitters.trimloops`). A range image keeps its grid: the grid gives
the parameterisation and its valid-pixel mask the trim. Scattered points are parameterised by projection
onto their best-fit plane and their trim comes from the occupied cells of that projection.

A boundary piece that lies in a plane (a cut, such as the hand's wrist) is kept as a *description*,
`intersect(surface, plane(...))`, which each back end approximates at its own accuracy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from rgm.fitters.freeform import SurfaceFit, design_matrix, grid_parameters, plane_parameters
from rgm.fitters.freeform_surface import fit_surface
from rgm.fitters.trimloops import TrimLoops, fit_trim_loops

__all__ = ["FreeformShape", "fit_freeform", "emit_freeform", "emit_freeform_set", "printed_surface", "retrimmed", "fitted_parameters",
           "trim_parameters"]

_DEC = 4   # decimals of model-space numbers (mm): 0.1 micrometre
_UV_DEC = 9
_PLANE_DEC = 12   # decimals of a cut plane's origin and normal: its ends stay on it to about 1e-10 mm


@dataclass
class PlanarCut:
    """A loop piece replaced by the intersection of the surface with the plane (origin, normal)."""

    origin: np.ndarray
    normal: np.ndarray


@dataclass
class FreeformShape:
    """The fitted surface, its trimming loops (2-D pieces; a piece may be a PlanarCut), and the fit."""

    fit: SurfaceFit
    loops: TrimLoops | None
    outer: list            # pieces: CurveFit or PlanarCut
    holes: list            # lists of CurveFit
    # the outer loop as written, a (u, v) polygon (k, 2), where it is not the data loop `loops.outer`
    # (shared edges in it: `rgm.fitters.shared_edges`), and for each vertex the patch its piece is shared
    # with (-1: a data piece); None: it is the data loop
    outline: np.ndarray | None = None
    outline_shared: np.ndarray | None = None

    def nurbs(self):
        return self.fit.nurbs()

    @property
    def band(self) -> tuple | None:
        """(u0, u1): the iso-lines a face cut from a closed wrap shares with the wrap's other face, its
        loops held along them (`TrimLoops.band`, `rgm.fitters.wrap`); None for any other face."""
        return self.loops.band if self.loops is not None else None

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Closest-point distances (n,) of points (n, 3) to the (untrimmed) surface, model units."""
        from rgm.geometry.inversion import closest_point_surface

        return np.asarray(closest_point_surface(self.nurbs(), points)[-1])


def _piece_points(piece, m=200):
    return design_matrix(np.linspace(0, 1, m), piece.knots, piece.degree) @ piece.ctrl


def grid_from_mesh(points: np.ndarray, faces: np.ndarray | None) -> np.ndarray | None:
    """The (rows, cols, 3) grid behind a mesh that triangulates a regular range grid row by row (as
    scanner meshes such as the paper's face scan do: faces (i, i+W, i+1)), or None if it is not one."""
    if faces is None or len(faces) == 0:
        return None
    spans = np.ptp(faces, axis=1)                 # W for both triangles of a grid cell
    width = int(np.bincount(spans).argmax())
    if width < 2 or len(points) % width or len(points) // width < 2 or np.any(spans > width):
        return None
    return points.reshape(len(points) // width, width, 3)


def _links(g: np.ndarray, mask: np.ndarray, jump: float):
    """4-neighbour pixel pairs of a range grid g (rows, cols, 3) (NaN where `mask` is False), as flat
    indices (a, b), that are not across a depth jump (farther apart than `jump` times the median step)."""
    du, dv = np.diff(g, axis=0), np.diff(g, axis=1)
    step = np.nanmedian(np.r_[np.linalg.norm(du, axis=2).ravel(), np.linalg.norm(dv, axis=2).ravel()])
    ids = np.arange(mask.size).reshape(mask.shape)
    pairs = []
    for d, (lo, hi) in ((du, (np.s_[:-1, :], np.s_[1:, :])), (dv, (np.s_[:, :-1], np.s_[:, 1:]))):
        near = np.linalg.norm(d, axis=2) <= jump * step               # NaN (invalid neighbour): no link
        pairs.append((ids[lo][near], ids[hi][near]))
    return tuple(np.concatenate(x) for x in zip(*pairs))


def _components(size: int, a, b, keep) -> np.ndarray:
    """Component labels (size,) of the graph of links (a, b) among flat pixels `keep`; 0 elsewhere."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    both = keep[a] & keep[b]
    graph = coo_matrix((np.ones(int(both.sum())), (a[both], b[both])), shape=(size, size))
    labels = connected_components(graph, directed=False)[1] + 1
    labels[~keep] = 0
    return labels


def range_specks(grid: np.ndarray, mask: np.ndarray, *, jump: float = 4.0, min_pixels: int = 50) -> np.ndarray:
    """(rows, cols) bool: valid pixels of a range grid (rows, cols, 3) in pieces of fewer than
    `min_pixels` pixels once links across depth jumps (`jump` times the median pixel step) are cut:
    specks (spurious returns, mixed pixels) too small to carry a surface patch."""
    g = np.where(mask[..., None], grid, np.nan)
    labels = _components(mask.size, *_links(g, mask, jump), mask.ravel())
    sizes = np.bincount(labels)
    return (mask.ravel() & (sizes[labels] < min_pixels)).reshape(mask.shape)


def split_patches(grid: np.ndarray, mask: np.ndarray, *, jump: float = 4.0, crease_deg: float = 40.0,
                  min_pixels: int = 200) -> list[np.ndarray]:
    """Split a range grid (rows, cols, 3) at its surface discontinuities: depth jumps (a neighbour
    further than `jump` times the median pixel step) and creases (surface normals of neighbouring
    pixels more than `crease_deg` apart). Returns one boolean mask per patch, largest first; patches
    smaller than `min_pixels` are dropped. The paper: "B-splines are subdivided where discontinuities
    take place".

    A depth jump cuts the link between its two pixels, each staying with its own surface. Pixels at a
    crease (whose normals mix both sides) are set aside while the 4-connected components are found,
    then each joins the component of its nearest pixel within two pixels."""
    g = np.where(mask[..., None], grid, np.nan)
    n = np.cross(np.gradient(g, axis=0), np.gradient(g, axis=1))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    crease_px = np.zeros(mask.shape, bool)
    for lo, hi in ((np.s_[:-1, :], np.s_[1:, :]), (np.s_[:, :-1], np.s_[:, 1:])):
        cos = np.nan_to_num(np.sum(n[hi] * n[lo], axis=2), nan=1.0)
        crease = (cos < np.cos(np.radians(crease_deg))) & mask[lo] & mask[hi]
        crease_px[lo] |= crease
        crease_px[hi] |= crease
    labels = _components(mask.size, *_links(g, mask, jump), (mask & ~crease_px).ravel()).reshape(mask.shape)
    if crease_px.any() and (labels > 0).any():
        dist, (ii, jj) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        join = crease_px & (dist <= 2)
        labels[join] = labels[ii[join], jj[join]]
    values, sizes = np.unique(labels[labels > 0], return_counts=True)
    order = np.argsort(-sizes, kind="stable")
    return [labels == values[k] for k in order if sizes[k] >= min_pixels]


def _occupancy(u: np.ndarray, v: np.ndarray, bins: int) -> np.ndarray:
    """Cells of a bins x bins raster of [0, 1]² that hold parameters, closed over one-cell gaps."""
    iu = np.clip((u * bins).astype(int), 0, bins - 1)
    iv = np.clip((v * bins).astype(int), 0, bins - 1)
    occ = np.zeros((bins, bins), bool)
    occ[iu, iv] = True
    return ndimage.binary_closing(np.pad(occ, 2), np.ones((3, 3)), iterations=1)[2:-2, 2:-2] | occ


def _surface_speed(fit: SurfaceFit) -> float:
    """An upper estimate of |dS/du|, |dS/dv| (model units per parameter unit) from the control net."""
    c = fit.ctrl
    du = np.linalg.norm(np.diff(c, axis=0), axis=2).sum(axis=0).max()
    dv = np.linalg.norm(np.diff(c, axis=1), axis=2).sum(axis=1).max()
    return float(max(du, dv, 1e-12))


def _bins(n: int) -> int:
    """Cells a side of the raster that scattered data of n points are trimmed on (`_occupancy`)."""
    return int(np.clip(np.sqrt(n) / 2, 24, 256))


def fitted_parameters(params, n: int) -> np.ndarray:
    """(n, 2) the surface parameters `fit_freeform` fits n scattered points at, given their `params` (u, v)
    in [0, 1]: inset by half a trimming raster cell (`_inset`)."""
    margin = 0.5 / _bins(n)
    return np.c_[[_inset(np.asarray(t, float), margin) for t in params]].T


def trim_parameters(shape: FreeformShape, params, n: int) -> np.ndarray:
    """(n, 2) the surface parameters a face's n scattered points were trimmed at: a face cut from a
    closed wrap (its loops held to a band, `rgm.fitters.wrap`) at its `params` as cut, any other at
    them inset as `fit_freeform` fits them (`fitted_parameters`)."""
    return np.c_[params] if shape.band is not None else fitted_parameters(params, n)


def retrimmed(shape: FreeformShape, points: np.ndarray, params, tol: float, statistic: str,
              cover: np.ndarray, past=None) -> FreeformShape:
    """`shape`, fitted by `fit_freeform` to scattered `points` over `params`, trimmed again to its data
    and the surface parameters `cover` (k, 2) with the band between each and its nearest data parameter
    (so the region stays one): its surface is unchanged. (`rgm.fitters.seam_cover`.) A face cut from a
    closed wrap keeps its loops along its seams (`shape.band`), `past` (k, 2) the neighbouring
    face's data past them, as `rgm.fitters.wrap` trimmed it."""
    from scipy.spatial import cKDTree

    margin = 0.5 / _bins(len(points))
    data = trim_parameters(shape, params, len(points))
    u, v = data.T
    band = band_samples(cover, data[cKDTree(data).query(cover)[1]], margin)
    if past is not None and len(past):
        band = np.r_[band, past]
    return fit_freeform(points, tol, statistic=statistic, cuts=False, params=(u, v), surface=shape.fit,
                        band=shape.band, cover=band)


def band_samples(a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    """Points every `step` or closer on the segments from a[i] to b[i] (k, 2), b[i] left out: the cells
    a trim must cover to reach from b to a in one region."""
    n = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / step)).astype(int)
    t = np.concatenate([np.arange(k) / k for k in n])
    return np.repeat(a, n, axis=0) + t[:, None] * np.repeat(b - a, n, axis=0)


def _inset(t: np.ndarray, margin: float) -> np.ndarray:
    """Parameters in [0, 1] moved into [margin, 1 - margin]: the surface reaches a little beyond its data,
    so trimming loops (and a cut's intersection with them) lie strictly inside its domain."""
    return margin + (1.0 - 2.0 * margin) * t


def fit_freeform(points: np.ndarray, tol: float, *, grid=None, mask=None, statistic: str = "p95",
                 max_ctrl: int = 40000, cuts: bool = True, params=None, anchors=None, surface=None,
                 band=None, cover=None, sides=None) -> FreeformShape:
    """Fit a trimmed NURBS surface to a part's points (n, 3), or to a range grid (rows, cols, 3) with
    its valid mask. `tol` (model units) bounds `statistic` of the residuals. With `cuts`, planar boundary
    pieces become described plane intersections, when the intersection follows the data's edge and the
    control net stays within twice the data's size. `params` (u, v), each (n,) in [0, 1],
    are scattered points' own parameters (a projection onto a base surface, `rgm.fitters.patches`);
    without them the points are projected onto their best-fit plane. `anchors`
    (`rgm.fitters.freeform.Anchors`, in the surface's parameters), scattered data only: points the
    surface is pulled through by a weighted penalty (`rgm.fitters.freeform_surface.fit_surface`), such
    as a boundary curve shared with a neighbouring patch. `surface` (a SurfaceFit over `params`, scattered
    data): the surface is already fitted, only trimmed here (a face cut from a closed wrap,
    `rgm.fitters.wrap`), with its loops held within `band` (u0, u1) and along its ends
    (`rgm.fitters.trimloops.fit_trim_loops`); `cover` (k, 2): parameters of the neighbour's data past the
    band's ends, whose cells count as occupied, so that the loops run along the ends without a notch.
    `sides` (n,): labels of scattered points on each of which the statistic must hold on its own
    (`fit_surface`)."""
    if grid is not None:
        mask = np.isfinite(grid).all(axis=2) if mask is None else mask
        ug, vg = (_inset(t, 0.5 / (len(t) - 1)) for t in grid_parameters(np.where(mask[..., None], grid, 0.0), mask))
        fit = fit_surface(grid, tol, mask=mask, params=(ug, vg), statistic=statistic, max_ctrl=max_ctrl,
                          anchors=anchors)
        region, rows, cols, snap = mask, ug, vg, None
        spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)[mask[:, 1:] & mask[:, :-1]]))
    else:
        bins = _bins(len(points))
        if surface is None:
            u, v = (_inset(np.asarray(t, float), 0.5 / bins)
                    for t in (plane_parameters(points)[:2] if params is None else params))
            fit = fit_surface(points, tol, params=(u, v), statistic=statistic, max_ctrl=max_ctrl, anchors=anchors,
                              sides=sides)
        else:
            (u, v), fit = map(np.asarray, params), surface
        region = _occupancy(u, v, bins) if cover is None else _occupancy(*np.r_[np.c_[u, v], cover].T, bins)
        rows = cols = (np.arange(bins) + 0.5) / bins
        # a cover counts as data for the snapping, but not past a band's ends (a wrap's neighbouring data)
        snap = np.c_[u, v] if cover is None else np.r_[np.c_[u, v], cover if band is None else
                                                         cover[(cover[:, 0] > band[0]) & (cover[:, 0] < band[1])]]
        from scipy.spatial import cKDTree

        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
        spacing = max(spacing, float(np.ptp(points, axis=0).max()) / bins)   # the edge is known to a raster cell
    loops = fit_trim_loops(region, rows, cols, tol_uv=tol / _surface_speed(fit), snap_to=snap,
                           domain=fit.nurbs().domain, band=band)
    outer = list(loops.outer)
    data = grid[mask] if grid is not None else points
    size = float(np.ptp(data, axis=0).max())
    tame = np.ptp(fit.ctrl.reshape(-1, 3), axis=0).max() <= 2 * size   # no wild net beyond the data,
    if cuts and tame and len(outer) > 1:   # whose intersections would be costly and stray from the data
        margin = 1.5 / len(rows) if grid is not None else -1.0  # a range image's edge is no cut
        flat = max(tol / 2, 2 * spacing)  # a data boundary is only known to within the point spacing
        view = None
        if grid is not None:              # a range view: its data face the sensor
            ii, jj = np.nonzero(mask)
            n = fit.nurbs().normal(ug[ii], vg[jj]).mean(axis=0)
            view = n / max(np.linalg.norm(n), 1e-300)
        described = [piece if _on_border(piece, margin) else (_as_cut(piece, fit, flat, size, view) or piece)
                     for piece in outer]
        for k in range(len(outer)):   # two cuts in a row meet at a corner no plane describes: keep one
            if isinstance(described[k], PlanarCut) and isinstance(described[k - 1], PlanarCut):
                described[k] = outer[k]
        surface = fit.nurbs()
        # the data's edge, a pixel staircase whose contour runs half a pixel outside the data, is known to
        # within about 1.5 point spacings: a described cut must follow it that closely (plus the tolerance)
        for k, cut in enumerate(described):
            if isinstance(cut, PlanarCut):
                cut = _pinned(cut.normal, surface, outer[k - 1].ctrl[-1], outer[(k + 1) % len(outer)].ctrl[0])
                described[k] = cut if _cut_follows(cut, outer, k, fit, tol + 1.5 * spacing) else outer[k]
        outer = described
    return FreeformShape(fit, loops, outer, [list(h) for h in loops.holes])


def _as_cut(piece, fit: SurfaceFit, flat: float, size: float, view=None):
    """A PlanarCut (the least-squares plane of the piece's 3-D image) when the piece lies in it within
    `flat`, is long enough to be a deliberate cut (a quarter of the data's size `size`), crosses the
    surface at more than 30 degrees and, in a range view (`view`: the mean direction the data face),
    faces the sensor there (within 60 degrees on average: where the surface turns away, its edge is a
    silhouette, not a cut); otherwise None."""
    uv = _piece_points(piece, 100)
    s = fit.nurbs()
    xyz = s.evaluate(uv[:, 0], uv[:, 1])
    length = np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()
    if length < 0.25 * size:
        return None
    normals = s.normal(uv[:, 0], uv[:, 1])
    if view is not None and np.mean(np.abs(normals @ view)) < 0.5:
        return None
    c = xyz.mean(axis=0)
    _, sv, vt = np.linalg.svd(xyz - c, full_matrices=False)
    n = vt[2]        # the plane that fits the piece best (for a nearly straight piece, one of many
    if np.abs((xyz - c) @ n).max() > flat:   # through its line: `_cut_follows` judges what it describes)
        return None
    if np.mean(np.abs(normals @ n)) > 0.5:                  # nearly tangent: not a cut
        return None
    return PlanarCut(c, n)


def _pinned(normal, surface, uv_start, uv_end) -> PlanarCut:
    """The cut plane nearest to `normal` through the surface's points at uv_start and uv_end (the ends of
    the loop pieces before and after it), so that the intersection meets them and the loop closes."""
    e0, e1 = surface.evaluate(*np.c_[uv_start, uv_end])
    d = e1 - e0
    n = np.asarray(normal, float) - (np.asarray(normal, float) @ d) / max(d @ d, 1e-300) * d
    return PlanarCut(e0, n / np.linalg.norm(n))


def _cut_follows(cut: PlanarCut, pieces, k: int, fit: SurfaceFit, within: float) -> bool:
    """Whether the intersection of the surface with the cut's plane, from the end of piece k-1 to the
    start of piece k+1 (as the back ends and `rgm.fitters.freeform_measure` take it; approximated to
    within / 2), stays within `within` of piece k in space, both ways (model units): the description is
    the data's boundary."""
    from scipy.spatial import cKDTree

    from rgm.errors import GeometryError
    from rgm.fitters.freeform_measure import branch_between
    from rgm.model import BSplineSurface, IntersectionCurve, Plane

    s = fit.nurbs()
    surface = BSplineSurface(s)
    try:
        branches = IntersectionCurve(surface, Plane(cut.origin, cut.normal), within / 2).uv_curves(surface)
    except GeometryError:
        return False
    if not branches:
        return False
    start, end = _piece_points(pieces[k - 1], 2)[-1], _piece_points(pieces[(k + 1) % len(pieces)], 2)[0]
    uv = branch_between(branches, start, end)
    mine = _piece_points(pieces[k], 200)
    a, b = s.evaluate(uv[:, 0], uv[:, 1]), s.evaluate(mine[:, 0], mine[:, 1])
    return bool(max(cKDTree(a).query(b)[0].max(), cKDTree(b).query(a)[0].max()) <= within)


def _on_border(piece, margin: float) -> bool:
    """Whether a loop piece runs along the border of the parameter domain [0, 1]² (a range image's edge)."""
    uv = _piece_points(piece, 50)
    return bool(np.all((uv.min(axis=1) < margin) | (uv.max(axis=1) > 1 - margin)))


# ----------------------------------------------------------------------------------------- emission
def _num(x: float, dec: int = _DEC) -> str:
    s = f"{round(float(x), dec) + 0.0:.{dec}f}".rstrip("0").rstrip(".")
    return s if s not in ("-0", "") else "0"


def _printed(values, dec: int) -> tuple[list[str], np.ndarray]:
    """The numbers as written (`dec` decimals) and as they read back: the model the file describes."""
    texts = [_num(x, dec) for x in np.ravel(values)]
    return texts, np.array([float(t) for t in texts]).reshape(np.shape(values))


def _entries(texts: list[str], width: int) -> list[str]:
    """Net entries ("x y z") from a flat list of numbers, `width` numbers each."""
    return [" ".join(texts[i:i + width]) for i in range(0, len(texts), width)]


def _knots(k: np.ndarray):
    texts, values = _printed(k, _UV_DEC)
    return "knots([" + ", ".join(texts) + "])", values


def _curve2(piece):
    """`bspline(...)` text of a 2-D loop piece and the model curve it reads back as."""
    from rgm.geometry import NurbsCurve
    from rgm.model import BSplineCurve

    ktext, knots = _knots(piece.knots)
    texts, ctrl = _printed(piece.ctrl, _UV_DEC)
    text = f"bspline({piece.degree}, {ktext}, net {len(ctrl)} [{', '.join(_entries(texts, 2))}])"
    return text, BSplineCurve(NurbsCurve(piece.degree, knots, ctrl, None))


def _curve3(curve):
    """`bspline(...)` text of a 3-D NurbsCurve (a seam curve, model units) and the model curve it reads back as."""
    from rgm.geometry import NurbsCurve
    from rgm.model import BSplineCurve

    ktext, knots = _knots(curve.knots)
    texts, ctrl = _printed(curve.ctrl, _DEC)
    text = f"bspline({curve.degree}, {ktext}, net {len(ctrl)} [{', '.join(_entries(texts, 3))}])"
    return text, BSplineCurve(NurbsCurve(curve.degree, knots, ctrl, None))


def _directed(edge, nurbs, uv_before):
    """A seam curve's (text, model curve) as a loop piece after a piece ending at `uv_before` on surface
    `nurbs`: `reverse(...)` when the loop meets it at its end."""
    from rgm.fitters.seam_curves import meets_start
    from rgm.model import BSplineCurve

    text, curve = edge
    c = curve.nurbs()
    if meets_start(nurbs, uv_before, c):
        return edge
    return f"reverse({text})", BSplineCurve(c.reverse())


def _cut(piece: PlanarCut, surf: str, surface, tolerance: float, ends):
    """`intersect(surface, plane(...))` text and model curve; the plane pinned through the printed
    surface's points at the printed ends `ends` (uv_start, uv_end) of the neighbouring pieces, written with
    _PLANE_DEC decimals so that they stay on it (the loop closes at the back ends' precision)."""
    from rgm.model import IntersectionCurve, Plane

    pinned = _pinned(piece.normal, surface.nurbs(), *ends)
    (ot, o), (nt, n) = _printed(pinned.origin, _PLANE_DEC), _printed(pinned.normal, _PLANE_DEC)
    text = f"intersect({surf}, plane(pt({', '.join(ot)}), vec({', '.join(nt)})))"
    return text, IntersectionCurve(surface, Plane(o, n), tolerance)


def printed_surface(shape: FreeformShape):
    """The model surface (BSplineSurface) a patch's surface reads back as from the `.rgm`: its numbers
    as written."""
    return _surface_binding(shape, "")[1]


def _surface_binding(shape: FreeformShape, suffix: str):
    """The `bsurface(...)` binding text of a patch's surface `surface{suffix}` and the model surface it
    reads back as (printed numbers)."""
    from rgm.geometry import NurbsSurface
    from rgm.model import BSplineSurface

    f = shape.fit
    (ku_text, ku), (kv_text, kv) = _knots(f.knots_u), _knots(f.knots_v)
    texts, ctrl = _printed(f.ctrl, _DEC)
    nu, nv = ctrl.shape[:2]
    entries = _entries(texts, 3)
    indent = " " * 8
    rows = (",\n" + indent).join(", ".join(entries[i * nv:(i + 1) * nv]) for i in range(nu))
    surf = f"surface{suffix}"
    surface = BSplineSurface(NurbsSurface(f.degree_u, f.degree_v, ku, kv, ctrl, None))
    text = (f"{surf} := bsurface(degree_u: {f.degree_u}, degree_v: {f.degree_v},\n"
            f"    knots_u: {ku_text},\n    knots_v: {kv_text},\n"
            f"    net: net {nu} x {nv} [\n{indent}{rows}]);")
    return text, surface


def emit_freeform(shape: FreeformShape, name: str, suffix: str = "", *, tolerance: float, shared=None):
    """The `.rgm` bindings of a free-form part: `surface`, its `boundary` and `hole` loops and the trimmed
    face `name`. `tolerance` (model units) is the file's (`tolerance` statement: the default accuracy of
    its intersections). Returns an `rgm.fitters.emit.EmittedPart` whose `ideal` is the trimmed face
    rebuilt from the printed numbers (`rgm.fitters.freeform_measure.TrimmedNurbs`, as `rgmc verify`
    compiles it), so the certificate measures exactly the model the file describes.

    A shape whose loop shares edges with its neighbours (`rgm.fitters.shared_edges.SharedEdge` pieces)
    is emitted with the others of its set: `emit_freeform_set`, which passes `shared`."""
    from rgm.fitters.emit import EmittedPart
    from rgm.fitters.freeform_measure import TrimmedNurbs
    from rgm.fitters.shared_edges import SharedEdge
    from rgm.model import Loop, TrimmedFace

    surf = f"surface{suffix}"
    if shared is None:
        if any(isinstance(p, SharedEdge) for p in shape.outer):
            raise ValueError("a patch with shared edges is emitted with its neighbours: emit_freeform_set")
        text, surface = _surface_binding(shape, suffix)
        bindings = [text]
    else:   # the set's printed surface and its shared intersections (name, model curve) by pair
        surface, edges, bindings = shared["surface"], shared["edges"], list(shared["bindings"])
    outer = [None if isinstance(p, (PlanarCut, SharedEdge)) else _curve2(p) for p in shape.outer]
    for k, p in enumerate(shape.outer):
        if isinstance(p, PlanarCut):
            ends = (outer[k - 1][1].nurbs().ctrl[-1], outer[(k + 1) % len(outer)][1].nurbs().ctrl[0])
            outer[k] = _cut(p, surf, surface, tolerance, ends)
        elif isinstance(p, SharedEdge):
            outer[k] = edges[p.pair]
            if p.curve is not None:   # a seam curve: run it the way the loop goes (from the piece before)
                outer[k] = _directed(outer[k], surface.nurbs(), outer[k - 1][1].nurbs().ctrl[-1])
    bindings.append(f"boundary{suffix} := loop(\n    " + ",\n    ".join(t for t, _ in outer) + ");")
    holes, hole_loops = [], []
    for k, hole in enumerate(shape.holes, 1):
        pieces = [_curve2(p) for p in hole]
        holes.append(f"hole{suffix}_{k}")
        hole_loops.append(Loop(tuple(c for _, c in pieces)))
        bindings.append(f"hole{suffix}_{k} := loop(\n    " + ",\n    ".join(t for t, _ in pieces) + ");")
    bindings.append(f"{name} := trim({surf}, outer: boundary{suffix}, holes: [{', '.join(holes)}]);")
    face = TrimmedFace(surface, Loop(tuple(c for _, c in outer)), tuple(hole_loops))
    return EmittedPart(name, [], bindings, surf, TrimmedNurbs.from_model(face))


def emit_freeform_set(shapes, names, suffixes, *, tolerance: float) -> list:
    """The EmittedParts of a set of patches (`emit_freeform` each) whose loops may share edges
    (`rgm.fitters.shared_edges.SharedEdge`, indices into `shapes`): each shared edge is one binding
    `crease{suffix_i}{suffix_j} := intersect(surface{suffix_i}, surface{suffix_j});` (written with patch i)
    used by both faces' loops, and one model IntersectionCurve of both printed surfaces, so the ideals
    (and their certificates) see the same curve the file describes."""
    from rgm.fitters.shared_edges import SharedEdge, snap_joins
    from rgm.model import IntersectionCurve

    printed = [_surface_binding(s, suffix) for s, suffix in zip(shapes, suffixes)]
    pairs = sorted({p.pair for s in shapes for p in s.outer if isinstance(p, SharedEdge)})
    edges, texts = {}, {k: [] for k in range(len(shapes))}
    seams = {p.pair: p.curve for s in shapes for p in s.outer if isinstance(p, SharedEdge) and p.curve is not None}
    for (i, j), curve in sorted(seams.items()):
        seam = f"seam{suffixes[i]}{suffixes[j]}"
        text, model_curve = _curve3(curve)
        texts[i].append(f"{seam} := {text};")
        edges[(i, j)] = (seam, model_curve)
    if pairs:   # the corners exactly on the printed surfaces' intersections (or the seam curves' ends)
        shapes = snap_joins(shapes, [surface.nurbs() for _, surface in printed],
                            {pair: edges[pair][1].nurbs() for pair in seams})
    for i, j in pairs:
        if (i, j) in seams:
            continue
        crease = f"crease{suffixes[i]}{suffixes[j]}"
        texts[i].append(f"{crease} := intersect(surface{suffixes[i]}, surface{suffixes[j]});")
        edges[(i, j)] = (crease, IntersectionCurve(printed[i][1], printed[j][1], tolerance, name=crease))
    return [emit_freeform(s, name, suffix, tolerance=tolerance,
                          shared={"surface": printed[k][1], "edges": edges, "bindings": [printed[k][0]] + texts[k]})
            for k, (s, name, suffix) in enumerate(zip(shapes, names, suffixes))]
