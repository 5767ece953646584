"""Seams whose surfaces do not cross along them share one curve midway between the surfaces (issue 8): a
tube wrapped all round, fitted as two halves apart (as when its closed surface misses the tolerance on a
half, `rgm.fitters.wrap`), meets tangentially (no intersection to share); their seam becomes one
`seam_1_2 := bspline(...)` in both faces' loops (one of them `reverse(seam_1_2)`), and the faces' edges,
each the curve's closest points on its own surface as the back ends take it, meet within the tolerance.
By default the tube is one closed surface whose two faces' seams are the same curve: no seam curve is
needed. Oracles: the alternating closest points land on two crossing planes' line and midway between two
parallel planes; OpenCASCADE builds valid faces from the file and reads the IGES back within tolerance."""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rgm
from rgm.compiler.diagnostics import CompileError
from rgm.errors import GeometryError
from rgm.fitters.patches import fit_patches
from rgm.fitters.seam_curves import _midway, measure_curve
from rgm.geometry import NurbsCurve, NurbsSurface
from rgm.geometry.inversion import closest_point_surface
from rgm.model import BSplineCurve

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_patches import assert_one_binding_in_both_loops, file_seams, patches_text  # noqa: E402

TOL = 0.1


def lobed_tube(rng, n=8000, noise=0.02):
    """n points on an open tube round the z axis, radius 20 + 1.5 cos 3a mm, 60 mm tall; Gaussian noise."""
    a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 60, n)
    r = 20 + 1.5 * np.cos(3 * a)
    return np.c_[r * np.cos(a), r * np.sin(a), z] + rng.normal(0, noise, (n, 3))


def _held_apart(*args, **kwargs):
    raise GeometryError("held apart for this test")


@pytest.fixture(scope="module")
def tube():
    """The tube fitted as two halves apart with one round of refits through common boundary curves
    (`_ROUNDS` 1) and without the extension energy past the data (with it the halves' separate trims meet
    within 0.063 mm after that round: no curve is needed): the two halves, meeting tangentially, stay over
    the tolerance apart and share a seam curve."""
    p = lobed_tube(np.random.default_rng(3))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("rgm.fitters.patches._ROUNDS", 1)
        mp.setattr("rgm.fitters.freeform_surface.EXTENSION", 0.0)
        mp.setattr("rgm.fitters.wrap.fit_wrap", _held_apart)
        result = fit_patches(p, TOL)
    assert any("fitted as two halves apart: held apart" in note for note in result.skipped)
    text, parts = patches_text(result, TOL, title="tube")
    return p, result, text


def test_the_default_refit_rounds_bring_the_wrap_halves_near_each_other_along_both_seams(monkeypatch):
    """With the rounds `fit_patches` runs by default the halves are refitted again from the first round's
    surfaces. As the file reads back (both seams, every sample: `rgm.fitters.seam_check`, as `rgmc
    verify` measures them) they lie 0.14 mm apart at worst, 0.06 mm at p95, with a tolerance of 0.1 mm;
    every patch still meets its certificate. Until 2026-12-07 this test read the one curve midway
    between the surfaces that the halves shared along one seam (0.036 mm along it): along the other seam
    they lay 2.0 mm apart (1.7 mm at p95), and the fitter's choices, which now weigh a shared seam's
    stretch beyond its edge, keep the separate trims instead."""
    monkeypatch.setattr("rgm.fitters.wrap.fit_wrap", _held_apart)
    p = lobed_tube(np.random.default_rng(3))
    result = fit_patches(p, TOL)
    (gap,) = result.gaps
    assert gap.worst <= 1.5 * TOL and all(s.fit.stats.holds for s in result.shapes)
    (seam,) = file_seams(p, patches_text(result, TOL, title="tube")[1]).values()
    assert seam.max <= 1.5 * TOL and seam.p95 <= TOL, seam


def test_the_tube_is_one_closed_surface_whose_faces_meet_at_round_off(tmp_path):
    """By default: one surface closed round the axis, two faces cut along its iso-lines, their seams the
    same curve (G0 at round-off, not 0.26 mm), every face within its certificate; the IGES file
    OpenCASCADE reads back is within the tolerance of the model (`--verify`)."""
    result = fit_patches(lobed_tube(np.random.default_rng(3)), TOL)
    (gap,) = result.gaps
    assert len(result) == 2 and all(s.fit.stats.holds for s in result.shapes)
    assert gap.max < 1e-9 and not gap.shared and "closed round its axis" in gap.why
    text, _ = patches_text(result, TOL, title="tube")
    assert "the two faces of one surface closed round its axis" in text   # the G0 note says why
    if importlib.util.find_spec("OCP") is not None:
        from rgm.cli import main

        src = tmp_path / "tube.rgm"
        src.write_text(text)
        assert main(["compile", str(src), "-t", "iges", "-o", str(tmp_path / "tube.igs"), "--verify"]) == 0


