"""G0 measured on a written model (`rgm.fitters.seam_check`): two flat faces whose edges are a known
distance apart, and a folded pair meeting at a crease, sampled as a scanner would."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from rgm.fitters.certificate import nearest_part
from rgm.fitters.freeform_measure import TrimmedNurbs
from rgm.fitters.seam_check import measure_seams, worst_per_face
from rgm.geometry.surface import NurbsSurface


def _plane(origin, du, dv) -> NurbsSurface:
    """The bilinear patch origin + s du + t dv, s, t in [0, 1] (mm)."""
    o, du, dv = (np.asarray(x, float) for x in (origin, du, dv))
    ctrl = np.array([[o, o + dv], [o + du, o + du + dv]])
    return NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], ctrl)


def _rectangle(lo, hi, ccw=True, per_side=64) -> np.ndarray:
    """The (u, v) rectangle lo..hi as a closed polygon (4 per_side vertices, last not repeated), as
    densely sampled as the loops a model's trims give (`TrimmedNurbs.from_model`)."""
    (u0, v0), (u1, v1) = lo, hi
    corners = np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1], [u0, v0]], float)
    t = np.linspace(0, 1, per_side, endpoint=False)[:, None]
    ring = np.vstack([p + t * (q - p) for p, q in zip(corners[:-1], corners[1:])])
    return ring if ccw else ring[::-1]


def _face(surface, lo, hi, holes=()) -> TrimmedNurbs:
    """The face of `surface` trimmed to the (u, v) rectangle lo..hi, with rectangular `holes` ((lo, hi) each)."""
    return TrimmedNurbs(surface, (_rectangle(lo, hi),) + tuple(_rectangle(*h, ccw=False) for h in holes))


def _scan(faces, spacing, rng):
    """Points on the faces about `spacing` apart (one in each cell of a grid over the face's parameter box,
    jittered about its centre), 0.01 mm of noise along z."""
    out = []
    for f in faces:
        lo, hi = f.loops[0].min(axis=0), f.loops[0].max(axis=0)
        corner = f.surface.evaluate(np.r_[lo[0], hi[0], lo[0]], np.r_[lo[1], lo[1], hi[1]])
        n = np.maximum(np.linalg.norm(corner[1:] - corner[0], axis=1) / spacing, 1).astype(int)
        u, v = np.meshgrid((np.arange(n[0]) + 0.5) / n[0], (np.arange(n[1]) + 0.5) / n[1])
        uv = lo + (np.c_[u.ravel(), v.ravel()] + rng.uniform(-0.3, 0.3, (u.size, 2)) / n) * (hi - lo)
        uv = uv[f.inside(uv)]
        out.append(f.surface.evaluate(uv[:, 0], uv[:, 1]))
    pts = np.vstack(out)
    return pts + rng.normal(0, 0.01, pts.shape) * [0, 0, 1]


@settings(max_examples=15, deadline=None)
@given(gap=st.floats(0.0, 3.5), seed=st.integers(0, 2**16))
def test_two_faces_a_known_distance_apart_measure_that_gap_and_free_borders_do_not_count(gap, seed):
    """A plate x in [0, 40 + gap], y in [0, 20], z = 0 (mm), scanned 0.5 mm apart, modelled by face A (x
    in [0, 20]) and face B (x in [20 + gap, 40 + gap]): one seam, whose largest gap is `gap` (to the
    sampling's few hundredths; up to twice the 5 spacings within which a neighbour's point is looked for
    (1.9 mm), as the points in the hole belong to the nearer face), however far the free borders y = 0
    and y = 20 run beside the seam's ends."""
    rng = np.random.default_rng(seed)
    a = _face(_plane([0, 0, 0], [20, 0, 0], [0, 20, 0]), (0, 0), (1, 1))
    b = _face(_plane([20 + gap, 0, 0], [20, 0, 0], [0, 20, 0]), (0, 0), (1, 1))
    pts = _scan([_face(_plane([0, 0, 0], [40 + gap, 0, 0], [0, 20, 0]), (0, 0), (1, 1))], 0.5, rng)
    owner, _ = nearest_part([a, b], pts)
    seams = measure_seams({0: a, 1: b}, pts, owner)
    assert [(s.a, s.b) for s in seams] == [(0, 1)]
    assert abs(seams[0].max - gap) <= 0.05, (seams[0], gap)
    # samples about 0.2 mm apart (half the scan's median spacing) along both faces' 20 mm edges (fewer
    # where the hole nears twice that search: the points half-way across it are farther from the edges)
    assert seams[0].samples >= (2 * 20 / 0.3 if gap <= 3.0 else 20)
    assert worst_per_face(seams) == {0: seams[0].max, 1: seams[0].max}


@pytest.mark.parametrize("degrees", [45, 90, 135])
def test_a_crease_measures_the_trims_not_the_surfaces_and_an_island_is_seen_from_its_hole(degrees):
    """A roof scanned whole: face A (z = 0, x <= 20) and face B rising at `degrees` from the crease x =
    20 (a box's edge at 90, a fold at 135), its trim starting 1 mm up the slope: the seam reads the 1 mm
    hole (both ways: A's edge, at the crease, to B's, and B's edge to A's face), not the surfaces'
    nearness (they meet). A small face C, 0.2 mm above a square hole of A whose edges lie 0.3 mm outside
    its own, reads its gap from both loops."""
    rng = np.random.default_rng(3)
    a = _face(_plane([0, 0, 0], [20, 0, 0], [0, 20, 0]), (0, 0), (1, 1), holes=[((0.4, 0.4), (0.6, 0.6))])
    slope = _plane([20, 0, 0], 15 * np.array([np.cos(np.radians(degrees)), 0, np.sin(np.radians(degrees))]),
                   [0, 20, 0])
    b = _face(slope, (1 / 15, 0), (1, 1))
    c = _face(_plane([8.3, 8.3, 0.2], [3.4, 0, 0], [0, 3.4, 0]), (0, 0), (1, 1))
    pts = _scan([_face(a.surface, (0, 0), (1, 1)), _face(slope, (0, 0), (1, 1))], 0.5, rng)
    owner, _ = nearest_part([a, b, c], pts)
    seams = {(s.a, s.b): s for s in measure_seams({0: a, 1: b, 2: c}, pts, owner)}
    assert set(seams) == {(0, 1), (0, 2)}
    # 1 mm along the crease; samples of A's free borders within a fifth of a millimetre of its corner,
    # where B's nearest points lie outward (at 45 and 90 degrees), read up to 0.16 mm more
    assert abs(seams[(0, 1)].p95 - 1.0) <= 0.02 and 1.0 - 0.02 <= seams[(0, 1)].max <= 1.2, seams[(0, 1)]
    # along the sides hypot(0.2, 0.3) = 0.36 mm; at the corners, 0.3 mm off in both directions, 0.47 mm
    # (the last samples before a corner, whose neighbour points lie diagonally, are not counted)
    assert np.hypot(0.2, 0.3) - 0.02 <= seams[(0, 2)].max <= np.sqrt(0.3**2 + 0.3**2 + 0.2**2) + 0.02, seams[(0, 2)]
    assert abs(seams[(0, 2)].p95 - np.hypot(0.2, 0.3)) <= 0.05, seams[(0, 2)]
