"""Lazy intersections: nothing is marched by `rgmc check` or `rgm.load`; results are cached per
tolerance and get more accurate as the tolerance shrinks."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rgm
from rgm.geometry import intersect
from rgm.model import IntersectionCurve, Plane, TrimmedFace

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

HAND_LIKE = """
units mm;
tolerance 0.01;
param cut_at := 27mm;
palm := bsurface(degree_u: 3, degree_v: 3, knots_u: uniform(3, 4), knots_v: uniform(3, 4),
                 net: net 4 x 4 [0 0 0, 0 30 1, 0 60 1, 0 90 0,
                                 30 0 2, 30 30 4, 30 60 4, 30 90 2,
                                 60 0 2, 60 30 4, 60 60 4, 60 90 2,
                                 90 0 0, 90 30 1, 90 60 1, 90 90 0]);
wrist := intersect(palm, plane(pt(0, cut_at, 0), vec(0, 1, 0)));
outline := loop(wrist, uvline(uv(0, 0.3), uv(0, 1)), uvline(uv(0, 1), uv(1, 1)), uvline(uv(1, 1), uv(1, 0.3)));
hand := trim(palm, outer: outline);
moved := translate(hand, vec(0, 0, 5));
export hand, moved;
"""


@pytest.fixture
def no_marching(monkeypatch):
    """Every intersection entry point raises: a test using this fixture proves nothing is marched."""
    def forbidden(*args, **kwargs):
        raise AssertionError("an intersection was computed")

    for name in ("intersect_surfaces", "intersect_surface_plane", "_solve"):
        monkeypatch.setattr(intersect, name, forbidden)


def _sources():
    files = sorted(EXAMPLES.glob("hand*.rgm"))
    return [(f.read_text(), str(f)) for f in files] + [(HAND_LIKE, "hand_like.rgm")]


@pytest.mark.parametrize("text,name", _sources(), ids=lambda v: Path(v).name if v.endswith(".rgm") else None)
def test_load_computes_no_intersection(no_marching, text, name):
    model = rgm.loads(text, filename=name)
    lazy = [o for o in model.objects.values() if isinstance(o, IntersectionCurve)]
    assert lazy, "the example has an intersect(...)"
    assert all(o.computed == () for o in lazy)
    face = next(o for o in model.exported() if isinstance(o, TrimmedFace))
    assert face.outer.is_lazy


def test_rgmc_check_computes_no_intersection(no_marching, tmp_path, capsys):
    from rgm.cli import main

    path = tmp_path / "hand.rgm"
    path.write_text(HAND_LIKE)
    files = [str(path)] + [str(f) for f in sorted(EXAMPLES.glob("hand*.rgm"))]
    assert main(["check", *files]) == 0


def test_approximate_is_cached_per_tolerance_and_tighter_is_better(monkeypatch):
    model = rgm.loads(HAND_LIKE, filename="hand_like.rgm")
    wrist = model["wrist"]
    calls = []
    real = intersect.intersect_surface_plane
    monkeypatch.setattr(intersect, "intersect_surface_plane", lambda *a: calls.append(a[-1]) or real(*a))
    coarse = wrist.approximate(1e-2)
    assert wrist.approximate(1e-2) is coarse and calls == [1e-2]
    fine = wrist.approximate(1e-5)
    assert calls == [1e-2, 1e-5] and wrist.computed == (1e-2, 1e-5)
    palm = model["palm"].nurbs()

    def true_error(branches):
        worst = 0.0
        for br in branches:
            pts = br.curve.evaluate(np.linspace(*br.curve.domain, 400))
            worst = max(worst, palm.closest_point(pts)[3].max(), np.abs(pts[:, 1] - 27.0).max())
        return worst

    e_coarse, e_fine = true_error(coarse), true_error(fine)
    assert e_coarse <= 1e-2 and e_fine <= 1e-5
    assert e_fine < e_coarse / 10


def test_plane_operand_gets_exact_plane_coordinates():
    model = rgm.loads(HAND_LIKE, filename="hand_like.rgm")
    wrist = model["wrist"]
    plane = wrist.b
    assert isinstance(plane, Plane)
    (branch,) = wrist.approximate(1e-3)
    t = np.linspace(*branch.curve.domain, 50)
    pts = branch.curve.evaluate(t)
    uv = branch.uv_b.evaluate(t)
    back = plane.origin + uv[:, :1] * plane.x_dir + uv[:, 1:] * plane.y_dir
    assert np.abs(back - pts).max() < 1e-9
    on_palm = model["palm"].nurbs().evaluate(*branch.uv_a.evaluate(t).T)
    assert np.linalg.norm(on_palm - pts, axis=1).max() <= 1e-3
    # the face's own surface finds its pcurve through the loop piece
    assert wrist.uv_curves(model["palm"], 1e-3)[0] is branch.uv_a


def test_transformed_face_keeps_the_intersection_on_its_surface():
    model = rgm.loads(HAND_LIKE, filename="hand_like.rgm")
    moved = model["moved"]
    piece = moved.outer.pieces[0]
    assert isinstance(piece, IntersectionCurve) and piece.computed == ()
    assert piece.a is moved.surface
    (branch,) = piece.approximate(1e-3)
    assert np.allclose(branch.curve.evaluate(np.array([0.5]))[0][2] - 5.0,
                       model["wrist"].approximate(1e-3)[0].curve.evaluate(np.array([0.5]))[0][2], atol=2e-3)


def test_compile_checks_lazy_loops_once_approximated(tmp_path, monkeypatch, capsys):
    import sys
    import types

    from rgm.cli import main
    from rgm.commands import compile as compile_cmd

    written = []
    fake = types.ModuleType("rgm.backends._lazyfake")
    fake.write_fake = lambda model, path, **opts: written.append(model["wrist"].computed)
    monkeypatch.setitem(sys.modules, "rgm.backends._lazyfake", fake)
    monkeypatch.setitem(compile_cmd.TARGETS, "iges", ("rgm.backends._lazyfake", "write_fake", {}))
    src = tmp_path / "hand.rgm"
    src.write_text(HAND_LIKE)
    assert main(["compile", str(src), "-t", "iges", "-o", str(tmp_path / "h.igs")]) == 0
    assert written == [(0.01,)], "approximated once, at the model tolerance, before the back end ran"
    # the wrist cut moved away from where the side lines start: the loop no longer closes
    assert main(["compile", str(src), "-t", "iges", "-o", str(tmp_path / "h.igs"), "-D", "cut_at=10"]) == 1
    out = capsys.readouterr().out
    assert "E0504" in out and "not closed" in out and len(written) == 1
