"""Model → `.rgm` source text (used by `rgmc import`): legacy IGES or Alpha_1 becomes an editable procedure.

Every model binding becomes `name := expr;` in dependency order, nested unnamed objects are written
inline, and names that are not identifiers (or clash with keywords and builtins) are made into ones.
Numbers are Python's shortest round-trip `repr`, so the compiled model has the same floats;
lengths are plain numbers in the file's units, angles carry `rad`. Control nets use the dense
`net R x C [x y z (w), ...]` form. A plane whose x direction is not the language's default, and a
trimmed face with no outer loop, are written in equivalent explicit forms (a bilinear `bsurface` in
plane coordinates; the rectangle of the surface's domain).
"""
from __future__ import annotations

import re

import numpy as np

from rgm.errors import BackendError
from rgm.model import (
    BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, HPoint, IntersectionCurve, Line,
    Loop, Plane, Point, Polyline, Revolution, RuledSurface, Shell, TrimmedFace, Vector,
)

__all__ = ["model_to_rgm", "identifier"]

_KEYWORDS = {"units", "tolerance", "param", "fn", "export", "net", "x"}
_BUILTINS = {"pt", "uv", "vec", "projPt", "clamped", "uniform", "knots", "line", "polyline", "arc", "circle",
             "bspline", "profile", "uvline", "revolve", "bsurface", "plane", "extrude", "ruled", "intersect",
             "loop", "trim", "shell", "translate", "rotate", "scale", "mirror"}


