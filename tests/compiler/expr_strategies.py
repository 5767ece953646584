"""Hypothesis strategies drawing well-typed `.rgm` expressions of one kind each, as ASTs.

`KINDS` maps a kind (`length`, `point3`, `curve3`, `transform`, ...: the language's types, plus
`intersection` for `intersect(...)` curves, which nothing else consumes so that no check marches
one) to a generator `gen(draw, env, depth=..., force=None)`: plain functions of a composite
strategy's `draw` (a strategy object per node made generation several times slower, and one
`st.integers` per choice shrinks well). `env` maps kinds to the names bound to values
of that kind (earlier bindings, or a fn's parameters inside its body), `depth` is the nesting budget,
and `force` names the builtin the expression must be a call of (the labels of each generator's
options are the builtins they call), so that `strategies.programs` can hold the generator to the
builtin table.

Values are built to pass the checker's value checks: distinct points, non-zero vectors, valid knot
vectors for their control points, positive weights and scaling factors, frame axes across each other,
sweeps within a turn, trimming loops closed in [0.1, 0.9]^2 (holes in [0.4, 0.6]^2). Numbers cover
what the formatter must write back exactly: floats of any finite magnitude (subnormals, 1e308) in
nets, ordinary decimals and integers up to 1e6 in expressions.
"""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from rgm.compiler import ast as A

LENGTH_UNITS = (None, "mm", "cm", "m", "in")
#: what translate/rotate/scale/mirror/place move (rgm.compiler.types.GEOMETRY), and those builtins
GEOMETRY = ("point3", "vec", "hpoint", "curve3", "surface", "plane", "face", "loop", "shell")
MOVES = ("translate", "rotate", "scale", "mirror", "place")
finite = st.floats(allow_nan=False, allow_infinity=False)
plain_number = st.one_of(st.integers(0, 10**6).map(lambda v: N(v)),
                         st.floats(0, 1e4, allow_nan=False).map(lambda v: N(v, is_int=False)))


def N(value, unit=None, is_int=None):
    """A Number node (is_int defaults to 'written without a point')."""
    return A.Number(float(value), unit, isinstance(value, int) if is_int is None else is_int)


def call(func, *args, **kwargs):
    return A.Call(A.Name(func), tuple(args), tuple(kwargs.items()))


def neg_safe(value):
    """A literal for a possibly negative number: -x is Neg(Number(x)), as the parser reads it."""
    return A.Neg(N(-value)) if value < 0 else N(value)


def add(a, b, op="+"):
    return A.BinOp(op, a, b)


def choice(draw, seq):
    """One item of the sequence `seq` (drawn as an index: cheap, and it shrinks to the first)."""
    return seq[draw(st.integers(0, len(seq) - 1))]


def either(draw, a, b):
    """(a, b) or (b, a)."""
    return (a, b) if draw(st.booleans()) else (b, a)


def _pick(draw, options: dict, force=None):
    """Build one of `options` (label -> thunk; None: unavailable here), the one labelled `force` if any."""
    if options.get(force) is not None:
        return options[force]()
    return options[choice(draw, sorted(k for k, v in options.items() if v is not None))]()


def _named(draw, env, kind):
    """A thunk drawing a name bound to `kind`, or None when there is none."""
    if not env.get(kind):
        return None
    return lambda: A.Name(choice(draw, env[kind]))


def _member(draw, env, kind, attrs):
    """A thunk drawing `name.attr` for a name of `kind`, or None."""
    if not env.get(kind):
        return None
    return lambda: A.Member(A.Name(choice(draw, env[kind])), choice(draw, attrs))


def _deeper(depth, thunk):
    return thunk if depth > 0 else None


def _with(draw, env, kind, depth, force, **options):
    """`options` plus a name of `kind` and, for geometry, a moved copy (with depth left, or forced)."""
    moving = kind in GEOMETRY and (depth > 0 or force in MOVES)
    return _pick(draw, {**options, "name": _named(draw, env, kind),
                        "moved": (lambda: moved(draw, kind, env, max(depth - 1, 0), force)) if moving else None},
                 "moved" if force in MOVES else force)


# ------------------------------------------------------------------------------------------- scalars

