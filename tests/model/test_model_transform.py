"""Transform values (`translation`, `rotation`, `scaling`, `mirroring`, `frame`, `t2 * t1`, `inverse`,
`place`) through the language: composition applies the right operand first, `inverse` undoes, `frame`
is the rigid placement of a part-aligned frame, `place` with a constructor moves geometry exactly as
the matching `translate`/`rotate`/`scale`/`mirror` does, spans and kinds survive, and what the
checker cannot see (axes given through a fn) fails as a diagnostic on the call."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rgm
from rgm.compiler.diagnostics import CompileError
from rgm.errors import GeometryError
from rgm.model import Circle, Revolution, Transform
from rgm.model.transform import frame, rotation, translation

small = st.integers(-9, 9)
vec3 = st.tuples(small, small, small).filter(any)


def _v(xyz) -> str:
    return ", ".join(str(c) for c in xyz)


@st.composite
def transforms(draw):
    """The text of a transform value expression (one constructor)."""
    kind = draw(st.sampled_from(["translation", "rotation", "scaling", "mirroring", "frame"]))
    if kind == "translation":
        return f"translation(vec({_v(draw(vec3))}))"
    if kind == "rotation":
        return f"rotation(vec({_v(draw(vec3))}), {draw(st.integers(-360, 360))}deg, about: pt({_v(draw(vec3))}))"
    if kind == "scaling":
        return f"scaling({draw(st.sampled_from([0.5, 2, 3]))}, about: pt({_v(draw(vec3))}))"
    if kind == "mirroring":
        return f"mirroring(plane(pt({_v(draw(vec3))}), vec({_v(draw(vec3))})))"
    z = draw(vec3)
    x = draw(vec3.filter(lambda x: np.linalg.norm(np.cross(x, z)) > 1e-6))
    return f"frame(pt({_v(draw(vec3))}), vec({_v(z)}), vec({_v(x)}))"


BODY = """units mm;
profile := polyline([pt(2, 0, 0), pt(3, 1, 0), pt(3, 4, 0), pt(2, 5, 0)]);
body := revolve(profile, line(pt(0, 0, 0), pt(0, 1, 0)), to: 270deg);
"""


def _samples(surface) -> np.ndarray:
    s = surface.nurbs()
    (u0, u1), (v0, v1) = s.domain
    return s.evaluate_grid(np.linspace(u0, u1, 9), np.linspace(v0, v1, 9)).reshape(-1, 3)


@settings(max_examples=20, deadline=None)
@given(transforms(), transforms())
def test_composition_applies_the_right_operand_first_and_inverse_undoes(t1, t2):
    model = rgm.loads(BODY + f"t1 := {t1};\nt2 := {t2};\nboth := place(body, t2 * t1);\n"
                      "step := place(place(body, t1), t2);\nback := place(both, inverse(t2 * t1));\n")
    both, step, back, body = (model[n] for n in ("both", "step", "back", "body"))
    assert isinstance(both, Revolution) and isinstance(model["t1"], Transform)
    scale = np.abs(_samples(body)).max() * 27 + 1
    assert np.abs(_samples(both) - _samples(step)).max() <= 1e-9 * scale
    assert np.abs(_samples(back) - _samples(body)).max() <= 1e-9 * scale
    expected = model["t2"].matrix @ model["t1"].matrix
    assert np.allclose(model["both"].axis_point, (expected @ [*body.axis_point, 1])[:3])


@settings(max_examples=20, deadline=None)
@given(vec3, vec3, st.integers(-360, 360), st.sampled_from([0.5, 2.0, -3.0]))
def test_place_with_a_constructor_moves_as_the_direct_transform_does(v, p, degrees, factor):
    pairs = {"translate(body, vec({v}))": "translation(vec({v}))",
             "rotate(body, vec({v}), {a}deg, about: pt({p}))": "rotation(vec({v}), {a}deg, about: pt({p}))",
             "mirror(body, plane(pt({p}), vec({v})))": "mirroring(plane(pt({p}), vec({v})))"}
    if factor > 0:   # `scale` may reflect through its centre; `scaling` only scales
        pairs["scale(body, {f}, about: pt({p}))"] = "scaling({f}, about: pt({p}))"
    text = BODY + "".join(f"d{i} := {d};\np{i} := place(body, {t});\n" for i, (d, t) in enumerate(pairs.items()))
    model = rgm.loads(text.format(v=_v(v), p=_v(p), a=degrees, f=factor))
    for i in range(len(pairs)):
        assert np.allclose(_samples(model[f"d{i}"]), _samples(model[f"p{i}"]), atol=1e-9 * 100)


@settings(max_examples=30, deadline=None)
@given(vec3, vec3, vec3)
def test_frame_is_the_rigid_placement_of_the_part_axes(origin, z, x):
    if np.linalg.norm(np.cross(z, x)) <= 1e-6 * np.linalg.norm(z) * np.linalg.norm(x):
        with pytest.raises(GeometryError, match="parallel"):
            frame(origin, z, x)
        return
    m = frame(origin, z, x)
    lin = m[:3, :3]
    assert np.allclose(lin.T @ lin, np.eye(3)) and np.linalg.det(lin) == pytest.approx(1.0)
    assert np.allclose(m[:3, 3], origin) and np.allclose(lin[:, 2], np.asarray(z) / np.linalg.norm(z))
    # local x is `x` made perpendicular to z: in the plane of x and z, on the side of x
    assert abs(lin[:, 0] @ lin[:, 2]) < 1e-12 and lin[:, 0] @ x > 0
    assert abs(np.linalg.det(np.column_stack([lin[:, 0], x, z]))) < 1e-9 * np.linalg.norm(x) * np.linalg.norm(z)


def test_frame_places_local_geometry_and_keeps_names_and_spans():
    text = ("units mm;\nseat := frame(pt(10, 0, 5), vec(0, 0, 2), vec(1, 1, 0));\n"
            "ring := circle(pt(3, 0, 0), 1mm);\nplaced := place(ring, seat);\ntip := place(pt(0, 0, 1), seat);\n"
            "turn := rotation(vec(0, 0, 1), 90deg) * translation(vec(1, 0, 0));\n")
    model = rgm.loads(text, filename="f.rgm")
    placed, seat, turn = model["placed"], model["seat"], model["turn"]
    assert isinstance(placed, Circle) and placed.name == "placed" and placed.span.line == 4
    assert np.allclose(placed.center, [10 + 3 / np.sqrt(2), 3 / np.sqrt(2), 5]) and placed.radius == 1.0
    assert np.allclose(model["tip"].xyz, [10, 0, 6])
    assert seat.name == "seat" and (seat.span.line, seat.span.col) == (2, 9)
    assert text[turn.span.start_pos:turn.span.end_pos] == text.splitlines()[5][8:-1]   # the span of `a * b`
    assert np.allclose(turn.matrix, rotation([0, 0, 1], np.pi / 2, [0, 0, 0]) @ translation([1, 0, 0]))


def test_this_flange_four_times():
    text = """units mm;
