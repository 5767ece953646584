"""Hypothesis strategies drawing well-typed `.rgm` programs as ASTs (rgm.compiler.ast).

`programs()` draws a Program in canonical statement order (headers first) whose bindings use only
earlier bindings. Each binding is headed by a builtin drawn from the signature table
(`rgm.compiler.builtins.FUNCTIONS`: the expression generators of `expr_strategies` build a call of
it, its arguments drawn by type), or is plain arithmetic, a list, a value only `_`-names hold
(strings, a domain, a net), or a `fn` definition whose typed parameters are bindings inside its body,
followed by calls of it. Annotations, `param`s, comments (leading, trailing, at the end) and an
`export` of geometry complete it. `programs(last=HEAD)` heads the last binding with HEAD (one of HEADS), using what came before;
`features(program)` names what a program uses, so tests can hold the generator to the table.

Spans are None: the nodes compare equal to parsed ones regardless. Integers up to 1e20 appear in
@fit, strings with quotes, escapes and non-ASCII text in annotations and outside them.
"""
from __future__ import annotations

from hypothesis import strategies as st

from rgm.compiler import ast as A
from rgm.compiler.builtins import FUNCTIONS
from rgm.compiler.types import MEMBERS

from expr_strategies import GEOMETRY, KINDS, N, call, choice, net_node

#: a dense net node as a strategy: `net(rows, cols, width=3, positive=False, weighted=False)`
net = st.composite(net_node)

NAME_PREFIXES = ("body", "rim", "edge", "p", "q", "hole", "cut", "wall", "s")
#: kinds an `export` may name (intersections are curve3 values kept apart: nothing else consumes them)
EXPORTABLE = ("point3", "hpoint", "curve2", "curve3", "surface", "plane", "face", "loop", "shell", "intersection")
#: fn parameter kinds and how their types may be spelled (aliases included); kinds a fn may return
FN_PARAMS = {"length": ("length",), "angle": ("angle",), "int": ("int",), "num": ("num", "number"),
             "point3": ("point3", "point"), "vec": ("vec",), "curve3": ("curve3", "curve"), "surface": ("surface",),
             "transform": ("transform",), "list[point3]": ("list[point3]",)}
FN_RESULTS = ("point3", "curve3", "surface", "face", "transform", "length")
#: what a binding is headed by: a builtin, arithmetic, a list, a fn (and its calls), another value
HEADS = tuple(sorted(FUNCTIONS)) + ("length", "angle", "list[point3]", "fn", "member", "other")

comment_text = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF, exclude_characters="\x7f"),
                       max_size=30).map(lambda s: ("# " + s).rstrip())
string_value = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF) | st.sampled_from('\n\t"\\'),
                       max_size=12)


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


OTHER_VALUES = ("str", "strs", "net", "net1")


def other_value(draw, env, focus=None):
    """A value nothing else consumes (held by an `_`-name, exempt from the unused warning): a string
    outside annotations, a list of them, a 2-D or 1-D net (`focus`: one of OTHER_VALUES)."""
    kind = focus if focus in OTHER_VALUES else choice(draw, OTHER_VALUES)
    if kind.startswith("net"):
        return net_node(draw, 2, None if kind == "net1" else 2)
    strings = [A.String(draw(string_value)) for _ in range(2)]
    return strings[0] if kind == "str" else A.ListExpr(tuple(strings))


def member_value(draw, env, focus=None):
    """`name.attr` for an earlier binding: any member the checker's table (rgm.compiler.types.MEMBERS)
    gives its kind; `focus` ("kind.attr") picks one. None when no binding has members."""
    owner, attr = focus.split(".") if focus else (None, None)
    owners = sorted(k for k in MEMBERS if env.get(k))
    if not owners:
        return None
    if owner not in owners:   # no binding of the focused kind yet: any member of any kind there is
        owner, attr = choice(draw, owners), None
    return A.Member(A.Name(choice(draw, env[owner])), attr or choice(draw, sorted(MEMBERS[owner])))


def fn_def(draw, env, name, focus=None):
    """`fn name(params) := body;` whose body may use its parameters (up to three consecutive kinds of
    FN_PARAMS, from `focus` if given); returns (FnDef, parameter kinds, result kind)."""
    order = sorted(FN_PARAMS)
    start = order.index(focus) if focus else draw(st.integers(0, len(order) - 1))
    kinds = [order[(start + j) % len(order)] for j in range(draw(st.integers(1, 3)))]
    params, local = [], {k: list(v) for k, v in env.items()}
    for j, kind in enumerate(kinds):
        pname = f"{'abc'[j]}_{kind[:3]}"
        ref = A.TypeRef("list", (A.TypeRef("point3"),)) if kind.startswith("list") else \
            A.TypeRef(choice(draw, FN_PARAMS[kind]))
        params.append(A.Param(pname, ref))
        local.setdefault(kind, []).append(pname)
    result = choice(draw, FN_RESULTS)
    return A.FnDef(name, tuple(params), KINDS[result](draw, local, 1)), kinds, result


def _head_kind(draw, head: str) -> str:
    """The kind of value a binding headed by `head` holds (a builtin's by its result type)."""
    if head not in FUNCTIONS:
        return head
    result = FUNCTIONS[head].overloads[0].result
    if head == "intersect":
        return "intersection"
    return choice(draw, GEOMETRY) if result.kind == "var" else result.name


