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
within `near` (5 point spacings), belongs to b, and lies *beyond* the edge: within 72 degrees of the direction in which the
surface leaves its trim. A sample on a free border next to a seam's end has its nearest other
point sideways or behind, along the border, and is not counted (the fitter's own measure counts it, and
reads a notch there). Its gap is its distance to the nearest other trimmed face among
those owning scan points within `near` of it (at a corner of three faces, the third may close it).
Faces of other kinds (revolutions, boxes) are not measured.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SeamGap", "edge_samples", "measure_seams", "worst_per_face"]

_NEAR = 5.0       # point spacings within which another face's scan point puts a sample on a seam
_BEYOND = 0.3     # cosine: the other face's nearest point lies beyond the edge (within 72 degrees of outward)
_PROBE = 1e-4     # parameter step (share of the domain) that finds which side of a loop is outside


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
    """(xyz (m, 3), segment (m,), uv (m, 2)): points on `surface` along the closed (u, v) polygon `loop`
    (k, 2) (last vertex not repeated), about `step` (model units) apart by arc length on the surface
    (linearly in (u, v) between its vertices; at least `least`), and the polygon segment each lies on."""
    uv = np.vstack([loop, loop[:1]])
    along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(surface.evaluate(uv[:, 0], uv[:, 1]), axis=0), axis=1))]
    t = np.linspace(0.0, along[-1], max(int(along[-1] / step), least), endpoint=False)
    segment = np.clip(np.searchsorted(along, t, side="right") - 1, 0, len(loop) - 1)
    at = np.c_[np.interp(t, along, uv[:, 0]), np.interp(t, along, uv[:, 1])]
    return surface.evaluate(at[:, 0], at[:, 1]), segment, at


def _outward(face, loop: np.ndarray, segment: np.ndarray, uv: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """(m, 3) unit directions in which the surface leaves the face across its loop at the samples: away
    from the side of the loop, probed a little way off in (u, v), that is on the face (zero where neither
    side or both are). A loop along the domain's edge has its outside off the surface: the inside tells."""
    (u0, u1), (v0, v1) = face.surface.domain
    tangent = np.roll(loop, -1, axis=0)[segment] - loop[segment]
    normal = np.c_[tangent[:, 1], -tangent[:, 0]]
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    h = _PROBE * max(u1 - u0, v1 - v0)
    lo, hi = np.array([u0, v0]), np.array([u1, v1])

    def on_face(probe):
        return np.all((probe >= lo) & (probe <= hi), axis=1) & face.inside(np.clip(probe, lo, hi))

    plus, minus = uv + h * normal, uv - h * normal
    in_plus, in_minus = on_face(plus), on_face(minus)
    inward = np.clip(np.where(in_plus[:, None], plus, minus), lo, hi)
    direction = xyz - face.surface.evaluate(inward[:, 0], inward[:, 1])
    direction[in_plus == in_minus] = 0.0
    return direction / np.maximum(np.linalg.norm(direction, axis=1), 1e-300)[:, None]


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
            xyz, segment, uv = edge_samples(face.surface, loop, spacing / 2)
            d, j = search.query(xyz, distance_upper_bound=near)
            hit = np.flatnonzero(np.isfinite(d))
            q = points[others[j[hit]]]
            toward = (q - xyz[hit]) / np.maximum(d[hit], 1e-300)[:, None]
            beyond = np.einsum("ij,ij->i", toward, _outward(face, loop, segment[hit], uv[hit], xyz[hit])) > _BEYOND
            hit, b = hit[beyond], owner[others[j[hit[beyond]]]]
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
