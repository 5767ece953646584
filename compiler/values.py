"""Constant values the checker can know before evaluation, and the rules they must obey.

The checker folds literal and constant expressions (numbers with units, lists, points, nets, the knot
helpers `clamped`/`uniform`/`knots`) into the small values below, then applies the validity rules of
a B-spline (Piegl & Tiller, *The NURBS Book*, 2nd ed., section 2.2 and 3.2): a knot vector is
non-decreasing, has n + p + 1 values for n control points of degree p, no interior knot repeats more
than p times, weights are positive and control nets are rectangular. Each rule returns a `Problem`
naming the offending piece so the caller can put the caret on the right argument.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from . import ast as A
from .types import ANY
from .units import to_model


@dataclass(frozen=True)
class Knots:
    """A folded knot vector. `degree` is the degree a helper built it for (`clamped(3)`), else None;
    `helper` is the helper's name ("clamped", "uniform", "knots")."""

    values: tuple[float, ...]
    degree: int | None = None
    helper: str = "knots"


@dataclass(frozen=True)
class Problem:
    """A violated rule: `code`, `message`, and `index` of the offending element (None: the whole value)."""

    code: str
    message: str
    index: int | None = None
    hint: str | None = None


def clamped_knots(degree: int, interior) -> Knots:
    """p+1 zeros, the interior values, p+1 ones: a clamped (open) knot vector on [0, 1]."""
    return Knots((0.0,) * (degree + 1) + tuple(float(t) for t in interior) + (1.0,) * (degree + 1), degree, "clamped")


def uniform_knots(degree: int, count: int) -> Knots:
    """The clamped knot vector on [0, 1] with uniformly spaced interior knots for `count` control points."""
    inner = count - degree - 1
    interior = tuple((i + 1) / (inner + 1) for i in range(max(inner, 0)))
    return Knots((0.0,) * (degree + 1) + interior + (1.0,) * (degree + 1), degree, "uniform")


def ordinal(i: int) -> str:
    """1 -> "1st", 2 -> "2nd", 11 -> "11th"."""
    suffix = "th" if 10 <= i % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(i % 10, "th")
    return f"{i}{suffix}"


def _fmt(x: float) -> str:
    return f"{x:g}"


def degree_problem(degree: int) -> Problem | None:
    if degree < 1:
        return Problem("E0401", f"degree must be at least 1, found {degree}")
    return None


def knot_order_problem(values) -> Problem | None:
    """The first place where the knot vector decreases (knot vectors are short: a plain scan)."""
    v = [float(x) for x in values]
    i = next((i for i in range(1, len(v)) if v[i] < v[i - 1]), None)
    if i is not None:
        return Problem("E0402", f"knot vector decreases at its {ordinal(i + 1)} value: "
                                f"{_fmt(v[i])} after {_fmt(v[i - 1])}", i,
                       "knots must be non-decreasing")
    return None


def multiplicity_problem(values, degree: int) -> Problem | None:
    """An interior knot repeated more than `degree` times (the curve would break apart there), or an
    end knot more than degree + 1 times."""
    v = [float(x) for x in values]
    if not v:
        return None
    counts: dict[float, list[int]] = {}   # value -> [first index, count]
    for i, x in enumerate(v):
        counts.setdefault(x, [i, 0])[1] += 1
    for value, (start, count) in sorted(counts.items()):
        end = value in (v[0], v[-1])
        limit = degree + 1 if end else degree
        if count > limit:
            where = "end" if end else "interior"
            return Problem("E0404", f"{where} knot {_fmt(value)} appears {count} times; "
                                    f"a degree-{degree} spline allows at most {limit}", start)
    return None


def count_problem(n_knots: int, degree: int, n_ctrl: int, what: str = "control points") -> Problem | None:
    """len(knots) must be n + degree + 1 (P&T eq. 2.4 / 3.1: m + 1 = n + p + 2 with n + 1 points)."""
    need = n_ctrl + degree + 1
    if n_knots != need:
        return Problem("E0403", f"knot vector has {n_knots} values but degree {degree} with {n_ctrl} {what} "
                                f"needs {need} (points + degree + 1)",
                       hint=f"with {n_knots} knots, degree {degree} takes {n_knots - degree - 1} {what}"
                       if n_knots - degree - 1 >= 1 else None)
    return None


def too_few_points_problem(n_ctrl: int, degree: int, what: str = "control points") -> Problem | None:
    if n_ctrl < degree + 1:
        return Problem("E0409", f"degree {degree} needs at least {degree + 1} {what}, found {n_ctrl}")
    return None


def weight_problem(weights) -> Problem | None:
    """The first weight that is not strictly positive (a rational B-spline needs w > 0, P&T 4.2)."""
    if hasattr(weights, "ravel"):   # a column of a net's numpy array: vectorised, without importing numpy
        w = weights.ravel()
        bad = (~(w > 0)).nonzero()[0]
        i = int(bad[0]) if bad.size else None
    else:
        w = [float(x) for x in weights]
        i = next((i for i, x in enumerate(w) if not x > 0), None)
    if i is not None:
        return Problem("E0405", f"weights must be positive, the {ordinal(i + 1)} is {_fmt(float(w[i]))}", i)
    return None


def ragged_problem(row_lengths: list[int]) -> Problem | None:
    """Rows of a control net given as nested lists must all have the same length."""
    for i, n in enumerate(row_lengths):
        if n != row_lengths[0]:
            return Problem("E0406", f"control net is ragged: row 1 has {row_lengths[0]} points "
                                    f"but row {i + 1} has {n}", i)
    return None


