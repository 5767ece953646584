"""Hypothesis strategies drawing well-typed `.rgm` programs as ASTs (rgm.compiler.ast).

`programs()` draws a Program in canonical statement order (headers first) whose bindings use only
earlier bindings, builtins with the signatures of docs/architecture.md, valid knot vectors (uniform
with the matching count of control points), rectangular nets with positive weights, and comments
(leading and trailing). Spans are None: the nodes compare equal to parsed ones regardless.

Numbers cover what the formatter must write back exactly: integers up to 1e20 (in @fit), floats of
any finite magnitude (subnormals, 1e308) in nets, and ordinary decimals in expressions. Curves are
built non-degenerate (distinct points, non-zero vectors, sweeps within a turn) so the checker's value
checks pass too.
"""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from rgm.compiler import ast as A

KEYWORDS = {"units", "tolerance", "param", "fn", "export", "net"}
NAME_PREFIXES = ("body", "rim", "edge", "p", "q", "hole", "cut", "wall", "s")
LENGTH_UNITS = (None, "mm", "cm", "m", "in")

comment_text = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF, exclude_characters="\x7f"),
                       max_size=30).map(lambda s: ("# " + s).rstrip())
string_value = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF) | st.sampled_from('\n\t"\\'),
                       max_size=12)
finite = st.floats(allow_nan=False, allow_infinity=False)


def N(value, unit=None, is_int=None):
    """A Number node (is_int defaults to 'written without a point')."""
    return A.Number(float(value), unit, isinstance(value, int) if is_int is None else is_int)


def call(func, *args, **kwargs):
    return A.Call(A.Name(func), tuple(args), tuple(kwargs.items()))


def neg_safe(value):
    """A literal for a possibly negative number: -x is Neg(Number(x)), as the parser reads it."""
    return A.Neg(N(-value)) if value < 0 else N(value)


plain_number = st.one_of(st.integers(0, 10**6).map(N),
                         st.floats(0, 1e4, allow_nan=False).map(lambda v: N(v, is_int=False)))
int_literal = st.integers(0, 1000).map(N)


@st.composite
def length(draw, env, depth=2):
    """An expression of type length (a bare number counts as one)."""
    options = ["lit", "lit", "lit"]
    if env.get("length"):
        options.append("name")
    if env.get("point3"):
        options.append("member")
    if depth > 0:
        options += ["add", "mul", "div", "neg"]
    kind = draw(st.sampled_from(options))
    if kind == "lit":
        n = draw(plain_number)
        return A.Number(n.value, draw(st.sampled_from(LENGTH_UNITS)), n.is_int)
    if kind == "name":
        return A.Name(draw(st.sampled_from(env["length"])))
    if kind == "member":
        return A.Member(A.Name(draw(st.sampled_from(env["point3"]))), draw(st.sampled_from("xyz")))
    if kind == "add":
        return A.BinOp(draw(st.sampled_from("+-")), draw(length(env, depth - 1)), draw(length(env, depth - 1)))
    if kind == "mul":
        a, b = draw(length(env, depth - 1)), draw(plain_number)
        return A.BinOp("*", *(draw(st.permutations([a, b]))))
    if kind == "div":
        return A.BinOp("/", draw(length(env, depth - 1)), N(draw(st.integers(1, 100))))
    return A.Neg(draw(length(env, depth - 1)))


@st.composite
def sweep(draw):
    """(from, to) angles of a revolution sweeping more than nothing and at most a full turn."""
    start = A.Number(float(draw(st.integers(0, 90))), "deg", True)
    if draw(st.booleans()):
        return start, A.Number(float(draw(st.integers(2, 3))), "rad", True)
    end = A.Number(float(draw(st.integers(120, 200))), "deg", True)
    if draw(st.booleans()):
        end = A.BinOp("+", end, A.Number(draw(st.floats(0, 150, allow_nan=False)), "deg", False))
    return start, end


@st.composite
def point3(draw, env):
    if env.get("point3") and draw(st.booleans()):
        p = A.Name(draw(st.sampled_from(env["point3"])))
        if env.get("vec") and draw(st.booleans()):
            return A.BinOp(draw(st.sampled_from("+-")), p, A.Name(draw(st.sampled_from(env["vec"]))))
        return p
    return call("pt", *(draw(length(env, 1)) for _ in range(3)))


