"""Scattered free-form data split into patches at sharp edges (issue 8): creases found from normals,
patches parameterised over a plane or a cylinder, each fitted as a trimmed NURBS to a tolerance,
neighbours sharing their boundary (the intersection of their surfaces) where they cross, the G0 gaps
between neighbours measured; a box, a capped cylinder, an open wrap, and the YCB mustard bottle."""
import importlib.util
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st
from scipy.spatial import cKDTree

import rgm
from rgm.errors import GeometryError
from rgm.fitters.certificate import nearest_part
from rgm.fitters.filters import statistical_outliers
from rgm.fitters.emit import write_rgm
from rgm.fitters.freeform_build import fit_freeform_part, patch_part
from rgm.fitters.freeform_part import emit_freeform_set
from rgm.fitters.creases import split_scattered
from rgm.fitters.patch_base import base_parameters
from rgm.fitters.patches import fit_patches
from rgm.fitters.seam_check import measure_seams
from rgm.fitters.trimloops import check_loops
from rgm.fitters.normals import pca_normals
from rgm.model import TrimmedFace

sys.path.insert(0, str(Path(__file__).resolve().parent))
from recovery_scans import mesh_views, random_rotation  # noqa: E402

YCB = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "ycb"
MUSTARD = YCB / "006_mustard_bottle_textured.obj"
MEAT_CAN = YCB / "010_potted_meat_can_textured.obj"
CRACKER_BOX = YCB / "003_cracker_box_textured.obj"


def written_gaps(points, result, model, step=0.1):
    """{(i, j): max gap} of the seams, measured on the written file (an oracle for
    `rgm.fitters.patches.as_written`): the 2-D pieces of each face's loops, outer and holes, as rgm reads
    them back (the data pieces: a shared edge's samples lie on its own seam), sampled about `step` mm apart
    (piece by piece: a hole's seam with a neighbour is measured as an outer loop's; a piece along a
    closed wrap's seam is on that seam, not measured here); a sample lies
    on the seam with the patch owning the nearest other input point within 5 point spacings, and is
    measured to the nearest other face of the file read back (`TrimmedNurbs.from_model`: trimmed as
    written) among the patches with input points within those 5 spacings."""
    from rgm.fitters.freeform_measure import TrimmedNurbs
    from rgm.model import IntersectionCurve

    tree = cKDTree(points)
    near = 5 * float(np.median(tree.query(points, 2)[0][:, 1]))
    label = np.full(len(points), -1)
    for k, q in enumerate(result.patches):
        label[q.indices] = k
    faces = [TrimmedNurbs.from_model(model.objects[f"patch_{k + 1}"]) for k in range(len(result))]
    trees = [cKDTree(points[label == k]) for k in range(len(result))]
    out = {}
    for a in range(len(result)):
        face = model.objects[f"patch_{a + 1}"]
        surface = face.surface.nurbs()
        xyz = []
        band = result.shapes[a].loops.band if result.shapes[a].loops is not None else None
        for piece in (piece for loop in face.loops() for piece in loop.pieces):
            if isinstance(piece, IntersectionCurve) or piece.dim != 2:
                continue
            c = piece.nurbs()
            if band is not None and any(np.abs(c.ctrl[:, 0] - u).max() < 1e-6 for u in band):
                continue   # along a closed wrap's seam: on the seam with its other face, whatever points are nearest
            uv = c.evaluate(np.linspace(*c.domain, 4001))[:, :2]
            on = surface.evaluate(uv[:, 0], uv[:, 1])
            along = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(on, axis=0), axis=1))]
            t = np.linspace(0.0, along[-1], max(int(along[-1] / step), 2))
            xyz.append(surface.evaluate(np.interp(t, along, uv[:, 0]), np.interp(t, along, uv[:, 1])))
        xyz = np.vstack(xyz)
        others = np.flatnonzero((label >= 0) & (label != a))
        d, j = cKDTree(points[others]).query(xyz, distance_upper_bound=near)
        owner = np.where(np.isfinite(d), label[others[np.minimum(j, len(others) - 1)]], -1)
        gap = np.full(len(xyz), np.inf)
        for b in range(len(result)):
            close = (owner >= 0) & np.isfinite(trees[b].query(xyz, distance_upper_bound=near)[0]) if b != a else None
            if close is not None and close.any():
                gap[close] = np.minimum(gap[close], faces[b].distance(xyz[close]))
        for b in np.unique(owner[owner >= 0]):
            pair = (min(a, b), max(a, b))
            out[pair] = max(out.get(pair, 0.0), float(gap[owner == b].max()))
    return out


