"""Trimming loops from a data mask (issue 8): closed loops, outer counter-clockwise, holes clockwise,
within tolerance of the mask's boundary; valid (simple, holes inside and apart) on pinched, narrow regions."""
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.fitters.freeform import design_matrix
from rgm.fitters.trimloops import (check_loops, crosses_itself, crossing_pairs, fit_trim_loops, is_simple,
                                   loop_stats_max, mask_contours, signed_area)


def loop_points(loop, m=500):
    """Points along a loop's consecutive pieces, checking that each piece starts where the last ended."""
    out = []
    for piece in loop:
        pts = design_matrix(np.linspace(0, 1, m), piece.knots, piece.degree) @ piece.ctrl
        if out:
            assert np.linalg.norm(out[-1][-1] - pts[0]) < 1e-12
        out.append(pts)
    return np.vstack(out)


@settings(max_examples=25, deadline=None)
@given(r0=st.integers(2, 10), c0=st.integers(2, 10), h=st.integers(12, 40), w=st.integers(12, 40),
       hole=st.booleans())
def test_rectangle_with_optional_hole(r0, c0, h, w, hole):
    mask = np.zeros((60, 60), bool)
    mask[r0:r0 + h, c0:c0 + w] = True
    if hole:
        mask[r0 + 4:r0 + 8, c0 + 4:c0 + 8] = False
    polys = mask_contours(mask)
    areas = sorted(signed_area(p) for p in polys)
    assert areas[-1] == pytest.approx(h * w - 0.5, abs=1e-9)  # contour at half level cuts the 4 corners
    assert len(polys) == 1 + hole
    if hole:
        assert areas[0] < 0  # holes run the other way
    rows, cols = np.linspace(0, 1, 60), np.linspace(0, 1, 60)
    loops = fit_trim_loops(mask, rows, cols, tol_uv=0.002)
    outer = loop_points(loops.outer)
    assert np.linalg.norm(outer[0] - outer[-1]) < 1e-12          # closed
    assert signed_area(outer) > 0                                   # counter-clockwise
    assert len(loops.holes) == hole
    for hl in loops.holes:
        assert signed_area(loop_points(hl)) < 0                     # clockwise
    assert loop_stats_max(loops.outer) <= 0.002
    if not hole:
        assert len(loops.outer) == 4  # a rectangle's four corners split it into four sides


def test_disc_loop_follows_the_boundary():
    yy, xx = np.mgrid[:200, :200]
    mask = (yy - 100) ** 2 + (xx - 100) ** 2 <= 70**2
    loops = fit_trim_loops(mask, np.arange(200.0), np.arange(200.0), tol_uv=0.5)
    pts = loop_points(loops.outer)
    r = np.linalg.norm(pts - 100, axis=1)
    assert np.abs(r - 70).max() < 1.2  # pixel staircase of the mask + tolerance


def test_empty_mask_is_refused():
    with pytest.raises(GeometryError, match="no valid cells"):
        fit_trim_loops(np.zeros((10, 10), bool), np.arange(10.0), np.arange(10.0), 0.1)


def pinched_necked_mask(seed, bins=24, per_cell=3):
    """An occupancy raster of scattered parameters like `fit_freeform`'s: two blocks joined by a neck one
    cell wide, a spike one cell wide, a hole behind a wall one cell thick and a piece touching the face
    only at a cell corner (a pinch); with `per_cell` random data parameters in each occupied cell."""
    rng = np.random.default_rng(seed)
    mask = np.zeros((bins, bins), bool)
    mask[3:11, 3:21] = True
    mask[15:21, 3:21] = True
    mask[11:15, 11] = True          # the neck
    mask[17:23, 2] = False
    mask[20:23, 20] = True          # the spike
    mask[4:8, 14:18] = False        # the hole, one cell from the outer boundary
    mask[0:3, 21:24] = True         # the pinched piece: touches cell (3, 20) at its corner
    ii, jj = np.nonzero(mask)
    uv = (np.repeat(np.c_[ii, jj], per_cell, axis=0) + rng.random((len(ii) * per_cell, 2))) / bins
    return mask, uv, (np.arange(bins) + 0.5) / bins


def test_validity_check_finds_crossings_touches_and_stray_holes():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    bowtie = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float)
    assert is_simple(square) and not is_simple(bowtie)
    assert not is_simple(np.array([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]], float))   # touches at a vertex
    assert not is_simple(np.array([[0, 0], [2, 0], [1, 0], [1, 1]], float))           # runs back on itself
    assert len(crossing_pairs([square, square * 0.5 + 0.25])) == 0                     # apart: fine
    assert len(crossing_pairs([square, square + 0.5])) == 2                            # two loops crossing
    phi = np.linspace(0, 2 * np.pi, 5000, endpoint=False)
    dense = np.c_[np.cos(phi), np.sin(phi)]
    assert is_simple(dense) and not is_simple(np.vstack([dense, [[0.5, 1.5], [0.5, -1.5]]]))
    # an open chain (an intersection's stretch in a surface's parameters): its ends may lie anywhere; a
    # small loop in it is found, a repeated sample is not a touch
    arc = np.c_[np.linspace(0, 1, 400), 0.1 * np.sin(3 * np.linspace(0, 1, 400))]
    assert not crosses_itself(arc) and not crosses_itself(np.repeat(arc, 2, axis=0))
    assert crosses_itself(np.r_[arc[:200], [[0.52, 0.2], [0.49, 0.2]], arc[200:]])


