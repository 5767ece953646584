"""The typed signature table of every builtin function and annotation (docs/architecture.md, "Builtins").

A builtin has one or more overloads (`line` of two point3 is a curve3, of two point2 a curve2); the
overloads of one builtin share their parameter names and order, so arguments are bound to parameters
once and then each overload is tried in turn. Transforms applied to geometry are generic:
`translate(g: G, by: vec) -> G` and `place(g: G, t: transform) -> G` return the type of their first
argument. Transform values (`translation`, `rotation`, `scaling`, `mirroring`, `frame`, `inverse`) are
of type `transform` and compose with `*`. The table is also what a diagnostic's `= note:` line prints.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from .types import (ANGLE, CURVE2, CURVE3, FACE, GEOMETRY, HPOINT, INT, KNOTS, LENGTH, LOOP, NET, NUM,
                    PLANE, POINT2, POINT3, SHELL, STR, SURFACE, TRANSFORM, VEC, Type, list_of, union, var)


@dataclass(frozen=True)
class Param:
    """A parameter: `default` is the source text of its default value, None when it is required."""

    name: str
    type: Type
    default: str | None = None
    variadic: bool = False   # takes every remaining positional argument (`loop(pieces...)`)

    @property
    def required(self) -> bool:
        return self.default is None and not self.variadic

    def __str__(self) -> str:
        text = f"{self.name}: {self.type}" + (" ..." if self.variadic else "")
        return text if self.default is None else f"{text} = {self.default}"


@dataclass(frozen=True)
class Signature:
    """One overload. `extra` is the type of further named arguments an annotation allows (None: none)."""

    name: str
    params: tuple[Param, ...]
    result: Type
    extra: Type | None = None
    named_only: bool = False

    def param(self, name: str) -> Param | None:
        return self.by_name.get(name)

    @cached_property
    def by_name(self) -> dict[str, Param]:
        """Parameters by name (computed once: the checker asks for every named argument)."""
        return {p.name: p for p in self.params}

    def __str__(self) -> str:
        if self.named_only:   # an annotation: every field optional, no result
            inner = ", ".join(f"{p.name}: {p.type}" for p in self.params)
            return f"@{self.name}({inner}{', ...' if self.extra is not None else ''})"
        inner = ", ".join(str(p) for p in self.params)
        text = f"{self.name}({inner}) -> {self.result}"
        gen = next((p.type for p in self.params if p.type.kind == "var"), None)
        return text + (f"  ({gen.name}: any geometry)" if gen is not None else "")


@dataclass(frozen=True)
class Builtin:
    name: str
    overloads: tuple[Signature, ...]
    kind: str = "function"   # "function" | "annotation"

    @property
    def params(self) -> tuple[Param, ...]:
        return self.overloads[0].params

    @cached_property
    def notes(self) -> tuple[str, ...]:
        """The `= note:` lines: one per overload, or one merged line when there are more than two."""
        if len(self.overloads) <= 2:
            return tuple(str(s) for s in self.overloads)
        first = self.overloads[0]
        params = tuple(Param(p.name, union(*(s.params[i].type for s in self.overloads)), p.default, p.variadic)
                       for i, p in enumerate(first.params))
        merged = Signature(first.name, params, union(*(s.result for s in self.overloads)), first.extra)
        return (str(merged),)


def _p(name: str, type_: Type, default: str | None = None, variadic: bool = False) -> Param:
    return Param(name, type_, default, variadic)


def _f(name: str, *overloads: tuple[tuple[Param, ...], Type]) -> Builtin:
    return Builtin(name, tuple(Signature(name, params, result) for params, result in overloads))


def _same(params: tuple[Param, ...], by_type: dict[Type, Type], slot_types) -> tuple:
    """Overloads of `params` where every parameter named in `slot_types` takes one type of `by_type`."""
    out = []
    for arg, result in by_type.items():
        out.append((tuple(_p(p.name, arg if p.name in slot_types else p.type, p.default, p.variadic)
                          for p in params), result))
    return tuple(out)


G = var("G", GEOMETRY)
_ORIGIN = "pt(0, 0, 0)"
_PIECES = (_p("pieces", CURVE3, variadic=True),)
_DIMENSIONAL = {POINT3: CURVE3, POINT2: CURVE2}

FUNCTIONS: dict[str, Builtin] = {b.name: b for b in (
    # points and vectors
    _f("pt", ((_p("x", LENGTH), _p("y", LENGTH), _p("z", LENGTH)), POINT3)),
    _f("uv", ((_p("u", NUM), _p("v", NUM)), POINT2)),
    _f("vec", ((_p("x", LENGTH), _p("y", LENGTH), _p("z", LENGTH)), VEC)),
    _f("projPt", ((_p("x", LENGTH), _p("y", LENGTH), _p("z", LENGTH), _p("w", NUM)), HPOINT)),
    # knot vectors
    _f("clamped", ((_p("degree", INT), _p("interior", list_of(NUM), "[]")), KNOTS)),
    _f("uniform", ((_p("degree", INT), _p("count", INT)), KNOTS)),
    _f("knots", ((_p("values", list_of(NUM)),), KNOTS)),
    # curves
    _f("line", *_same((_p("a", POINT3), _p("b", POINT3)), _DIMENSIONAL, {"a", "b"})),
    _f("polyline", ((_p("points", list_of(POINT3)),), CURVE3), ((_p("points", list_of(POINT2)),), CURVE2)),
    _f("arc", *_same((_p("start", POINT3), _p("through", POINT3), _p("end", POINT3)), _DIMENSIONAL,
                     {"start", "through", "end"})),
    _f("circle", ((_p("center", POINT3), _p("radius", LENGTH), _p("normal", VEC, "vec(0, 0, 1)")), CURVE3)),
    _f("bspline", *(((_p("degree", INT), _p("knots", KNOTS), _p("points", pts),
                      _p("weights", list_of(NUM), "none")), result)
                    for pts, result in ((list_of(POINT3), CURVE3), (list_of(HPOINT), CURVE3),
                                        (list_of(POINT2), CURVE2), (NET, CURVE3)))),
    _f("profile", *_same(_PIECES, {CURVE3: CURVE3, CURVE2: CURVE2}, {"pieces"})),
    _f("uvline", ((_p("a", POINT2), _p("b", POINT2)), CURVE2)),
    _f("reverse", *_same((_p("curve", CURVE3),), {CURVE3: CURVE3, CURVE2: CURVE2}, {"curve"})),
    # surfaces
    _f("revolve", ((_p("profile", CURVE3), _p("axis", CURVE3), _p("from", ANGLE, "0deg"),
                    _p("to", ANGLE, "360deg")), SURFACE)),
    _f("bsurface", ((_p("degree_u", INT), _p("degree_v", INT), _p("knots_u", KNOTS), _p("knots_v", KNOTS),
                     _p("net", union(NET, list_of(list_of(POINT3)))),
                     _p("weights", union(NET, list_of(list_of(NUM))), "none")), SURFACE)),
    _f("plane", ((_p("origin", POINT3), _p("normal", VEC)), PLANE)),
    _f("extrude", ((_p("profile", CURVE3), _p("direction", VEC)), SURFACE)),
    _f("ruled", ((_p("a", CURVE3), _p("b", CURVE3)), SURFACE)),
    _f("intersect", ((_p("a", SURFACE), _p("b", SURFACE)), CURVE3)),
    # topology
    _f("loop", ((_p("pieces", union(CURVE2, CURVE3), variadic=True),), LOOP)),
    _f("trim", ((_p("surface", SURFACE), _p("outer", LOOP), _p("holes", list_of(LOOP), "[]")), FACE)),
    _f("shell", ((_p("faces", list_of(union(FACE, SURFACE))),), SHELL)),
    # transforms on any geometry G
    _f("translate", ((_p("g", G), _p("by", VEC)), G)),
    _f("rotate", ((_p("g", G), _p("axis", VEC), _p("angle", ANGLE), _p("about", POINT3, _ORIGIN)), G)),
    _f("scale", ((_p("g", G), _p("factor", NUM), _p("about", POINT3, _ORIGIN)), G)),
    _f("mirror", ((_p("g", G), _p("plane", PLANE)), G)),
    # transform values: `t2 * t1` applies t1 first; `place` applies one to any geometry G
    _f("translation", ((_p("by", VEC),), TRANSFORM)),
    _f("rotation", ((_p("axis", VEC), _p("angle", ANGLE), _p("about", POINT3, _ORIGIN)), TRANSFORM)),
    _f("scaling", ((_p("factor", NUM), _p("about", POINT3, _ORIGIN)), TRANSFORM)),
    _f("mirroring", ((_p("plane", PLANE),), TRANSFORM)),
    _f("frame", ((_p("origin", POINT3), _p("z", VEC), _p("x", VEC)), TRANSFORM)),
    _f("inverse", ((_p("t", TRANSFORM),), TRANSFORM)),
    _f("place", ((_p("g", G), _p("t", TRANSFORM)), G)),
)}


def _annotation(name: str, params: tuple[Param, ...], extra: Type | None) -> Builtin:
    return Builtin(name, (Signature(name, params, Type("annotation"), extra, named_only=True),), "annotation")


_OPT = "none"
#: annotations attached to a binding: what the fitters know about it (all fields optional, named)
ANNOTATIONS: dict[str, Builtin] = {b.name: b for b in (
    _annotation("fit", (_p("points", INT, _OPT), _p("max", LENGTH, _OPT), _p("rms", LENGTH, _OPT),
                        _p("p95", LENGTH, _OPT), _p("tol", LENGTH, _OPT), _p("coverage", NUM, _OPT),
                        _p("statistic", STR, _OPT), _p("g0", LENGTH, _OPT)), None),
    _annotation("classified", (_p("as", STR, _OPT), _p("confidence", NUM, _OPT), _p("runner_up", STR, _OPT)),
                NUM),
    _annotation("source", (_p("scans", list_of(STR), _OPT), _p("sha256", list_of(STR), _OPT)),
                union(STR, NUM, list_of(STR), list_of(NUM))),
)}

#: parameters whose constant value must lie in [0, 1]: (annotation, field)
FRACTIONS = {("fit", "coverage"), ("classified", "confidence")}


def lookup(name: str) -> Builtin | None:
    return FUNCTIONS.get(name)
