"""IGES → model objects: a tolerant reader for files from rgm and from other systems.

Supported entities: 100 arc/circle, 102 composite, 106 forms 11/12/13/63 (polylines), 108 form 0
(unbounded plane), 110 line (form 0), 112/114 parametric splines (exact B-splines), 116 point, 120 surface of revolution, 124 transformation (applied through DE field 7), 126 and 128
(rational B-splines; parameter sub-ranges are split off exactly), 142 curve on surface, 144 trimmed
surface, 186/514/510/508/504/502 and 190 (manifold solid B-rep → shell or revolution, `iges_brep_read`), 402
forms 1/7 (group → shell), 406 form 15 (names) and 314 (colour, read and ignored: the model has no
colours). Anything else is reported by type, form and DE number (`IgesImport.unsupported`);
entities whose data are invalid are reported with the reason (`IgesImport.problems`); nothing is
dropped silently. A malformed file raises IgesFormatError naming the record.

Roots (the model's exports) are the independent entities no other entity refers to. On a 120 the
IGES (u, v) is (profile parameter, angle), not the (u, v) of rgm's rational NURBS form, so loops of a
144 on a 120 are read from their model-space curves (or mapped to model space and fitted).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rgm.errors import GeometryError, RgmError
from rgm.model import (
    BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Line, Loop, Model, Plane, Point,
    Polyline, Revolution, Shell, TrimmedFace,
)

from .iges_brep_read import BREP_TYPES, BrepReading, circles_started_at_vertices, started_at_joins
from .iges_format import IgesFormatError
from .iges_parse import IgesData, parse_iges
from .iges_shapes import as_arc, as_plane, sub_curve, sub_surface

__all__ = ["IgesImport", "read_iges", "read_iges_file", "SUPPORTED"]

SUPPORTED = {0, 100, 102, 106, 108, 110, 112, 114, 116, 120, 124, 126, 128, 142, 144, 314, 402, 406} | BREP_TYPES
_NOT_OBJECTS = {0, 124, 314, 406, 502, 504, 508}
#: unit lengths in mm of IGES units the language does not have (converted to mm on import)
_TO_MM = {"ft": 304.8, "mi": 1609344.0, "km": 1e6, "mil": 0.0254, "um": 1e-3, "uin": 2.54e-5}


#: what inconsistent entity data can raise while model objects are built from it
_DATA_ERRORS = (RgmError, ValueError, IndexError, ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError,
                RecursionError)


class _Skip(Exception):
    """An entity that cannot become a model object (unsupported or invalid); already reported."""


@dataclass
class IgesImport:
    """Result of reading an IGES file: the model, and what could not be imported."""

    model: Model
    unsupported: list = field(default_factory=list)   # (type, form, DE) of unsupported entities
    problems: list = field(default_factory=list)      # "entity ... at DE n: reason"
    notes: list = field(default_factory=list)         # adjustments made (e.g. a looser tolerance)

    @property
    def ok(self) -> bool:
        return not self.unsupported and not self.problems

    def messages(self) -> list[str]:
        """One line per unsupported entity and per invalid entity."""
        out = [f"unsupported IGES entity {t} (form {f}) at DE {de}" for t, f, de in self.unsupported]
        return out + self.problems + self.notes


class _Reader(BrepReading):
    def __init__(self, data: IgesData):
        self.d = data
        self.memo: dict = {}
        self.unsupported: dict = {}
        self.problems: dict = {}
        self.named: list = []
        self.tol = data.global_section.resolution if data.global_section.resolution > 0 else 1e-6

    # -- structure ---------------------------------------------------------------------------
    def own_count(self, de: int) -> int | None:
        """Number of an entity's own parameters (after the type), so trailing property pointers can be
        found; None when unknown."""
        d, t = self.d, self.d.entries[de].type
        fixed = {100: 7, 110: 6, 116: 4, 120: 4, 124: 12, 142: 5, 314: 4}
        if t in fixed:
            return fixed[t]
        if t in BREP_TYPES:
            return self.brep_own_count(de, t)
        if t == 112:
            return 4 + (d.int(de, 4) + 1) * 13
        if t == 114:
            m, n = d.int(de, 3), d.int(de, 4)
            return 4 + (m + 1) + (n + 1) + 48 * (m + 1) * (n + 1)
        if t in (102, 402):
            return 1 + d.int(de, 1)
        if t == 144:
            return 4 + d.int(de, 3)
        if t == 106:
            ip, n = d.int(de, 1), d.int(de, 2)
            return 2 + {1: 1 + 2 * n, 2: 3 * n, 3: 6 * n}.get(ip, 0)
        if t == 126:
            k, m = d.int(de, 1), d.int(de, 2)
            return 6 + (k + m + 2) + (k + 1) * 4 + 5
        if t == 128:
            k1, k2, m1, m2 = d.ints(de, 1, 4)
            return 9 + (k1 + m1 + 2) + (k2 + m2 + 2) + 4 * (k1 + 1) * (k2 + 1) + 4
        return None

    def children(self, de: int) -> list[int]:
        d, e = self.d, self.d.entries[de]
        try:
            out = [e.transform] if e.transform > 0 else []
            if e.type in (102, 402):
                out += d.ints(de, 2, d.int(de, 1))
            elif e.type == 120:
                out += d.ints(de, 1, 2)
            elif e.type == 142:
                out += d.ints(de, 2, 3)
            elif e.type == 144:
                out += [d.int(de, 1), d.int(de, 4)] + d.ints(de, 5, d.int(de, 3))
            elif e.type in BREP_TYPES:
                out += self.brep_children(de, e.type)
        except IgesFormatError:
            return []
        return [c for c in out if c > 0]

    def name(self, de: int) -> str | None:
        """The 406 form 15 name among the entity's property pointers, else the DE label."""
        d = self.d
        try:
            own = self.own_count(de)
        except IgesFormatError:
            own = None
        toks = d.params[de]
        if own is not None and len(toks) > own + 1:
            try:
                nv = d.int(de, own + 1)
                np_ = d.int(de, own + 2 + nv)
                for ptr in d.ints(de, own + 3 + nv, np_):
                    p = d.entries.get(ptr)
                    if p is not None and p.type == 406 and p.form == 15:
                        return d.string(ptr, 2).strip() or None
            except IgesFormatError:
                pass
        return d.entries[de].label or None

    def roots(self) -> list[int]:
        referenced = set()
        for de in self.d.entries:
            referenced.update(self.children(de))
        return [de for de, e in self.d.entries.items()
                if e.subordinate == 0 and de not in referenced and e.type not in _NOT_OBJECTS
                and not (e.type in (402,) and e.form not in (1, 7))]

    # -- conversion --------------------------------------------------------------------------
    def get(self, de: int, dim: int = 3):
        """The model object of entity `de` (2-D in parameter space when dim == 2); _Skip if none."""
        key = (de, dim)
        if key in self.memo:
            obj = self.memo[key]
            if obj is None:
                raise _Skip
            return obj
        e = self.d.entries.get(de)
        if e is None:
            self.memo[key] = None
            self.problems[de] = f"pointer to DE {de}, which is not an entity"
            raise _Skip
        if e.type not in SUPPORTED or e.type in _NOT_OBJECTS:
            self.unsupported[de] = (e.type, e.form, de)
            self.memo[key] = None
            raise _Skip
        try:
            obj = getattr(self, f"_e{e.type}")(de, dim)
            if e.transform > 0:
                obj = obj.transform(self.matrix(e.transform))
            name = self.name(de)
            if name:
                obj = obj.named(name)
                self.named.append(obj)
        except _Skip:
            self.memo[key] = None
            raise
        except _DATA_ERRORS as exc:
            self.problems[de] = f"{e.where()}: {exc or type(exc).__name__}"
            self.memo[key] = None
            raise _Skip from None
        self.memo[key] = obj
        return obj

    def matrix(self, de: int) -> np.ndarray:
        e = self.d.entries.get(de)
        if e is None or e.type != 124:
            raise GeometryError(f"transformation pointer {de} is not a 124 entity")
        if e.form not in (0, 1):
            raise GeometryError(f"124 form {e.form} (a FEM coordinate system) is not supported")
        m = np.eye(4)
        m[:3, :] = self.d.reals(de, 1, 12).reshape(3, 4)
        if e.transform > 0:
            m = self.matrix(e.transform) @ m
        return m

    def _e116(self, de, dim):
        return Point(self.d.reals(de, 1, 3)[:dim])

    def _e110(self, de, dim):
        if self.d.entries[de].form != 0:
            self.unsupported[de] = (110, self.d.entries[de].form, de)
            raise _Skip
        p = self.d.reals(de, 1, 6).reshape(2, 3)
        return Line(p[0, :dim], p[1, :dim])

    def _e100(self, de, dim):
        zt, cx, cy, sx, sy, ex, ey = self.d.reals(de, 1, 7)
        c = np.array([cx, cy, zt])[:dim]
        s = np.array([sx, sy, zt])[:dim]
        e = np.array([ex, ey, zt])[:dim]
        radius = float(np.linalg.norm(s - c))
        if np.array_equal(s, e):   # a full circle: in a loop, it starts where its neighbours join it
            return Circle(c, [0.0, 0.0, 1.0], radius)
        return CircularArc(c, [0.0, 0.0, 1.0], radius, s, e)

    def _e102(self, de, dim):
        members = [self.get(m, dim) for m in self.d.ints(de, 2, self.d.int(de, 1))]
        curves = tuple(m for m in members if not isinstance(m, Point))  # 116 members only mark joints
        if not curves:
            raise GeometryError("composite curve with no curve members")
        return CompositeCurve(curves)

    def _e106(self, de, dim):
        e, d = self.d.entries[de], self.d
        if e.form not in (11, 12, 13, 63):
            self.unsupported[de] = (106, e.form, de)
            raise _Skip
        ip, n = d.int(de, 1), d.int(de, 2)
        if ip == 1:
            zt = d.real(de, 3)
            xy = d.reals(de, 4, 2 * n).reshape(n, 2)
            pts = np.column_stack([xy, np.full(n, zt)])
        else:
            pts = d.reals(de, 3, (3 if ip == 2 else 6) * n).reshape(n, -1)[:, :3]
        if e.form == 63 and not np.array_equal(pts[0], pts[-1]):
            pts = np.vstack([pts, pts[:1]])
        return Polyline(pts[:, :dim])

    def _e126(self, de, dim):
        from rgm.geometry import NurbsCurve

        d = self.d
        k, m, _planar, _closed, poly, _periodic = d.ints(de, 1, 6)
        n = k + 1
        vals = d.reals(de, 7, (k + m + 2) + 4 * n + 2)
        knots = vals[:k + m + 2]
        w = vals[k + m + 2:k + m + 2 + n]
        ctrl = vals[k + m + 2 + n:k + m + 2 + 4 * n].reshape(n, 3)[:, :dim]
        v0, v1 = vals[-2:]
        curve = sub_curve(NurbsCurve(m, knots, ctrl, None if poly == 1 else w), v0, v1)
        arc = as_arc(curve) if self.d.entries[de].form == 2 else None
        return arc if arc is not None else BSplineCurve(curve)

    def _e128(self, de, dim):
        from rgm.geometry import NurbsSurface

        d = self.d
        k1, k2, m1, m2, _c1, _c2, poly, _p1, _p2 = d.ints(de, 1, 9)
        nu, nv = k1 + 1, k2 + 1
        nk1, nk2 = k1 + m1 + 2, k2 + m2 + 2
        vals = d.reals(de, 10, nk1 + nk2 + 4 * nu * nv + 4)
        ku, kv = vals[:nk1], vals[nk1:nk1 + nk2]
        o = nk1 + nk2
        w = vals[o:o + nu * nv].reshape(nv, nu).T
        ctrl = vals[o + nu * nv:o + 4 * nu * nv].reshape(nv, nu, 3).transpose(1, 0, 2)
        u0, u1, v0, v1 = vals[-4:]
        s = sub_surface(NurbsSurface(m1, m2, ku, kv, ctrl, None if poly == 1 else w), u0, u1, v0, v1)
        if self.d.entries[de].form == 1:
            plane = as_plane(s)
            if plane is not None:
                return plane
        return BSplineSurface(s)

    def _e108(self, de, dim):
        """Unbounded plane (form 0) A x + B y + C z = D, origin at the display point's projection."""
        e = self.d.entries[de]
        if e.form != 0:
            self.unsupported[de] = (108, e.form, de)
            raise _Skip
        a, b, c, dd = self.d.reals(de, 1, 4)
        n = np.array([a, b, c])
        nn = float(n @ n)
        if not nn > 0:
            raise GeometryError("plane with a zero normal")
        p = np.array([self.d.real(de, 6), self.d.real(de, 7), self.d.real(de, 8)])
        origin = p - ((n @ p - dd) / nn) * n
        return Plane(origin, n)

    def _e112(self, de, dim):
        """Parametric spline curve: N cubic segments between N+1 breakpoints (exact B-spline)."""
        from .iges_legacy import spline_curve

        n = self.d.int(de, 4)
        breaks = self.d.reals(de, 5, n + 1)
        coef = self.d.reals(de, 6 + n, 12 * n).reshape(n, 3, 4)
        return BSplineCurve(spline_curve(breaks, coef, dim))

    def _e114(self, de, dim):
        """Parametric spline surface: M x N bicubic patches (exact B-spline surface)."""
        from .iges_legacy import spline_surface

        m, n = self.d.int(de, 3), self.d.int(de, 4)
        tu = self.d.reals(de, 5, m + 1)
        tv = self.d.reals(de, 6 + m, n + 1)
        sets = self.d.reals(de, 7 + m + n, 48 * (m + 1) * (n + 1)).reshape(m + 1, n + 1, 3, 16)
        return BSplineSurface(spline_surface(tu, tv, sets[:m, :n]))

    def _e120(self, de, dim):
        axis_de, gen_de = self.d.ints(de, 1, 2)
        sa, ta = self.d.real(de, 3), self.d.real(de, 4)
        axis = self.get(axis_de)
        if not isinstance(axis, Line):
            raise GeometryError(f"the axis (DE {axis_de}) of a surface of revolution must be a line (110)")
        return Revolution(self.get(gen_de), axis.p0, axis.p1 - axis.p0, sa, ta)

    def _e142(self, de, dim):
        """A 142 on its own (a root): its model-space curve."""
        pieces = self.loop_pieces(de, self.get(self.d.int(de, 2)))
        return pieces[0] if len(pieces) == 1 else CompositeCurve(tuple(pieces))

    def loop_pieces(self, de: int, surface) -> list:
        """Pieces of the loop a 142 describes, in the parameter space of the model `surface` when its
        (u, v) are IGES's, otherwise in model space."""
        d = self.d
        if d.entries[de].type != 142:
            raise GeometryError(f"a trimmed surface's boundary (DE {de}) must be a 142 curve on a surface")
        _crtn, _s, bptr, cptr, pref = d.ints(de, 1, 5)
        revolution = isinstance(surface, Revolution)
        use_2d = bptr > 0 and not (revolution or (pref == 2 and cptr > 0) or (cptr > 0 and self._failed(bptr, 2)))
        if use_2d:
            return self._members(bptr, 2)
        if cptr > 0:
            return self._members(cptr, 3)
        if revolution and bptr > 0:
            return [self._revolution_curve(surface, p) for p in self._members(bptr, 2)]
        raise GeometryError("curve on a surface with neither a parameter-space nor a model-space curve")

    def _failed(self, de, dim) -> bool:
        try:
            self.get(de, dim)
        except _Skip:
            return True
        return False

    def _members(self, de: int, dim: int) -> list:
        if self.d.entries[de].type == 102 and self.d.entries[de].transform == 0:
            return [self.get(m, dim) for m in self.d.ints(de, 2, self.d.int(de, 1))]
        return [self.get(de, dim)]

    def _revolution_curve(self, rev: Revolution, uv_curve):
        """Model-space curve of an IGES (profile parameter, angle) curve on a 120, fitted at tolerance."""
        from rgm.geometry.revolve import evaluate_revolution

        from .iges_curves import fit_parametric

        b = uv_curve.nurbs()
        prof = rev.profile.nurbs()

        def func(t):
            p = b.evaluate(t)
            return evaluate_revolution(prof, rev.axis_point, rev.axis_dir, p[:, 1], p[:, 0])

        return BSplineCurve(fit_parametric(func, np.unique(b.knots[b.degree:b.n + 1]), self.tol))

    def _e144(self, de, dim):
        d = self.d
        pts, n1, n2, pto = d.ints(de, 1, 4)
        surface = self.get(pts)
        outer = Loop(started_at_joins(self.loop_pieces(pto, surface)), name=self.name(pto)) if n1 and pto > 0 else None
        holes = tuple(Loop(started_at_joins(self.loop_pieces(h, surface)), name=self.name(h)) for h in d.ints(de, 5, n2))
        return TrimmedFace(surface, outer, holes)

    def _e402(self, de, dim):
        e = self.d.entries[de]
        if e.form not in (1, 7):
            self.unsupported[de] = (402, e.form, de)
            raise _Skip
        return Shell(circles_started_at_vertices([self.get(m) for m in self.d.ints(de, 2, self.d.int(de, 1))], self.tol))


