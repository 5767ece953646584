"""IGES 5.3 writer: the evaluated model lowered to IGES entities (`rgmc compile -t iges`).

Mapping (docs/backends.md has the full table and the options):

| model                         | IGES                                                            |
|-------------------------------|-----------------------------------------------------------------|
| Line                          | 110                                                             |
| Polyline                      | 106 form 12 (3-D) / form 11 (parameter space)                   |
| CircularArc, Circle           | 100, placed by a 124 when not in the XY plane (exact frame)     |
| BSplineCurve                  | 126 (form 0)                                                    |
| CompositeCurve                | 102 of its (flattened) pieces, physically dependent             |
| IntersectionCurve             | 126, approximated here at the file's tolerance (and only here)  |
| BSplineSurface, Extrusion, RuledSurface | 128 of the exact NURBS form                           |
| Plane                         | 128 form 1, bilinear, parameters = plane coordinates            |
| Revolution                    | 120 = profile + axis 110 (under a trim: 128, see below)         |
| TrimmedFace                   | 144 with one 142 per loop (parameter-space and model-space curve)|
| Shell                         | 402 form 7 group of its faces                                   |
| closed Shell / Revolution     | with trim_entity=186: 186 manifold solid B-rep (`iges_brep`)     |
| binding names                 | 406 form 15 name property + the 8-character DE label            |

Rules followed (research notes §2.6): children are written before parents, everything a root
refers to is physically dependent (status 01), parameter-space curves have use flag 05, a root is
never referred to (an exported object that another export also uses is written twice: once as a
root, once as a child), 126/128 always carry complete clamped knot vectors, weights and the
parameter range. A trimmed revolution is written as the 128 of its exact NURBS form, because rgm's
trimming curves live in that surface's (u, v) while a 120's (u, v) is (profile parameter, angle).
The two curves of a 142 share a parameter (a model-space arc in a loop is its 126 form 2; a fitted
partner has the parameter of the exact curve's entity). Transforms are baked: the model holds moved
objects of their own kinds, so 124 only places arcs (docs/backends.md says why).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from rgm.errors import BackendError
from rgm.model import (
    BSplineCurve, BSplineSurface, Circle, CircularArc, CompositeCurve, Extrusion, IntersectionCurve, Line, Loop,
    Plane, Polyline, Revolution, RuledSurface, Shell, TrimmedFace,
)
from rgm.model.validate import loop_stretches

from .iges_brep import NotClosed, write_msbo
from .iges_curves import arc_placement, model_curve, parameter_curve
from .iges_format import (
    PHYSICAL, UNIT_FLAGS, USE_DEFINITION, USE_PARAMETRIC, Entity, GlobalSection, IgesFile, iges_date,
)

__all__ = ["write_iges", "iges_text", "iges_file", "PCURVE_PREFERENCES"]

#: `pcurve_preference` option -> 142 PREF value (None: decided per loop, see `_loop`)
PCURVE_PREFERENCES = {"auto": None, "2d": 1, "3d": 2, "both": 3}
_TWO_PI = 2.0 * np.pi


def _as3(pts) -> np.ndarray:
    pts = np.asarray(pts, dtype=float)
    if pts.shape[-1] == 2:
        pts = np.concatenate([pts, np.zeros(pts.shape[:-1] + (1,))], axis=-1)
    return pts


class _Lowering:
    """Walks the model and appends entities to an IgesFile (one instance per file)."""

    def __init__(self, model, iges: IgesFile, *, nurbs_only: bool, pcurve_preference: str, tol: float,
                 color=None, brep: bool = False):
        if pcurve_preference not in PCURVE_PREFERENCES:
            raise BackendError(f"unknown pcurve preference {pcurve_preference!r}; choose "
                               f"{', '.join(PCURVE_PREFERENCES)}")
        self.model, self.iges, self.tol = model, iges, tol
        self.nurbs_only, self.pref = nurbs_only, PCURVE_PREFERENCES[pcurve_preference]
        self.brep = brep              # trim_entity 186: closed shells and solids as manifold solid B-reps
        self.memo: dict = {}          # (id(obj), dim, as_nurbs) -> DE of its dependent entity
        self.keep: list = []          # objects whose ids key the memo (kept alive)
        self.extent = 0.0             # max |coordinate| written (Global parameter 20)
        self.color = 0
        if color is not None:
            rgb = [float(c) for c in color]
            self.color = -self.iges.add(Entity(314, [*rgb], use=USE_DEFINITION, hierarchy=0))

    # -- bookkeeping -------------------------------------------------------------------------
    def _add(self, obj, entity: Entity, root: bool) -> int:
        """Add `entity` (of model object `obj`, or None): independent when a root, else physically
        dependent; geometry gets the file's colour; a named object its 406 name and DE label."""
        entity.subordinate = 0 if root else PHYSICAL
        if entity.use == 0:
            entity.color = self.color
        name = getattr(obj, "name", None)
        if name:
            entity.label = name[:8]
            entity.properties = [self.iges.add(Entity(406, [1, name], form=15, subordinate=0,
                                                      use=USE_DEFINITION, hierarchy=0))]
        return self.iges.add(entity)

    def _points(self, pts) -> np.ndarray:
        pts = _as3(pts)
        if pts.size:
            self.extent = max(self.extent, float(np.abs(pts).max()))
        return pts

    def root(self, obj) -> int:
        if self.brep and isinstance(obj, (Revolution, Shell)):
            try:
                return write_msbo(self, obj, True)
            except NotClosed:   # not a closed solid: as with 144
                pass
        return self._lower(obj, root=True, dim=getattr(obj, "dim", 3))

    def child(self, obj, dim: int = 3, use: int = 0) -> int:
        key = (id(obj), dim, use)
        if key not in self.memo:
            self.keep.append(obj)
            self.memo[key] = self._lower(obj, root=False, dim=dim, use=use)
        return self.memo[key]

    def _lower(self, obj, *, root: bool, dim: int, use: int = 0) -> int:
        if isinstance(obj, TrimmedFace):
            return self._trimmed(obj, root)
        if isinstance(obj, Shell):
            members = [self.child(f) for f in obj.faces]
            return self._add(obj, Entity(402, [len(members), *members], form=7), root)
        if isinstance(obj, (Plane, BSplineSurface, Revolution, Extrusion, RuledSurface)):
            return self._surface(obj, root)
        return self._curve(obj, root, dim, use)

    # -- curves ------------------------------------------------------------------------------
    def _curve(self, obj, root: bool, dim: int, use: int) -> int:
        add = lambda entity: self._add(obj, entity, root)  # noqa: E731
        if isinstance(obj, IntersectionCurve):
            branches = obj.approximate(self.tol)
            if len(branches) != 1:
                raise BackendError(f"the intersection{_of(obj)} has {len(branches)} branches at tolerance "
                                   f"{self.tol:g}; IGES needs one curve")
            return add(self._bspline(branches[0].curve, 0, 3, use))
        if self.nurbs_only:
            form = 1 if isinstance(obj, Line) else 2 if isinstance(obj, (Circle, CircularArc)) else 0
            nurbs = _joined(obj) if isinstance(obj, CompositeCurve) else obj.nurbs()
            return add(self._bspline(nurbs, form, dim, use))
        if isinstance(obj, Line):
            return add(Entity(110, [self._points(np.stack([obj.p0, obj.p1])).ravel()], use=use))
        if isinstance(obj, Polyline):
            pts = self._points(obj.points)
            if dim == 2:
                return add(Entity(106, [1, len(pts), 0.0, pts[:, :2].ravel()], form=11, use=use))
            return add(Entity(106, [2, len(pts), pts.ravel()], form=12, use=use))
        if isinstance(obj, (Circle, CircularArc)):
            return self._arc(obj, root, use)
        if isinstance(obj, BSplineCurve):
            return add(self._bspline(obj.curve, 0, dim, use))
        if isinstance(obj, CompositeCurve):
            members = [self.child(p, dim, use) for p in _flatten(obj)]
            return add(Entity(102, [len(members), *members], use=use))
        raise BackendError(f"IGES: cannot write {type(obj).__name__}{_of(obj)}")

    def _arc(self, obj, root: bool, use: int) -> int:
        """100 in its definition plane, placed by a 124 unless the normal is +z (`arc_placement`)."""
        placement = arc_placement(obj)
        self._points(_as3(obj.center))
        entity = Entity(100, placement.params, use=use)
        if placement.matrix is not None:
            entity.transform = self.iges.add(Entity(124, [placement.matrix.ravel()], form=0, subordinate=PHYSICAL,
                                                    use=USE_DEFINITION, hierarchy=0))
        return self._add(obj, entity, root)

    def _bspline(self, curve, form: int, dim: int, use: int) -> Entity:
        """126: K, M, PROP1-4, knots (K+M+2), weights (K+1), points, V0, V1, normal."""
        ctrl = self._points(curve.ctrl)
        n, p = curve.n, curve.degree
        w = curve.weights if curve.is_rational else np.ones(n)
        closed = bool(np.array_equal(curve.start, curve.end))
        normal, planar = (np.array([0.0, 0.0, 1.0]), 1) if dim == 2 or curve.dim == 2 else _plane_normal(ctrl)
        u0, u1 = curve.domain
        return Entity(126, [n - 1, p, planar, int(closed), int(not curve.is_rational), 0,
                            np.asarray(curve.knots, float), np.asarray(w, float), ctrl.ravel(),
                            u0, u1, normal], form=form, use=use)

    # -- surfaces ----------------------------------------------------------------------------
    def _surface(self, obj, root: bool, size: float | None = None, as_nurbs: bool = False) -> int:
        if isinstance(obj, Revolution) and not (self.nurbs_only or as_nurbs):
            return self._revolution(obj, root)
        if isinstance(obj, Plane):
            size = size or max(self.extent, float(np.abs(obj.origin).max()), 1.0)
            return self._add(obj, self._bsurface(obj.nurbs(size), 0 if self.nurbs_only else 1), root)
        return self._add(obj, self._bsurface(obj.nurbs(), 0), root)

    def _bsurface(self, s, form: int) -> Entity:
        """128: K1, K2, M1, M2, PROP1-5, knots u, knots v, weights and points with u fastest, U0-V1."""
        ctrl = self._points(s.ctrl)
        w = s.weights if s.is_rational else np.ones((s.nu, s.nv))
        closed_u = bool(np.array_equal(ctrl[0], ctrl[-1]))
        closed_v = bool(np.array_equal(ctrl[:, 0], ctrl[:, -1]))
        (u0, u1), (v0, v1) = s.domain
        return Entity(128, [s.nu - 1, s.nv - 1, s.degree_u, s.degree_v, int(closed_u), int(closed_v),
                            int(not s.is_rational), 0, 0, np.asarray(s.knots_u, float),
                            np.asarray(s.knots_v, float), np.ascontiguousarray(np.asarray(w, float).T),
                            np.ascontiguousarray(ctrl.transpose(1, 0, 2)), u0, u1, v0, v1], form=form)

    def _revolution(self, obj: Revolution, root: bool) -> int:
        """120: axis (110) and generatrix, angles in radians with 0 <= SA < TA <= 2 pi."""
        start, end = obj.start, obj.end
        if not 0.0 < end - start <= _TWO_PI * (1 + 1e-15):
            raise BackendError(f"the revolution{_of(obj)} sweeps {end - start:g} rad; IGES needs (0, 2 pi]")
        shift = np.floor(start / _TWO_PI) * _TWO_PI
        profile = obj.profile
        if start - shift >= 0.0 and end - shift <= _TWO_PI:
            start, end = start - shift, end - shift
        else:  # rotate the profile to the start angle, sweep from 0
            profile = profile.transform(_rotation(obj.axis_point, obj.axis_dir, start))
            start, end = 0.0, end - start
        axis_pts = self._points(np.stack([obj.axis_point, obj.axis_point + obj.axis_dir]))
        axis = self._add(None, Entity(110, [axis_pts.ravel()]), False)
        gen = self.child(profile)
        return self._add(obj, Entity(120, [axis, gen, float(start), float(min(end, _TWO_PI))]), root)

    # -- trimmed faces -----------------------------------------------------------------------
    def trim_surface(self, face: TrimmedFace) -> int:
        """DE of the surface a trimmed face's loops live on: its 128 (a plane's spans its loops, a
        revolution's is its exact NURBS form, whose (u, v) rgm's trimming curves use)."""
        surface = face.surface
        size = self._plane_size(face) if isinstance(surface, Plane) else None
        key = (id(surface), "trim-base", size)
        if key not in self.memo:
            self.keep.append(surface)
            if isinstance(surface, (Plane, Revolution)):
                self.memo[key] = self._surface(surface, False, size=size, as_nurbs=True)
            else:
                self.memo[key] = self.child(surface)
        return self.memo[key]

    def _trimmed(self, face: TrimmedFace, root: bool) -> int:
        surface = face.surface
        sde = self.trim_surface(face)
        outer = self._loop(face.outer, surface, sde) if face.outer is not None else 0
        holes = [self._loop(h, surface, sde) for h in face.holes]
        return self._add(face, Entity(144, [sde, int(face.outer is not None), len(holes), outer, *holes]), root)

    def _plane_size(self, face) -> float:
        """Half-width of the square of plane coordinates the 128 of a trimmed plane spans."""
        ext = 1.0
        for loop in face.loops():
            for piece in loop.pieces:
                c = self._loop_piece(piece, face.surface)[0]
                c = c if hasattr(c, "ctrl") else c.nurbs()
                ext = max(ext, float(np.abs(c.ctrl).max()))
        return 1.5 * ext

    def _loop_piece(self, piece, surface, near=None):
        """(uv NurbsCurve or model object (2-D), model-space NurbsCurve or model object (3-D), crtn);
        `near`: the (u, v) the previous piece ended at, which picks the side of a closed surface's seam."""
        if isinstance(piece, IntersectionCurve):
            branches = piece.approximate(self.tol)
            if len(branches) != 1:
                raise BackendError(f"the intersection{_of(piece)} has {len(branches)} branches; a loop piece "
                                   f"needs one")
            return piece.uv_curves(surface, self.tol)[0], branches[0].curve, 2
        if piece.dim == 2:
            return piece, self._partner(lambda t: model_curve(surface, piece, t), surface), 0
        exact = piece.nurbs() if isinstance(piece, (Circle, CircularArc)) else piece   # see `_piece`
        return self._partner(lambda t: parameter_curve(surface, exact, t, near), surface), piece, 0

    def _partner(self, make, surface):
        """The approximated partner curve of a loop piece, make(tol): far tighter than the file's tolerance,
        1e-10 of the surface's size, so that receivers that prefer it still get the exact geometry; where
        that cannot be reached (a trimming curve across a densely knotted fitted surface), 1e-8, then 1e-6
        of the size, then the file's tolerance."""
        size = _size(surface)
        tols = sorted({min(self.tol, f * size) for f in (1e-10, 1e-8, 1e-6)} | {self.tol})
        for t in tols[:-1]:
            try:
                return make(t)
            except BackendError:
                continue
        return make(tols[-1])

    def _loop(self, loop: Loop, surface, sde: int) -> int:
        """142: CRTN, SPTR, BPTR (2-D curve or 102 of them), CPTR (3-D), PREF."""
        uv, xyz, kinds, near = [], [], [], None
        # a composite piece's members are pieces of their own: each arc keeps its exact form (`_piece`)
        stretches = loop_stretches(loop, surface, self.tol)
        pieces = [(k, m) for k, p in enumerate(loop.pieces)
                  for m in (_flatten(p) if isinstance(p, CompositeCurve) else [p])]
        for k, piece in pieces:
            # an intersection between two curves: its stretch between them, in loop order (of any branch)
            b, c, crtn = (*stretches[k], 2) if k in stretches else self._loop_piece(piece, surface, near)
            near = np.asarray(b.end, float)
            uv.append(self._piece(b, 2))
            xyz.append(self._piece(c, 3))
            kinds.append((crtn, piece.dim if not isinstance(piece, IntersectionCurve) else 0))
        pref = self.pref
        if pref is None:
            pref = 2 if all(dim == 3 for _c, dim in kinds) else 1
        bptr = self._chain(uv, USE_PARAMETRIC)
        cptr = self._chain(xyz, 0)
        crtn = 2 if any(c == 2 for c, _d in kinds) else 0
        return self._add(loop, Entity(142, [crtn, sde, bptr, cptr, pref], use=USE_PARAMETRIC), False)

    def _piece(self, curve, dim: int) -> int:
        """A loop piece's curve: a fitted partner (NurbsCurve) as a 126; a model-space circle or arc as the
        126 form 2 of its exact NURBS (so its parameter is its pcurve's: a receiver that keeps both
        curves, OpenCASCADE with PREF = 2, would otherwise re-approximate the pcurve); else the object."""
        from rgm.geometry import NurbsCurve

        use = USE_PARAMETRIC if dim == 2 else 0
        if isinstance(curve, NurbsCurve) or (dim == 3 and isinstance(curve, (Circle, CircularArc))):
            form = 0 if isinstance(curve, NurbsCurve) else 2
            e = self._bspline(curve if form == 0 else curve.nurbs(), form, dim, use)
            return self._add(curve if form else None, e, False)
        return self.child(curve, dim, use)

    def _chain(self, des: list, use: int) -> int:
        if len(des) == 1:
            return des[0]
        return self._add(None, Entity(102, [len(des), *des], use=use), False)