def length(draw, env, depth=2, force=None):
    """An expression of type length (a bare number counts as one)."""
    sub = lambda: length(draw, env, depth - 1)
    return _pick(draw, {
        "lit": lambda: (lambda n: A.Number(n.value, choice(draw, LENGTH_UNITS), n.is_int))(draw(plain_number)),
        "name": _named(draw, env, "length"), "coord": _member(draw, env, "point3", "xyz"),
        "hcoord": _member(draw, env, "hpoint", "xyz"), "norm": _member(draw, env, "vec", ["length"]),
        "add": _deeper(depth, lambda: add(sub(), sub(), choice(draw, "+-"))),
        "mul": _deeper(depth, lambda: A.BinOp("*", *either(draw, sub(), draw(plain_number)))),
        "div": _deeper(depth, lambda: A.BinOp("/", sub(), N(draw(st.integers(1, 100))))),
        "neg": _deeper(depth, lambda: A.Neg(sub())),
    })


def angle(draw, env, depth=1, force=None):
    sub = lambda: angle(draw, env, depth - 1)
    return _pick(draw, {
        "deg": lambda: N(draw(st.integers(0, 360)), "deg"),
        "rad": lambda: A.Number(draw(st.floats(0, 6.28)), "rad", False), "name": _named(draw, env, "angle"),
        "add": _deeper(depth, lambda: add(sub(), sub(), choice(draw, "+-"))),
        "times": _deeper(depth, lambda: A.BinOp("*", integer(draw, env), sub())),
        "div": _deeper(depth, lambda: A.BinOp("/", sub(), N(draw(st.integers(1, 4))))),
        "neg": _deeper(depth, lambda: A.Neg(sub())),
    })


def integer(draw, env, depth=0, force=None):
    name = _named(draw, env, "int")
    return _pick(draw, {"lit": lambda: N(draw(st.integers(0, 8))), "name": name,
                        "next": name and (lambda: add(name(), N(1)))})


def positive(draw, env, depth=0, force=None):
    """A plain number > 0: literals, fn parameters of kind num, weights `h.w`, coordinates `q.u`."""
    return _pick(draw, {"int": lambda: N(draw(st.integers(1, 9))),
                        "float": lambda: N(draw(st.floats(0.125, 4.0)), is_int=False),
                        "name": _named(draw, env, "num"), "weight": _member(draw, env, "hpoint", ["w"]),
                        "uv": _member(draw, env, "point2", ["u", "v", "x", "y"])})


# ------------------------------------------------------------------------------------ points, vectors

def step(i: int):
    """One of four small displacements in the x-y plane (no two of them cancel)."""
    x, y = ((1, 0), (1, 1), (2, 0), (0, 1))[i]
    return call("vec", N(x), N(y), N(0))


def point3(draw, env, depth=1, force=None):
    name = _named(draw, env, "point3")
    return _with(draw, env, "point3", depth, force, pt=lambda: call("pt", *(length(draw, env, 1) for _ in range(3))),
                 shifted=name and (lambda: add(name(), vector(draw, env, 0), choice(draw, "+-"))),
                 end=_member(draw, env, "curve3", ["start", "end"]), origin=_member(draw, env, "plane", ["origin"]))


def vector(draw, env, depth=1, force=None):
    """A non-zero vector."""
    z = call("vec", N(0), N(0), N(1))
    sub = lambda: vector(draw, env, depth - 1)
    return _with(draw, env, "vec", depth, force,
                 vec=lambda: call("vec", length(draw, env, 1), length(draw, env, 1), N(draw(st.integers(1, 100)))),
                 diff=lambda: (lambda p: add(add(p, z), p, "-"))(point3(draw, env, 0)),
                 scaled=lambda: A.BinOp("*", *either(draw, N(draw(st.integers(1, 9))), z)),
                 div=_deeper(depth, lambda: A.BinOp("/", sub(), N(draw(st.integers(1, 9))))),
                 neg=_deeper(depth, lambda: A.Neg(sub())), normal=_member(draw, env, "plane", ["normal"]))


def hpoint(draw, env, depth=1, force=None):
    return _with(draw, env, "hpoint", depth, force,
                 projPt=lambda: call("projPt", *(length(draw, env, 1) for _ in range(3)), positive(draw, env)))


def uv_point(u: float, v: float):
    return call("uv", N(u, is_int=False), N(v, is_int=False))


def point2(draw, env, depth=0, force=None):
    return _pick(draw, {"uv": lambda: uv_point(draw(st.floats(0.1, 0.9)), draw(st.floats(0.1, 0.9))),
                        "name": _named(draw, env, "point2")}, force)


