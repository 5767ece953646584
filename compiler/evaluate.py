"""The evaluator: a checked `.rgm` program becomes an evaluated `rgm.model.Model`.

Bindings are evaluated once each, in the resolver's dependency order, with `-D` overrides replacing
the expressions of `param`s. Every number leaves here in model units (lengths, through
`rgm.compiler.units.to_model`) or radians (angles). Builtins build model objects of the kind the
language names (a `revolve` is a `Revolution`, not an anonymous NURBS); transforms become 4x4
homogeneous matrices (`rgm.model.transform`) applied with `.transform`, which keeps that kind, and
transform values (`rotation(...)`, `t2 * t1`, `inverse(t)`) are `Transform` objects with the span of
the expression that built them; `place(g, t)` applies one. `intersect(a, b)` builds a lazy
`IntersectionCurve`: nothing is marched here. User `fn`s are expanded at each call with their
arguments bound in a local scope.

Runtime failures the checker cannot foresee (an arc through collinear points, a knot vector that does
not fit its control points, division by zero) become diagnostics E0510/E0511 on the offending call.
"""
from __future__ import annotations

from collections import ChainMap
from functools import lru_cache

import numpy as np

from rgm.compiler import ast as A
from rgm.compiler.builtins import FUNCTIONS
from rgm.compiler.diagnostics import Diagnostic, error
from rgm.compiler.units import to_model
from rgm.compiler.values import clamped_knots, uniform_knots
from rgm.errors import GeometryError
from rgm import model as M
from rgm.model.transform import frame, mirroring, rotation, scaling, translation

#: the model tolerance when a file has no `tolerance` statement (model units)
DEFAULT_TOLERANCE = 0.01
#: builtins that move geometry (`translate(g, ...) -> G`, `place(g, t) -> G`): the moved copy is
#: anonymous and points at the call that moved it
_MOVES = frozenset(n for n, b in FUNCTIONS.items() if b.overloads[0].result.kind == "var")


class _Failure(Exception):
    """Evaluation of one binding failed; carries the diagnostic (None: a dependency already failed)."""

    def __init__(self, diagnostic: Diagnostic | None):
        super().__init__(diagnostic.message if diagnostic else "a dependency failed")
        self.diagnostic = diagnostic


@lru_cache(maxsize=None)
def _default_expr(text: str) -> A.Expr:
    """A builtin parameter's default (source text such as `360deg` or `vec(0, 0, 1)`) as an expression."""
    from rgm.compiler.parser import parse

    program, diagnostics = parse(f"_default := {text};", "<default>")
    if program is None or diagnostics:
        raise RuntimeError(f"unparsable builtin default {text!r}")
    return program.statements[0].expr


# --- builtins ------------------------------------------------------------------------------------

def _xyz(p) -> np.ndarray:
    return p.xyz if isinstance(p, (M.Point, M.Vector, M.HPoint)) else np.asarray(p, float)


def _arc(start, through, end, span):
    """The circular arc through three points (center from the perpendicular bisectors)."""
    p0, p1, p2 = (_xyz(p) for p in (start, through, end))
    dim = p0.shape[0]
    a, b, c = (np.concatenate([p, [0.0]]) if dim == 2 else p for p in (p0, p1, p2))
    u, v = b - a, c - a
    w = np.cross(u, v)
    ww = w @ w
    if ww <= 1e-24 * max(u @ u, v @ v) ** 2:
        raise GeometryError("the three points of the arc are collinear")
    center = a + (np.cross(w, u) * (v @ v) + np.cross(v, w) * (u @ u)) / (2 * ww)
    radius = float(np.linalg.norm(a - center))
    return M.CircularArc(center[:dim], w, radius, p0, p2, span=span)


def _reverse(a, span):
    """The curve traversed the other way (its NURBS form reversed on the same domain): a loop piece that
    a neighbouring face runs in the opposite direction, such as a seam curve two patches share."""
    curve = a["curve"]
    if isinstance(curve, M.IntersectionCurve):
        raise GeometryError("an intersection has no direction of its own (a loop runs it from the previous "
                            "piece's end): use it as it is")
    return M.BSplineCurve(curve.nurbs().reverse(), span=span)