def _of(obj) -> str:
    return f" `{obj.name}`" if getattr(obj, "name", None) else ""


def _joined(curve):
    """The single NURBS of a composite curve (pieces joined end to start, exact)."""
    from rgm.geometry.revolve import composite_curve

    pieces = [p.nurbs() for p in _flatten(curve)]
    if curve.dim == 2:
        from rgm.geometry import NurbsCurve

        lifted = [NurbsCurve(c.degree, c.knots, np.column_stack([c.ctrl, np.zeros(c.n)]), c.weights) for c in pieces]
        c = composite_curve(lifted)
        return NurbsCurve(c.degree, c.knots, c.ctrl[:, :2], c.weights)
    return composite_curve(pieces)


def _size(surface) -> float:
    """Largest extent of a surface's control net (1 for a plane), model units."""
    if isinstance(surface, Plane):
        return max(1.0, float(np.abs(surface.origin).max()))
    return max(1.0, float(np.ptp(surface.nurbs().ctrl.reshape(-1, 3), axis=0).max()))


def _flatten(curve) -> list:
    out = []
    for p in curve.pieces:
        out.extend(_flatten(p) if isinstance(p, CompositeCurve) else [p])
    return out


def _plane_normal(ctrl: np.ndarray):
    """(unit normal, 1) when the control points are coplanar (so the curve is planar), else (0, 0)."""
    if len(ctrl) < 3:
        return np.zeros(3), 0
    centred = ctrl - ctrl.mean(axis=0)
    _u, s, vt = np.linalg.svd(centred, full_matrices=False)
    size = float(s[0]) or 1.0
    if s.shape[0] >= 2 and s[1] > 1e-9 * size and s[-1] <= 1e-12 * size:
        return vt[-1], 1
    return np.zeros(3), 0


