"""Alpha_1-style procedural text (`rgmc compile -t alpha1`) and its reader.

The style is that of the paper's Figure 7 (RLISP-era shape_edit): one statement a line, each model
binding a named step `name := ...;`, control points as their own statements
`p12 := projPt(x, y, z, w);` and B-splines as `curve(parminfo(cubic, ec_open, knots(...)), list(...))`.
The mapping table is in docs/backends.md. Conventions:

- points are Euclidean x, y, z plus a weight w (rgm's convention; Alpha_1's own P3 points were
  homogeneous, see the research notes §1.3), `pt(x, y)` / `projPt(u, v, w)` in parameter space;
- orders are named as in Alpha_1 (linear = 2 ... quintic = 6, else `order(k)`), order = degree + 1;
  knot vectors are written in full; the first `parminfo` of a surface is for the mesh rows (u);
- angles are radians, lengths model units; numbers are Python's shortest round-trip `repr`;
- objects used twice, and B-splines without a binding name, get generated names starting with
  `_anon`; the reader drops those names, so model → text → model gives back the same model.

`read_alpha1` reads exactly this subset (plus `#` comments) and raises Alpha1Error with the line.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from rgm.errors import BackendError
from rgm.model import (
    BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, HPoint, IntersectionCurve, Line,
    Loop, Model, Plane, Point, Polyline, Revolution, RuledSurface, Shell, Transform, TrimmedFace, Vector,
)



def identifier(name: str, taken: set) -> str:
    """A valid, unused identifier of the text made from `name` (added to `taken`); the subset's
    reserved words (nil, ec_open, the order names, units, tolerance) get a trailing `_`."""
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name.strip()) or "object"
    if ident[0].isdigit():
        ident = "_" + ident
    if ident in RESERVED:
        ident += "_"
    base, k = ident, 2
    while ident in taken:
        ident, k = f"{base}_{k}", k + 1
    taken.add(ident)
    return ident

__all__ = ["write_alpha1", "alpha1_text", "read_alpha1", "Alpha1Error"]

ORDERS = {2: "linear", 3: "quadratic", 4: "cubic", 5: "quartic", 6: "quintic"}
_ORDER_OF = {v: k for k, v in ORDERS.items()}
_ANON = "_anon"
RESERVED = {"nil", "ec_open", "units", "tolerance", "export", *ORDERS.values()}


class Alpha1Error(BackendError):
    """Alpha_1 text outside the subset rgm reads; the message names the line."""


def _n(x) -> str:
    return repr(float(x))


def _ns(values) -> str:
    return ", ".join(map(repr, np.asarray(values, float).ravel().tolist()))


def _pt(p) -> str:
    return f"pt({_ns(p)})"


def _vec(v) -> str:
    return f"vec({_ns(v)})"


class _Writer:
    def __init__(self, model):
        self.model = model
        self.lines: list = []
        self.names: dict = {}          # id(obj) -> statement name
        self.taken: set = set()
        self.anon = 0
        self.uses: dict = {}
        for obj in model.objects.values():
            self._count(obj)

    def _count(self, obj):
        """Reference counts by identity, so that an object used twice gets one named statement."""
        key = id(obj)
        self.uses[key] = self.uses.get(key, 0) + 1
        if self.uses[key] > 1:
            return
        for child in _children(obj):
            self._count(child)

    def _fresh(self, base: str | None) -> str:
        if base:
            return identifier(base, self.taken)
        self.anon += 1
        return identifier(f"{_ANON}{self.anon}", self.taken)

    def statement(self, name: str | None, obj) -> str:
        if id(obj) in self.names:
            return self.names[id(obj)]
        ident = self._fresh(name)
        self.names[id(obj)] = ident
        expr = self.expr(obj, ident)
        self.lines.append(f"{ident} := {expr};")
        return ident

    def ref(self, obj) -> str:
        if isinstance(obj, (int, float, str)):
            return _scalar(obj)
        if id(obj) in self.names:
            return self.names[id(obj)]
        name = getattr(obj, "name", None)
        if name and self.model.objects.get(name) is obj:
            return self.statement(name, obj)
        if self.uses.get(id(obj), 0) > 1 or isinstance(obj, (BSplineCurve, BSplineSurface)) or name:
            return self.statement(name, obj)
        return self.expr(obj, None)

    def _points(self, owner: str, ctrl, weights, rational: bool) -> list[str]:
        names = []
        for i, p in enumerate(np.asarray(ctrl, float)):
            n = identifier(f"{owner}_p{i + 1}", self.taken)
            body = f"projPt({_ns(p)}, {_n(weights[i])})" if rational else f"pt({_ns(p)})"
            self.lines.append(f"{n} := {body};")
            names.append(n)
        return names

    def expr(self, obj, ident: str | None) -> str:
        r = self.ref
        if isinstance(obj, (list, tuple)):
            return f"list({', '.join(r(x) for x in obj)})"
        if isinstance(obj, Point):
            return _pt(obj.xyz)
        if isinstance(obj, Vector):
            return _vec(obj.xyz)
        if isinstance(obj, HPoint):
            return f"projPt({_ns(obj.xyz)}, {_n(obj.w)})"
        if isinstance(obj, Line):
            return f"line({_pt(obj.p0)}, {_pt(obj.p1)})"
        if isinstance(obj, Polyline):
            return f"polyline(list({', '.join(_pt(p) for p in obj.points)}))"
        if isinstance(obj, CircularArc):
            return (f"arc({_pt(obj.center)}, {_vec(obj.normal)}, {_n(obj.radius)}, {_pt(obj.start_point)}, "
                    f"{_pt(obj.end_point)})")
        if isinstance(obj, Circle):
            return f"circle({_pt(obj.center)}, {_vec(obj.normal)}, {_n(obj.radius)})"
        if isinstance(obj, BSplineCurve):
            c = obj.curve
            w = c.weights if c.is_rational else None
            pts = self._points(ident, c.ctrl, w, c.is_rational)
            return f"curve({_parminfo(c.degree, c.knots)}, list({', '.join(pts)}))"
        if isinstance(obj, BSplineSurface):
            s = obj.surface
            rows = []
            for i in range(s.nu):
                w = s.weights[i] if s.is_rational else None
                pts = self._points(f"{ident}_{i + 1}", s.ctrl[i], w, s.is_rational)
                rows.append(f"list({', '.join(pts)})")
            return (f"surface({_parminfo(s.degree_u, s.knots_u)}, {_parminfo(s.degree_v, s.knots_v)}, "
                    f"list({', '.join(rows)}))")
        if isinstance(obj, CompositeCurve):
            return f"profile({', '.join(r(p) for p in obj.pieces)})"
        if isinstance(obj, IntersectionCurve):
            tol = "nil" if obj.tolerance is None else _n(obj.tolerance)
            return f"srfIntersect({r(obj.a)}, {r(obj.b)}, {tol})"
        if isinstance(obj, Plane):
            return f"plane({_pt(obj.origin)}, {_vec(obj.normal)}, {_vec(obj.x_dir)})"
        if isinstance(obj, Revolution):
            return (f"surfRev({r(obj.profile)}, {_pt(obj.axis_point)}, {_vec(obj.axis_dir)}, {_n(obj.start)}, "
                    f"{_n(obj.end)})")
        if isinstance(obj, Extrusion):
            return f"extrude({r(obj.profile)}, {_vec(obj.direction)})"
        if isinstance(obj, RuledSurface):
            return f"ruled({r(obj.a)}, {r(obj.b)})"
        if isinstance(obj, Loop):
            return f"loop({', '.join(r(p) for p in obj.pieces)})"
        if isinstance(obj, TrimmedFace):
            outer = "nil" if obj.outer is None else r(obj.outer)
            return f"trim({r(obj.surface)}, {outer}, list({', '.join(r(h) for h in obj.holes)}))"
        if isinstance(obj, Shell):
            return f"shell(list({', '.join(r(f) for f in obj.faces)}))"
        raise BackendError(f"Alpha_1 text: cannot write {type(obj).__name__}")


def _scalar(value) -> str:
    if isinstance(value, str):
        return '"' + value.replace('"', "'") + '"'
    return _n(value)


def _parminfo(degree: int, knots) -> str:
    order = ORDERS.get(degree + 1, f"order({degree + 1})")
    return f"parminfo({order}, ec_open, knots({_ns(knots)}))"


def _children(obj) -> list:
    if isinstance(obj, (CompositeCurve, Loop)):
        return list(obj.pieces)
    if isinstance(obj, IntersectionCurve):
        return [obj.a, obj.b]
    if isinstance(obj, (Revolution, Extrusion)):
        return [obj.profile]
    if isinstance(obj, RuledSurface):
        return [obj.a, obj.b]
    if isinstance(obj, TrimmedFace):
        return [obj.surface] + list(obj.loops())
    if isinstance(obj, Shell):
        return list(obj.faces)
    return []


def alpha1_text(model) -> str:
    """The Alpha_1-style text of every binding of `model` (dependencies first), then its exports."""
    w = _Writer(model)
    scalars = {**model.params, **{k: v for k, v in model.objects.items() if isinstance(v, (int, float, str))}}
    for key, value in scalars.items():  # parameters and other number bindings first
        body = f"param({_n(value)})" if key in model.params else _scalar(value)
        w.lines.append(f"{identifier(key, w.taken)} := {body};")
    for key in model.exports:
        w.statement(key, model.objects[key])
    for key, obj in model.objects.items():   # transform values are not geometry: place() baked them in
        if id(obj) not in w.names and key not in scalars and not isinstance(obj, Transform):
            w.statement(key, obj)
    src = f" from {Path(model.source).name}" if model.source else ""
    head = [f"# Alpha_1 shape_edit procedure written by rgm{src}", f'units := "{model.units}";',
            f"tolerance := {_n(model.tolerance)};"]
    tail = [f"export({', '.join(w.names[id(model.objects[k])] for k in model.exports)});"] if model.exports else []
    return "\n".join(head + w.lines + tail) + "\n"


def write_alpha1(model, path, **ignored) -> Path:
    """Write `model` as Alpha_1-style text to `path` atomically."""
    from rgm.atomic import write_atomic

    return write_atomic(path, alpha1_text(model))


# --- reader --------------------------------------------------------------------------------------

_TOKEN = re.compile(r"\s*(?:(#[^\n]*)|(:=)|([A-Za-z_][A-Za-z0-9_]*)|"
                    r"(-?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)|(\"[^\"\n]*\")|([(),;]))")


def _tokens(text: str):
    pos, line = 0, 1
    while True:
        m = _TOKEN.match(text, pos)
        if m is None:
            rest = text[pos:].lstrip()
            if not rest:
                return
            line += text[pos:len(text) - len(rest)].count("\n")
            raise Alpha1Error(f"line {line}: unexpected `{rest[:20].splitlines()[0]}`")
        line += text[pos:m.start(m.lastindex)].count("\n")
        pos = m.end()
        kind = m.lastindex
        if kind == 1:
            continue
        yield kind, m.group(kind), line


class _Parser:
    def __init__(self, text: str):
        self.toks = list(_tokens(text))
        self.i = 0

    def peek(self):
        return self.toks[self.i] if self.i < len(self.toks) else (0, "<end>", self.toks[-1][2] if self.toks else 1)

    def take(self, value=None):
        tok = self.peek()
        if tok[0] == 0 or (value is not None and tok[1] != value):
            raise Alpha1Error(f"line {tok[2]}: expected `{value or 'a value'}`, found `{tok[1]}`")
        self.i += 1
        return tok

    def statements(self):
        while self.i < len(self.toks):
            kind, value, line = self.take()
            if kind != 3:
                raise Alpha1Error(f"line {line}: a statement starts with a name, not `{value}`")
            if self.peek()[1] == "(":
                yield None, self.call(value, line), line
            else:
                self.take(":=")
                yield value, self.expr(), line
            self.take(";")

    def expr(self):
        kind, value, line = self.take()
        if kind == 4:
            return ("num", float(value), line)
        if kind == 5:
            return ("str", value[1:-1], line)
        if kind == 3:
            if self.peek()[1] == "(":
                return self.call(value, line)
            return ("name", value, line)
        raise Alpha1Error(f"line {line}: unexpected `{value}`")

    def call(self, name, line):
        self.take("(")
        args = []
        while self.peek()[1] != ")":
            args.append(self.expr())
            if self.peek()[1] != ")":
                self.take(",")
        self.take(")")
        return ("call", name, line, args)


class _Param(float):
    """`param(x)`: a number binding that is one of the model's parameters."""


