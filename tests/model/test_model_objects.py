"""Model objects: immutable, and transforms keep the object's kind while moving its exact NURBS form
exactly as the 4x4 matrix moves points (oracle: transform the NURBS of the original)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from rgm.model.transform import mirroring, rotation, scaling, translation
from rgm.geometry import NurbsSurface
from rgm.model import (BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, Line, Model, Plane, Point,
                       Polyline, Revolution, RuledSurface)

finite = st.floats(-50, 50, allow_nan=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)


def _objects():
    arc = CircularArc([0, 0, 0], [0, 0, 1], 2.0, [2, 0, 0], [0, 2, 0])
    profile = Polyline([[0, 0, 0], [3, 0, 1], [3, 0, 5], [0, 0, 6]])
    net = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), axis=2)
    net = np.concatenate([net, np.sin(net[..., :1] + net[..., 1:])], axis=2)
    k = [0, 0, 0, 0, 1, 1, 1, 1]
    return [
        Line([0, 0, 0], [1, 2, 3]),
        profile,
        Circle([1, 2, 3], [0, 1, 1], 4.0),
        arc,
        CompositeCurve([Line([2, 2, 0], [2, 0, 0]), arc]),
        Revolution(profile, [0, 0, 0], [0, 0, 1], 0.0, 1.5),
        Extrusion(arc, [0, 0, 4]),
        RuledSurface(Line([0, 0, 0], [4, 0, 0]), arc),
        BSplineSurface(NurbsSurface(3, 3, k, k, net)),
    ]


def _similarity(draw_axis, angle, shift, factor, mirror):
    m = translation(shift) @ rotation(draw_axis, angle, [1.0, -2.0, 0.5]) @ scaling(factor, [0.3, 0.0, 0.0])
    return mirroring(Plane([0, 0, 1], [0.2, 1.0, 0.3])) @ m if mirror else m


def _samples(obj, n=7):
    nurbs = obj.nurbs()
    if hasattr(nurbs, "knots_u"):
        (u0, u1), (v0, v1) = nurbs.domain
        return nurbs.evaluate_grid(np.linspace(u0, u1, n), np.linspace(v0, v1, n)).reshape(-1, 3)
    return nurbs.evaluate(np.linspace(*nurbs.domain, 4 * n))


def _apply(m, pts):
    return pts @ m[:3, :3].T + m[:3, 3]


@settings(max_examples=15, deadline=None)
@given(axis=vec3.filter(lambda v: np.linalg.norm(v) > 1e-3), angle=st.floats(-6.3, 6.3), shift=vec3,
       factor=st.floats(0.2, 5.0), mirror=st.booleans())
def test_transform_keeps_kind_and_moves_the_exact_shape(axis, angle, shift, factor, mirror):
    m = _similarity(axis, angle, shift, factor, mirror)
    for obj in _objects():
        moved = obj.transform(m)
        assert type(moved) is type(obj)
        expected = _apply(m, _samples(obj))
        got = _samples(moved)
        if isinstance(obj, (Circle, Revolution)):
            # same point set, but the seam may start elsewhere: each side lies on the other
            scale = np.abs(expected).max() + 1
            exact = obj.nurbs().transform(m)
            assert exact.closest_point(got)[-1].max() <= 1e-7 * scale, type(obj).__name__
            assert moved.nurbs().closest_point(expected)[-1].max() <= 1e-7 * scale, type(obj).__name__
        else:
            assert np.abs(expected - got).max() <= 1e-9 * (np.abs(expected).max() + 1), type(obj).__name__


def test_objects_are_immutable():
    line = Line([0, 0, 0], [1, 0, 0], name="a")
    with pytest.raises(dataclasses.FrozenInstanceError):
        line.p0 = np.zeros(3)
    with pytest.raises(ValueError):
        line.p0[0] = 5.0
    plane = Plane([0, 0, 0], [0, 0, 2])
    assert np.isclose(np.linalg.norm(plane.normal), 1.0) and not plane.normal.flags.writeable


def test_named_keeps_geometry_and_span():
    p = Point([1, 2, 3])
    q = p.named("corner")
    assert q.name == "corner" and q is not p and np.array_equal(q.xyz, p.xyz)


def test_exported_defaults_to_surfaces_when_nothing_is_exported():
    line = Line([0, 0, 0], [1, 0, 0])
    surf = Extrusion(line, [0, 0, 1])
    model = Model("mm", 0.01, {"l": line, "s": surf})
    assert model.exported() == [surf]
    assert Model("mm", 0.01, {"l": line, "s": surf}, exports=("l",)).exported() == [line]


@settings(max_examples=25, deadline=None)
@given(st.floats(0.1, 10), st.floats(-3, 3), st.booleans(), st.integers(0, 2**16))
def test_trimmed_plane_loops_follow_a_similarity(factor, angle, mirrored, seed):
    """A plane's (u, v) are lengths along its unit axes: after any similarity (scale, rotation, mirror)
    the parameter-space loop of a trimmed plane still traces the transformed trim in space."""
    from rgm.model import Loop, Polyline, TrimmedFace

    rng = np.random.default_rng(seed)
    plane = Plane(rng.uniform(-5, 5, 3), rng.normal(size=3))
    ring = Polyline(np.vstack([rng.uniform(-3, 3, (5, 2)), [[0.0, 0.0]]])[[0, 1, 2, 3, 4, 0]])
    face = TrimmedFace(plane, Loop((ring,)))
    matrix = rotation(rng.normal(size=3), angle, rng.uniform(-2, 2, 3)) @ scaling(factor, rng.uniform(-2, 2, 3))
    if mirrored:
        matrix = mirroring(Plane(rng.uniform(-1, 1, 3), rng.normal(size=3))) @ matrix
    moved = face.transform(matrix)

    def in_space(f):
        uv = f.outer.pieces[0].nurbs().ctrl
        return f.surface.origin + uv[:, :1] * f.surface.x_dir + uv[:, 1:] * f.surface.y_dir

    expected = in_space(face) @ matrix[:3, :3].T + matrix[:3, 3]
    assert np.abs(in_space(moved) - expected).max() <= 1e-12 * (1 + np.abs(expected).max())