def identifier(name: str, taken: set) -> str:
    """A valid, unused `.rgm` identifier made from `name` (added to `taken`)."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name.strip()) or "object"
    if ident[0].isdigit():
        ident = "_" + ident
    if ident in _KEYWORDS or ident in _BUILTINS:
        ident += "_"
    base, k = ident, 2
    while ident in taken:
        ident, k = f"{base}_{k}", k + 1
    taken.add(ident)
    return ident


def _num(x) -> str:
    return repr(float(x))


def _nums(values) -> str:
    return ", ".join(map(repr, np.asarray(values, float).ravel().tolist()))


def _point(p) -> str:
    p = np.asarray(p, float)
    return f"uv({_nums(p)})" if p.shape[0] == 2 else f"pt({_nums(p)})"


def _net(rows: np.ndarray) -> str:
    """`net R x C [...]` (or `net N [...]`) of entries (..., width)."""
    shape = rows.shape[:-1]
    head = " x ".join(map(str, shape))
    body = ", ".join(" ".join(map(repr, e)) for e in rows.reshape(-1, rows.shape[-1]).tolist())
    return f"net {head} [{body}]"


class _Writer:
    def __init__(self, model):
        self.model = model
        self.taken: set = set()
        self.names: dict = {}       # id(obj) -> identifier of its binding
        self.lines: list = []
        self.by_name = {}
        for key, obj in model.objects.items():
            self.by_name[key] = obj

    def binding(self, key: str, obj) -> str:
        if id(obj) in self.names:
            return self.names[id(obj)]
        ident = identifier(key, self.taken)
        self.names[id(obj)] = ident      # reserve before the dependencies (no cycles in a model)
        expr = self.expr(obj, top=True)
        self.lines.append(f"{ident} := {expr};")
        return ident

    def ref(self, obj) -> str:
        """A nested object: its binding's name when it is (or is named like) a model binding, else inline."""
        if id(obj) in self.names:
            return self.names[id(obj)]
        name = getattr(obj, "name", None)
        if name and name in self.by_name and type(self.by_name[name]) is type(obj):
            return self.binding(name, self.by_name[name])
        return self.expr(obj)

    def expr(self, obj, top: bool = False) -> str:
        r = self.ref
        if isinstance(obj, Point):
            return _point(obj.xyz)
        if isinstance(obj, Vector):
            return f"vec({_nums(obj.xyz)})"
        if isinstance(obj, HPoint):
            return f"projPt({_nums(obj.xyz)}, {_num(obj.w)})"
        if isinstance(obj, Line):
            return f"{'uvline' if obj.dim == 2 else 'line'}({_point(obj.p0)}, {_point(obj.p1)})"
        if isinstance(obj, Polyline):
            return f"polyline([{', '.join(_point(p) for p in obj.points)}])"
        if isinstance(obj, CircularArc):   # the language's arc is the one through three points
            x, y = obj.frame
            at = lambda a: _point((np.concatenate([obj.center, [0.0]])[:3] + obj.radius * (  # noqa: E731
                np.cos(a) * x + np.sin(a) * y))[:obj.dim])
            if obj.sweep < 2 * np.pi:
                return f"arc({_point(obj.start_point)}, {at(0.5 * obj.sweep)}, {_point(obj.end_point)})"
            # a full turn from its start point (a loop piece where a circle would start elsewhere): two halves
            return f"profile(arc({_point(obj.start_point)}, {at(0.5 * np.pi)}, {at(np.pi)}), " \
                   f"arc({at(np.pi)}, {at(1.5 * np.pi)}, {_point(obj.start_point)}))"
        if isinstance(obj, Circle):
            if obj.dim == 2:  # the language's circle is 3-D: a parameter-space circle is its exact NURBS
                return self._bspline(obj.nurbs())
            return f"circle({_point(obj.center)}, {_num(obj.radius)}, normal: vec({_nums(obj.normal)}))"
        if isinstance(obj, BSplineCurve):
            return self._bspline(obj.curve)
        if isinstance(obj, CompositeCurve):
            return f"profile({', '.join(r(p) for p in obj.pieces)})"
        if isinstance(obj, IntersectionCurve):
            return f"intersect({r(obj.a)}, {r(obj.b)})"
        if isinstance(obj, Plane):
            if np.allclose(Plane(obj.origin, obj.normal).x_dir, obj.x_dir, rtol=0, atol=1e-14):
                return f"plane({_point(obj.origin)}, vec({_nums(obj.normal)}))"
            return self._bsurface(obj.nurbs(self._plane_size()))
        if isinstance(obj, BSplineSurface):
            return self._bsurface(obj.surface)
        if isinstance(obj, Revolution):
            axis = f"line({_point(obj.axis_point)}, {_point(obj.axis_point + obj.axis_dir)})"
            return f"revolve({r(obj.profile)}, {axis}, from: {_num(obj.start)}rad, to: {_num(obj.end)}rad)"
        if isinstance(obj, Extrusion):
            return f"extrude({r(obj.profile)}, vec({_nums(obj.direction)}))"
        if isinstance(obj, RuledSurface):
            return f"ruled({r(obj.a)}, {r(obj.b)})"
        if isinstance(obj, Loop):
            return f"loop({', '.join(r(p) for p in obj.pieces)})"
        if isinstance(obj, TrimmedFace):
            outer = r(obj.outer) if obj.outer is not None else self._domain_loop(obj.surface)
            holes = ", ".join(r(h) for h in obj.holes)
            return f"trim({r(obj.surface)}, outer: {outer}, holes: [{holes}])"
        if isinstance(obj, Shell):
            return f"shell([{', '.join(r(f) for f in obj.faces)}])"
        if isinstance(obj, (list, tuple)):
            return f"[{', '.join(r(x) if not isinstance(x, (int, float, str)) else _scalar(x) for x in obj)}]"
        raise BackendError(f"cannot write {type(obj).__name__} as .rgm source")

    def _plane_size(self) -> float:
        ext = [np.abs(np.asarray(o.xyz)).max() for o in self.model.objects.values() if hasattr(o, "xyz")]
        return 1e3 * max(ext + [1.0])

    def _domain_loop(self, surface) -> str:
        if isinstance(surface, Plane):
            raise BackendError("a trimmed plane needs an outer loop")
        (u0, u1), (v0, v1) = surface.domain
        c = [(u0, v0), (u1, v0), (u1, v1), (u0, v1), (u0, v0)]
        return "loop(" + ", ".join(f"uvline({_point(a)}, {_point(b)})" for a, b in zip(c, c[1:])) + ")"

    def _bspline(self, c) -> str:
        knots = f"knots([{_nums(c.knots)}])"
        if c.dim == 2:
            pts = ", ".join(_point(p) for p in c.ctrl)
            weights = f", weights: [{_nums(c.weights)}]" if c.is_rational else ""
            return f"bspline({c.degree}, {knots}, [{pts}]{weights})"
        ctrl = np.column_stack([c.ctrl, c.weights]) if c.is_rational else np.asarray(c.ctrl)
        return f"bspline({c.degree}, {knots}, {_net(ctrl)})"

    def _bsurface(self, s) -> str:
        net = np.concatenate([s.ctrl, s.weights[..., None]], axis=2) if s.is_rational else np.asarray(s.ctrl)
        return (f"bsurface(degree_u: {s.degree_u}, degree_v: {s.degree_v}, knots_u: knots([{_nums(s.knots_u)}]), "
                f"knots_v: knots([{_nums(s.knots_v)}]), net: {_net(net)})")


def _scalar(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return _num(value)


def model_to_rgm(model, header: str = "") -> str:
    """The `.rgm` text of `model` (all bindings, exports in order); `header` lines become comments."""
    w = _Writer(model)
    scalars = {**model.params, **{k: v for k, v in model.objects.items() if isinstance(v, (int, float, str))}}
    for key, value in scalars.items():  # parameters (and other number bindings) first
        ident = identifier(key, w.taken)
        w.lines.append(f"{'param ' if key in model.params else ''}{ident} := {_scalar(value)};")
    for key in model.exports:
        w.binding(key, model.objects[key])
    for key, obj in model.objects.items():
        if key not in scalars:
            w.binding(key, obj)
    out = [f"# {line}" if line else "#" for line in header.splitlines()]
    out += [f"units {model.units};", f"tolerance {_num(model.tolerance)};", ""]
    out += w.lines
    if model.exports:
        out += ["", "export " + ", ".join(w.names[id(model.objects[k])] for k in model.exports) + ";"]
    return "\n".join(out) + "\n"