def _rotation(point, axis, angle: float) -> np.ndarray:
    """4x4 rotation by `angle` about the line through `point` along unit `axis` (Rodrigues)."""
    k = np.asarray(axis, float)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    r = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = point - r @ point
    return m


def _global(model, file_name: str, tol: float, extent: float, author: str, organization: str) -> GlobalSection:
    units = model.units.lower()
    if units not in UNIT_FLAGS:
        raise BackendError(f"IGES has no unit flag for `{units}`")
    flag, name = UNIT_FLAGS[units]
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    try:
        date = iges_date(float(epoch) if epoch else None)
    except ValueError:
        raise BackendError(f"SOURCE_DATE_EPOCH={epoch!r} is not a number of seconds") from None
    product = Path(model.source).stem if model.source else Path(file_name).stem
    return GlobalSection(product_id=product, file_name=file_name, receiver_product_id=product,
                         unit_flag=flag, unit_name=name, date=date, modified_date=date,
                         resolution=float(tol), max_coordinate=float(extent), author=author,
                         organization=organization, max_line_weight=float(tol))


def iges_text(model, **options) -> str:
    """The IGES 5.3 text of `model`'s exported objects (see the module docstring for the mapping;
    options as for `iges_file`)."""
    return iges_file(model, **options).to_text()