def read_iges(text: str, source: str | None = None) -> IgesImport:
    """Read IGES text into an `IgesImport` (model + unsupported entities + problems)."""
    data = parse_iges(text)
    g = data.global_section
    reader = _Reader(data)
    units = g.units or "mm"
    objects: dict = {}
    exports = []
    kinds = {100: "curve", 102: "curve", 106: "curve", 110: "curve", 112: "curve", 126: "curve", 142: "curve",
             116: "point", 108: "plane", 114: "surface", 120: "surface", 128: "surface", 144: "face", 402: "shell",
             186: "solid", 510: "face", 514: "shell"}
    for de in reader.roots():
        e = data.entries[de]
        try:
            obj = reader.get(de, 2 if e.use == 5 else 3)
        except _Skip:
            continue
        name = obj.name
        if not name or name in objects:
            name = f"{kinds.get(e.type, 'object')}{de}" if not name else f"{name}_{de}"
            obj = obj.named(name)
        objects[name] = obj
        exports.append(name)
    for obj in reader.named:
        objects.setdefault(obj.name, obj)
    if units in _TO_MM:
        m = np.diag([_TO_MM[units]] * 3 + [1.0])
        objects = {k: v.transform(m) for k, v in objects.items()}
        units, reader.tol = "mm", reader.tol * _TO_MM[units]
    notes = []
    gap = _loop_gap(objects.values(), reader.tol)
    if gap > reader.tol:
        notes.append(f"model-space trimming curves lie up to {gap:.3g} from their surfaces, more than the "
                     f"file's resolution {reader.tol:g}; the model tolerance is set to {2 * gap:.3g}")
        reader.tol = 2 * gap
    model = Model(units, reader.tol, objects, tuple(exports), {}, source)
    return IgesImport(model, sorted(reader.unsupported.values(), key=lambda t: t[2]),
                      [reader.problems[k] for k in sorted(reader.problems)], notes)