def points(draw, env, depth=1, force=None):
    """A list[point3] of two to four distinct points."""
    def lit():
        p = point3(draw, env, 0)
        return A.ListExpr((p,) + tuple(add(p, step(i)) for i in range(draw(st.integers(1, 3)))))
    return _pick(draw, {"lit": lit, "name": _named(draw, env, "list[point3]")})


def net_node(draw, rows, cols, width=3, positive=False, weighted=False):
    """A Net node of shape (rows, cols) (cols None: 1-D) with any finite float64 values; `positive`:
    all in [0.1, 10]; `weighted`: the last column is a positive weight."""
    shape = (rows,) if cols is None else (rows, cols)
    count = int(np.prod(shape)) * width
    values = st.floats(0.1, 10.0) if positive else finite
    data = np.array(draw(st.lists(values, min_size=count, max_size=count)), dtype=float).reshape(shape + (width,))
    if weighted:
        data[..., -1] = np.abs(data[..., -1]) % 9 + 0.5
    data.flags.writeable = False
    return A.Net(shape, width, data)


def knot_vector(draw, degree: int, count: int, force=None):
    """Knots for `count` control points of `degree`: by `uniform`, `clamped` or written out."""
    inner = [N((i + 1) / (count - degree), is_int=False) for i in range(count - degree - 1)]
    ends = lambda v: [N(v)] * (degree + 1)
    return _pick(draw, {
        "uniform": lambda: call("uniform", N(degree), N(count)),
        "clamped": lambda: call("clamped", N(degree), A.ListExpr(tuple(inner))) if inner else call("clamped", N(degree)),
        "knots": lambda: call("knots", A.ListExpr(tuple(ends(0) + inner + ends(1))))}, force)


def knots(draw, env, depth=0, force=None):
    return knot_vector(draw, draw(st.integers(1, 3)), draw(st.integers(4, 6)), force)


# -------------------------------------------------------------------------------------------- curves

def bspline(draw, env, dim: int):
    degree = draw(st.integers(1, 3))
    count = draw(st.integers(degree + 1, degree + 3))
    kwargs = {"degree": N(degree), "knots": knot_vector(draw, degree, count)}
    form = choice(draw, ["list", "net", "hpoints", "weighted_net"] if dim == 3 else ["list", "net"])
    if form == "list":
        make = (lambda i: call("pt", N(i), length(draw, env, 1), N(0))) if dim == 3 else \
            (lambda i: uv_point(0.1 + 0.8 * i / count, draw(st.floats(0.1, 0.9))))
        kwargs["points"] = A.ListExpr(tuple(make(i) for i in range(count)))
        if draw(st.booleans()):
            kwargs["weights"] = A.ListExpr(tuple(N(draw(st.integers(1, 3))) for _ in range(count)))
    elif form == "hpoints":
        kwargs["points"] = A.ListExpr(tuple(call("projPt", N(i), N(i % 2), N(0), positive(draw, env))
                                            for i in range(count)))
    else:
        kwargs["points"] = net_node(draw, count, None, dim + (form == "weighted_net"), weighted=form == "weighted_net")
    return call("bspline", **kwargs)


def curve3(draw, env, depth=1, force=None):
    p = lambda: point3(draw, env, 0)
    s = lambda: step(draw(st.integers(0, 3)))

    def circle():
        radius = N(draw(st.integers(1, 500)), choice(draw, LENGTH_UNITS))
        return A.Call(A.Name("circle"), (p(), radius), (("normal", vector(draw, env, 0)),) * draw(st.booleans()))

    def joined():
        a = p()
        b = add(a, s())
        return call("profile", call("line", a, b), call("line", b, add(b, step(3))))
    return _with(draw, env, "curve3", depth, force, line=lambda: (lambda a: call("line", a, add(a, s())))(p()),
                 polyline=lambda: call("polyline", points(draw, env)), circle=circle,
                 arc=lambda: (lambda a: call("arc", a, add(a, step(1)), add(a, step(2))))(p()),
                 bspline=lambda: bspline(draw, env, 3), profile=joined,
                 reverse=lambda: call("reverse", bspline(draw, env, 3)))


def _box(u0, v0, u1, v1):
    return [uv_point(u0, v0), uv_point(u1, v0), uv_point(u1, v1), uv_point(u0, v1)]


