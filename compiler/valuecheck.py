"""Value checks on the constant arguments of builtin calls, with the span of the offending argument.

Runs after a call type-checks. Arguments are folded (`rgm.compiler.values.Folder`); what is not
constant (geometry, fn parameters) is skipped. Rules (Piegl & Tiller, *The NURBS Book*, 2.2, 3.2, 4.2):
degree >= 1; knot vectors non-decreasing with len = n + degree + 1 and no interior knot repeated more
than `degree` times; weights > 0 and one per control point; control nets rectangular, entries of the
right width, and as many rows/columns as the knot vectors need; plus geometric sanity that needs no
evaluation (positive radius, non-zero directions, a revolution of at most one turn, a positive
`scaling` factor, `frame` axes that are not parallel).
Intrinsic problems of a knot vector are reported where it is built (`knots([...])`, `clamped(...)`),
problems relative to a spline (count, multiplicity for its degree) where it is used.
"""
from __future__ import annotations

import math
from typing import NamedTuple

from . import ast as A
from . import types as T
from .builtins import FUNCTIONS
from .diagnostics import error
from .values import (Folder, Knots, Point, Problem, as_int, degree_problem, knot_order_problem,
                     knot_vector_problems, multiplicity_problem, ragged_problem, too_few_points_problem,
                     weight_problem)


class Arg(NamedTuple):
    """An argument bound to a parameter: its expression, type and positional index (None if named).
    A tuple: the checker makes one per argument of every call."""

    expr: object
    type: T.Type
    pos: int | None


def _item(expr, i: int | None):
    """The span of the i-th item when `expr` is a list literal (else of `expr` itself)."""
    if i is not None and isinstance(expr, A.ListExpr) and 0 <= i < len(expr.items):
        return expr.items[i].span
    return expr.span


def _whole(prob: Problem | None) -> Problem | None:
    """The problem without an element index: for nets, whose entries have no spans of their own."""
    return prob and Problem(prob.code, prob.message, None, prob.hint)


