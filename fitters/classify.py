"""Shape classification from a recovered superellipsoid, and the splitting of multipart scans.

Categories select the model builder (Solina & Bajcsy 1990; Raja & Jain 1992, "Recognizing geons from
superquadrics fitted to range data"): ``sphere``, ``ellipsoid``, ``cylinder``, ``box``,
``other_revolution`` and ``free_form``.

The rules (each a soft membership in [0, 1], so that the winner comes with a confidence and a runner-up):

- *good fit*  G = s((QUALITY_FREE_FORM - quality) / 0.006): the median radial distance is below ~2.5 % of
  the mean semi-axis.  Every category but ``free_form`` is multiplied by G; ``free_form`` scores 1 - G.
- *flat* exponent  (eps <= ~0.45: straight edges) f(eps) = s((0.45 - eps) / 0.06);
  *round* exponent (eps >= ~0.7: an ellipse) r(eps) = s((eps - 0.7) / 0.06), s the logistic function.
- *equal* semi-axes  e(a, b) = exp(-((max/min - 1) / 0.06)^2): within a few per cent.
- box = G f(eps1) f(eps2);  cylinder = G f(eps1) r(eps2) e(a1, a2) (axis = local z);
  sphere = G r(eps1) r(eps2) e(a1, a2) e(a2, a3) e(a1, a3);
  ellipsoid = G r(eps1) r(eps2) (1 - e(a1, a2) e(a2, a3) e(a1, a3));
  other_revolution = G r(eps2) e(a1, a2) (1 - f(eps1)) (1 - r(eps1))  (round section, curved profile).
- *symmetric*  R = s((SPREAD_REVOLUTION - spread) / 0.006), when the points are given: spread is how far
  the part is from any surface of revolution, the profile's noise sigma about the axis from the normals
  (`rgm.fitters.revolution.refine_axis`: differences of consecutive r along z and z along r, which
  cancel the profile's own shape but not a lack of symmetry) over the mean semi-axis.  A part that no
  superellipsoid fits but that is rotationally symmetric (a vase, a bulged pin) is a revolution all
  the same: other_revolution gains (1 - G) R and free_form becomes (1 - G)(1 - R).
- confidence = winner's score / sum of scores.

Splitting (`split_parts`): connected components of the radius graph (scipy cKDTree pairs within
`gap` of each other on a voxel grid, `scipy.sparse.csgraph.connected_components`), then, for a component whose
superellipsoid fits badly and that is not rotationally symmetric (spread at or above SPREAD_REVOLUTION:
a vase is one part, not two), a recursive cut by the plane through the centroid across the principal
axis (Leonardis, Jaklič & Solina 1997 split-and-merge in its simplest form), kept only when both halves
fit clearly better.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.fitters.superellipsoid import Superellipsoid, fit_superellipsoid

__all__ = ["CATEGORIES", "Classification", "classify", "category_scores", "revolution_spread", "split_parts",
           "QUALITY_FREE_FORM", "SPREAD_REVOLUTION"]

CATEGORIES = ("sphere", "ellipsoid", "cylinder", "box", "other_revolution", "free_form")
#: quality (median radial distance / mean semi-axis) above which a part counts as free form
QUALITY_FREE_FORM = 0.025
#: spread (profile noise sigma about the best axis / mean semi-axis) below which a part is rotationally symmetric
SPREAD_REVOLUTION = 0.025


@dataclass(frozen=True)
class Classification:
    """category and runner_up are names from CATEGORIES; scores maps every category to its score."""

    category: str
    confidence: float
    runner_up: str
    scores: dict
    superellipsoid: Superellipsoid


def _s(x):
    return 1.0 / (1.0 + np.exp(-np.clip(x, -50, 50)))


def _equal(a, b):
    return float(np.exp(-((max(a, b) / min(a, b) - 1.0) / 0.06) ** 2))


def revolution_spread(points, se: Superellipsoid, *, max_points: int = 3000, seed: int = 0) -> float:
    """How far the points (n, 3) are from a surface of revolution (module docstring, R), on a fixed-seed
    subsample of at most `max_points`: the profile's noise sigma (mm) over the mean semi-axis of `se`."""
    from rgm.fitters.normals import pca_normals
    from rgm.fitters.revolution import axis_from_normals, refine_axis

    points = np.asarray(points, float)
    if len(points) > max_points:
        points = points[np.random.default_rng(seed).choice(len(points), max_points, replace=False)]
    normals, _ = pca_normals(points)
    sigma = refine_axis(points, normals, *axis_from_normals(points, normals))[2]
    return float(sigma / np.mean(se.size))


