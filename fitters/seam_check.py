"""G0 of a written model: the gaps where its trimmed faces meet, measured from the file and the scans.

`rgmc fit` measures its seams while it fits (`rgm.fitters.patches.g0_gaps`, on the patches' own points).
A designer who edits the `.rgm` needs the same check on the file alone: `rgmc verify` compiles it, and
every face's edges are measured against its neighbours' faces as the file describes them (trims and
described intersections as `rgm.fitters.freeform_measure.TrimmedNurbs.from_model` evaluates them).
`rgmc fit` records each face's worst gap, measured this same way on the faces it prints, in its `@fit`
annotation (`g0`), so that verify tells a seam the fit left open from one an edit opened.

Which samples lie on a seam (the scans say it, not the geometry): each face's loops, outer and holes, are
sampled about half a point spacing apart (by arc length on the surface). A sample lies on the seam with
face b when the nearest scan point owned by another face (`rgm.fitters.certificate.nearest_part`) is
within `near` (5 point spacings) and belongs to b, and b's points among the 8 nearest lie *across* the
edge, not along it: their centre more than 60 degrees from the edge's direction. Across a seam the
neighbour's data leave the edge at right angles to it, whatever the angle between the faces (in line
with the face, or at a box's right-angled crease); a sample on a free border next to a seam's end has
the neighbour's nearest points ahead of it, along the border, and is not counted (the fitter's own
measure counts it up to 5 spacings from the seam, and reads a notch there). So are the samples within
about a spacing of a face's corner, where the neighbours' points lie diagonally: a gap that opens at the
corner itself reads as it is a spacing before it. Its gap
is its distance to the nearest other trimmed face among those owning scan points within `near` of it
(at a corner of three faces, the third may close it). A hole wider than twice `near` is not seen as a
seam (the points in it belong to the nearer face: half-way across, none is near the other face's
edge). Faces of other kinds (revolutions, boxes) are not measured.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SeamGap", "edge_samples", "measure_seams", "worst_per_face"]

_NEAR = 5.0       # point spacings within which another face's scan point puts a sample on a seam
_ALONG = 0.5      # |cosine| between the edge and the way to the other face's nearest points, above which they lie along it
_K = 8            # the other face's nearest points whose centre says which way they lie


@dataclass(frozen=True)
class SeamGap:
    """The measured G0 gap between faces a < b (model units): max and 95th percentile over `samples`
    edge samples of both faces."""

    a: int
    b: int
    max: float
    p95: float
    samples: int


def edge_samples(surface, loop: np.ndarray, step: float, least: int = 16):
    """(xyz (m, 3), segment (m,), directions (k, 3)): points on `surface` along the closed (u, v) polygon
    `loop` (k, 2) (last vertex not repeated), about `step` (model units) apart by arc length on the
    surface (linearly in (u, v) between its vertices; at least `least`), the polygon segment each lies
    on, and each segment's unit direction in space."""
    uv = np.vstack([loop, loop[:1]])
    step_xyz = np.diff(surface.evaluate(uv[:, 0], uv[:, 1]), axis=0)
    length = np.linalg.norm(step_xyz, axis=1)
    along = np.r_[0.0, np.cumsum(length)]
    t = np.linspace(0.0, along[-1], max(int(along[-1] / step), least), endpoint=False)
    segment = np.clip(np.searchsorted(along, t, side="right") - 1, 0, len(loop) - 1)
    xyz = surface.evaluate(np.interp(t, along, uv[:, 0]), np.interp(t, along, uv[:, 1]))
    return xyz, segment, step_xyz / np.maximum(length, 1e-300)[:, None]


def _partners(xyz, directions, points, owner, others, search, near: float):
    """(hit (h,), partner (h,)): which of the edge samples xyz (m, 3), running along `directions` (m, 3),
    lie on a seam (module docstring), and the face each lies on a seam with. `owner` (n,): the face of
    each point (n, 3); `others` the indices of the points of faces other than the edge's, `search` their
    k-d tree; `near` (model units) how far a neighbour's point may lie."""
    d, j = search.query(xyz, k=_K, distance_upper_bound=near)
    hit = np.flatnonzero(np.isfinite(d[:, 0]))
    j = np.minimum(j[hit], len(others) - 1)
    b = owner[others[j[:, 0]]]
    mine = np.isfinite(d[hit]) & (owner[others[j]] == b[:, None])   # b's among the k nearest
    toward = np.einsum("mk,mkd->md", mine, points[others[j]]) / mine.sum(axis=1)[:, None] - xyz[hit]
    toward /= np.maximum(np.linalg.norm(toward, axis=1), 1e-300)[:, None]
    across = np.abs(np.einsum("ij,ij->i", toward, directions[hit])) < _ALONG
    return hit[across], b[across]


def measure_seams(faces: dict, points: np.ndarray, owner: np.ndarray, spacing: float | None = None) -> list[SeamGap]:
    """The seams between trimmed faces (module docstring): `faces` {index: TrimmedNurbs} of the model's
    parts, `owner` (n,) the part nearest each scan point (n, 3) (indices as in `faces`; parts not in it
    own points but are not measured), `spacing` the scans' point spacing (None: as `rgmc fit` measures
    it, `rgm.fitters.classify.spacing`)."""
    from rgm.fitters.classify import spacing as point_spacing

    points = np.asarray(points, float)
    spacing = point_spacing(points) if spacing is None else spacing
    near = _NEAR * spacing
    trees = {k: cKDTree(points[owner == k]) for k in faces if np.any(owner == k)}
    found: dict[tuple[int, int], list[np.ndarray]] = {}
    for a, face in faces.items():
        others = np.flatnonzero((owner >= 0) & (owner != a))
        if len(others) == 0:
            continue
        search = cKDTree(points[others])
        for loop in face.loops or ():
            xyz, segment, directions = edge_samples(face.surface, loop, spacing / 2)
            hit, b = _partners(xyz, directions[segment], points, owner, others, search, near)
            keep = np.isin(b, list(faces))
            hit, b = hit[keep], b[keep]
            gap = np.full(len(hit), np.inf)
            for c, tree in trees.items():
                if c == a:
                    continue
                close = np.isfinite(tree.query(xyz[hit], distance_upper_bound=near)[0])
                if close.any():
                    gap[close] = np.minimum(gap[close], faces[c].distance(xyz[hit][close]))
            for other in np.unique(b):
                found.setdefault((min(a, int(other)), max(a, int(other))), []).append(gap[b == other])
    out = []
    for (a, b), parts in sorted(found.items()):
        d = np.concatenate(parts)
        out.append(SeamGap(a, b, float(d.max()), float(np.percentile(d, 95)), len(d)))
    return out


def worst_per_face(seams: list[SeamGap]) -> dict[int, float]:
    """{face: the largest gap of any seam it is on}."""
    worst: dict[int, float] = {}
    for s in seams:
        for k in (s.a, s.b):
            worst[k] = max(worst.get(k, 0.0), s.max)
    return worst