def curve2(draw, env, depth=0, force=None):
    c = _box(0.1, 0.2, 0.8, 0.9)
    return _pick(draw, {
        "uvline": lambda: call("uvline", c[0], c[draw(st.integers(1, 3))]),
        "line": lambda: call("line", c[1], c[choice(draw, [0, 2, 3])]),
        "polyline": lambda: call("polyline", A.ListExpr(tuple(c[:draw(st.integers(2, 4))]))),
        "arc": lambda: call("arc", c[0], c[1], c[2]), "bspline": lambda: bspline(draw, env, 2),
        "profile": lambda: call("profile", call("uvline", c[0], c[1]), call("uvline", c[1], c[2])),
        "reverse": lambda: call("reverse", call("uvline", c[draw(st.integers(1, 3))], c[0])),
        "name": _named(draw, env, "curve2")}, force)


def loop(draw, env, depth=0, force=None, hole=False):
    """A loop closed by construction, of uv lines, a closed polyline, a 2-D bspline, a profile or an
    arc; or (outer loops only) an intersection closed by a uv line, which only its evaluation for a
    back end can check."""
    c = _box(0.4, 0.4, 0.6, 0.6) if hole else _box(0.1, 0.1, 0.9, 0.9)
    line = lambda i, j: call("uvline", c[i], c[j])
    cut = _named(draw, {} if hole else env, "intersection")
    bulge = uv_point(0.5, 0.45 if hole else 0.2)
    return _with(draw, env, "loop", depth, force,
                 rect=lambda: call("loop", *(line(i, (i + 1) % 4) for i in range(4))),
                 reversed=lambda: call("loop", call("reverse", line(1, 0)), line(1, 2), line(2, 3), line(3, 0)),
                 polyline=lambda: call("loop", call("polyline", A.ListExpr(tuple(c) + (c[0],)))),
                 bspline=lambda: call("loop", call("bspline", degree=N(2), knots=call("uniform", N(2), N(3)),
                                                   points=A.ListExpr((c[0], c[1], c[2]))), line(2, 0)),
                 profile=lambda: call("loop", call("profile", line(0, 1), line(1, 2)), line(2, 0)),
                 arc=lambda: call("loop", call("arc", c[0], bulge, c[1]), call("line", c[1], c[0])),
                 cut=cut and (lambda: call("loop", cut(), line(0, 1))))


# ------------------------------------------------------------------------------------------ surfaces

def sweep(draw):
    """(from, to) angles of a revolution sweeping more than nothing and at most a full turn."""
    start = N(draw(st.integers(0, 90)), "deg")
    if draw(st.booleans()):
        return start, N(draw(st.integers(2, 3)), "rad")
    end = N(draw(st.integers(120, 200)), "deg")
    if draw(st.booleans()):
        end = add(end, A.Number(draw(st.floats(0, 150, allow_nan=False)), "deg", False))
    return start, end


def plane(draw, env, depth=1, force=None):
    return _with(draw, env, "plane", depth, force,
                 plane=lambda: call("plane", point3(draw, env, 0), vector(draw, env, 0)))


def bsurface(draw, env):
    du, dv = draw(st.integers(1, 3)), draw(st.integers(1, 3))
    nu, nv = draw(st.integers(du + 1, du + 2)), draw(st.integers(dv + 1, dv + 2))
    kw = {"degree_u": N(du), "degree_v": N(dv), "knots_u": knot_vector(draw, du, nu), "knots_v": knot_vector(draw, dv, nv)}
    form = choice(draw, ["net", "weighted_net", "rows"])
    if form == "rows":
        kw["net"] = A.ListExpr(tuple(A.ListExpr(tuple(call("pt", N(i), N(j), length(draw, env, 0)) for j in range(nv)))
                                     for i in range(nu)))
    else:
        kw["net"] = net_node(draw, nu, nv, 3 + (form == "weighted_net"), weighted=form == "weighted_net")
    weights = choice(draw, ["none", "net", "rows"] if form != "weighted_net" else ["none"])
    if weights == "net":
        kw["weights"] = net_node(draw, nu, nv, 1, positive=True)
    elif weights == "rows":
        kw["weights"] = A.ListExpr(tuple(A.ListExpr(tuple(N(1 + (i + j) % 2) for j in range(nv))) for i in range(nu)))
    return call("bsurface", **kw)