def _bspline(a, span):
    pts = a["points"]
    weights = a["weights"]
    if isinstance(pts, np.ndarray):  # a net of entries: xyz or xyz + weight
        flat = pts.reshape(-1, pts.shape[-1])
        ctrl, w = (flat[:, :3], flat[:, 3]) if flat.shape[1] == 4 else (flat, None)
    else:
        ctrl = np.array([_xyz(p) for p in pts])
        w = np.array([p.w for p in pts]) if pts and isinstance(pts[0], M.HPoint) else None
    if weights is not None:
        w = np.asarray(weights, float)
    from rgm.geometry import NurbsCurve

    return M.BSplineCurve(NurbsCurve(a["degree"], a["knots"], ctrl, w), span=span)


def _grid(value) -> np.ndarray:
    """A net (nu, nv, w) array or a list of rows of points as an (nu, nv, w) array."""
    if isinstance(value, np.ndarray):
        return value
    return np.array([[_xyz(p) if not isinstance(p, (int, float)) else [p] for p in row] for row in value])


def _bsurface(a, span):
    net = _grid(a["net"])
    if net.ndim != 3:
        raise GeometryError(f"a surface needs a 2-D grid of control points, got shape {net.shape[:-1]}")
    ctrl, w = (net[..., :3], net[..., 3]) if net.shape[-1] == 4 else (net, None)
    if a["weights"] is not None:
        w = _grid(a["weights"]).reshape(ctrl.shape[:2])
    from rgm.geometry import NurbsSurface

    return M.BSplineSurface(NurbsSurface(a["degree_u"], a["degree_v"], a["knots_u"], a["knots_v"], ctrl, w),
                            span=span)


def _axis(axis) -> tuple[np.ndarray, np.ndarray]:
    """Point and direction of an axis given as a 3-D curve (its start and end)."""
    p0, p1 = np.asarray(axis.start, float), np.asarray(axis.end, float)
    return p0, p1 - p0


def _revolve(a, span):
    point, direction = _axis(a["axis"])
    return M.Revolution(a["profile"], point, direction, a["from"], a["to"], span=span)


def _scaling(a, span):
    """`scaling(factor, about)`: a transform value scales by a positive factor (a reflection is `mirroring`)."""
    if not a["factor"] > 0:
        raise GeometryError(f"a scaling factor must be positive, found {a['factor']:g}")
    return M.Transform(scaling(a["factor"], _xyz(a["about"])), span=span)


def _knots(values) -> np.ndarray:
    return np.asarray(values, float)


def _make_builtins(tolerance: float) -> dict:
    """name -> f(args: dict of bound parameter values, span) -> value."""
    return {
        "pt": lambda a, s: M.Point([a["x"], a["y"], a["z"]], span=s),
        "uv": lambda a, s: M.Point([a["u"], a["v"]], span=s),
        "vec": lambda a, s: M.Vector([a["x"], a["y"], a["z"]], span=s),
        "projPt": lambda a, s: M.HPoint([a["x"], a["y"], a["z"]], a["w"], span=s),
        "clamped": lambda a, s: _knots(clamped_knots(a["degree"], a["interior"]).values),
        "uniform": lambda a, s: _knots(uniform_knots(a["degree"], a["count"]).values),
        "knots": lambda a, s: _knots(a["values"]),
        "line": lambda a, s: M.Line(_xyz(a["a"]), _xyz(a["b"]), span=s),
        "uvline": lambda a, s: M.Line(_xyz(a["a"]), _xyz(a["b"]), span=s),
        "polyline": lambda a, s: M.Polyline([_xyz(p) for p in a["points"]], span=s),
        "arc": lambda a, s: _arc(a["start"], a["through"], a["end"], s),
        "circle": lambda a, s: M.Circle(_xyz(a["center"]), _xyz(a["normal"]), a["radius"], span=s),
        "bspline": _bspline,
        "profile": lambda a, s: M.CompositeCurve(a["pieces"], span=s),
        "reverse": _reverse,
        "revolve": _revolve,
        "bsurface": _bsurface,
        "plane": lambda a, s: M.Plane(_xyz(a["origin"]), _xyz(a["normal"]), span=s),
        "extrude": lambda a, s: M.Extrusion(a["profile"], _xyz(a["direction"]), span=s),
        "ruled": lambda a, s: M.RuledSurface(a["a"], a["b"], span=s),
        "intersect": lambda a, s: M.IntersectionCurve(a["a"], a["b"], tolerance, span=s),
        "loop": lambda a, s: M.Loop(a["pieces"], span=s),
        "trim": lambda a, s: M.TrimmedFace(a["surface"], a["outer"], tuple(a["holes"]), span=s),
        "shell": lambda a, s: M.Shell(a["faces"], span=s),
        "translate": lambda a, s: a["g"].transform(translation(_xyz(a["by"]))),
        "rotate": lambda a, s: a["g"].transform(rotation(_xyz(a["axis"]), a["angle"], _xyz(a["about"]))),
        "scale": lambda a, s: a["g"].transform(scaling(a["factor"], _xyz(a["about"]))),
        "mirror": lambda a, s: a["g"].transform(mirroring(a["plane"])),
        "translation": lambda a, s: M.Transform(translation(_xyz(a["by"])), span=s),
        "rotation": lambda a, s: M.Transform(rotation(_xyz(a["axis"]), a["angle"], _xyz(a["about"])), span=s),
        "scaling": _scaling,
        "mirroring": lambda a, s: M.Transform(mirroring(a["plane"]), span=s),
        "frame": lambda a, s: M.Transform(frame(_xyz(a["origin"]), _xyz(a["z"]), _xyz(a["x"])), span=s),
        "inverse": lambda a, s: a["t"].inverse().named(None, s),
        "place": lambda a, s: a["t"].apply(a["g"]),
    }


