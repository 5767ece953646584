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

from rgm.fitters.freeform import (SurfaceFit, design_matrix, fit_surface, grid_parameters,
                                  plane_parameters)
from rgm.fitters.trimloops import TrimLoops, fit_trim_loops

__all__ = ["FreeformShape", "fit_freeform", "emit_freeform"]

_DEC = 4   # decimals of model-space numbers (mm): 0.1 micrometre
_UV_DEC = 9


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

    def nurbs(self):
        return self.fit.nurbs()

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Closest-point distances (n,) of points (n, 3) to the (untrimmed) surface, model units."""
        from rgm.geometry.inversion import closest_point_surface

        return np.asarray(closest_point_surface(self.nurbs(), points)[-1])

    def sample_surface(self, spacing: float) -> np.ndarray:
        """Points on the surface about `spacing` apart, inside the outer loop (holes ignored), (k, 3)."""
        s = self.nurbs()
        (u0, u1), (v0, v1) = s.domain
        ext = np.ptp(self.fit.ctrl.reshape(-1, 3), axis=0).max()
        n = int(np.clip(ext / max(spacing, 1e-9), 8, 400))
        u, v = np.meshgrid(np.linspace(u0, u1, n), np.linspace(v0, v1, n), indexing="ij")
        uv = np.c_[u.ravel(), v.ravel()]
        if self.loops is not None:
            poly = np.vstack([_piece_points(p, 50) for p in self.loops.outer])
            uv = uv[_inside(uv, poly)]
        return s.evaluate(uv[:, 0], uv[:, 1])


def _piece_points(piece, m=200):
    return design_matrix(np.linspace(0, 1, m), piece.knots, piece.degree) @ piece.ctrl


def _inside(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for q (m, 2) against a closed polygon (k, 2), vectorised over q."""
    a, b = poly, np.roll(poly, -1, axis=0)
    inside = np.zeros(len(q), bool)
    for (x0, y0), (x1, y1) in zip(a, b):  # loop over polygon edges, arrays over the queries
        crosses = (y0 > q[:, 1]) != (y1 > q[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            x = x0 + (q[:, 1] - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (q[:, 0] < x)
    return inside


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


def split_patches(grid: np.ndarray, mask: np.ndarray, *, jump: float = 4.0, crease_deg: float = 40.0,
                  min_pixels: int = 200) -> list[np.ndarray]:
    """Split a range grid (rows, cols, 3) at its surface discontinuities: depth jumps (a neighbour
    further than `jump` times the median pixel step) and creases (surface normals of neighbouring
    pixels more than `crease_deg` apart). Returns one boolean mask per patch, largest first; patches
    smaller than `min_pixels` are dropped. The paper: "B-splines are subdivided where discontinuities
    take place"."""
    g = np.where(mask[..., None], grid, np.nan)
    du = np.diff(g, axis=0)
    dv = np.diff(g, axis=1)
    step = np.nanmedian(np.r_[np.linalg.norm(du, axis=2).ravel(), np.linalg.norm(dv, axis=2).ravel()])
    bad = ~mask.copy()
    for d, axis in ((du, 0), (dv, 1)):
        far = ~(np.linalg.norm(d, axis=2) <= jump * step)     # NaN (invalid neighbour) counts as far
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        both_valid = mask[tuple(lo)] & mask[tuple(hi)]
        cut = far & both_valid
        bad[tuple(lo)] |= cut
        bad[tuple(hi)] |= cut
    n = np.cross(np.gradient(g, axis=0), np.gradient(g, axis=1))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    cos_limit = np.cos(np.radians(crease_deg))
    for axis in (0, 1):
        cos = np.sum(np.take(n, range(1, n.shape[axis]), axis=axis)
                     * np.take(n, range(0, n.shape[axis] - 1), axis=axis), axis=2)
        crease = np.nan_to_num(cos, nan=1.0) < cos_limit
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        bad[tuple(lo)] |= crease
        bad[tuple(hi)] |= crease
    labels, count = ndimage.label(~bad)
    sizes = np.bincount(labels.ravel())[1:]
    order = np.argsort(-sizes)
    return [labels == k + 1 for k in order if sizes[k] >= min_pixels]


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


def fit_freeform(points: np.ndarray, tol: float, *, grid=None, mask=None, statistic: str = "p95",
                 max_ctrl: int = 40000, cuts: bool = True, params=None) -> FreeformShape:
    """Fit a trimmed NURBS surface to a part's points (n, 3), or to a range grid (rows, cols, 3) with
    its valid mask. `tol` (model units) bounds `statistic` of the residuals. With `cuts`, straight
    planar boundary pieces become described plane intersections. `params` (u, v), each (n,) in [0, 1],
    are scattered points' own parameters (a projection onto a base surface, `rgm.fitters.patches`);
    without them the points are projected onto their best-fit plane."""
    if grid is not None:
        mask = np.isfinite(grid).all(axis=2) if mask is None else mask
        ug, vg = grid_parameters(np.where(mask[..., None], grid, 0.0), mask)
        fit = fit_surface(grid, tol, mask=mask, params=(ug, vg), statistic=statistic, max_ctrl=max_ctrl)
        region, rows, cols, snap = mask, ug, vg, None
        spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)[mask[:, 1:] & mask[:, :-1]]))
    else:
        u, v = plane_parameters(points)[:2] if params is None else map(np.asarray, params)
        fit = fit_surface(points, tol, params=(u, v), statistic=statistic, max_ctrl=max_ctrl)
        bins = int(np.clip(np.sqrt(len(points)) / 2, 24, 256))
        region = _occupancy(u, v, bins)
        rows = cols = (np.arange(bins) + 0.5) / bins
        snap = np.c_[u, v]
        from scipy.spatial import cKDTree

        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
    loops = fit_trim_loops(region, rows, cols, tol_uv=tol / _surface_speed(fit), snap_to=snap)
    outer = list(loops.outer)
    if cuts and len(outer) > 1:  # a range image's own edge is where the sensor stopped, not a cut
        margin = 1.5 / len(rows) if grid is not None else -1.0
        flat = max(tol / 2, 2 * spacing)  # a data boundary is only known to within the point spacing
        outer = [piece if _on_border(piece, margin) else (_as_cut(piece, fit, flat) or piece) for piece in outer]
    return FreeformShape(fit, loops, outer, [list(h) for h in loops.holes])