def category_scores(se: Superellipsoid, spread: float | None = None) -> dict:
    """The membership score of each category (module docstring rules) for a recovered superellipsoid and,
    if known, the part's `revolution_spread`."""
    a1, a2, a3 = se.size
    e1, e2 = se.eps
    good = float(_s((QUALITY_FREE_FORM - se.quality) / 0.006))
    flat1, flat2 = _s((0.45 - e1) / 0.06), _s((0.45 - e2) / 0.06)
    round1, round2 = _s((e1 - 0.7) / 0.06), _s((e2 - 0.7) / 0.06)
    eq12, all_eq = _equal(a1, a2), _equal(a1, a2) * _equal(a2, a3) * _equal(a1, a3)
    symmetric = 0.0 if spread is None else float(_s((SPREAD_REVOLUTION - spread) / 0.006))
    scores = {
        "sphere": good * round1 * round2 * all_eq,
        "ellipsoid": good * round1 * round2 * (1.0 - all_eq),
        "cylinder": good * flat1 * round2 * eq12,
        "box": good * flat1 * flat2,
        "other_revolution": good * round2 * eq12 * (1.0 - flat1) * (1.0 - round1) + (1.0 - good) * symmetric,
        "free_form": (1.0 - good) * (1.0 - symmetric),
    }
    return {k: float(v) for k, v in scores.items()}


def classify(points=None, *, superellipsoid: Superellipsoid | None = None) -> Classification:
    """Classify a part from its points (n, 3) (a superellipsoid is recovered unless given) or from a given
    superellipsoid alone.  With the points, a part that no superellipsoid fits is also tested for
    rotational symmetry (`revolution_spread`)."""
    se = superellipsoid if superellipsoid is not None else fit_superellipsoid(points)
    spread = None
    if points is not None and se.quality > 0.5 * QUALITY_FREE_FORM:
        spread = revolution_spread(points, se)
    scores = category_scores(se, spread)
    order = sorted(scores, key=scores.get, reverse=True)
    total = sum(scores.values()) or 1.0
    return Classification(order[0], scores[order[0]] / total, order[1], scores, se)


def connected_components(points, gap: float) -> list[np.ndarray]:
    """Index arrays of the connected components of the points (n, 3) joined when closer than about `gap`
    (largest first).  Computed on a voxel grid of cell `gap`: occupied cells sharing a face, edge or
    corner are connected (scipy.sparse.csgraph.connected_components), so points up to gap apart are
    always joined and points more than 2 sqrt(3) gap apart never directly."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components as _cc

    cell = np.floor((points - points.min(axis=0)) / gap).astype(np.int64) + 1
    dims = cell.max(axis=0) + 2
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    cells, inverse = np.unique(key, return_inverse=True)
    offsets = np.array([(dx * dims[1] + dy) * dims[2] + dz for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                        for dz in (-1, 0, 1) if (dx, dy, dz) > (0, 0, 0)])
    nb = cells[:, None] + offsets[None, :]
    pos = np.minimum(np.searchsorted(cells, nb), len(cells) - 1)
    hit = cells[pos] == nb
    rows = np.broadcast_to(np.arange(len(cells))[:, None], nb.shape)[hit]
    m = len(cells)
    count, labels = _cc(coo_matrix((np.ones(len(rows)), (rows, pos[hit])), shape=(m, m)), directed=False)
    labels = labels[inverse.ravel()]
    parts = [np.flatnonzero(labels == k) for k in range(count)]
    return sorted(parts, key=len, reverse=True)


def spacing(points) -> float:
    """Median nearest-neighbour distance of `points` (n, 3): the scan's sampling pitch."""
    from scipy.spatial import cKDTree

    sample = points[:: max(1, len(points) // 5000)]
    d, _ = cKDTree(points).query(sample, k=2)
    return float(np.median(d[:, 1]))


def split_parts(points, *, gap: float | None = None, min_points: int = 200, max_depth: int = 2,
                min_fraction: float = 0.02) -> list[tuple[np.ndarray, Superellipsoid]]:
    """Split a cloud (n, 3) into parts; returns (index array into `points`, its superellipsoid) pairs,
    largest part first.

    gap : points closer than this are connected (default 4 x the median point spacing).
    Components smaller than `min_fraction` of the cloud (or `min_points`) are dropped as debris.
    Badly fitting components are cut recursively (module docstring) up to `max_depth` times.
    """
    points = np.asarray(points, float)
    gap = 4.0 * spacing(points) if gap is None else gap
    keep = max(min_points, int(min_fraction * len(points)))
    parts = [p for p in connected_components(points, gap) if len(p) >= keep]
    out = []
    for part in parts:
        out.extend(_split_badly_fitting(points, part, fit_superellipsoid(points[part]), max_depth, min_points))
    return sorted(out, key=lambda pair: len(pair[0]), reverse=True)


def _split_badly_fitting(points, idx, se, depth, min_points):
    if depth == 0 or se.quality <= QUALITY_FREE_FORM or len(idx) < 2 * min_points:
        return [(idx, se)]
    if revolution_spread(points[idx], se) < SPREAD_REVOLUTION:  # one surface of revolution: one part
        return [(idx, se)]
    x = points[idx] - points[idx].mean(axis=0)
    axis = np.linalg.eigh(np.cov(x.T))[1][:, -1]
    side = x @ axis > 0
    halves = [idx[side], idx[~side]]
    if min(len(h) for h in halves) < min_points:
        return [(idx, se)]
    fits = [fit_superellipsoid(points[h]) for h in halves]
    if max(f.quality for f in fits) > 0.6 * se.quality:
        return [(idx, se)]
    return [pair for h, f in zip(halves, fits) for pair in _split_badly_fitting(points, h, f, depth - 1, min_points)]