# --- members and arithmetic ----------------------------------------------------------------------

def _member(value, attr: str):
    if isinstance(value, (M.Point, M.Vector, M.HPoint)):
        xyz = value.xyz
        index = {"x": 0, "y": 1, "z": 2, "u": 0, "v": 1}
        if attr in index:
            return float(xyz[index[attr]])
        if attr == "length":
            return float(np.linalg.norm(xyz))
        if attr == "w":
            return value.w
    if attr in ("start", "end") and isinstance(value, M.Curve):
        return M.Point(value.start if attr == "start" else value.end)
    if attr == "domain" and isinstance(value, M.Surface):
        (u0, u1), (v0, v1) = value.domain
        return [u0, u1, v0, v1]
    if isinstance(value, M.Plane) and attr in ("origin", "normal"):
        return M.Point(value.origin) if attr == "origin" else M.Vector(value.normal)
    if isinstance(value, M.TrimmedFace) and attr == "surface":
        return value.surface
    raise GeometryError(f"{type(value).__name__} has no member `{attr}`")


def _binary(op: str, left, right):
    if isinstance(left, M.Transform):   # the checker allows only transform * transform
        return left.after(right)
    lp, rp = isinstance(left, M.Point), isinstance(right, M.Point)
    lv, rv = isinstance(left, M.Vector), isinstance(right, M.Vector)
    if op == "/" and not (lp or lv) and right == 0:
        raise ZeroDivisionError("division by zero")
    if op == "/" and lv:
        if right == 0:
            raise ZeroDivisionError("division of a vector by zero")
        return M.Vector(left.xyz / right)
    if lp and rp and op == "-":
        return M.Vector(left.xyz - right.xyz)
    if (lp and rv) or (lv and rp) or (lv and rv):
        sign = -1.0 if op == "-" else 1.0
        xyz = left.xyz + sign * right.xyz
        return M.Vector(xyz) if lv and rv else M.Point(xyz)
    if lv or rv:  # scalar * vec or vec * scalar
        vec, k = (left, right) if lv else (right, left)
        return M.Vector(vec.xyz * k)
    return {"+": lambda: left + right, "-": lambda: left - right, "*": lambda: left * right,
            "/": lambda: left / right}[op]()


# --- the evaluator -------------------------------------------------------------------------------