class _UVW:
    """`projPt(u, v, w)`: a weighted control point of a parameter-space curve (not a model object)."""

    def __init__(self, uv, w):
        self.xyz, self.w = uv, w


class _Eval:
    def __init__(self):
        self.env: dict = {"nil": None, "ec_open": "ec_open", **{v: k for k, v in ORDERS.items()}}
        self.helpers: set = set()     # ids of points used as control points

    def __call__(self, node):
        kind = node[0]
        if kind in ("num", "str"):
            return node[1]
        if kind == "name":
            if node[1] not in self.env:
                raise Alpha1Error(f"line {node[2]}: `{node[1]}` is not defined")
            return self.env[node[1]]
        _k, name, line, args = node
        values = [self(a) for a in args]
        fn = getattr(self, f"f_{name}", None)
        if fn is None:
            raise Alpha1Error(f"line {line}: `{name}` is not part of the Alpha_1 subset rgm reads")
        try:
            return fn(*values)
        except TypeError:
            raise Alpha1Error(f"line {line}: wrong arguments to `{name}`") from None
        except (BackendError, ValueError) as exc:
            raise Alpha1Error(f"line {line}: {exc}") from None
        except Exception as exc:  # geometry validation (GeometryError) and shape errors
            raise Alpha1Error(f"line {line}: {name}: {exc}") from None

    # constructors of the subset
    def f_pt(self, *xyz):
        return Point(xyz)

    def f_vec(self, x, y, z):
        return Vector([x, y, z])

    def f_projPt(self, *args):
        if len(args) == 3:  # a weighted parameter-space point
            return _UVW(np.array(args[:2], float), float(args[2]))
        return HPoint(args[:3], args[3])

    def f_param(self, value):
        return _Param(float(value))

    def f_list(self, *items):
        return list(items)

    def f_knots(self, *values):
        return np.array(values, float)

    def f_order(self, k):
        return int(k)

    def f_parminfo(self, order, end_condition, knots):
        if end_condition != "ec_open":
            raise ValueError(f"end condition {end_condition} is not supported (only ec_open)")
        return int(order) - 1, knots

    def _ctrl(self, pts):
        self.helpers.update(id(p) for p in pts)
        if isinstance(pts[0], (HPoint, _UVW)):
            return np.array([p.xyz for p in pts]), np.array([p.w for p in pts])
        return np.array([p.xyz for p in pts]), None

    def f_curve(self, parminfo, pts):
        from rgm.geometry import NurbsCurve

        ctrl, w = self._ctrl(pts)
        return BSplineCurve(NurbsCurve(parminfo[0], parminfo[1], ctrl, w))

    def f_surface(self, pu, pv, rows):
        from rgm.geometry import NurbsSurface

        grid = [self._ctrl(row) for row in rows]
        ctrl = np.stack([g[0] for g in grid])
        w = None if grid[0][1] is None else np.stack([g[1] for g in grid])
        return BSplineSurface(NurbsSurface(pu[0], pv[0], pu[1], pv[1], ctrl, w))

    def f_line(self, a, b):
        return Line(a.xyz, b.xyz)

    def f_polyline(self, pts):
        return Polyline([p.xyz for p in pts])

    def f_arc(self, center, normal, radius, start, end):
        return CircularArc(center.xyz, normal.xyz, radius, start.xyz, end.xyz)

    def f_circle(self, center, normal, radius):
        return Circle(center.xyz, normal.xyz, radius)

    def f_profile(self, *pieces):
        return CompositeCurve(tuple(pieces))

    def f_srfIntersect(self, a, b, tol):
        return IntersectionCurve(a, b, tol)

    def f_plane(self, origin, normal, x_dir):
        return Plane(origin.xyz, normal.xyz, x_dir.xyz)

    def f_surfRev(self, profile, point, axis, start, end):
        return Revolution(profile, point.xyz, axis.xyz, start, end)

    def f_extrude(self, profile, direction):
        return Extrusion(profile, direction.xyz)

    def f_ruled(self, a, b):
        return RuledSurface(a, b)

    def f_loop(self, *pieces):
        return Loop(tuple(pieces))

    def f_trim(self, surface, outer, holes):
        return TrimmedFace(surface, outer, tuple(holes))

    def f_shell(self, faces):
        return Shell(tuple(faces))