@st.composite
def programs(draw, max_bindings=6, last=None, focus=None):
    """A well-typed Program: headers, params, bindings (each using earlier ones), fns and their calls,
    an export of geometry bindings. It checks without errors (unused bindings may draw warnings).
    `last` heads the last binding (a builtin or another of HEADS); `focus` is the first parameter
    kind of a `last="fn"`, the "kind.attr" of a `last="member"` (a binding of that kind comes first)
    or one of OTHER_VALUES for `last="other"`."""
    env: dict[str, list[str]] = {}
    stmts = []
    comments = lambda: draw(st.lists(comment_text, max_size=2).map(tuple))
    trailing = lambda: draw(st.none() | comment_text)
    if draw(st.booleans()):
        stmts.append(A.Units(choice(draw, A.LENGTH_UNITS), comments(), trailing()))
    if draw(st.booleans()):
        unit = choice(draw, (None, "mm"))
        stmts.append(A.Tolerance(A.Number(draw(st.floats(1e-6, 0.05)), unit, False), comments()))
    for i in range(draw(st.integers(0, 2))):
        kind = choice(draw, ("length", "angle"))
        value = (A.Number(draw(st.floats(0.5, 500)), "mm", False) if kind == "length"
                 else N(draw(st.integers(1, 90)), "deg"))
        stmts.append(A.Binding(f"dim{i}", value, True, (), comments(), trailing()))
        env.setdefault(kind, []).append(f"dim{i}")
    heads = [choice(draw, HEADS) for _ in range(draw(st.integers(1, max_bindings)))]
    if last:
        heads[-1:] = ([focus.split(".")[0]] if last == "member" and focus else []) + [last]
    for i, head in enumerate(heads):
        name = f"{choice(draw, NAME_PREFIXES)}{i}"
        kind = _head_kind(draw, head)
        if kind in ("other", "member"):
            mine = focus if head == last else None    # the focus is the last binding's (a member's "kind.attr")
            value = member_value(draw, env, mine) if kind == "member" else None
            stmts.append(A.Binding("_" + name, value or other_value(draw, env, mine), False, (), comments()))
        elif kind == "fn":
            fn, kinds, result = fn_def(draw, env, f"make{i}", focus if head == last else None)
            stmts.append(A.FnDef(fn.name, fn.params, fn.body, (), comments(), trailing()))
            for j in range(draw(st.integers(1, 2))):
                args = [KINDS[k](draw, env, 0) for k in kinds]
                named = A.Call(A.Name(fn.name), tuple(args[:1]), tuple((p.name, a) for p, a in zip(fn.params[1:], args[1:])))
                stmts.append(A.Binding(f"{name}_{j}", choice(draw, (call(fn.name, *args), named))))
                env.setdefault(result, []).append(f"{name}_{j}")
        else:
            expr = KINDS[kind](draw, env, force=head)
            stmts.append(A.Binding(name, expr, False, draw(annotations()), comments(), trailing()))
            env.setdefault(kind, []).append(name)
    geometry = [x for k in EXPORTABLE for x in env.get(k, [])]
    if not geometry:
        stmts.append(A.Binding("origin", call("pt", N(0), N(0), N(0))))
        geometry = ["origin"]
    exported = draw(st.lists(st.sampled_from(geometry), min_size=1, unique=True))
    stmts.append(A.Export(tuple(A.Name(x) for x in exported), comments(), trailing()))
    return A.Program(tuple(stmts), draw(st.lists(comment_text, max_size=2).map(tuple)))


def features(program: A.Program) -> set[str]:
    """What `program` uses: `call:NAME` (builtins; `call:fn` for user fns), `@NAME` annotations,
    `node:CLASS` of every node, `op:+` ..., `unit:mm` ..., `member:ATTR`, `net:1d|2d`, `param`,
    `fn-param:TYPE`, `string` (outside annotations), `kwarg`, `comment:leading|trailing|end`."""
    fns = {s.name for s in program.statements if isinstance(s, A.FnDef)}
    out = {"comment:end"} if program.end_comments else set()
    in_annotations = {id(n) for s in program.statements for a in getattr(s, "annotations", ()) for n in A.walk(a)}
    for node in A.walk(program):
        out.add(f"node:{type(node).__name__}")
        if isinstance(node, A.Call):
            out |= {"call:fn" if node.func.id in fns else f"call:{node.func.id}"} | ({"kwarg"} if node.kwargs else set())
        elif isinstance(node, A.Annotation):
            out.add(f"@{node.name}")
        elif isinstance(node, A.BinOp):
            out.add(f"op:{node.op}")
        elif isinstance(node, A.Number) and node.unit:
            out.add(f"unit:{node.unit}")
        elif isinstance(node, A.Member):
            out.add(f"member:{node.attr}")
        elif isinstance(node, A.Net):
            out.add(f"net:{len(node.shape)}d")
        elif isinstance(node, A.String) and id(node) not in in_annotations:
            out.add("string")
        elif isinstance(node, A.Param):
            out.add(f"fn-param:{node.type}")
        elif isinstance(node, A.Binding) and node.is_param:
            out.add("param")
        out |= {"comment:leading"} if getattr(node, "leading", ()) else set()
        out |= {"comment:trailing"} if getattr(node, "trailing", None) else set()
    return out