def _as_cut(piece, fit: SurfaceFit, flat: float):
    """A PlanarCut when the piece's 3-D image lies in a plane within `flat`, is long enough to be a
    deliberate cut (a quarter of the part's size) and crosses the surface at more than 30 degrees;
    otherwise None. A (nearly) straight piece, whose plane the data cannot fix, takes the plane through
    its line and the mean surface normal: a cut square to the surface."""
    uv = _piece_points(piece, 100)
    s = fit.nurbs()
    xyz = s.evaluate(uv[:, 0], uv[:, 1])
    length = np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum()
    if length < 0.25 * np.ptp(fit.ctrl.reshape(-1, 3), axis=0).max():
        return None
    c = xyz.mean(axis=0)
    _, sv, vt = np.linalg.svd(xyz - c, full_matrices=False)
    normals = s.normal(uv[:, 0], uv[:, 1])
    along = (xyz - c) @ vt[0]
    if np.linalg.norm((xyz - c) - np.outer(along, vt[0]), axis=1).max() <= 3 * flat:
        n = np.cross(vt[0], normals.mean(axis=0))          # (nearly) straight: the plane is ambiguous,
        #                                                    take the one through the line and the normal
    else:
        n = vt[2]
        if np.abs((xyz - c) @ n).max() > flat:
            return None
    if np.linalg.norm(n) < 1e-9:
        return None
    n = n / np.linalg.norm(n)
    if np.mean(np.abs(normals @ n)) > 0.5:                  # nearly tangent: not a cut
        return None
    return PlanarCut(np.round(c, _DEC), np.round(n, 8))


def _on_border(piece, margin: float) -> bool:
    """Whether a loop piece runs along the border of the parameter domain [0, 1]² (a range image's edge)."""
    uv = _piece_points(piece, 50)
    return bool(np.all((uv.min(axis=1) < margin) | (uv.max(axis=1) > 1 - margin)))


# ----------------------------------------------------------------------------------------- emission
def _num(x: float, dec: int = _DEC) -> str:
    s = f"{round(float(x), dec) + 0.0:.{dec}f}".rstrip("0").rstrip(".")
    return s if s not in ("-0", "") else "0"


def _knots(k: np.ndarray) -> str:
    return "knots([" + ", ".join(_num(x, _UV_DEC) for x in k) + "])"


def _net_rows(ctrl: np.ndarray, dec: int, indent: str) -> str:
    """Net body rows, one row of the control net per line."""
    rows = [", ".join(" ".join(_num(x, dec) for x in p) for p in row) for row in ctrl]
    return (",\n" + indent).join(rows)


def _curve2(piece) -> str:
    ctrl = np.round(piece.ctrl, _UV_DEC)
    pts = ", ".join(" ".join(_num(x, _UV_DEC) for x in p) for p in ctrl)
    return f"bspline({piece.degree}, {_knots(piece.knots)}, net {len(ctrl)} [{pts}])"


def emit_freeform(shape: FreeformShape, name: str, suffix: str = ""):
    """The `.rgm` bindings of a free-form part: `surface`, its `boundary` and `hole` loops and the trimmed
    face `name`. Returns an `rgm.fitters.emit.EmittedPart` whose `ideal` is rebuilt from the printed
    numbers, so the certificate measures exactly the model the file describes."""
    from rgm.fitters.emit import EmittedPart

    f = shape.fit
    ctrl = np.round(f.ctrl, _DEC)
    nu, nv = ctrl.shape[:2]
    surf = f"surface{suffix}"
    indent = " " * 8
    bindings = [f"{surf} := bsurface(degree_u: {f.degree_u}, degree_v: {f.degree_v},\n"
                f"    knots_u: {_knots(f.knots_u)},\n    knots_v: {_knots(f.knots_v)},\n"
                f"    net: net {nu} x {nv} [\n{indent}{_net_rows(ctrl, _DEC, indent)}]);"]
    pieces = []
    for piece in shape.outer:
        if isinstance(piece, PlanarCut):
            o, n = piece.origin, piece.normal
            pieces.append(f"intersect({surf}, plane(pt({', '.join(_num(x) for x in o)}), "
                          f"vec({', '.join(_num(x, 8) for x in n)})))")
        else:
            pieces.append(_curve2(piece))
    bindings.append(f"boundary{suffix} := loop(\n    " + ",\n    ".join(pieces) + ");")
    holes = []
    for k, hole in enumerate(shape.holes, 1):
        holes.append(f"hole{suffix}_{k}")
        bindings.append(f"hole{suffix}_{k} := loop(\n    " + ",\n    ".join(_curve2(p) for p in hole) + ");")
    bindings.append(f"{name} := trim({surf}, outer: boundary{suffix}, holes: [{', '.join(holes)}]);")
    ideal_fit = SurfaceFit(f.degree_u, f.degree_v, np.round(f.knots_u, _UV_DEC), np.round(f.knots_v, _UV_DEC),
                           ctrl, f.stats, f.residuals, f.history, f.stopped)
    ideal = FreeformShape(ideal_fit, shape.loops, shape.outer, shape.holes)
    return EmittedPart(name, [], bindings, surf, ideal)