def read_alpha1(text: str, source: str | None = None) -> Model:
    """The model of Alpha_1-style text written by `alpha1_text` (Alpha1Error naming the line otherwise)."""
    ev = _Eval()
    objects, params, exports = {}, {}, ()
    units, tolerance = "mm", None
    for name, node, line in _Parser(text).statements():
        if name is None:
            if node[1] != "export":
                raise Alpha1Error(f"line {line}: only `export(...)` may stand alone")
            exports = tuple(a[1] for a in node[3])
            continue
        value = ev(node)
        if name in ("units", "tolerance"):
            units, tolerance = (value, tolerance) if name == "units" else (units, float(value))
            continue
        if isinstance(value, _Param):
            value = params[name] = float(value)
        if hasattr(value, "named"):
            value = value.named(None if name.startswith(_ANON) else name)
        ev.env[name] = value
        objects[name] = value
    for name in exports:
        if name not in objects:
            raise Alpha1Error(f"export of `{name}`, which is not defined")
    objects = {k: v for k, v in objects.items()
               if not k.startswith(_ANON) and id(v) not in ev.helpers and not isinstance(v, _UVW)}
    if tolerance is None:
        raise Alpha1Error("the text sets no `tolerance`")
    return Model(units, tolerance, objects, exports, params, source)

