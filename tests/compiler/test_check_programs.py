"""Whole programs through the checker: generated well-typed programs check clean (no error, no warning)
with a dependency-respecting order and the types they were built with; mutated programs (bytes, tokens,
lines) give diagnostics, never an exception from the checker, and every diagnostic points inside the
file. (The CLI's last-resort catch-all is tested in tests/test_cli_frontend.py.)"""
import random
import re
from pathlib import Path

from hypothesis import HealthCheck, assume, given, settings, strategies as st

from rgm.compiler import ast as A
from rgm.compiler import types as T
from rgm.compiler.check import check
from rgm.compiler.diagnostics import sort_and_dedupe
from rgm.compiler.parser import parse

from strategies import programs as shared_programs

GOLDEN = sorted((Path(__file__).parent / "golden").glob("*.rgm"))
EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "examples").glob("*.rgm"))

# ------------------------------------------------------------------------------------- generator
# Each builder draws the text of an expression of one type, using earlier bindings of that type.

num = st.integers(1, 50).map(str)
pos_len = st.sampled_from(["mm", "cm", "in", ""]).flatmap(lambda u: st.integers(1, 90).map(lambda v: f"{v}{u}"))


class Env:
    def __init__(self):
        self.by_type: dict[str, list[str]] = {}
        self.lines: list[str] = []
        self.types: dict[str, T.Type] = {}

    def names(self, t):
        return self.by_type.get(t, [])


@st.composite
def length(draw, env, depth=0):
    options = [pos_len.map(lambda s: s)]
    if env.names("length"):
        options.append(st.sampled_from(env.names("length")))
    if depth < 1:
        options.append(st.tuples(length(env, depth + 1), num).map(lambda t: f"{t[0]} * {t[1]}"))
        options.append(st.tuples(length(env, depth + 1), length(env, depth + 1)).map(lambda t: f"({t[0]} + {t[1]})"))
    return draw(st.one_of(options))


@st.composite
def point3(draw, env, depth=0):
    options = [st.tuples(length(env, depth + 1), length(env, depth + 1), length(env, depth + 1))
               .map(lambda t: f"pt({t[0]}, {t[1]}, {t[2]})")]
    if env.names("point3"):
        options.append(st.sampled_from(env.names("point3")))
    if depth < 1:
        options.append(st.tuples(point3(env, depth + 1), vec(env, depth + 1)).map(lambda t: f"{t[0]} + {t[1]}"))
    return draw(st.one_of(options))


@st.composite
def vec(draw, env, depth=0):
    # the x component is a positive literal so a folded vector is never zero
    options = [st.tuples(pos_len, length(env, depth + 1), length(env, depth + 1))
               .map(lambda t: f"vec({t[0]}, {t[1]}, {t[2]})")]
    if env.names("vec"):
        options.append(st.sampled_from(env.names("vec")))
    return draw(st.one_of(options))


@st.composite
def curve3(draw, env):
    p = draw(point3(env))
    options = [
        st.just(f"line({p}, {p} + {draw(vec(env))})"),
        st.just(f"circle({p}, {draw(pos_len)}, normal: {draw(vec(env))})"),
        st.lists(point3(env), min_size=2, max_size=5).map(lambda ps: f"polyline([{', '.join(ps)}])"),
        st.integers(1, 3).flatmap(lambda d: st.lists(point3(env), min_size=d + 1, max_size=d + 4).map(
            lambda ps: f"bspline({d}, uniform({d}, {len(ps)}), [{', '.join(ps)}])")),
    ]
    if env.names("curve3"):
        c = draw(st.sampled_from(env.names("curve3")))
        options.append(st.just(f"translate({c}, {draw(vec(env))})"))
        options.append(st.integers(1, 359).map(lambda a: f"rotate({c}, {draw(vec(env))}, {a}deg)"))
    return draw(st.one_of(options))


