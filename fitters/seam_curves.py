"""Seams no intersection can share: one 3-D boundary curve midway between both surfaces, in both loops.

`rgm.fitters.shared_edges` makes two neighbouring patches share their seam as the intersection of their
surfaces, where the surfaces cross along it. Where they do not (they meet nearly tangentially, stop short
of the crease, or cross elsewhere), each face kept its own data trim, and the two trims, each a few point
spacings inside its data, missed each other by a few millimetres at a 1 mm tolerance (the YCB potted meat
can: 16 of 42 seams). Yet the surfaces themselves usually pass within the tolerance of each other along
the seam; only the trims are apart. Here such a seam becomes one curve that both faces' loops use:

1. The seam samples of one face's data loop (`rgm.fitters.shared_edges`: the longer of the two faces'
   runs whose nearest other point belongs to the other face) are moved midway between the surfaces by
   alternating closest points, x <- (P_i(x) + P_j(x)) / 2 (`_ROUNDS` rounds), which brings them onto the
   intersection where the surfaces cross (a round shrinks the distance to it by (1 + cos t) / 2 at worst,
   t the crossing angle, and the distances to the surfaces by (1 - cos t) / 2) and into the middle of their
   closest approach where they do not.
2. The stretch both faces border (the other face's seam samples located on it) is fitted by a cubic
   B-spline to a twentieth of the tolerance (`fit_curve`: knots inserted where it is exceeded). Where the
   surfaces part by more than the tolerance along it, the curve keeps the longest stretch where they pass
   within `_WITHIN` of it, and both faces' runs are cut to that stretch: beyond its ends they keep their
   data pieces (YCB meat can: the lid's pieces meet the mantle's rolled rim along part of their seam).
3. Each back end takes a 3-D trimming curve's closest points on its face's surface, so the two faces'
   edges lie at most d_i + d_j apart, d being the curve's distance from each surface: the curve is used
   only if d_i + d_j <= the tolerance at dense samples, and its closest points on each surface do not
   jump (a surface folding back near the seam would give an edge that leaves the curve). The loops are
   then rebuilt and the gap measured as the back ends see it (`measure_curve`), as for a shared
   intersection.

The `.rgm` says it: `seam_3_5 := bspline(3, knots(...), net k [x y z, ...]);` used in both `trim`s.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rgm.errors import GeometryError

__all__ = ["seam_curve", "measure_curve", "curve_edge", "meets_start"]

_ROUNDS = 8         # alternating closest-point rounds
_FIT = 20           # the curve is fitted to tol / _FIT
_SAMPLES = 400      # dense samples of the curve: its distance to both surfaces, each face's uv of it
_JUMP = 8           # a step between consecutive closest points this many times their median is a jump
_WITHIN = 0.8       # the curve runs where the surfaces pass within this share of the tolerance of each other


def _midway(si, sj, x):
    """x (k, 3) moved midway between surfaces si and sj: alternating closest points."""
    from rgm.geometry.inversion import closest_point_surface

    for _ in range(_ROUNDS):
        x = 0.5 * (np.asarray(closest_point_surface(si, x)[2]) + np.asarray(closest_point_surface(sj, x)[2]))
    return x


def _apart(si, sj, x) -> np.ndarray:
    """(k,) the distances of points x (k, 3), midway between surfaces si and sj, to both surfaces summed:
    how far apart the surfaces pass there."""
    from rgm.geometry.inversion import closest_point_surface

    return np.asarray(closest_point_surface(si, x)[3]) + np.asarray(closest_point_surface(sj, x)[3])


def curve_edge(surface, curve, m: int = _SAMPLES):
    """(uv (m, 2), distances (m,)) of the closest points on `surface` (NurbsSurface) of m samples of a 3-D
    `curve` (NurbsCurve) at equal parameter steps: the face's edge as the back ends take the curve."""
    from rgm.geometry.inversion import closest_point_surface

    u, v, _, d = closest_point_surface(surface, curve.evaluate(np.linspace(*curve.domain, m)))
    return np.c_[u, v], np.asarray(d)


def meets_start(surface, uv, curve) -> bool:
    """Whether a face's loop arriving at uv (2,) on `surface` (NurbsSurface) meets the 3-D seam `curve`
    (NurbsCurve) at its start (nearer C(t0) than C(t1)), so runs it forwards."""
    here = surface.evaluate(*np.asarray(uv, float)[:, None])[0]
    tips = curve.evaluate(np.array(curve.domain, float))
    return bool(np.linalg.norm(here - tips[0]) <= np.linalg.norm(here - tips[1]))