def test_the_wrap_halves_share_one_seam_curve_and_meet_within_the_tolerance(tube):
    p, result, text = tube
    assert len(result) == 2 and all(s.fit.stats.holds for s in result.shapes)
    (gap,) = result.gaps
    # measured as the back ends take the curve (its closest points on each surface), far closer than the
    # separate trims (0.26 mm, over the tolerance)
    assert gap.shared and gap.curve and gap.max <= 0.5 * TOL and gap.before > TOL and gap.length > 50
    assert_one_binding_in_both_loops(text, gap)
    assert "a curve midway between their surfaces" in text
    model = rgm.loads(text)
    assert not model.diagnostics        # closed loops, no piece running backwards (W0505)
    seam = model.objects["seam_1_2"]
    c = seam.nurbs()
    x = c.evaluate(np.linspace(*c.domain, 300))
    for k in (1, 2):                     # the curve lies within the tolerance of both surfaces
        surface = model.objects[f"patch_{k}"].surface.nurbs()
        assert np.max(closest_point_surface(surface, x)[3]) <= TOL
    # along the data: the tube's radius where the curve runs
    a = np.arctan2(x[:, 1], x[:, 0])
    assert np.abs(np.hypot(x[:, 0], x[:, 1]) - (20 + 1.5 * np.cos(3 * a))).max() < TOL


def test_the_tube_compiles_to_valid_step_faces(tube, tmp_path):
    pytest.importorskip("OCP")
    from rgm.backends import occ

    _, _, text = tube
    model = rgm.loads(text)
    occ.write_step(model, tmp_path / "tube.step", tol=TOL)
    back = occ.read_step(tmp_path / "tube.step", "mm")
    assert occ.is_valid(back) and len(occ.faces_of(back)) == 2


def test_the_tube_compiles_to_iges_read_back_within_the_tolerance(tube, tmp_path):
    """`rgmc compile -t iges --verify`: the seam curve lies off both surfaces (by up to half the
    tolerance), so its pcurves are the closest points' images, fitted with breaks where they cross the
    surfaces' knot lines; the fitted data pieces across densely knotted surfaces take their partner
    curves as tight as they can be fitted (the writer refused these faces at 1e-10 of their size)."""
    pytest.importorskip("OCP")
    from rgm.cli import main

    _, _, text = tube
    src = tmp_path / "tube.rgm"
    src.write_text(text)
    assert main(["compile", str(src), "-t", "iges", "-o", str(tmp_path / "tube.igs"), "--verify"]) == 0


def _plane(origin, normal, size=40.0):
    """A bilinear NurbsSurface patch of the plane through `origin` with unit `normal`, size mm square."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    s = np.array([-size, size])
    ctrl = origin + s[:, None, None] * e1 + s[None, :, None] * e2
    return NurbsSurface(1, 1, [0, 0, 1, 1], [0, 0, 1, 1], ctrl)


@settings(max_examples=25, deadline=None)
@given(st.floats(20, 160), st.floats(-3, 3))
def test_midway_points_land_on_the_line_of_two_crossing_planes(angle, shift):
    """Two planes through the x axis at `angle` degrees: alternating closest points from points a few mm
    off it converge onto the axis (where both planes are), staying beside where they started. A round,
    (P_a + P_b) / 2 across the axis, shrinks the distance to the axis by (1 + cos t) / 2 at worst (along the
    bisector of the planes at t degrees), and the distances to the planes by (1 - cos t) / 2 besides."""
    t = np.radians(angle)
    a, b = _plane(np.zeros(3), [0, 0, 1]), _plane(np.zeros(3), [0, -np.sin(t), np.cos(t)])
    start = np.c_[np.linspace(-10, 10, 9), np.full(9, 2.0 + shift), np.full(9, 0.5)]
    mid = _midway(a, b, start)
    rate = (1 + abs(np.cos(t))) / 2
    off = np.linalg.norm(mid[:, 1:], axis=1)
    assert np.all(off <= np.linalg.norm(start[:, 1:], axis=1) * rate ** 8 * (1 + 1e-9) + 1e-12)
    assert np.abs(mid[:, 0] - start[:, 0]).max() < 1e-9


@settings(max_examples=25, deadline=None)
@given(st.floats(0.01, 2.0), st.floats(-5, 5))
def test_midway_points_lie_halfway_between_parallel_planes(gap, height):
    """Two parallel planes `gap` mm apart: the midway points lie on the plane halfway between."""
    a, b = _plane(np.zeros(3), [0, 0, 1]), _plane(np.array([0, 0, gap]), [0, 0, 1])
    start = np.c_[np.linspace(-10, 10, 9), np.zeros(9), np.full(9, height)]
    assert np.allclose(_midway(a, b, start)[:, 2], gap / 2, atol=1e-9)


def test_the_faces_edges_on_a_seam_curve_are_measured_as_the_back_ends_take_it():
    """A curve halfway between parallel planes 0.6 mm apart: each face's edge is the curve's closest points
    on its plane, so the two edges are 0.6 mm apart along the curve's 20 mm (measure_curve)."""
    a, b = _plane(np.zeros(3), [0, 0, 1]), _plane(np.array([0, 0, 0.6]), [0, 0, 1])
    curve = NurbsCurve(2, [0, 0, 0, 1, 1, 1], [[-10, 0, 0.3], [0, 4, 0.3], [10, 0, 0.3]])

    class Shape:   # what measure_curve reads of a fitted shape: its NURBS surface
        def __init__(self, s):
            self.s = s

        def nurbs(self):
            return self.s

    gmax, p95, n, length = measure_curve(0, 1, Shape(a), Shape(b), curve)
    x = curve.evaluate(np.linspace(0, 1, 2001))
    assert abs(gmax - 0.6) < 1e-6 and abs(p95 - 0.6) < 1e-6
    assert abs(length - np.linalg.norm(np.diff(x, axis=0), axis=1).sum()) < 1e-3