@st.composite
def surface(draw, env):
    curves = env.names("curve3")
    options = [st.tuples(point3(env), vec(env)).map(lambda t: f"plane({t[0]}, {t[1]})"),
               st.integers(2, 4).flatmap(lambda n: st.just(
                   f"bsurface(1, 1, uniform(1, {n}), uniform(1, 2), net {n} x 2 ["
                   + ", ".join(f"{i} {j} {i * j}" for i in range(n) for j in range(2)) + "])"))]
    if curves:
        c = st.sampled_from(curves)
        options += [
            st.tuples(c, c, st.integers(0, 180), st.integers(1, 180)).map(
                lambda t: f"revolve({t[0]}, {t[1]}, from: {t[2]}deg, to: {t[2] + t[3]}deg)"),
            st.tuples(c, vec(env)).map(lambda t: f"extrude({t[0]}, {t[1]})"),
            st.tuples(c, c).map(lambda t: f"ruled({t[0]}, {t[1]})"),
        ]
    return draw(st.one_of(options))


@st.composite
def face(draw, env):
    s = draw(st.sampled_from(env.names("surface")))
    corners = ["uv(0, 0)", "uv(1, 0)", "uv(1, 1)", "uv(0, 1)", "uv(0, 0)"]
    pieces = ", ".join(f"uvline({a}, {b})" for a, b in zip(corners, corners[1:]))
    return f"trim({s}, outer: loop({pieces}), holes: [])"


BUILDERS = {"length": (length, T.LENGTH), "point3": (point3, T.POINT3), "vec": (vec, T.VEC),
            "curve3": (curve3, T.CURVE3), "surface": (surface, T.SURFACE), "face": (face, T.FACE)}


@st.composite
def programs(draw):
    """(text, expected types of the bindings). Bindings are written in a shuffled order (order is free);
    every geometric binding is exported and every number is used, so a clean check has no warnings."""
    env = Env()
    n = draw(st.integers(2, 9))
    for i in range(n):
        kinds = [k for k in BUILDERS if k != "face" or env.names("surface")]
        kind = draw(st.sampled_from(kinds))
        builder, t = BUILDERS[kind]
        expr = draw(builder(env))
        name = f"b{i}"
        prefix = "param " if kind == "length" and draw(st.booleans()) else ""
        env.lines.append(f"{prefix}{name} := {expr};")
        env.by_type.setdefault(kind, []).append(name)
        env.types[name] = T.PLANE if expr.startswith("plane(") else t
    order = draw(st.permutations(env.lines))
    geometric = [nm for nm, t in env.types.items() if t not in (T.LENGTH, T.VEC)]
    scalars = [nm for nm, t in env.types.items() if t in (T.LENGTH, T.VEC)]
    lines = ["units mm;", "tolerance 0.01;", *order]
    if scalars:   # use every number and vector once more so none is reported unused
        args = ", ".join(f"pt({s}, 0, 0)" if env.types[s] == T.LENGTH else f"pt(0, 0, 0) + {s}" for s in scalars)
        lines.append(f"uses := polyline([pt(0, 0, 0), {args}]);")
        geometric.append("uses")
        env.types["uses"] = T.CURVE3
    lines.append(f"export {', '.join(geometric)};")
    return "\n".join(lines) + "\n", env.types


@given(programs())
@settings(max_examples=30, deadline=None)
def test_generated_programs_check_clean(case):
    text, expected = case
    program, diags = parse(text, "gen.rgm")
    assert not diags, [d.message for d in diags]
    result = check(program)
    assert result.diagnostics == [], "\n".join(f"{d.code} {d.span}: {d.message}" for d in result.diagnostics) + "\n" + text
    for name, t in expected.items():   # a bare number may stand for a length
        got = result.types[name]
        assert got != T.ANY and T.accepts(t, got) and (got == t or t == T.LENGTH), (name, got, t)
    position = {name: i for i, name in enumerate(result.order)}
    assert set(position) == set(result.bindings)
    for name, binding in result.bindings.items():   # every dependency is evaluated first
        for node in A.walk(binding.expr):
            if isinstance(node, A.Name) and node.id in result.bindings:
                assert position[node.id] < position[name]