def ycb_views(path, seed=1):
    """Six scan-like views of a YCB mesh merged (mm, 1.5 mm pitch, 0.05 mm noise, 2 % outliers removed by
    the statistical filter; `seed` draws the noise and outliers)."""
    dirs = [(1, 0, 0.3), (-1, 0, 0.3), (0, 1, -0.3), (0, -1, -0.3), (0, 0, 1), (0, 0, -1)]
    views, _ = mesh_views(path, dirs, pitch=1.5, noise=0.05, outliers=0.02, seed=seed)
    p = np.vstack(views)
    return p[~statistical_outliers(p)]


def patches_text(result, tol, title="patches"):
    """The `.rgm` text of a PatchSet as `rgmc fit` writes free-form patches (patch_1, ...), the measured
    G0 gaps as header notes; and the emitted parts (their `ideal` rebuilt from the printed numbers)."""
    part = patch_part(result)
    count = range(1, len(part.shapes) + 1)
    parts = emit_freeform_set(part.shapes, [f"patch_{k}" for k in count], [f"_{k}" for k in count], tolerance=tol)
    return write_rgm(parts, inputs=[], options={}, tol=tol, notes=part.notes, title=title), parts


def file_seams(points, parts) -> dict:
    """{(i, j): SeamGap}: the seams of the written faces (the emitted `parts`' ideals, as `rgmc verify`
    reads the file back), measured as verify measures them (`rgm.fitters.seam_check`: every sample along
    them, beyond a shared edge's ends too; free borders left out)."""
    faces = [q.ideal for q in parts]
    owner, _ = nearest_part(faces, points)
    return {(g.a, g.b): g for g in measure_seams(dict(enumerate(faces)), points, owner)}


def assert_one_binding_in_both_loops(text, gap):
    """The shared edge of `gap` is one binding in the .rgm (an intersection, or a seam curve) that both
    faces' loops use (a seam curve perhaps as `reverse(...)`)."""
    i, j = gap.i + 1, gap.j + 1
    name = f"seam_{i}_{j}" if gap.curve else f"crease_{i}_{j}"
    head = f"{name} := bspline(" if gap.curve else f"{name} := intersect(surface_{i}, surface_{j});"
    assert text.count(head) == 1
    uses = [f"    {name}", f"    reverse({name})"]
    assert sum(text.count(u + ",") + text.count(u + ");") for u in uses) == 2


def box_points(rng, n, half, noise):
    """n points area-uniform on the box [-half, half] (mm), Gaussian noise; returns points (n, 3) in the
    box frame and the face index (0..5) each point was drawn from."""
    areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]])
    axis = rng.choice(3, n, p=areas / areas.sum())
    side = rng.choice([-1, 1], n)
    p = rng.uniform(-1, 1, (n, 3)) * half
    p[np.arange(n), axis] = side * half[axis]
    return p + rng.normal(0, noise, p.shape), 2 * axis + (side > 0)


def capped_cylinder(rng, n, r, h, noise):
    """n points area-uniform on a cylinder of radius r, height h (axis z, centred) with flat caps;
    returns points and the true part (0 side, 1 bottom, 2 top)."""
    cap = rng.random(n) < r / (r + h)
    phi = rng.uniform(0, 2 * np.pi, n)
    rad = np.where(cap, r * np.sqrt(rng.random(n)), r)
    top = rng.random(n) < 0.5
    z = np.where(cap, np.where(top, h / 2, -h / 2), rng.uniform(-h / 2, h / 2, n))
    p = np.c_[rad * np.cos(phi), rad * np.sin(phi), z] + rng.normal(0, noise, (n, 3))
    return p, np.where(cap, np.where(top, 2, 1), 0)


