"""Seams closed by growing a trim (`rgm.fitters.seam_cover`): where two patches' surfaces pass within the
tolerance of each other but their trims stop short (no edge shared), one face's trim is grown to the
other's edge. The oracle is independent of the growing: points of the true surface across the band
between the halves' data lie within the tolerance of a face as trimmed after, and did not before."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from rgm.fitters.creases import median_spacing
from rgm.fitters.patch_base import Base, reach_past, unit_box
from rgm.fitters.patches import _covered, _fit_patch, _written_loops, g0_gaps, written_face
from rgm.fitters.trimloops import check_loops


def _halves(seed, gap, tilt_deg):
    """Two patches of a gently curved sheet (z = 0.002 x^2 mm) 60 x 40 mm, split at x = 0 with a band
    `gap` mm wide left without data, the right half tilted by `tilt_deg` about the y axis (their surfaces
    then cross at a small angle: no edge is shared there, as on a fitted bottle's shoulder)."""
    rng = np.random.default_rng(seed)
    p = np.c_[rng.uniform(-30, 30, 6000), rng.uniform(-20, 20, 6000)]
    p = p[np.abs(p[:, 0]) > gap / 2]
    z = 0.002 * p[:, 0] ** 2 + rng.normal(0, 0.02, len(p))
    right = p[:, 0] > 0
    t = np.radians(tilt_deg)
    x = np.where(right, p[:, 0] * np.cos(t), p[:, 0])
    z = np.where(right, z + p[:, 0] * np.sin(t), z)
    pts = np.c_[x, p[:, 1], z]
    return pts, np.flatnonzero(~right), np.flatnonzero(right)


def _hole(patches, tilt_deg, tol):
    """The largest distance from the sheet's true surface across the band between the two halves' data
    (x in [-0.6, 0.6] mm, |y| <= 18: away from the free borders) to the nearer of the two faces as
    trimmed: over `tol`, the model has a hole there."""
    x, y = np.meshgrid(np.linspace(-0.6, 0.6, 7), np.linspace(-18, 18, 61))
    x, y = x.ravel(), y.ravel()
    t = np.radians(tilt_deg)
    z = 0.002 * x**2 + np.where(x > 0, x * np.sin(t), 0.0)
    probe = np.c_[np.where(x > 0, x * np.cos(t), x), y, z]
    return float(np.minimum(*(written_face(q.shape).distance(probe) for q in patches)).max())


def _fitted(points, left, right, tol):
    """(spacing, the two halves fitted as patches over their base plane, their seam's gaps)."""
    spacing = median_spacing(cKDTree(points))
    patches = [_fit_patch(points, idx, Base("plane", 1.0), reach_past(points[idx], *unit_box(points[idx][:, :2]),
                                                                      5 * spacing), tol, "p95", 4000)
               for idx in (left, right)]
    return spacing, patches, g0_gaps(points, patches, 5 * spacing)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_gap_between_trims_closes_where_the_surfaces_pass_within_tol(seed):
    tol = 0.3
    points, left, right = _halves(seed, gap=1.2, tilt_deg=1.0)
    spacing, patches, gaps = _fitted(points, left, right, tol)
    assert len(gaps) == 1 and gaps[0].max > 2 * tol     # the trims stop at their data, 1.2 mm apart
    assert _hole(patches, 1.0, tol) > 2 * tol
    grown, after = _covered(points, patches, gaps, tol, "p95", 5 * spacing)
    # the surfaces and their certificates are the ones fitted; only a trim changed, and it is valid
    assert all(g.shape.fit is p.shape.fit for g, p in zip(grown, patches))
    assert sum(g.shape is not p.shape for g, p in zip(grown, patches)) == 1
    assert all(check_loops(g.shape.loops.outer, g.shape.loops.holes) == [] for g in grown)
    # no hole is left across the band (independent of the seam measure), and the seam's samples are
    # within the tolerance of the other face but at its ends, where a grown face's free border runs on
    # past the other's corner (g0_gaps counts those samples too: it does not know the border is free)
    assert _hole(grown, 1.0, tol) <= tol
    assert len(after) == 1 and after[0].p95 <= tol and after[0].max < gaps[0].max


def test_a_gap_the_surfaces_do_not_close_is_left_as_measured():
    """Surfaces 20 degrees apart leave more than the tolerance between them a few tenths of a mm from
    where they cross: nothing to cover within it, so the seam keeps its figure (no trim is grown to a
    surface that is not there)."""
    tol = 0.05
    points, left, right = _halves(2, gap=1.2, tilt_deg=20.0)
    spacing, patches, gaps = _fitted(points, left, right, tol)
    grown, after = _covered(points, patches, gaps, tol, "p95", 5 * spacing)
    assert after[0].max > tol
    assert after[0].max >= 0.9 * gaps[0].max or all(g.shape is p.shape for g, p in zip(grown, patches))


def _square_face(hole=False, grid=None):
    """A plane 40 x 40 mm fitted over [0.2, 0.8]² of its parameters (so it reaches past its data), its
    outer loop the square [0.2, 0.8]² with the side v = 0.2 shared with patch 7 (`FreeformShape.outline`)
    and the other three sides one data stretch; with `hole`, a hole [0.4, 0.6]² (clockwise) with no data
    in it. The data: 2000 random parameters, or with `grid` a regular grid of grid x grid."""
    from rgm.fitters.freeform_part import FreeformShape
    from rgm.fitters.freeform_surface import fit_surface
    from rgm.fitters.shared_edges import SharedEdge
    from rgm.fitters.trimloops import TrimLoops, fit_closed_loop, fit_open_chain

    rng = np.random.default_rng(3)
    uv = rng.uniform(0.2, 0.8, (2000, 2)) if grid is None else \
        np.stack(np.meshgrid(*[np.linspace(0.2, 0.8, grid)] * 2), axis=-1).reshape(-1, 2)
    if hole:
        uv = uv[np.abs(uv - 0.5).max(axis=1) > 0.1]
    pts = np.c_[(uv - 0.2) * 40 / 0.6, np.zeros(len(uv))]
    fit = fit_surface(pts, 0.1, params=(uv[:, 0], uv[:, 1]))
    side = np.linspace(0.2, 0.8, 61)
    shared_arc = np.c_[side, np.full(61, 0.2)]
    rest = np.vstack([np.c_[np.full(60, 0.8), side[1:]], np.c_[side[::-1][1:], np.full(60, 0.8)],
                      np.c_[np.full(60, 0.2), side[::-1][1:]]])
    data_pieces = list(fit_open_chain(rest, 1e-4))
    outline = np.vstack([shared_arc, rest])
    flags = np.r_[np.full(61, 7), np.full(len(rest), -1)]
    h = np.linspace(0.4, 0.6, 21)
    holes = [list(fit_closed_loop(np.vstack([np.c_[h, np.full(21, 0.4)], np.c_[np.full(20, 0.6), h[1:]],
                                             np.c_[h[::-1][1:], np.full(20, 0.6)], np.c_[np.full(19, 0.4), h[::-1][1:-1]]])[::-1], 1e-4))] if hole else []
    loops = TrimLoops(tuple(fit_closed_loop(outline, 1e-4)), tuple(tuple(x) for x in holes), 0)
    shape = FreeformShape(fit, loops, [SharedEdge(7, (0, 7))] + data_pieces, holes, outline, flags)
    return shape, uv


def test_a_face_with_a_shared_edge_grows_its_data_stretch_and_keeps_the_edge():
    from rgm.fitters.seam_cover import grown_outline
    from rgm.fitters.shared_edges import SharedEdge
    from rgm.geometry.polygon import inside_polygons

    shape, uv = _square_face()
    feet = np.c_[np.full(20, 0.86), np.linspace(0.35, 0.65, 20)]     # past the side u = 0.8
    grown = grown_outline(shape, feet, uv, 0.1)
    assert grown is not None and grown.fit is shape.fit
    # every foot is inside the grown loop or on it (its contour is snapped to the feet: the grown edge
    # runs through them), none was inside before
    on = cKDTree(grown.outline).query(feet)[0] < 0.01
    assert (inside_polygons(feet, [grown.outline]) | on).all() and not inside_polygons(feet, [shape.outline]).any()
    # the shared edge is the same piece and the same arc, at the start of the loop
    assert isinstance(grown.outer[0], SharedEdge) and grown.outer[0] == shape.outer[0]
    assert np.array_equal(grown.outline[grown.outline_shared == 7], shape.outline[:61])
    # the rest of the square is where it was (the grown stretch keeps to the data elsewhere)
    o = grown.outline
    top = o[(o[:, 1] > 0.7) & (o[:, 0] > 0.3) & (o[:, 0] < 0.7)]
    left = o[(o[:, 0] < 0.3) & (o[:, 1] > 0.3) & (o[:, 1] < 0.7)]
    assert np.abs(top[:, 1] - 0.8).max() < 0.03 and np.abs(left[:, 0] - 0.2).max() < 0.03
    # feet inside the face grow nothing; feet in a hole shrink it, and the hole stays where no foot
    # reaches (on the raster the grown hole's contour runs outside the old hole here: taken as the hole
    # only where it started inside it, it was dropped and the face closed over its hole)
    assert grown_outline(shape, np.array([[0.5, 0.5]]), uv, 0.1) is None
    holed, uv = _square_face(hole=True)
    inner = np.c_[np.full(10, 0.43), np.linspace(0.42, 0.58, 10)]
    filled = grown_outline(holed, inner, uv, 0.1)
    assert filled is not None
    from rgm.fitters.trimloops import loop_samples
    holes = [loop_samples(tuple(h))[0] for h in filled.holes]
    assert len(holes) == 1 and inside_polygons(np.array([[0.55, 0.5]]), holes).all()
    on = cKDTree(holes[0]).query(inner)[0] < 0.01      # its contour is snapped to the feet
    assert (~inside_polygons(inner, holes) | on).all()
    assert np.array_equal(filled.outline, holed.outline[:-1])   # as it was (its closing vertex not repeated)


@pytest.mark.parametrize("radius", [0.07, 0.085])
def test_a_grown_hole_runs_through_the_feet_within_a_fraction_of_the_tolerance(radius):
    """A neighbour's round edge (feet on a circle, in the square face's hole, 40 mm / 0.6 a parameter
    unit): the hole grown over it runs through the feet closer than the trims' raster and the tolerance
    allow a data loop. A grown edge lies on the neighbour only as closely as its loop follows the feet,
    so that fit takes a quarter of the tolerance: 0.16 and 0.19 mm at tol 1 mm (the contour's cells are
    0.57 mm), where fitted at the whole tolerance, as a data loop is, it ran 0.52 and 0.63 mm from them
    (the YCB mustard bottle's shoulder ring, noise seed 4: its hole round the cap's wrap 1.02 and 1.10
    mm from the cap's faces)."""
    from rgm.fitters.seam_cover import grown_outline
    from rgm.fitters.trimloops import loop_samples
    from rgm.geometry.polygon import inside_polygons

    holed, uv = _square_face(hole=True, grid=140)
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    feet = 0.5 + radius * np.c_[np.cos(t), np.sin(t)]
    grown = grown_outline(holed, feet, uv, 1.0)
    assert grown is not None
    # the hole round the feet (the old hole's corners, which no foot's band reaches, stay holes as well)
    round_hole, = [h for h in (loop_samples(tuple(h))[0] for h in grown.holes)
                   if inside_polygons(np.array([[0.5, 0.5]]), [h]).all()]
    assert cKDTree(round_hole).query(feet)[0].max() * 40 / 0.6 <= 0.25


def test_a_closed_wrap_grows_down_to_its_neighbours_edge_and_keeps_its_seams():
    """A can's mantle (radius 20 mm, a full wrap: one closed surface cut into two faces along two
    iso-lines, `rgm.fitters.wrap`) whose data stop 1.5 mm above its flat bottom; the bottom's edge lies
    on the mantle's surface, which reaches past its data. The wrap's faces are grown down to the bottom's
    edge like any face, their loops still running straight along their seams: measured on the faces as
    trimmed (`rgm.fitters.seam_check`, as `rgmc verify` measures them), the seams with the bottom within
    the tolerance. (Wrap faces were not grown: the YCB mustard bottle's body halves stopped 2.49 mm above
    its bottom, noise seed 1.)"""
    from rgm.fitters.certificate import nearest_part
    from rgm.fitters.freeform_part import retrimmed
    from rgm.fitters.normals import pca_normals
    from rgm.fitters.patch_base import base_parameters
    from rgm.fitters.patches import _fit_piece, _past_seams
    from rgm.fitters.seam_check import measure_seams

    tol, rng = 1.0, np.random.default_rng(4)
    phi, z = rng.uniform(0, 2 * np.pi, 4500), rng.uniform(1.5, 40, 4500)
    mantle = np.c_[20 * np.cos(phi), 20 * np.sin(phi), z]
    rad, psi = 20 * np.sqrt(rng.uniform(0, 1, 5000)), rng.uniform(0, 2 * np.pi, 5000)
    bottom = np.c_[rad * np.cos(psi), rad * np.sin(psi), np.zeros(5000)]
    points = np.vstack([mantle, bottom]) + rng.normal(0, 0.02, (9500, 3))
    spacing = median_spacing(cKDTree(points))
    wrap_idx, bottom_idx = np.arange(4500), np.arange(4500, 9500)
    (sub, u, v, base), = base_parameters(points[wrap_idx], pca_normals(points[wrap_idx])[0], spacing=spacing)
    assert base.closed and len(sub) == 4500
    faces = _fit_piece(points, wrap_idx[sub], base, (u, v), tol, "p95", 4000, 16, spacing, [])
    assert len(faces) == 2 and all(f.base.wrap is not None for f in faces)
    flat = reach_past(points[bottom_idx], *unit_box(points[bottom_idx][:, :2]), 5 * spacing)   # trimmed finely:
    plane = _fit_patch(points, bottom_idx, Base("plane", 1.0), flat, tol / 4, "p95", 4000)      # its edge, its data's
    patches = faces + [plane]

    def seams(patches):
        written = {k: written_face(q.shape) for k, q in enumerate(patches)}
        owner, _ = nearest_part(list(written.values()), points)
        return {(g.a, g.b): g.max for g in measure_seams(written, points, owner, spacing)}

    # a wrap's face trimmed again with nothing to cover is the face it was: its own parameters (as cut
    # from the closed surface, not inset) and the other face's data past its seams (`_past_seams`)
    for f in faces:
        again = retrimmed(f.shape, points[f.indices], f.params, tol, "p95", np.c_[f.params][:1], past=_past_seams(f))
        a, b = _written_loops(f.shape)[0][0], _written_loops(again)[0][0]
        assert max(cKDTree(a).query(b)[0].max(), cKDTree(b).query(a)[0].max()) < 1e-12
    before = seams(patches)
    assert before[(0, 2)] > 1.5 * tol and before[(1, 2)] > 1.5 * tol   # the mantle's trims stop 1.5 mm up
    gaps = g0_gaps(points, patches, 5 * spacing)
    grown, _ = _covered(points, patches, gaps, tol, "p95", 5 * spacing)
    assert all(g.shape.fit is p.shape.fit for g, p in zip(grown, patches))   # only trims changed
    assert all(check_loops(g.shape.loops.outer, g.shape.loops.holes) == [] for g in grown)
    after = seams(grown)
    assert after[(0, 2)] <= tol and after[(1, 2)] <= tol, after      # 2.01 and 2.11 mm before; 0.56, 0.78
    # the faces' loops still run along their seams, exactly on the iso-lines both faces share, down to
    # the bottom (where the seam between them meets the bottom, it read 0.40 mm before, 0.16 after)
    assert after[(0, 1)] <= before[(0, 1)], (before, after)
    for g in grown[:2]:
        band = g.shape.loops.band
        loop = _written_loops(g.shape)[0][0]
        on = np.abs(loop[:, [0]] - np.array(band)).min(axis=1) < 1e-12
        assert on.sum() >= 4 and loop[:, 0].min() > band[0] - 1e-12 and loop[:, 0].max() < band[1] + 1e-12
        z = g.shape.nurbs().evaluate(loop[on, 0], loop[on, 1])[:, 2]
        assert z.min() < 1.0 and z.max() > 39.0                       # the seams run the full height