class ValueChecker:
    def __init__(self, folder: Folder, report):
        self.folder, self.report = folder, report
        self.local: frozenset = frozenset()
        self.knot_problems: dict[tuple, list[Problem]] = {}

    def fold(self, expr):
        return None if expr is None else self.folder.fold(expr, self.local)

    def problem(self, prob: Problem | None, expr, index: int | None = None, label: str = "", notes=()) -> bool:
        if prob is None:
            return False
        at = prob.index if index is None else index
        self.report(error(prob.code, prob.message, _item(expr, at), label or "here", notes, prob.hint))
        return True

    # ------------------------------------------------------------------------------- entry points
    def check(self, name: str, call: A.Call, args: dict, local: frozenset) -> T.Type | None:
        """Check `call` of builtin `name`, given its parameters' argument expressions (those given one
        argument); returns a refined result type (a bspline over a 2-D net is a curve2) or None."""
        method = RULES.get(name)
        if method is None:
            return None
        self.local = local
        return method(self, args)

    def fraction(self, ann: str, key: str, expr) -> None:
        v = self.fold(expr)
        if isinstance(v, float) and not 0.0 <= v <= 1.0:
            self.report(error("E0413", f"`{key}` of `@{ann}` is a fraction between 0 and 1, found {v:g}", expr.span,
                              "outside [0, 1]"))

    def division(self, expr: A.BinOp, env) -> None:
        if self.folder.fold(expr.right, frozenset(env)) == 0.0:
            self.report(error("E0414", "division by zero", expr.right.span, "this is 0"))

    # ------------------------------------------------------------------------------- helpers
    def _degree(self, args, key="degree") -> int | None:
        p = as_int(self.fold(args.get(key)))
        if p is not None and self.problem(degree_problem(p), args[key], label="not at least 1"):
            return None
        return p

    def _nonzero(self, args, key: str, what: str) -> None:
        v = self.fold(args.get(key))
        if isinstance(v, Point) and not any(v.coords):
            self.report(error("E0417", f"{what} is the zero vector", args[key].span, "has no direction"))

    def _knots_against(self, args, key: str, degree, count, what, code="E0403", notes=()) -> None:
        """Count and multiplicity of the knot vector `args[key]` for a spline of `degree` over `count`."""
        knots = self.fold(args.get(key))
        if not isinstance(knots, Knots):
            return   # not constant
        memo = (knots, degree, count, what)
        problems = self.knot_problems.get(memo)
        if problems is None:   # a file repeats a few knot vectors: their rules are checked once
            problems = self.knot_problems[memo] = (
                [] if len(knots.values) < 2 or knot_order_problem(knots.values) is not None   # reported where built
                else knot_vector_problems(knots, degree, count, what))
        for prob in problems:
            if prob.code == "E0404" and knots.helper != "knots":
                continue   # clamped/uniform report their own multiplicities
            expr = args[key]
            index = None
            if prob.code == "E0404" and isinstance(expr, A.Call) and expr.func.id == "knots" and expr.args:
                expr, index = expr.args[0], prob.index
            msg = prob.message if code == "E0403" or prob.code != "E0403" else f"`{key}`: {prob.message}"
            label = f"{len(knots.values)} knots" if prob.code == "E0403" else "repeated too often"
            self.problem(Problem(code if prob.code == "E0403" else prob.code, msg, None, prob.hint), expr, index,
                         label, notes)

    def _weights(self, args, count: int | None, shape=None) -> None:
        expr = args.get("weights")
        w = self.fold(expr)
        if isinstance(w, A.Net):
            if w.width != 1 or (shape is not None and w.shape != shape):
                want = " x ".join(map(str, shape)) if shape else "one weight per point"
                self.report(error("E0408", f"weights must be a net of single numbers shaped like the control net "
                                  f"({want}), found net {' x '.join(map(str, w.shape))} of width {w.width}",
                                  expr.span, "wrong shape"))
            else:
                self.problem(_whole(weight_problem(w.data)), expr)
            return
        if not isinstance(w, tuple):
            return
        if shape is not None:     # nested lists for a surface
            rows = [len(r) if isinstance(r, tuple) else 1 for r in w]
            if (len(rows), rows[0] if rows else 0) != shape or len(set(rows)) > 1:
                self.report(error("E0408", f"weights must be {shape[0]} rows of {shape[1]} numbers, like the net",
                                  expr.span, "wrong shape"))
                return
            flat = [x for r in w for x in r]
            if all(isinstance(x, float) for x in flat):
                self.problem(_whole(weight_problem(flat)), expr)
            return
        if count is not None and len(w) != count:
            self.report(error("E0408", f"{len(w)} weights for {count} control points", expr.span,
                              "one weight per control point"))
        elif all(isinstance(x, float) for x in w):
            self.problem(weight_problem(w), expr, label="not positive")

    # ------------------------------------------------------------------------------- builtins
    def _projPt(self, args):
        w = self.fold(args.get("w"))
        if isinstance(w, float) and not w > 0:
            self.report(error("E0405", f"the weight of a projPt must be positive, found {w:g}", args["w"].span,
                              "not positive"))

    def _clamped(self, args):
        p = self._degree(args)
        expr = args.get("interior")
        interior = self.fold(expr)
        if not isinstance(interior, tuple) or not all(isinstance(v, float) for v in interior):
            return
        for i, v in enumerate(interior):
            if not 0.0 <= v <= 1.0:
                self.report(error("E0411", f"interior knot {v:g} lies outside the domain [0, 1]", _item(expr, i),
                                  "outside [0, 1]"))
                return
        if self.problem(knot_order_problem(interior), expr, label="decreasing") or p is None:
            return
        full = (0.0,) * (p + 1) + interior + (1.0,) * (p + 1)
        prob = multiplicity_problem(full, p)
        if prob is not None:
            self.problem(prob, expr, max(0, min(prob.index - p - 1, len(interior) - 1)), "repeated too often")

    def _uniform(self, args):
        p = self._degree(args)
        n = as_int(self.fold(args.get("count")))
        if p is not None and n is not None and n < p + 1:
            self.report(error("E0410", f"a degree-{p} knot vector needs at least {p + 1} control points, "
                              f"`count` is {n}", args["count"].span, f"fewer than {p + 1}"))

    def _knots(self, args):
        expr = args.get("values")
        values = self.fold(expr)
        if not isinstance(values, tuple) or not all(isinstance(v, float) for v in values):
            return
        if len(values) < 2:
            self.report(error("E0412", f"a knot vector needs at least 2 values, found {len(values)}", expr.span,
                              "too short"))
            return
        self.problem(knot_order_problem(values), expr, label="decreasing")

    def _bspline(self, args):
        p = self._degree(args)
        points_expr = args.get("points")
        pts = self.fold(points_expr)
        result, n = None, None
        if isinstance(pts, A.Net):
            if len(pts.shape) == 2 and min(pts.shape) > 1:
                self.report(error("E0406", f"the control points of a curve are one row, this net is "
                                  f"{pts.shape[0]} x {pts.shape[1]}", points_expr.span, "not one row",
                                  hint=f"write `net {pts.shape[0] * pts.shape[1]} [...]`"))
                return None
            if pts.width not in (2, 3, 4):
                self.report(error("E0416", f"control points need 2 (u v), 3 (x y z) or 4 (x y z w) numbers each, "
                                  f"this net has {pts.width}", points_expr.span, f"width {pts.width}"))
                return None
            n, result = math.prod(pts.shape), (T.CURVE2 if pts.width == 2 else None)
            if pts.width == 4:
                self.problem(_whole(weight_problem(pts.data[..., 3])), points_expr)
                self._no_double_weights(args, "the net's 4th column")
        elif isinstance(pts, tuple):
            n = len(pts)
            if any(isinstance(q, Point) and q.kind == "projPt" for q in pts):
                self._no_double_weights(args, "the projPt points")
        if p is None or n is None:
            return result
        if self.problem(too_few_points_problem(n, p), points_expr, label=f"{n} point{'s' * (n != 1)}"):
            return result
        self._knots_against(args, "knots", p, n, "control points")
        self._weights(args, n)
        return result

    def _no_double_weights(self, args, where):
        if "weights" in args:
            self.report(error("E0408", f"weights are given twice: by `weights` and by {where}", args["weights"].span,
                              "second set of weights"))

    def _bsurface(self, args):
        pu, pv = self._degree(args, "degree_u"), self._degree(args, "degree_v")
        expr = args.get("net")
        net = self.fold(expr)
        shape = None
        if isinstance(net, A.Net):
            if len(net.shape) != 2:
                self.report(error("E0406", "a surface's control net needs rows and columns: `net NU x NV [...]`",
                                  expr.span, f"net {net.shape[0]} has one dimension"))
                return
            if net.width not in (3, 4):
                self.report(error("E0416", f"control-net entries need 3 (x y z) or 4 (x y z w) numbers, "
                                  f"this net has {net.width}", expr.span, f"width {net.width}"))
                return
            shape = net.shape
            if net.width == 4:
                self.problem(_whole(weight_problem(net.data[..., 3])), expr)
                self._no_double_weights(args, "the net's 4th column")
        elif isinstance(net, tuple):
            rows = [len(r) if isinstance(r, tuple) else 0 for r in net]
            if rows and self.problem(ragged_problem(rows), expr, label="ragged row"):
                return
            shape = (len(rows), rows[0] if rows else 0)
        if shape is None:
            return
        nu, nv = shape
        notes = [f"the control net has {nu} rows (u) and {nv} columns (v)"]
        for key, p, count, what in (("knots_u", pu, nu, "rows"), ("knots_v", pv, nv, "columns")):
            if p is None:
                continue
            if count < p + 1:
                self.report(error("E0409", f"degree {p} needs at least {p + 1} net {what}, found {count}",
                                  expr.span, f"{count} {what}"))
                continue
            self._knots_against(args, key, p, count, f"net {what}", "E0407", notes)
        self._weights(args, None, shape)

    def _circle(self, args):
        r = self.fold(args.get("radius"))
        if isinstance(r, float) and not r > 0:
            self.report(error("E0415", f"a circle's radius must be positive, found {r:g}", args["radius"].span,
                              "not positive"))
        self._nonzero(args, "normal", "the circle's normal")

    def _plane(self, args):
        self._nonzero(args, "normal", "the plane's normal")

    def _extrude(self, args):
        self._nonzero(args, "direction", "the extrusion direction")

    def _rotate(self, args):
        self._nonzero(args, "axis", "the rotation axis")

    def _scale(self, args):
        f = self.fold(args.get("factor"))
        if f == 0.0:
            self.report(error("E0418", "a scale factor of 0 collapses the geometry to a point", args["factor"].span,
                              "zero"))

    _rotation = _rotate

    def _scaling(self, args):
        f = self.fold(args.get("factor"))
        if isinstance(f, float) and not f > 0:
            self.report(error("E0421", f"a scaling factor must be positive, found {f:g}", args["factor"].span,
                              "not positive",
                              hint="a reflection is `mirroring(plane)`" if f < 0 else None))

    def _frame(self, args):
        self._nonzero(args, "z", "the frame's z axis")
        self._nonzero(args, "x", "the frame's x axis")
        z, x = self.fold(args.get("z")), self.fold(args.get("x"))
        if not (isinstance(z, Point) and isinstance(x, Point) and any(z.coords) and any(x.coords)):
            return
        (a, b, c), (d, e, f) = z.coords, x.coords
        cross = math.hypot(b * f - c * e, c * d - a * f, a * e - b * d)
        if cross <= PARALLEL_SINE * math.hypot(a, b, c) * math.hypot(d, e, f):
            self.report(error("E0422", "the frame's x axis is parallel to its z axis", args["x"].span,
                              "along z", ["x is made perpendicular to z (its part along z is removed), so it only "
                                          "needs to be not parallel to z"],
                              "give x any direction across z, for example `vec(1, 0, 0)` for z = `vec(0, 0, 1)`"))

    def _line(self, args):
        a, b = self.fold(args.get("a")), self.fold(args.get("b"))
        if isinstance(a, Point) and a == b:
            self.report(error("E0420", "a line needs two different points", args["b"].span, "same as the start"))

    def _revolve(self, args):
        start = self.fold(args["from"]) if "from" in args else 0.0
        end = self.fold(args["to"]) if "to" in args else 2 * math.pi
        if not (isinstance(start, float) and isinstance(end, float)):
            return
        where = args.get("to") or args.get("from")
        if end == start:
            self.report(error("E0419", "the revolution sweeps no angle (`from` equals `to`)", where.span, "zero sweep"))
        elif abs(end - start) > 2 * math.pi * (1 + 1e-12):
            self.report(error("E0419", f"the revolution sweeps {math.degrees(abs(end - start)):g}deg, "
                              "more than a full turn", where.span, "over 360deg"))


#: `frame` axes count as parallel below this sine of their angle (rgm.model.transform.PARALLEL_SINE,
#: which needs numpy and so cannot be imported here)
PARALLEL_SINE = 1e-9

#: builtin name -> its check (the method `_name` above), looked up once
RULES = {name: getattr(ValueChecker, "_" + name) for name in FUNCTIONS if hasattr(ValueChecker, "_" + name)}