@pytest.mark.parametrize("seed", [9, 10])   # the plain fit: its hole crosses the outer loop (9), itself (10)
def test_a_pinched_narrow_necked_region_gets_valid_loops_where_the_plain_fit_crossed(seed):
    """The loop construction as it was (contour vertices snapped to their nearest data points, the
    polygon fitted at the tolerance, split at corners) crosses itself or its hole on these rasters: the neck,
    spike and thin wall are a cell wide, the tolerance half a cell. fit_trim_loops now gives valid loops
    (holding back snaps that would cross, fitting the pieces that would cross closer), within the
    tolerance of its boundary polygon, and says what it did and that the pinched piece is left out."""
    from scipy import ndimage
    from scipy.spatial import cKDTree

    from rgm.fitters.trimloops import _to_uv, fit_closed_loop, loop_samples

    mask, uv, rows = pinched_necked_mask(seed)
    tol = 0.02
    lab = ndimage.label(mask)[0]
    face = lab == np.bincount(lab.ravel())[1:].argmax() + 1
    tree = cKDTree(uv)
    plain = []
    for k, poly in enumerate(sorted(mask_contours(face), key=lambda p: -abs(signed_area(p)))):
        snapped = tree.data[tree.query(_to_uv(poly, rows, rows))[1]]
        snapped = snapped[np.r_[True, np.any(np.diff(snapped, axis=0) != 0, axis=1)]]
        if (signed_area(snapped) > 0) != (k == 0):
            snapped = snapped[::-1]
        # control points clamped into the domain, as it was
        plain.append(tuple(replace(c, ctrl=np.clip(c.ctrl, rows[0], rows[-1])) for c in fit_closed_loop(snapped, tol)))
    assert len(plain) == 2   # outer boundary and the hole
    before = check_loops(plain[0], plain[1:])
    assert any(("between loops" if seed == 9 else "with themselves") in w for w in before)

    loops = fit_trim_loops(mask, rows, rows, tol, snap_to=uv)
    assert check_loops(loops.outer, loops.holes) == [] and len(loops.holes) == 1
    assert signed_area(loop_points(loops.outer)) > 0 and signed_area(loop_points(loops.holes[0])) < 0
    assert any("pinch" in n for n in loops.notes) and any("closer" in n or "held back" in n for n in loops.notes)
    # within the tolerance of the boundary polygon it follows: the contour with vertices moved at most to
    # their data points (each less than a cell diagonal away)
    for loop, poly in zip((loops.outer, *loops.holes), sorted(mask_contours(face), key=lambda p: -abs(signed_area(p)))):
        assert loop_stats_max(loop) <= tol
        contour = _to_uv(poly, rows, rows)
        pts = loop_samples(loop)[0]
        assert cKDTree(contour).query(pts)[0].max() <= tol + np.sqrt(2) / 24


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), tol=st.sampled_from([0.005, 0.01, 0.02, 0.04]))
def test_trim_loops_are_always_valid(seed, tol):
    mask, uv, rows = pinched_necked_mask(seed)
    loops = fit_trim_loops(mask, rows, rows, tol, snap_to=uv)
    assert check_loops(loops.outer, loops.holes) == []
    assert len(fit_trim_loops(mask, rows, rows, tol).holes) == 1   # unsnapped (a range image's mask) too


@settings(max_examples=30, deadline=None)
@given(jump=st.floats(0.1, 0.4), step=st.sampled_from([0.005, 0.01, 0.02]), tol=st.sampled_from([1e-3, 3e-3]))
def test_an_open_chain_with_a_long_jump_is_fitted_along_it(jump, step, tol):
    """A loop rebuilt between shared edges (`rgm.fitters.shared_edges.rebuild_loop`) runs from one edge's
    join across a stretch with no data samples to the data loop, turning there (within 3 vertices of the
    chain's end, where no corner is cut). Its B-spline stays within 5 tolerances of the polyline all along,
    not only at its points: with 4 samples on each edge, the jump's span swung 0.3-0.8 away (the rebuilt
    loop crossed itself on the YCB potted meat can)."""
    from rgm.fitters.trimloops import fit_open_chain

    bottom = np.c_[np.arange(0.2, 0.85, step), np.full(len(np.arange(0.2, 0.85, step)), 0.22)]
    right = np.c_[np.full(len(np.arange(0.22 + step, 0.75, step)), 0.85), np.arange(0.22 + step, 0.75, step)]
    chain = np.vstack([[0.19, 0.22 + jump], bottom, right])
    fitted = loop_points(fit_open_chain(chain, tol), 2000)
    t = np.linspace(0.0, 1.0, 40)[:, None, None]
    dense = (chain[:-1][None] + t * np.diff(chain, axis=0)[None]).reshape(-1, 2)
    from scipy.spatial import cKDTree

    assert cKDTree(dense).query(fitted)[0].max() <= 5 * tol   # the corner rounded: 3.2 tol at most seen
    assert np.allclose(fitted[[0, -1]], chain[[0, -1]])