def iges_file(model, *, file_name: str = "model.igs", nurbs_only: bool = False, trim_entity: str = "144",
              pcurve_preference: str = "auto", tol: float | None = None, color=None, author: str = "",
              organization: str = "") -> IgesFile:
    """The `IgesFile` of `model`'s exported objects, ready for `to_text()` / `to_bytes()`."""
    if str(trim_entity) not in ("144", "186"):
        raise BackendError(f"trim entity {trim_entity!r} is not supported; choose 144 (trimmed surfaces) or 186 "
                           f"(manifold solid B-rep of closed shells and solids)")
    tol = float(model.tolerance if tol is None else tol)
    if not tol > 0:
        raise BackendError("the IGES resolution (tolerance) must be positive")
    iges = IgesFile(GlobalSection())
    lowering = _Lowering(model, iges, nurbs_only=nurbs_only, pcurve_preference=pcurve_preference, tol=tol,
                         color=color, brep=str(trim_entity) == "186")
    for obj in model.exported():
        lowering.root(obj)
    iges.global_section = _global(model, file_name, tol, lowering.extent, author, organization)
    iges.start = f"rgm IGES 5.3 of {Path(model.source).name if model.source else file_name}"
    return iges


def write_iges(model, path, *, verify: bool = False, nurbs_only: bool = False, trim_entity: str = "144",
               pcurve_preference: str = "auto", tol: float | None = None, color=None, report=None,
               **ignored) -> Path:
    """Write `model` as IGES 5.3 to `path` atomically.

    With `verify`, the file is first written beside `path` under a temporary name, read back by
    OpenCASCADE and by rgm's reader, and compared with the model (`iges_verify.verify_iges`); it is
    renamed into place only if both deviations are within `tol` (default: the model tolerance), and
    the figures are given to `report` (a callable taking one line of text) when there is one.
    """
    from rgm.atomic import temp_path_beside, write_atomic

    path = Path(path)
    data = iges_file(model, file_name=path.name, nurbs_only=nurbs_only, trim_entity=trim_entity,
                     pcurve_preference=pcurve_preference, tol=tol, color=color).to_bytes()
    if not verify:
        return write_atomic(path, data)
    from .iges_verify import verify_iges

    tmp = temp_path_beside(path)
    try:
        write_atomic(tmp, data)
        dev = verify_iges(model, tmp, tol=tol)
        if report is not None:
            report(f"verified {path}: read back by rgm and by OpenCASCADE, max deviation from the model "
                   f"{dev['rgm']:.3g} and {dev['occ']:.3g} {model.units} (tolerance {dev['tol']:g})")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