# ------------------------------------------------------------------------------------- mutations

TOKEN = re.compile(r"[A-Za-z_]\w*|\d+(?:\.\d+)?(?:mm|cm|in|deg|rad|m)?|:=|\S")
JUNK = ["(", ")", "[", "]", ",", ";", ":=", "-", "*", "/", "pt", "revolve", "net 2 x 2 [", '"', "@fit(", "fn",
        "param", "export", "units", "0", "1e400", "360deg", "uv(0, 0)", "knots([1, 0])", ".", "x", "#"]


def _mutate(text: str, rnd: random.Random, kind: str) -> str:
    if kind == "bytes":
        data = bytearray(text.encode())
        for _ in range(rnd.randint(1, 4)):
            i = rnd.randrange(len(data) + 1)
            op = rnd.choice("idr")
            if op == "i":
                data[i:i] = bytes([rnd.randrange(256)])
            elif op == "d":
                del data[i:i + 1]
            elif i < len(data):
                data[i] = rnd.randrange(256)
        return data.decode("utf-8", errors="replace")
    if kind == "tokens":
        toks = [(m.start(), m.end()) for m in TOKEN.finditer(text)]
        for _ in range(rnd.randint(1, 3)):
            a, b = rnd.choice(toks)
            repl = rnd.choice(["", rnd.choice(JUNK), text[slice(*rnd.choice(toks))]])
            text = text[:a] + repl + text[b:]
            toks = [(m.start(), m.end()) for m in TOKEN.finditer(text)] or [(0, 0)]
        return text
    lines = text.splitlines(keepends=True)
    i, j = rnd.randrange(len(lines)), rnd.randrange(len(lines))
    op = rnd.choice(["drop", "dup", "swap"])
    if op == "drop":
        del lines[i]
    elif op == "dup":
        lines.insert(j, lines[i])
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return "".join(lines)


SEEDS = [p.read_text() for p in EXAMPLES + GOLDEN]


@given(st.data(), st.sampled_from(["bytes", "tokens", "lines"]), st.integers(0, 2**32 - 1))
@settings(max_examples=60, deadline=None)
def test_mutations_give_diagnostics_never_an_exception(data, kind, seed):
    text = data.draw(st.sampled_from(SEEDS))
    mutated = _mutate(text, random.Random(seed), kind)
    try:
        program, syntax = parse(mutated, "m.rgm")
    except Exception:   # noqa: BLE001 - a parser crash is the parser's tests' business; this tests the checker
        assume(False)
    diags = sort_and_dedupe(list(syntax) + check(program, {"radius": "3mm"}).diagnostics)
    n_lines = mutated.count("\n") + 1
    for d in diags:
        if d.span is not None:
            assert 1 <= d.span.line <= n_lines and d.span.col >= 1, (d, mutated)
    keys = [(d.span.line, d.span.col) for d in diags if d.span]
    assert keys == sorted(keys)


@given(shared_programs())
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_parser_engineers_generated_programs_have_no_errors(program):
    """The AST generator shared with the parser's round-trip tests (tests/compiler/strategies.py) draws
    well-typed programs with valid knots, nets and weights; unused bindings there are warnings only."""
    errors = [d for d in check(program).diagnostics if d.is_error]
    assert errors == []


def test_a_long_sum_is_checked_not_a_recursion_error():
    text = "param w := " + " + ".join(["1mm"] * 5000) + ";\nx := pt(w, 0, 0);\nexport x;\n"
    program, syntax = parse(text, "long.rgm")
    result = check(program)
    assert syntax == [] and result.diagnostics == [] and result.types["w"] == T.LENGTH