def knot_vector_problems(knots: Knots, degree: int | None, n_ctrl: int | None, what: str = "control points"):
    """Every rule for a knot vector used by a spline of `degree` over `n_ctrl` points (either may be
    unknown: None). Returns a list of Problems, most basic first."""
    out = [knot_order_problem(knots.values)]
    if degree is not None and degree >= 1:
        if out[0] is None:
            out.append(multiplicity_problem(knots.values, degree))
        if n_ctrl is not None:
            prob = count_problem(len(knots.values), degree, n_ctrl, what)
            if prob is not None and knots.degree is not None and knots.degree != degree:
                prob = Problem(prob.code, prob.message, None,
                               f"these knots were built by `{knots.helper}` for degree {knots.degree}; "
                               f"use {knots.helper}({degree}, ...)")
            out.append(prob)
    return [p for p in out if p is not None]


@dataclass(frozen=True)
class Point:
    """A folded `pt`/`uv`/`vec`/`projPt`: `kind` is the builtin's name, `coords` in model units."""

    kind: str
    coords: tuple[float, ...]


def _arg(call, i: int, name: str):
    """The expression passed as the i-th positional or the `name` argument of a call, or None."""
    return call.args[i] if len(call.args) > i else call.kwarg(name)


def as_int(value) -> int | None:
    """A folded number that is a whole number, as an int (degrees, counts)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return None


class Folder:
    """Constant folding of expressions into floats (model units, radians), strings, tuples (lists),
    Points, Knots and Nets; anything not known before evaluation (geometry, fn parameters, a name in a
    cycle) folds to None. Bindings are folded once, with `-D` overrides in place of param values."""

    _POINTS = {"pt": ("x", "y", "z"), "uv": ("u", "v"), "vec": ("x", "y", "z"), "projPt": ("x", "y", "z", "w")}

    def __init__(self, bindings: dict, overrides: dict, units: str, user_fns=(), types: dict | None = None):
        self.bindings, self.overrides, self.units = bindings, overrides, units
        self.types = {} if types is None else types   # the checker's; ill-typed expressions never fold
        self.user_fns = set(user_fns)
        self.memo: dict[str, object] = {}
        self.busy: set[str] = set()
        self.uniform: dict[tuple[int, int], Knots] = {}

    def binding(self, name: str):
        if name in self.memo:
            return self.memo[name]
        if name in self.busy or name not in self.bindings:
            return None
        self.busy.add(name)
        value = self.fold(self.overrides.get(name, self.bindings[name].expr))
        self.busy.discard(name)
        self.memo[name] = value
        return value

    def fold(self, expr, local: frozenset = frozenset()):
        if self.types.get(id(expr)) is ANY:
            return None
        cls = expr.__class__     # the node classes have no subclasses: `is` tests, most common first
        if cls is A.Number:
            return to_model(expr.value, expr.unit, self.units)
        if cls is A.String:
            return expr.value
        if cls is A.Name:
            return None if expr.id in local else self.binding(expr.id)
        if cls is A.ListExpr:
            return tuple(self.fold(e, local) for e in expr.items)
        if cls is A.Net:
            return expr
        if cls is A.Call:
            return self.call(expr, local)
        if cls is A.Neg:
            v = self.fold(expr.operand, local)
            return -v if isinstance(v, float) else None
        if cls is A.BinOp:
            a, b = self.fold(expr.left, local), self.fold(expr.right, local)
            if not (isinstance(a, float) and isinstance(b, float)):
                return None
            if expr.op == "/":
                return a / b if b != 0 else None
            return {"+": a + b, "-": a - b, "*": a * b}[expr.op]
        if cls is A.Member:
            obj = self.fold(expr.obj, local)
            if isinstance(obj, Point):
                if expr.attr == "length" and obj.kind == "vec":
                    return math.hypot(*obj.coords)
                names = self._POINTS[obj.kind]
                attr = {"x": "u", "y": "v"}.get(expr.attr, expr.attr) if obj.kind == "uv" else expr.attr
                return obj.coords[names.index(attr)] if attr in names else None
            return None
        return None

    def call(self, call, local):
        name = call.func.id
        if name in self.user_fns:
            return None
        if name in self._POINTS:
            coords = [self.fold(_arg(call, i, p), local) if _arg(call, i, p) is not None else None
                      for i, p in enumerate(self._POINTS[name])]
            return Point(name, tuple(coords)) if all(isinstance(c, float) for c in coords) else None
        if name in ("clamped", "uniform", "knots"):
            return self.knots(call, name, local)
        return None

    def knots(self, call, name, local) -> Knots | None:
        def get(i, pname):
            e = _arg(call, i, pname)
            return None if e is None else self.fold(e, local)

        if name == "knots":
            values = get(0, "values")
            ok = isinstance(values, tuple) and all(isinstance(v, float) for v in values)
            return Knots(values, None, "knots") if ok else None
        degree = as_int(get(0, "degree"))
        if degree is None or degree < 1:
            return None
        if name == "uniform":
            count = as_int(get(1, "count"))
            if count is None or count <= degree:
                return None
            if (degree, count) not in self.uniform:   # one object per knot vector: checks memoise on it
                self.uniform[degree, count] = uniform_knots(degree, count)
            return self.uniform[degree, count]
        interior = get(1, "interior") if _arg(call, 1, "interior") is not None else ()
        if isinstance(interior, tuple) and all(isinstance(v, float) for v in interior):
            return clamped_knots(degree, interior)
        return None