def test_reverse_runs_a_curve_the_other_way():
    model = rgm.loads("units mm;\nc := bspline(2, knots([0, 0, 0, 1, 1, 1]), net 3 [0 0 0, 1 1 0, 2 0 1]);\n"
                      "r := reverse(c);\nu := reverse(uvline(uv(0, 0), uv(1, 0.5)));\n")
    c, r = model.objects["c"], model.objects["r"]
    assert isinstance(r, BSplineCurve) and np.allclose(r.start, c.end) and np.allclose(r.end, c.start)
    t = np.linspace(0, 1, 7)
    assert np.allclose(r.nurbs().evaluate(t), c.nurbs().evaluate(1 - t)[:, :3])
    assert model.objects["u"].dim == 2 and np.allclose(model.objects["u"].start, [1, 0.5])
    with pytest.raises(CompileError) as err:
        rgm.loads("units mm;\np := plane(pt(0, 0, 0), vec(0, 0, 1));\nq := plane(pt(0, 0, 0), vec(0, 1, 0));\n"
                  "r := reverse(intersect(p, q));\n")
    assert "4:6" in str(err.value) and "intersection has no direction" in str(err.value)


def test_a_seam_whose_surfaces_part_shares_a_curve_where_they_pass_within_the_tolerance():
    """Two strips side by side, 0.3 mm apart in height where they meet for x < 25 and parting to 2.5 mm by
    x = 40 (z = 0 and z = h(x), a smooth step): at a 0.5 mm tolerance no curve lies within it of both
    surfaces along the whole seam (the midway points keep to the seam up to x = 29.8), so the curve keeps
    the stretch where they pass within 0.4 mm of each other (to about x = 26, where h = 0.4), and each face's
    run is cut to it (the rest of the seam stays data, joined at its ends)."""
    from scipy.spatial import cKDTree

    from rgm.fitters.freeform_part import fit_freeform
    from rgm.fitters.patch_base import reach_past
    from rgm.fitters.seam_curves import seam_curve
    from rgm.fitters.shared_edges import _Loop, _loop_samples, _seam_runs

    rng = np.random.default_rng(4)

    def h(x):
        s = np.clip((x - 25) / 10, 0, 1)
        return 0.3 + 2.2 * s * s * (3 - 2 * s)

    n = 3200
    x, y = rng.uniform(0, 40, (2, n)), rng.uniform(0, 10, (2, n))
    clouds = [np.c_[x[0], y[0], rng.normal(0, 0.02, n)], np.c_[x[1], y[1] + 10, h(x[1]) + rng.normal(0, 0.02, n)]]
    spacing = float(np.median(cKDTree(clouds[0]).query(clouds[0], 2)[0][:, 1]))
    shapes = [fit_freeform(c, 0.1, cuts=False, params=reach_past(c, c[:, 0] / 40, (c[:, 1] % 10) / 10,
                                                                  5 * spacing)) for c in clouds]
    loops = []
    for k, shape in enumerate(shapes):
        uv = _loop_samples(shape, spacing)
        xyz = shape.nurbs().evaluate(uv[:, 0], uv[:, 1])
        beside = (xyz[:, 1] > 9) if k == 0 else (xyz[:, 1] < 11)     # the side along the other strip
        loops.append(_Loop(uv, xyz, np.where(beside & (xyz[:, 0] > 1) & (xyz[:, 0] < 39), 1 - k, -1)))
    runs = _seam_runs(0, 1, loops)
    assert not isinstance(runs, str), runs
    c = seam_curve(0, 1, shapes, loops, runs, 0.5, 5 * spacing, spacing)
    assert not isinstance(c, str), c
    xyz = c.curve.evaluate(np.linspace(*c.curve.domain, 200))
    assert xyz[:, 0].min() < 3 and 25 < xyz[:, 0].max() < 27.5
    assert np.abs(xyz[:, 2] - h(xyz[:, 0]) / 2).max() < 0.05          # midway between the surfaces
    for k in (0, 1):   # each face's run is cut to the curve's stretch
        assert loops[k].xyz[c.runs[k].idx, 0].max() < 28