def seam_curve(i: int, j: int, shapes, loops, runs, tol: float, near: float, spacing: float):
    """A `rgm.fitters.shared_edges._Candidate` for the seam of faces i and j whose edge is one 3-D curve
    (its `curve`, a NurbsCurve) midway between their surfaces (module docstring), or the reason (str) why
    there is none. `loops`: the faces' `_Loop` samples; `runs`: {face: its `_Run` of the seam}; `near`
    (model units): how far a face's seam samples may lie from the other face's.

    The longer of the two runs, moved midway, is the curve's course; the other face's side of the seam is
    its loop samples bordering the first face within `near` of that run; the curve runs where both sides
    do (the longer run is cut there, its rest staying data joined at the curve's ends)."""
    from rgm.fitters.freeform import fit_curve
    from rgm.fitters.shared_edges import _Candidate, _Run, _longest_run
    from rgm.geometry import NurbsCurve

    si, sj = shapes[i].nurbs(), shapes[j].nurbs()
    a, b = (i, j) if len(runs[i].idx) >= len(runs[j].idx) else (j, i)
    # face b's side: its loop samples bordering face a within `near` of face a's run (a face may border
    # its neighbour in two places, and each face's longest run be another one)
    d = cKDTree(loops[a].xyz[runs[a].idx]).query(loops[b].xyz)[0]
    run_b = _longest_run((loops[b].owner == a) & (d <= near))
    if run_b is None or len(run_b.idx) < 6:
        return "the two faces' sides of the seam lie apart"
    runs = {a: runs[a], b: run_b}
    start = loops[a].xyz[runs[a].idx]
    mid = _midway(si, sj, start)
    # the crease lies a few spacings from each trim: a sample that moved farther found another part of
    # a surface (a closest point elsewhere, surfaces crossing away from the seam), and the curve keeps
    # the longest stretch of samples that did not
    moved = _longest_run(np.r_[np.linalg.norm(mid - start, axis=1) <= near, False], close=0)
    if moved is None or len(moved.idx) < 6:
        return "the surfaces' closest approach lies away from the seam"
    # the curve runs where both faces border each other: face a's run cut to face b's side (the rest of
    # face a's run stays data, joined at the curve's ends)
    k = cKDTree(mid[moved.idx]).query(loops[b].xyz[run_b.idx])[1]
    keep = moved.idx[k.min():k.max() + 1]
    # and where the surfaces pass within the tolerance of each other: where they part, the curve keeps the
    # longest stretch where they pass within `_WITHIN` of it (a margin for the curve's own error), and
    # beyond it the faces keep their data pieces, joined at the curve's ends
    apart = _apart(si, sj, mid[keep])
    if apart.max() > tol:
        within = _longest_run(np.r_[apart <= _WITHIN * tol, False], close=0)
        if within is None or len(within.idx) < 6:
            return (f"no curve lies within the tolerance of both surfaces along the seam (they pass "
                    f"{apart.min():.2f} mm apart at their closest)")
        keep = keep[within.idx]
        on = cKDTree(mid[keep]).query(loops[b].xyz[run_b.idx])[1]   # face b's side cut to the same stretch
        inner = _longest_run(np.r_[(on > 0) & (on < len(keep) - 1), False], close=0)
        if inner is None or len(inner.idx) < 6:
            return "the two faces' sides of the seam lie apart where the surfaces pass within the tolerance"
        idx_b = run_b.idx[inner.idx]
        runs[b] = _Run(int(idx_b[0]), int(idx_b[-1]), idx_b)
    stretch = mid[keep]
    idx = runs[a].idx[keep]
    runs[a] = _Run(int(idx[0]), int(idx[-1]), idx)
    length = float(np.linalg.norm(np.diff(stretch, axis=0), axis=1).sum())
    if length < 4 * spacing:
        return f"a common curve would be {length:.2f} mm long, under four point spacings"
    side = loops[b].xyz[runs[b].idx[[0, -1]]]    # face b runs the curve forwards if its run starts near C(0)
    forward = np.linalg.norm(side - stretch[[0, -1]], axis=1).sum() <= \
        np.linalg.norm(side - stretch[[-1, 0]], axis=1).sum()
    try:
        fit = fit_curve(stretch, tol / _FIT, fix_ends=True)
    except GeometryError as exc:
        return f"no common curve could be fitted ({exc})"
    curve = NurbsCurve(fit.degree, fit.knots, fit.ctrl, None)
    (uv_i, d_i), (uv_j, d_j) = curve_edge(si, curve), curve_edge(sj, curve)
    apart = float(np.max(d_i + d_j))
    if apart > tol:
        return f"no curve lies within the tolerance of both surfaces along the seam ({apart:.2f} mm apart)"
    for face, uv in ((i, uv_i), (j, uv_j)):   # each face's edge, the curve's closest points, must not jump
        step = np.linalg.norm(np.diff(uv, axis=0), axis=1)
        if step.max() > _JUMP * np.median(step):
            return (f"the common curve's closest points on surface {face + 1} jump (its surface folds back "
                    f"near the seam): its edge would not follow the curve")
    xyz = curve.evaluate(np.linspace(*curve.domain, _SAMPLES))
    rising = {a: True, b: bool(forward)}   # the curve runs along face a's loop
    return _Candidate(i, j, xyz, {i: uv_i, j: uv_j}, 0, _SAMPLES - 1, runs, rising, None, curve)


def measure_curve(i: int, j: int, shape_i, shape_j, curve) -> tuple[float, float, int, float]:
    """(max, p95, samples, length) of the G0 gap along a shared 3-D seam curve as the back ends see it:
    each face's edge is its surface at the closest points of the curve's samples; the points of each
    edge are measured to the other edge (a dense polyline), both ways."""
    from rgm.fitters.shared_edges import edge_gap

    edges = []
    for shape in (shape_i, shape_j):
        s = shape.nurbs()
        uv, _ = curve_edge(s, curve, 4 * _SAMPLES)
        edges.append(s.evaluate(uv[:, 0], uv[:, 1]))
    return edge_gap(*edges)
