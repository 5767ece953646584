"""Trimming loops from a data mask (issue 8): closed loops, outer counter-clockwise, holes clockwise,
within tolerance of the mask's boundary."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.errors import GeometryError
from rgm.fitters.freeform import design_matrix
from rgm.fitters.trimloops import fit_trim_loops, loop_stats_max, mask_contours, signed_area


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