@st.composite
def vector(draw, env):
    kind = draw(st.sampled_from(["lit", "diff", "scaled"] + (["name"] if env.get("vec") else [])))
    if kind == "lit":   # the last component is positive: never the zero vector
        return call("vec", draw(length(env, 1)), draw(length(env, 1)), N(draw(st.integers(1, 100))))
    if kind == "diff":
        p = draw(point3(env))
        return A.BinOp("-", A.BinOp("+", p, call("vec", N(0), N(0), N(1))), p)
    if kind == "scaled":
        return A.BinOp("*", N(draw(st.integers(1, 9))), call("vec", N(0), N(0), N(1)))
    return A.Name(draw(st.sampled_from(env["vec"])))


@st.composite
def net(draw, rows, cols, width=3, positive=False):
    """A Net node of shape (rows, cols) (cols None: 1-D) with any finite float64 values."""
    shape = (rows,) if cols is None else (rows, cols)
    count = int(np.prod(shape)) * width
    values = st.floats(0.1, 10.0) if positive else finite
    data = np.array(draw(st.lists(values, min_size=count, max_size=count)), dtype=float).reshape(shape + (width,))
    data.flags.writeable = False
    return A.Net(shape, width, data)


@st.composite
def curve3(draw, env):
    kind = draw(st.sampled_from(["line", "polyline", "circle", "arc", "bspline", "bspline_net", "moved"]
                                + (["name"] if env.get("curve3") else [])))
    p = draw(point3(env))
    step = [call("vec", N(a), N(b), N(0)) for a, b in ((1, 0), (1, 1), (2, 0), (0, 1))]
    if kind == "line":
        return call("line", p, A.BinOp("+", p, step[draw(st.integers(0, 3))]))
    if kind == "polyline":
        k = draw(st.integers(1, 3))
        return call("polyline", A.ListExpr((p,) + tuple(A.BinOp("+", p, step[i]) for i in range(k))))
    if kind == "circle":
        radius = A.Number(float(draw(st.integers(1, 500))), draw(st.sampled_from(LENGTH_UNITS)), True)
        return A.Call(A.Name("circle"), (p, radius), (("normal", draw(vector(env))),))
    if kind == "arc":
        return call("arc", p, A.BinOp("+", p, step[1]), A.BinOp("+", p, step[2]))
    if kind in ("bspline", "bspline_net"):
        degree = draw(st.integers(1, 3))
        count = draw(st.integers(degree + 1, degree + 3))
        knots = call("uniform", N(degree), N(count))
        if kind == "bspline":
            pts = A.ListExpr(tuple(call("pt", N(i), draw(length(env, 1)), N(0)) for i in range(count)))
        else:
            pts = draw(net(count, None))
        return call("bspline", degree=N(degree), knots=knots, points=pts)
    if kind == "moved":
        return call("translate", draw(curve3({})), by=draw(vector(env)))
    return A.Name(draw(st.sampled_from(env["curve3"])))


@st.composite
def surface(draw, env):
    kind = draw(st.sampled_from(["revolve", "bsurface", "plane", "extrude", "ruled", "rotated"]))
    if kind == "revolve":
        start, end = draw(sweep())
        return A.Call(A.Name("revolve"), (draw(curve3(env)), call("line", call("pt", N(0), N(0), N(0)),
                                                                   call("pt", N(0), N(1), N(0)))),
                      (("from", start), ("to", end)))
    if kind == "bsurface":
        du, dv = draw(st.integers(1, 3)), draw(st.integers(1, 3))
        nu, nv = draw(st.integers(du + 1, du + 2)), draw(st.integers(dv + 1, dv + 2))
        kwargs = [("degree_u", N(du)), ("degree_v", N(dv)), ("knots_u", call("uniform", N(du), N(nu))),
                  ("knots_v", call("uniform", N(dv), N(nv))), ("net", draw(net(nu, nv)))]
        if draw(st.booleans()):
            kwargs.append(("weights", draw(net(nu, nv, 1, positive=True))))
        return A.Call(A.Name("bsurface"), (), tuple(kwargs))
    if kind == "plane":
        return call("plane", draw(point3(env)), draw(vector(env)))
    if kind == "extrude":
        return call("extrude", draw(curve3(env)), draw(vector(env)))
    if kind == "ruled":
        return call("ruled", draw(curve3(env)), draw(curve3(env)))
    return A.Call(A.Name("rotate"), (draw(surface({})),),
                  (("axis", call("vec", N(0), N(0), N(1))), ("angle", draw(sweep())[1])))


