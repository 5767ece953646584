"""Types, arithmetic rules, units and the builtin signature table against docs/architecture.md."""
import re
from pathlib import Path

from hypothesis import given, settings, strategies as st

from rgm.compiler import builtins, types as T, units
from rgm.compiler.suggest import did_you_mean, edit_distance, suggest

ARCH = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def _contract_section(title: str) -> str:
    text = ARCH.read_text()
    start = text.index(title)
    return text[start:text.index("\n## ", start + 1) if "\n## " in text[start + 1:] else len(text)]


def test_every_builtin_of_the_contract_has_a_signature():
    section = _contract_section("Builtins (the signature table")
    section = section[:section.index("- members:")]
    names = set(re.findall(r"`([A-Za-z_]\w*)\(", section))
    assert {"revolve", "bsurface", "translate", "projPt", "uvline", "shell"} <= names  # the regexp works
    assert names <= set(builtins.FUNCTIONS), names - set(builtins.FUNCTIONS)


def test_contract_parameter_names_and_defaults_match():
    revolve = builtins.FUNCTIONS["revolve"]
    assert revolve.notes == ("revolve(profile: curve3, axis: curve3, from: angle = 0deg, to: angle = 360deg) -> surface",)
    assert [p.name for p in builtins.FUNCTIONS["bspline"].params] == ["degree", "knots", "points", "weights"]
    assert [p.required for p in builtins.FUNCTIONS["trim"].params] == [True, True, False]
    assert builtins.FUNCTIONS["loop"].params[0].variadic


def test_overloads_share_parameter_names():
    for b in builtins.FUNCTIONS.values():
        names = {tuple(p.name for p in s.params) for s in b.overloads}
        assert len(names) == 1, b.name


def test_annotations_are_typed():
    fit = builtins.ANNOTATIONS["fit"].overloads[0]
    assert fit.param("max").type == T.LENGTH and fit.param("points").type == T.INT
    assert fit.param("statistic").type == T.STR and fit.extra is None
    cls = builtins.ANNOTATIONS["classified"].overloads[0]
    assert cls.param("as").type == T.STR and cls.extra == T.NUM
    assert builtins.ANNOTATIONS["source"].overloads[0].param("scans").type == T.list_of(T.STR)
    assert str(fit).startswith("@fit(points: int, max: length")


def test_acceptance_rules():
    assert T.accepts(T.LENGTH, T.NUM) and T.accepts(T.LENGTH, T.INT)   # plain numbers are lengths
    assert not T.accepts(T.ANGLE, T.NUM)                                 # an angle needs deg/rad
    assert not T.accepts(T.ANGLE, T.LENGTH) and not T.accepts(T.NUM, T.LENGTH)
    assert T.accepts(T.SURFACE, T.PLANE) and not T.accepts(T.PLANE, T.SURFACE)
    assert T.accepts(T.list_of(T.union(T.FACE, T.SURFACE)), T.list_of(T.PLANE))
    assert T.accepts(T.list_of(T.POINT3), T.list_of(T.ANY))             # the empty list
    assert not T.accepts(T.INT, T.NUM)
    assert T.accepts(builtins.G, T.SURFACE) and not T.accepts(builtins.G, T.NUM)


def test_arithmetic_rules():
    b = T.binary
    assert b("-", T.POINT3, T.POINT3) == T.VEC
    assert b("+", T.POINT3, T.VEC) == T.POINT3 and b("-", T.POINT3, T.VEC) == T.POINT3
    assert b("+", T.POINT3, T.POINT3) is None
    assert b("*", T.NUM, T.VEC) == T.VEC and b("*", T.VEC, T.INT) == T.VEC and b("/", T.VEC, T.NUM) == T.VEC
    assert b("*", T.LENGTH, T.NUM) == T.LENGTH and b("*", T.INT, T.LENGTH) == T.LENGTH
    assert b("/", T.LENGTH, T.LENGTH) == T.NUM and b("/", T.LENGTH, T.INT) == T.LENGTH
    assert b("+", T.ANGLE, T.ANGLE) == T.ANGLE and b("+", T.ANGLE, T.NUM) is None
    assert b("*", T.LENGTH, T.LENGTH) is None and b("+", T.LENGTH, T.ANGLE) is None
    assert b("+", T.INT, T.INT) == T.INT and b("/", T.INT, T.INT) == T.NUM
    assert b("+", T.LENGTH, T.INT) == T.LENGTH
    assert b("*", T.ANY, T.STR) == T.ANY


@given(st.sampled_from([T.INT, T.NUM, T.LENGTH, T.ANGLE]), st.sampled_from([T.INT, T.NUM, T.LENGTH, T.ANGLE]),
       st.sampled_from("+-*/"))