class Evaluator:
    """Evaluates expressions of one program; `env` maps binding names to values."""

    def __init__(self, units: str, tolerance: float, fns: dict):
        self.units = units
        self.fns = fns
        self.builtins = _make_builtins(tolerance)
        self.env: dict = {}

    def eval(self, expr, scope):
        if isinstance(expr, A.Number):
            value = to_model(expr.value, expr.unit, self.units)
            return int(expr.value) if expr.is_int and expr.unit is None else value
        if isinstance(expr, A.String):
            return expr.value
        if isinstance(expr, A.Name):
            if expr.id in scope:
                return scope[expr.id]
            constants = {"none": None, "true": True, "false": False}
            if expr.id in constants:
                return constants[expr.id]
            raise _Failure(None)  # its binding failed and was reported
        if isinstance(expr, A.ListExpr):
            return [self.eval(e, scope) for e in expr.items]
        if isinstance(expr, A.Net):
            return np.array(expr.data)
        if isinstance(expr, A.Neg):
            value = self.eval(expr.operand, scope)
            return M.Vector(-value.xyz) if isinstance(value, M.Vector) else -value
        if isinstance(expr, A.BinOp):
            left, right = self.eval(expr.left, scope), self.eval(expr.right, scope)
            value = self._guard(expr, lambda: _binary(expr.op, left, right))
            return value.named(None, expr.span) if isinstance(value, M.Transform) else value
        if isinstance(expr, A.Member):
            value = self.eval(expr.obj, scope)
            return self._guard(expr, lambda: _member(value, expr.attr))
        if isinstance(expr, A.Call):
            return self.call(expr, scope)
        raise _Failure(error("E0512", f"cannot evaluate {type(expr).__name__}", getattr(expr, "span", None)))

    def _guard(self, expr, thunk):
        try:
            return thunk()
        except ZeroDivisionError as exc:
            raise _Failure(error("E0511", str(exc), expr.span, "evaluates to a division by zero")) from None
        except (GeometryError, ValueError, np.linalg.LinAlgError) as exc:
            raise _Failure(error("E0510", str(exc), expr.span, "cannot be built")) from None

    def call(self, expr: A.Call, scope):
        name = expr.func.id
        args = [self.eval(e, scope) for e in expr.args]
        kwargs = {k: self.eval(e, scope) for k, e in expr.kwargs}
        if name in self.fns:
            fn = self.fns[name]
            local = dict(zip((p.name for p in fn.params), args))
            local.update(kwargs)
            return self.eval(fn.body, ChainMap(local, self.env))
        bound = self._bind(FUNCTIONS[name], args, kwargs)
        value = self._guard(expr, lambda: self.builtins[name](bound, expr.span))
        if name in _MOVES and isinstance(value, M.ModelObject):
            value = value.named(None, expr.span)
        return value

    def _bind(self, builtin, args, kwargs) -> dict:
        """Arguments by parameter name, with defaults filled in (the checker has matched them)."""
        bound = {}
        rest = list(args)
        for p in builtin.params:
            if p.variadic:
                bound[p.name], rest = rest, []
            elif rest:
                bound[p.name] = rest.pop(0)
            elif p.name in kwargs:
                bound[p.name] = kwargs[p.name]
            elif p.default is not None:
                bound[p.name] = self.eval(_default_expr(p.default), {})
        return bound


def evaluate(program: A.Program, checked=None, params: dict[str, str] | None = None,
             source: str | None = None) -> tuple[M.Model, list[Diagnostic]]:
    """Evaluate a checked program into a Model; returns (model, diagnostics of evaluation).

    `checked` is `rgm.compiler.check.check(program, params)`'s result (computed here when None);
    `params` are `-D` overrides as text (`{"radius": "30"}`, model units when unitless). A binding
    whose evaluation fails is left out of the model and reported once; bindings that use it are
    skipped without further noise.
    """
    if checked is None:
        from rgm.compiler.check import check

        checked = check(program, params)
    units = checked.units
    tolerance = DEFAULT_TOLERANCE if checked.tolerance is None else float(checked.tolerance)
    ev = Evaluator(units, tolerance, checked.fns)
    diagnostics: list[Diagnostic] = []
    for name in checked.order:
        binding = checked.bindings.get(name)
        if binding is None:
            continue
        expr = checked.overrides.get(name, binding.expr) if binding.is_param else binding.expr
        try:
            value = ev.eval(expr, ev.env)
        except _Failure as exc:
            if exc.diagnostic is not None:
                diagnostics.append(exc.diagnostic)
            continue
        if isinstance(value, M.ModelObject):
            value = value.named(name)
        ev.env[name] = value
    params_out = {n: ev.env[n] for n, b in checked.bindings.items() if b.is_param and n in ev.env}
    exports = tuple(n for n in checked.exports if n in ev.env)
    model = M.Model(units, tolerance, dict(ev.env), exports, params_out,
                    source or (program.span.file if program.span else None))
    return model, diagnostics