@st.composite
def face(draw, env):
    """A trimmed surface whose outer loop is a uv rectangle (closed by construction)."""
    u0, u1 = 0.1, 0.9
    corners = [(u0, u0), (u1, u0), (u1, u1), (u0, u1)]
    uv = [call("uv", N(a, is_int=False), N(b, is_int=False)) for a, b in corners]
    pieces = tuple(call("uvline", uv[i], uv[(i + 1) % 4]) for i in range(4))
    holes = A.ListExpr(())
    return A.Call(A.Name("trim"), (draw(surface(env)),), (("outer", call("loop", *pieces)), ("holes", holes)))


@st.composite
def annotations(draw):
    out = []
    if draw(st.booleans()):
        out.append(A.Annotation("fit", (("points", N(draw(st.integers(0, 10**20)))),
                                         ("max", A.Number(draw(st.floats(0, 1)), "mm", False)),
                                         ("statistic", A.String(draw(string_value))))))
    if draw(st.booleans()):
        out.append(A.Annotation("classified", (("as", A.String("cylinder")),
                                                ("confidence", N(draw(st.floats(0, 1)), is_int=False)))))
    if draw(st.booleans()):
        out.append(A.Annotation("source", (("scans", A.ListExpr((A.String("scans/a.ply"),))),)))
    return tuple(out)


_KINDS = {"length": length, "point3": point3, "vec": vector, "curve3": curve3, "surface": surface,
          "face": face}


@st.composite
def programs(draw, max_bindings=6):
    """A well-typed Program: headers, params, bindings (each using earlier ones), a fn, an export of
    geometry bindings. It checks without errors (unused lengths or vectors may draw warnings)."""
    env: dict[str, list[str]] = {}
    stmts = []
    comments = st.lists(comment_text, max_size=2).map(tuple)
    trailing = st.none() | comment_text
    if draw(st.booleans()):
        stmts.append(A.Units(draw(st.sampled_from(["mm", "cm", "m", "in"])), draw(comments), draw(trailing)))
    if draw(st.booleans()):
        stmts.append(A.Tolerance(A.Number(draw(st.floats(1e-6, 1.0)), None, False), draw(comments)))
    n = draw(st.integers(1, max_bindings))
    for i in range(n):
        kind = draw(st.sampled_from(list(_KINDS)))
        expr = draw(_KINDS[kind](env) if kind != "length" else length(env, 2))
        name = f"{draw(st.sampled_from(NAME_PREFIXES))}{i}"
        is_param = kind == "length" and draw(st.booleans())
        if is_param:
            expr = A.Number(draw(st.floats(0.5, 500)), "mm", False)
        stmts.append(A.Binding(name, expr, is_param, draw(annotations()), draw(comments), draw(trailing)))
        env.setdefault(kind, []).append(name)
    if draw(st.booleans()):
        body = call("translate", call("pt", A.Name("r"), N(0), N(0)), by=A.Name("d"))
        stmts.append(A.FnDef("place", (A.Param("r", A.TypeRef("length")), A.Param("d", A.TypeRef("vec"))), body,
                             (), draw(comments)))
        stmts.append(A.Binding(f"placed{n}", call("place", N(3, "mm"), call("vec", N(0), N(1), N(0)))))
        env.setdefault("point3", []).append(f"placed{n}")
    geometry = [x for k in ("point3", "curve3", "surface", "face") for x in env.get(k, [])]
    if not geometry:
        stmts.append(A.Binding("origin", call("pt", N(0), N(0), N(0))))
        geometry = ["origin"]
    exported = draw(st.lists(st.sampled_from(geometry), min_size=1, unique=True))
    stmts.append(A.Export(tuple(A.Name(x) for x in exported), draw(comments), draw(trailing)))
    return A.Program(tuple(stmts), draw(st.lists(comment_text, max_size=2).map(tuple)))