def surface(draw, env, depth=1, force=None):
    def revolve():
        axis = call("line", call("pt", N(0), N(0), N(0)), call("pt", N(0), N(1), N(0)))
        start, end = sweep(draw)
        kwargs = choice(draw, [(), (("to", end),), (("from", start), ("to", end))])
        return A.Call(A.Name("revolve"), (curve3(draw, env, 0), axis), kwargs)
    return _with(draw, env, "surface", depth, force, revolve=revolve, bsurface=lambda: bsurface(draw, env),
                 plane=lambda: plane(draw, env, depth),
                 extrude=lambda: call("extrude", curve3(draw, env, 0), vector(draw, env, 0)),
                 ruled=lambda: call("ruled", curve3(draw, env, 0), curve3(draw, env, 0)),
                 of_face=_member(draw, env, "face", ["surface"]))


def face(draw, env, depth=1, force=None):
    def trim():
        s, outer = surface(draw, env, 0), loop(draw, env, 0)
        holes = A.ListExpr((loop(draw, env, 0, hole=True),) * draw(st.booleans()))
        return choice(draw, [A.Call(A.Name("trim"), (s, outer), ()),
                                     A.Call(A.Name("trim"), (s,), (("outer", outer), ("holes", holes)))])
    return _with(draw, env, "face", depth, force, trim=trim)


def shell(draw, env, depth=1, force=None):
    faces = lambda: tuple(choice(draw, (face, surface))(draw, env, 0) for _ in range(draw(st.integers(1, 3))))
    return _with(draw, env, "shell", depth, force, shell=lambda: call("shell", A.ListExpr(faces())))


def intersection(draw, env, depth=0, force=None):
    return call("intersect", surface(draw, env, 0), choice(draw, (plane, surface))(draw, env, 0))


# ---------------------------------------------------------------------------------------- transforms

def transform(draw, env, depth=1, force=None):
    """A transform value: made by a constructor, composed (`t2 * t1`), inverted or named."""
    sub = lambda: transform(draw, env, depth - 1)
    about = lambda: (("about", point3(draw, env, 0)),) * draw(st.booleans())

    def frame():   # z has a positive last component and x none: never parallel, not even nearly
        z = call("vec", neg_safe(draw(st.integers(-9, 9))), neg_safe(draw(st.integers(-9, 9))), N(draw(st.integers(1, 9))))
        x = call("vec", N(1), neg_safe(draw(st.integers(-9, 9))), N(0))
        origin = point3(draw, env, 0)
        return choice(draw, [call("frame", origin, z, x), call("frame", origin=origin, z=z, x=x)])
    return _with(draw, env, "transform", depth, force, translation=lambda: call("translation", vector(draw, env, 0)),
                 rotation=lambda: A.Call(A.Name("rotation"), (vector(draw, env, 0), angle(draw, env)), about()),
                 scaling=lambda: A.Call(A.Name("scaling"), (positive(draw, env),), about()),
                 mirroring=lambda: call("mirroring", plane(draw, env, 0)), frame=frame,
                 compose=_deeper(depth, lambda: A.BinOp("*", sub(), sub())),
                 inverse=_deeper(depth or force == "inverse", lambda: call("inverse", transform(draw, env, max(depth - 1, 0)))))


def moved(draw, kind, env, depth=0, how=None):
    """A geometry expression of `kind` moved by `how` (one of MOVES; drawn when None)."""
    g = KINDS[kind](draw, env, depth)
    how = how if how in MOVES else choice(draw, MOVES)
    if how == "translate":
        by = vector(draw, env, 0)
        return choice(draw, [call("translate", g, by), call("translate", g, by=by)])
    if how == "rotate":
        about = (("about", point3(draw, env, 0)),) * draw(st.booleans())
        return A.Call(A.Name("rotate"), (g, vector(draw, env, 0)), (("angle", angle(draw, env)),) + about)
    if how == "scale":
        return call("scale", g, neg_safe(choice(draw, [-2, -1, 0.5, 1.5, 3])))
    if how == "mirror":
        return call("mirror", g, plane(draw, env, 0))
    return call("place", g, transform(draw, env, 1))


KINDS = {"length": length, "angle": angle, "int": integer, "num": positive, "point3": point3, "point2": point2,
         "vec": vector, "hpoint": hpoint, "list[point3]": points, "knots": knots, "curve3": curve3, "curve2": curve2,
         "plane": plane, "surface": surface, "face": face, "loop": loop, "shell": shell, "transform": transform,
         "intersection": intersection}