@settings(max_examples=40, deadline=None)
def test_scalar_rules_follow_dimensional_analysis(left, right, op):
    """Oracle: dimensions as exponent pairs (length, angle); a plain number may stand for a length in + and -."""
    dims = {T.INT: (0, 0), T.NUM: (0, 0), T.LENGTH: (1, 0), T.ANGLE: (0, 1)}
    dl, dr = dims[left], dims[right]
    if op in "+-":
        want = dl if dl == dr else ((1, 0) if {dl, dr} == {(0, 0), (1, 0)} else None)
    else:
        sign = 1 if op == "*" else -1
        want = (dl[0] + sign * dr[0], dl[1] + sign * dr[1])
    got = T.binary(op, left, right)
    named = {(0, 0): (T.NUM, T.INT), (1, 0): (T.LENGTH,), (0, 1): (T.ANGLE,)}
    if want not in named:
        assert got is None
    else:
        assert got in named[want]


def test_members():
    assert T.member(T.POINT3, "x") == T.LENGTH and T.member(T.CURVE3, "start") == T.POINT3
    assert T.member(T.CURVE2, "end") == T.POINT2 and T.member(T.VEC, "length") == T.LENGTH
    assert T.member(T.SURFACE, "domain") == T.list_of(T.NUM) and T.member(T.NUM, "x") is None


def test_type_names_and_descriptions():
    assert T.parse_type_name("list[point3]") == T.list_of(T.POINT3)
    assert T.parse_type_name("curve2 | curve3") == T.union(T.CURVE2, T.CURVE3)
    assert T.parse_type_name("point") == T.POINT3 and T.parse_type_name("blob") is None
    assert T.describe(T.ANGLE) == "an angle" and T.describe(T.LENGTH) == "a length"
    assert T.describe(T.list_of(T.LOOP)) == "a list of loop"


def test_units():
    assert units.dimension("mm") == "length" and units.dimension("deg") == "angle"
    assert units.dimension(None) == "num" and units.dimension("km") is None
    assert units.to_model(1, "in", "mm") == 25.4 and units.to_model(2.54, "cm", "in") == 1.0
    assert abs(units.to_model(180, "deg") - 3.141592653589793) < 1e-15


@given(st.text(alphabet="abcdef", max_size=8), st.text(alphabet="abcdef", max_size=8))
@settings(max_examples=50, deadline=None)
def test_edit_distance_is_a_metric_bounded_by_lengths(a, b):
    d = edit_distance(a, b)
    assert d == edit_distance(b, a)
    assert abs(len(a) - len(b)) <= d <= max(len(a), len(b))
    assert (d == 0) == (a == b)


def test_suggestions():
    assert edit_distance("profiel", "profile") == 1          # a transposition costs one
    assert did_you_mean("profiel", ["profile", "pin", "axis"]) == "did you mean `profile`?"
    assert suggest("xyz", ["profile", "revolve"]) == []
    assert suggest("Radius", ["radius"]) == ["radius"]


def test_transforms_compose_and_place_keeps_the_geometry_type():
    from rgm.compiler.check import check
    from rgm.compiler.parser import parse

    assert T.binary("*", T.TRANSFORM, T.TRANSFORM) is T.TRANSFORM
    assert T.binary("*", T.TRANSFORM, T.CURVE3) is None and T.binary("+", T.TRANSFORM, T.TRANSFORM) is None
    program, _ = parse("t := rotation(vec(0, 0, 1), 90deg) * inverse(frame(pt(0, 0, 0), vec(0, 0, 1), vec(1, 0, 0)));\n"
                       "c := place(circle(pt(1, 0, 0), 1), t);\n"
                       "f := place(trim(plane(pt(0, 0, 0), vec(0, 0, 1)), loop(uvline(uv(0, 0), uv(1, 0)))), t);\n"
                       "export c, f;\n", "t.rgm")
    result = check(program)
    assert result.ok and (result.types["t"], result.types["c"], result.types["f"]) == (T.TRANSFORM, T.CURVE3, T.FACE)


def test_swapped_arguments_are_one_diagnostic_for_builtins_and_fns():
    from rgm.compiler.check import check
    from rgm.compiler.parser import parse

    program, _ = parse("fn ring(at: point3, r: length) := circle(at, r);\n"
                       "a := ring(5mm, pt(0, 0, 0));\nb := circle(5mm, pt(0, 0, 0));\n"
                       "c := place(translation(vec(1, 0, 0)), a);\nd := place(5, translation(vec(1, 0, 0)));\n"
                       "export a, b, c, d;\n", "s.rgm")
    errors = [d for d in check(program).diagnostics if d.is_error]
    assert [(d.code, d.span.line, d.span.col) for d in errors] == [
        ("E0312", 2, 11), ("E0312", 3, 13), ("E0312", 4, 12), ("E0301", 5, 12)]   # no cascade into `export`
    assert errors[0].hint == "swap them: `ring(pt(0, 0, 0), 5mm)`"
    assert errors[2].hint == "swap them: `place(a, translation(vec(1, 0, 0)))`"