def _loop_gap(objects, tol: float) -> float:
    """Largest distance (model units) from a model-space loop piece to its face's surface, over the
    trimmed faces among `objects` (shells included), exact where it exceeds `tol` (the model's check,
    `rgm.model.validate.distances_to_surface`: a local bound, the global search only past `tol`)."""
    from rgm.model.validate import distances_to_surface

    gap = 0.0
    for obj in objects:
        for face in obj.faces if isinstance(obj, Shell) else [obj]:
            if not isinstance(face, TrimmedFace) or isinstance(face.surface, Plane):
                continue
            curves = []
            for piece in (p for loop in face.loops() for p in loop.pieces if p.dim == 3):
                for p in piece.pieces if isinstance(piece, CompositeCurve) else (piece,):
                    try:
                        curves.append(p.nurbs())
                    except _DATA_ERRORS:  # a degenerate piece: the compiler's checks will name it
                        continue
            try:
                gap = max([gap] + [float(d.max()) for d in distances_to_surface(face.surface, curves, tol)])
            except _DATA_ERRORS:
                continue
    return gap


def read_iges_file(path) -> IgesImport:
    """Read an IGES file; IgesFormatError (naming the file and record) if it is malformed or unreadable."""
    path = Path(path)
    try:
        text = path.read_bytes().decode("latin-1")
    except OSError as exc:
        raise IgesFormatError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        return read_iges(text, str(path))
    except IgesFormatError as exc:
        raise IgesFormatError(f"{path}: {exc}") from None
    except RgmError as exc:
        raise IgesFormatError(f"{path}: {exc}") from None