flange := circle(pt(40, 0, 0), 5mm);
fn flange_at(k: int) := place(flange, rotation(vec(0, 0, 1), k * 90deg));
f0 := flange_at(0);
f1 := flange_at(1);
f2 := flange_at(2);
f3 := flange_at(3);
export f0, f1, f2, f3;
"""
    model = rgm.loads(text)
    centers = np.array([model[f"f{k}"].center for k in range(4)])
    assert np.allclose(centers, [[40, 0, 0], [0, 40, 0], [-40, 0, 0], [0, -40, 0]], atol=1e-12)


@pytest.mark.parametrize("body, words", [
    ("frame(pt(0, 0, 0), vec(0, 0, 1), d)", "parallel"),
    ("frame(pt(0, 0, 0), d - d, vec(1, 0, 0))", "zero length"),
    ("rotation(d - d, 90deg)", "zero length"),
])
def test_axes_the_checker_cannot_see_fail_on_the_call(body, words):
    text = f"fn bad(d: vec) := {body};\nt := bad(vec(0, 0, 3));\np := place(pt(1, 2, 3), t);\nexport p;\n"
    with pytest.raises(CompileError) as info:
        rgm.loads(text, filename="bad.rgm")
    diag = next(d for d in info.value.diagnostics if d.is_error)
    assert diag.code == "E0510" and words in diag.message and diag.span.line == 1


def test_a_scaling_factor_from_a_fn_must_be_positive():
    text = "fn grow(k: num) := scaling(k);\nt := grow(0 - 2);\np := place(pt(1, 2, 3), t);\nexport p;\n"
    with pytest.raises(CompileError) as info:
        rgm.loads(text, filename="bad.rgm")
    assert any(d.code == "E0510" and "positive" in d.message for d in info.value.diagnostics)


def test_transform_objects_are_immutable_4x4_similarities():
    t = Transform(rotation([1, 2, 3], 0.7, [1, 0, 0]))
    with pytest.raises(ValueError):
        t.matrix[0, 0] = 2.0
    with pytest.raises(GeometryError):
        Transform(np.eye(3))
    assert np.allclose(t.after(t.inverse()).matrix, np.eye(4))


@settings(max_examples=20, deadline=None)
@given(st.floats(0.1, 10.0), st.floats(0.0, 2 * np.pi))
def test_a_scaled_plane_face_keeps_its_arcs_on_their_circles(scale, turn):
    """A trimmed face on a plane, a half-disc hole (a 2-D arc and its chord) in its loops, scaled by s:
    the hole's arc is still a circle through its ends (radius s r = |start - centre|), where the plane
    coordinates of every point scale by s (an arc's radius took s^(2/3): --hypothesis-profile=explore)."""
    from rgm.model import CircularArc, Line, Loop, Plane, TrimmedFace
    from rgm.model.transform import scaling

    c, r = np.array([-1.9, 0.3]), 0.55
    a, b = c + r * np.array([np.cos(turn), np.sin(turn)]), c - r * np.array([np.cos(turn), np.sin(turn)])
    hole = Loop((CircularArc(c, [0, 0, 1.0], r, a, b), Line(b, a)))
    square = np.array([[-4.0, -3], [3, -3], [3, 3], [-4, 3]])
    outer = Loop(tuple(Line(square[k], square[(k + 1) % 4]) for k in range(4)))
    face = TrimmedFace(Plane([1.0, 2, 3], [0, 0, 1.0]), outer, (hole,))
    arc = face.transform(scaling(scale, [0.5, -1.0, 2.0])).holes[0].pieces[0]
    assert np.isclose(arc.radius, scale * r, rtol=1e-12)
    assert np.isclose(np.linalg.norm(arc.start_point - arc.center), arc.radius, rtol=1e-12)
    assert np.isclose(np.linalg.norm(arc.end_point - arc.center), arc.radius, rtol=1e-12)