def purity(groups, truth):
    """For each patch, the share of its points drawn from its majority true face."""
    return [np.bincount(truth[g]).max() / len(g) for g in groups]


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1))
@example(89150283)   # a crease point 4 mm from a corner, 0.09 mm off its face, joined the face 0.49 mm away
def test_a_noisy_box_splits_into_its_six_faces(seed):
    rng = np.random.default_rng(seed)
    half = rng.uniform(15, 40, 3)
    p, face = box_points(rng, 6000, half, 0.05)
    rot = random_rotation(rng)
    groups = split_scattered(p @ rot.T + rng.uniform(-200, 200, 3))
    assert len(groups) == 6
    majority = [np.bincount(face[g]).argmax() for g in groups]
    assert sorted(majority) == list(range(6))
    # every point of a patch, crease band included, lies on that patch's true face (within the noise:
    # a point drawn from the neighbouring face within noise of the edge is on both)
    for g, f in zip(groups, majority):
        on_face = np.clip(p[g], -half, half)
        on_face[:, f // 2] = (1 if f % 2 else -1) * half[f // 2]
        assert np.linalg.norm(p[g] - on_face, axis=1).max() < 0.4


def test_box_patches_meet_the_tolerance_and_every_edge_has_a_measured_gap():
    rng = np.random.default_rng(7)
    p, _ = box_points(rng, 6000, np.array([30.0, 22.0, 16.0]), 0.05)
    t0 = time.perf_counter()
    result = fit_patches(p, 0.2)
    seconds = time.perf_counter() - t0
    assert len(result) == 6 and all(q.base.kind == "plane" for q in result.patches)
    assert all(s.fit.stats.holds and s.fit.stats.p95 <= 0.2 for s in result.shapes)
    # a box has 12 edges: each is a seam between two faces, and only those are neighbours
    assert len(result.gaps) == 12
    spacing = np.median(cKDTree(p).query(p, k=2)[0][:, 1])
    # every edge is one shared intersection: the gap measured along it (as the back ends approximate it,
    # at the tolerance) is far below what the separate trims had (a few point spacings: measured too).
    # The seams are measured face to face, corners included: each edge runs to tol / 4 short of the
    # corner where its three planes meet (`shared_edges._corner_joins`), so the faces' short data pieces
    # there leave at most a fraction of the tolerance (ending where the seam runs ended, the edges left
    # every corner rounded off on each face's own data: 1.49 mm)
    assert all(g.shared for g in result.gaps)
    edges, before = np.array([g.max for g in result.gaps]), np.array([g.before for g in result.gaps])
    rest = np.array([g.rest for g in result.gaps])
    assert np.all(before > 0) and before.max() < 10 * spacing
    assert edges.max() < 0.01 * before.min() and rest.max() <= 0.5 * 0.2
    print(f"box: {len(result)} patches, ctrl {[s.fit.n_ctrl for s in result.shapes]}, "
          f"p95 {[round(s.fit.stats.p95, 3) for s in result.shapes]}, G0 gap max {edges.max():.2g} mm on the "
          f"shared edges, {rest.max():.2g} mm face to face at the corners (separate trims: {before.max():.2f} "
          f"mm, {before.max() / spacing:.1f} spacings), {seconds:.1f} s")


def test_capped_cylinder_splits_at_its_rims_and_the_wrap_is_cut_in_two(tmp_path):
    rng = np.random.default_rng(11)
    r, h = 25.0, 60.0
    p, part = capped_cylinder(rng, 10000, r, h, 0.05)
    groups = split_scattered(p)
    assert len(groups) == 3 and min(purity(groups, part)) > 0.97
    result = fit_patches(p, 0.2)
    kinds = sorted(q.base.kind for q in result.patches)
    assert kinds == ["cylinder", "cylinder", "plane", "plane"]  # a full wrap has no gap: two faces
    text, parts = patches_text(result, 0.2)
    for q, part in zip(result.patches, parts):
        s = q.shape
        assert s.fit.stats.holds
        on = part.ideal.sample_surface(2.0)
        if q.base.kind == "cylinder":   # the fitted surface is the true cylinder within the tolerance
            err = np.abs(np.hypot(on[:, 0], on[:, 1]) - r)
        else:
            err = np.abs(np.abs(on[:, 2]) - h / 2)
        assert np.percentile(err, 95) < 0.2
    assert all(np.isfinite(g.max) and g.max > 0 for g in result.gaps)
    # the four rims are shared (cap plane and mantle cross there); the wrap is one surface closed round its
    # axis, cut into two faces along two of its iso-lines: their seams are the same curve on both, G0 to
    # round-off (fitted as two halves apart, their edges met at 8.6 degrees and shared an intersection)
    assert [g.shared for g in result.gaps].count(True) == 4
    assert all(g.max <= 0.2 for g in result.gaps)
    wrap = [g for g in result.gaps if result.patches[g.i].base.wrap and result.patches[g.j].base.wrap]
    assert len(wrap) == 1 and wrap[0].max < 1e-9 and "closed round its axis" in wrap[0].why
    # where a rim meets the wrap's seams, both faces' rim edges run to tol / 4 short of the point where
    # they cross it (one surface: the same point), and each face's loop on by it, so the faces meet at
    # those corners too. As the file reads back (`rgmc verify`): every seam within the tolerance, the
    # rims 0.009 mm, the wrap's seam 0.064 mm (ending where the seam runs ended, the edges left each
    # rim's data pieces 0.17-0.34 mm from the other face, and the wrap's seam read 0.53 mm at the rims;
    # the fitter's own measure beyond the edges' ends, which counts samples ahead along a border, 0.12 mm)
    assert max(g.rest for g in result.gaps) <= 0.75 * 0.2
    seams = file_seams(p, parts)
    assert set(seams) == {(g.i, g.j) for g in result.gaps} and max(g.max for g in seams.values()) <= 0.5 * 0.2, seams
    model = rgm.loads(text)
    assert not [d for d in model.diagnostics if d.is_error]
    assert all(isinstance(model.objects[f"patch_{k}"], TrimmedFace) for k in range(1, 5))
    assert text.count("G0 gap") == len(result.gaps)
    if importlib.util.find_spec("OCP") is not None:   # OpenCASCADE's exact intersections agree
        from rgm.backends.occ import write_step

        write_step(model, tmp_path / "cylinder.step", tol=0.2)


def test_linked_components_of_a_single_point():
    """A merge's union split by `base_parameters` can leave an end of one point: one component, not an
    IndexError (the YCB meat can, 1.5 mm views, seed 2, stopped on it once the mantle was swept)."""
    from rgm.fitters.creases import linked_components

    assert linked_components(np.zeros((1, 3)), None, 1.0, 0.0).tolist() == [0]
    assert linked_components(np.array([[0.0, 0, 0], [0.5, 0, 0], [5.0, 0, 0]]), None, 1.0, 0.0).tolist() == [0, 0, 1]


def test_an_open_wrap_is_one_patch_parameterised_by_its_angle():
    rng = np.random.default_rng(5)
    phi = rng.uniform(0, np.radians(250), 5000)
    z = rng.uniform(0, 40, 5000)
    p = np.c_[30 * np.cos(phi), 30 * np.sin(phi), z] + rng.normal(0, 0.03, (5000, 3))
    (idx, u, v, base), = base_parameters(p, pca_normals(p)[0])
    assert base.kind == "cylinder" and len(idx) == len(p)
    # one-to-one: u orders the points as their angle does (up to direction), v as their height
    order = np.argsort(phi[idx])
    du = np.diff(u[order])
    assert max(np.mean(du >= -1e-3), np.mean(du <= 1e-3)) > 0.999
    assert abs(np.corrcoef(v, z[idx])[0, 1]) > 0.999
    shape = fit_patches(p, 0.1).shapes
    assert len(shape) == 1 and shape[0].fit.stats.holds


def test_a_piece_no_surface_fits_over_its_projection_is_split_and_its_halves_hold():
    """A half cylinder (r 20 mm, 40 mm long) parameterised by projection onto its base plane: its slope
    runs to infinity at the plane, and the fit over that projection meets the tolerance only with a
    control point per fewer than 4 data points (840 for 3000), if at all. The piece is split across its
    longest extent and each half parameterised again: both hold with about 30 control points. (On the YCB meat can, seeds 2-4 of the
    views, pieces of the lid's corner projected onto a cylinder failed so before; with the split every patch
    holds and 29-33 seams are within 1 mm, 20-24 before.)"""
    from rgm.fitters.patch_base import Base, reach_past, unit_box
    from rgm.fitters.patches import _fit_patch, _fit_piece

    rng = np.random.default_rng(5)
    t, y = rng.uniform(0.0, np.pi, 3000), rng.uniform(0, 40, 3000)
    p = np.c_[20 * np.cos(t), y, 20 * np.sin(t)] + rng.normal(0, 0.01, (3000, 3))
    idx, uv = np.arange(len(p)), unit_box(p[:, :2])
    one = _fit_patch(p, idx, Base("plane", 0.0), reach_past(p, *uv, 3.5), 0.05, "max", 4000)
    assert one.shape.fit.n_ctrl * 4 > len(p)
    notes = []
    halves = _fit_piece(p, idx, Base("plane", 0.0), uv, 0.05, "max", 4000, 16, 0.7, notes)
    assert len(halves) >= 2 and all(h.shape.fit.stats.holds for h in halves)
    assert sorted(np.concatenate([h.indices for h in halves]).tolist()) == idx.tolist()
    assert sum(h.shape.fit.n_ctrl for h in halves) < one.shape.fit.n_ctrl / 5
    assert any("split in" in n for n in notes)
    # a piece that fits is left whole
    flat = np.c_[p[:, :2], rng.normal(0, 0.01, len(p))]
    assert len(_fit_piece(flat, idx, Base("plane", 1.0), uv, 0.05, "max", 4000, 16, 0.7, [])) == 1


def test_bad_input_gives_clear_errors():
    with pytest.raises(GeometryError, match="at least 16 points"):
        fit_patches(np.zeros((5, 3)), 0.1)
    bad = np.random.default_rng(0).normal(size=(100, 3))
    bad[3, 1] = np.nan
    with pytest.raises(GeometryError, match="NaN"):
        split_scattered(bad)


@pytest.mark.skipif(not MUSTARD.exists(), reason=f"shared data folder absent: {MUSTARD}")
@pytest.mark.parametrize("seed", [1, 4])
def test_mustard_bottle_views_become_patches_split_at_its_sharp_edges(tmp_path, seed):
    """Six scan-like views of the YCB mustard bottle (mm, 1.5 mm pitch, 0.05 mm noise, 2 % outliers
    removed by the statistical filter) -> patches split at the cap and shoulder edges, each a trimmed
    NURBS meeting 1 mm at p95, its trimming loops valid; the .rgm checks clean and OpenCASCADE accepts its faces."""
    p = ycb_views(MUSTARD, seed)
    t0 = time.perf_counter()
    result = fit_patches(p, 1.0, statistic="p95")
    seconds = time.perf_counter() - t0
    assert len(result) >= 4
    assert all(s.fit.stats.holds and s.fit.stats.p95 <= 1.0 for s in result.shapes)
    z = [p[q.indices, 2] for q in result.patches]
    # the cap (above the shoulder, z > 168 mm) is split from the body: no patch spans both
    assert not any(zz.min() < 100 and zz.max() > 175 for zz in z)
    assert any(zz.min() > 150 for zz in z) and any(zz.max() < 10 for zz in z)  # a cap patch, a bottom patch
    assert result.unassigned < 0.01 * len(p)
    # every trimming loop is valid: simple, holes inside the outer loop and apart (patches 5, 7, 9 and 11
    # crossed themselves at narrow necks and corners before, and OpenCASCADE refused their faces)
    assert all(check_loops(s.loops.outer, s.loops.holes) == [] for s in result.shapes)
    text, parts = patches_text(result, 1.0, title="mustard")
    model = rgm.loads(text)
    assert not [d for d in model.diagnostics if d.is_error]
    assert all(isinstance(model.objects[f"patch_{k}"], TrimmedFace) for k in range(1, len(result) + 1))
    if importlib.util.find_spec("OCP") is not None:   # the faces OpenCASCADE builds pass BRepCheck_Analyzer
        from rgm.backends.occ import write_step

        write_step(model, tmp_path / "mustard.step", tol=1.0)
    # the printed (rounded) trimmed surface of the largest patch is as close to its points as the fit said
    # (all of them: the fit stops as soon as its p95 holds, so a sample's p95 may lie either side of 1 mm)
    assert np.percentile(parts[0].ideal.distance(p[result.patches[0].indices]), 95) <= 1.0
    gaps = np.array([g.max for g in result.gaps])
    assert len(gaps) >= len(result) - 1 and np.all(np.isfinite(gaps))
    # the bottom, shoulder and cap creases are shared where the surfaces cross (each reaches past its data,
    # so no domain edge clamps the intersection): within the tolerance along the edge; every pair not
    # shared says why. The body's wrap is one surface closed round its axis, its two faces meeting along
    # the same curve. (The counts of seams within 1 mm recorded here until 2026-12-07, 13 of 13 for seed 1
    # and all for seeds 2-11, took a shared seam along its edge alone; their history is in docs/fitting.md
    # and the commit log.)
    shared = [g for g in result.gaps if g.shared]
    assert any("closed round its axis" in g.why and not g.shared for g in result.gaps)
    assert len(shared) >= 3 and all(g.max <= 1.0 for g in shared)
    # G0 as the file reads back (`rgmc verify`): every sample of every seam, beyond a shared edge's ends
    # too. Seeds 1 and 4: 10 of 10 within 1 mm, worst 0.80 and 0.56 mm, since the closed body takes the
    # neighbours its surface serves (pieces of its shoulder, 240-290 points). Seed 1 before: 13 of 13
    # within 1 mm, worst 0.69 mm, since the faces of a closed wrap grow (the body's
    # half stopped 2.49 mm above the bottom beyond the edge they share; until 2026-12-07 the count took
    # the edge alone and read 13 of 13). Seed 4: 12 of 12, worst 0.69 mm, since a grown hole follows the
    # neighbour's edge within a quarter of the tolerance and the cap's edges with its top run to the
    # wrap's seam (9 of 12 before, worst 1.10 mm: the shoulder ring's hole round the cap's wrap 1.02 and
    # 1.10 mm from it, the cap's top 1.02 mm from a wrap face beside the seam; 1.72 before the wraps grew;
    # 11 of 12 before the fitter's choices weighed a shared seam's rest). Floating-point differences steer
    # the fitter's discrete choices by machine: one seam may fall just over
    seams = file_seams(p, parts)
    assert set(seams) == {(g.i, g.j) for g in result.gaps}
    within = sum(g.max <= 1.0 for g in seams.values())
    assert within >= len(seams) - 1 and max(g.max for g in seams.values()) < 1.2, \
        sorted((round(g.max, 2), g.a, g.b) for g in seams.values() if g.max > 1.0)
    assert max(g.max for g in shared) < min(g.before for g in shared)
    assert all(g.why for g in result.gaps if not g.shared)
    for g in shared:   # one binding, used by both faces' loops
        assert_one_binding_in_both_loops(text, g)
    apart = [g for g in result.gaps if not g.shared]
    # the gaps reported are those of the loops as written (a face with shared edges has its data loop
    # re-fitted between their joins): measured again on the file read back, every sample 0.05 mm apart, to
    # the faces as rgm reads them back (a seam's largest gap can be a peak under 0.1 mm wide, where the
    # faces near a sample change: samples 0.1 mm apart, placed otherwise than rgm's, missed one by 0.11 mm)
    written = written_gaps(p, result, model, step=0.05)
    for g in result.gaps:
        if (g.i, g.j) in written and "closed round its axis" not in g.why:
            if g.shared:   # the file's data pieces near the neighbour; the edge itself is measured along it
                assert abs(written[(g.i, g.j)] - g.rest) <= 0.1, (g.i, g.j, g.rest, written[(g.i, g.j)])
            else:
                assert abs(written[(g.i, g.j)] - g.max) <= 0.1, (g.i, g.j, g.max, written[(g.i, g.j)])
    print(f"mustard: {len(p)} points, {len(result)} patches, ctrl {[s.fit.n_ctrl for s in result.shapes]}, "
          f"p95 {[round(s.fit.stats.p95, 2) for s in result.shapes]}, "
          f"max {[round(s.fit.stats.max, 2) for s in result.shapes]}; {len(shared)} of {len(gaps)} seams shared, "
          f"{within} within 1 mm as written; G0 gap on the shared edges max {max(g.max for g in shared):.3f} mm (separate trims "
          f"{[round(g.before, 2) for g in shared]} mm); the others max {max(g.max for g in apart):.2f} mm, "
          f"median {np.median([g.max for g in apart]):.2f} mm, {seconds:.1f} s")


@pytest.mark.skipif(not MEAT_CAN.exists(), reason=f"shared data folder absent: {MEAT_CAN}")
def test_potted_meat_can_patches_share_only_edges_an_exact_intersector_finds(tmp_path):
    """The YCB potted meat can, viewed as the mustard bottle: every patch meets 1 mm, every shared edge is
    within it, and OpenCASCADE builds the faces. Regressions: a seam's run following the branch to the end
    of its samples (an IndexError); patches 7 and 8, whose intersection marched at the tolerance joins a
    branch and a small closed loop where the surfaces nearly touch (OpenCASCADE splits them, and its edge
    missed the joins by 4.47 mm): such a stretch is not shared; patches 4 and 9, whose stretch marched at
    the tolerance ran from one branch onto another passing 0.57 mm away (OpenCASCADE's edge missed a join
    by 2.33 mm): not shared either; patch 4 (39 x 35 control points), the pcurve of whose seam curve,
    projected onto it at the tolerance, looped back on itself (OpenCASCADE refused the wire): the back end
    projects at a hundredth of it."""
    p = ycb_views(MEAT_CAN)
    result = fit_patches(p, 1.0, statistic="p95")
    assert all(s.fit.stats.holds and s.fit.stats.p95 <= 1.0 for s in result.shapes)
    shared = [g for g in result.gaps if g.shared]
    # (4 shared of 35 seams until the mantle took its rim's slivers, 3 of 18 since)
    assert len(shared) >= 3 and all(g.max <= 1.0 for g in shared)
    # G0 as the file reads back (`rgmc verify`, every sample of every seam, beyond a shared edge's ends
    # too): 8 of 18 seams within 1 mm, worst 3.49 mm (seeds 2-4 23/34, 9/13, 3/13; at 1 mm views seeds
    # 1-3 4/8, 6/14, 3/8: 52 seams over 1 mm in the ten view sets of docs/fitting.md, summed excess 51.6
    # mm), since a shared intersection that stops short of its seam's ends may give way to one curve along
    # all of it, and a seam curve keeps the stretch where the surfaces pass within the tolerance (before:
    # worst 3.63; 23/33, 8/13, 6/14; 4/8, 6/14, 2/8: 51 over, 57.2 mm), since the
    # mantle and its rolled rim are one surface swept along their profile (before: seeds 2-4 30/41,
    # 41/58, 14/37; 6/11, 10/19, 6/12; this seed's rim pieces need more control points than the sweep may
    # take, and its figures did not move), since the closed mantle takes slivers of the rolled rim that its surface serves (before: 16/35, 36/65,
    # 53/68, 39/56; 8/21, 13/20, 13/19), since grown holes follow a neighbour's edge within a quarter of the
    # tolerance and edges run to a closed wrap's seam (before: 16/35, 45/63, 60/72, 40/52; 8/21, 13/20,
    # 11/19; the rim's slivers steer the choices: a shared stretch moved at the mantle's seam changes
    # which loops rebuild), since the faces of the closed wrap grow too (before: 20/38, 46/65,
    # 59/76, 42/54; 6/21, 8/19, 13/18; before the fitter's choices weighed a shared seam's rest and a
    # shared stretch that stops short of a three-patch corner was carried on to it: 17/36, 26/60, 36/75,
    # 34/55; 5/20, 10/21, 13/18). Until 2026-12-07 the counts here took a shared seam along its edge
    # alone (23 of 39, worst 3.79 mm); their history is in docs/fitting.md and the commit log. What stays
    # open: the rolled rim's slivers and the lid's three-patch corners, whose trims stop 1-4 mm short
    text, parts = patches_text(result, 1.0, title="meat can")
    seams = file_seams(p, parts)
    within = sum(g.max <= 1.0 for g in seams.values())
    curves = [g for g in shared if g.curve]
    print(f"meat can: {len(shared)} of {len(result.gaps)} seams shared ({len(curves)} as seam curves), "
          f"{within} of {len(seams)} within 1 mm as written, worst {max(g.max for g in seams.values()):.2f} mm, "
          f"ctrl {[s.fit.n_ctrl for s in result.shapes]}")
    # the figures move by machine (floating-point differences steer discrete choices: the segmentation's
    # pieces, the knots inserted); regression bounds
    assert within >= 0.4 * len(seams) and max(g.max for g in seams.values()) < 5.0
    assert all(g.max < g.before for g in curves)
    assert all(g.why for g in result.gaps if not g.shared)
    for g in shared:
        assert_one_binding_in_both_loops(text, g)
    model = rgm.loads(text)
    assert not model.diagnostics      # no error, and no loop piece running backwards (W0505)
    # every loop closes as rgmc compile reads the file back: the intersections of the printed surfaces run
    # between their joins (one of seed 4's, marched from the printed digits, was a closed loop 29.6 mm off)
    from rgm.model.validate import validate_lazy

    assert validate_lazy(model) == []
    if importlib.util.find_spec("OCP") is not None:
        from rgm.backends.occ import write_step

        write_step(model, tmp_path / "meat_can.step", tol=1.0)


def test_anchors_pull_a_surface_through_a_curve_and_the_data_keep_their_certificate():
    """`Anchors`: points a fitted surface passes through at fixed parameters (a weighted penalty), not
    data: the refinement inserts knots until they are met within their tolerance, and the certificate
    is measured on the data alone."""
    from rgm.fitters.freeform import Anchors
    from rgm.fitters.freeform_part import fit_freeform

    rng = np.random.default_rng(3)
    p = np.c_[rng.uniform(0, 50, (3000, 2)), rng.normal(0, 0.02, 3000)]   # a noisy plane z = 0
    u, v = p[:, 0] / 50, p[:, 1] / 50
    t = np.linspace(0.05, 0.95, 200)
    uv = np.c_[np.full_like(t, 0.1), t]                                  # along one edge, lifted 0.3 mm
    lifted = np.c_[50 * uv, np.full(len(t), 0.3)]
    plain = fit_freeform(p, 0.2, params=(u, v), cuts=False)
    pulled = fit_freeform(p, 0.2, params=(u, v), cuts=False, anchors=Anchors(uv, lifted, 10.0, 0.03))
    assert pulled.fit.stats.holds and pulled.fit.stats.p95 <= 0.2
    on = pulled.nurbs().evaluate(uv[:, 0], uv[:, 1])
    assert np.percentile(np.linalg.norm(on - lifted, axis=1), 95) <= 0.03
    assert np.abs(plain.nurbs().evaluate(uv[:, 0], uv[:, 1])[:, 2]).max() < 0.1   # without: the plane
    assert pulled.fit.n_ctrl > plain.fit.n_ctrl          # knots were inserted for the anchors


def _rounded_box(seed=0, half=(30.0, 20.0, 15.0), radius=6.0, pitch=1.0, noise=0.02):
    """Points (n, 3) on a box (half sizes, mm) whose edges and corners are rounded to `radius`: the inner box
    grown by it, about `pitch` apart (one point per cubic cell), with noise."""
    rng = np.random.default_rng(seed)
    half = np.asarray(half)
    inner = half - radius
    x = rng.uniform(-1, 1, size=(200_000, 3)) * (half + 5)
    d = x - np.clip(x, -inner, inner)
    n = np.linalg.norm(d, axis=1)
    s = np.clip(x, -inner, inner)[n > 1e-9] + radius * d[n > 1e-9] / n[n > 1e-9, None]
    _, first = np.unique(np.floor(s / pitch).astype(int), axis=0, return_index=True)
    return s[first] + rng.normal(0, noise, (len(first), 3))


def test_edges_rounded_to_6_mm_split_only_at_a_lower_crease_angle():
    """A box with 6 mm rounded edges (1 mm pitch): at the default 35 degrees (and at 25) the crease finder
    sees no crease, its 32 nearest neighbours turning by about 30 degrees across a rounding; at 20 degrees
    it finds the six faces (`rgmc fit --crease-angle`)."""
    p = _rounded_box()
    assert len(split_scattered(p)) == 1 and len(split_scattered(p, angle_deg=25)) == 1
    faces = split_scattered(p, angle_deg=20)
    assert len(faces) == 6
    normals = [np.linalg.svd(p[f] - p[f].mean(axis=0), full_matrices=False)[2][-1] for f in faces]
    assert sorted(int(np.argmax(np.abs(n))) for n in normals) == [0, 0, 1, 1, 2, 2]   # one face per side


@pytest.mark.skipif(not CRACKER_BOX.exists(), reason=f"shared data folder absent: {CRACKER_BOX}")
def test_cracker_box_with_rounded_edges_becomes_its_six_faces():
    """The YCB cracker box's edges are rounded (the scan's mesh): at the default 35 degrees the crease finder
    sees no crease between its four long faces, which were fitted as one surface closed round the box (p95
    0.8 mm, but 11.8-13.5 mm off at the edges). A fit that misses points by 10 tolerances while its
    statistic holds has rounded off an edge: the group is split again at 20 degrees (`fit_patches`), and
    the box is its six faces, every seam within 1 mm as the file reads back (seed 1: 12 of 12, worst 0.45
    mm, all shared; 5 of 12, worst 4.15 mm, before a shared stretch that stopped short of a corner, up to
    34 mm where the corner's rounded data belong to any of the three faces, was carried on to it: the
    faces' data pieces rounded the corners off)."""
    p = ycb_views(CRACKER_BOX)
    assert len(split_scattered(p)) < 6
    part = fit_freeform_part(p, np.arange(len(p)), 1.0)
    assert len(part.shapes) == 6
    assert any("split at 20 degrees" in n for n in part.notes)
    assert all(s.fit.stats.holds and s.fit.stats.max < 10.0 for s in part.shapes)
    gaps = [float(m) for n in part.notes for m in re.findall(r"G0 gap (?:on it )?max ([0-9.]+) mm", n)]
    assert len(gaps) >= 9 and max(gaps) <= 1.0, gaps
    count = range(1, len(part.shapes) + 1)
    seams = file_seams(p, emit_freeform_set(part.shapes, [f"patch_{k}" for k in count], [f"_{k}" for k in count],
                                            tolerance=1.0))
    assert len(seams) >= 9 and max(g.max for g in seams.values()) <= 1.0, seams


def test_the_crease_angle_reaches_the_splitter(monkeypatch):
    """`rgmc fit --crease-angle` (`fit_freeform_part(crease_deg=)`) is the angle the scattered points are
    split at."""
    import rgm.fitters.patches as patches

    seen = []
    real = patches.split_scattered
    monkeypatch.setattr(patches, "split_scattered", lambda *a, **kw: seen.append(kw["angle_deg"]) or real(*a, **kw))
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 30, size=(600, 2))
    p = np.c_[xy, 0.002 * (xy ** 2).sum(axis=1) + rng.normal(0, 0.01, len(xy))]
    part = fit_freeform_part(p, np.arange(len(p)), 0.1, crease_deg=27.0)
    assert seen[0] == 27.0 and len(part.shapes) == 1
