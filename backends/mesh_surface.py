"""Surfaces as the mesher sees them: point and first-derivative evaluation over a parameter rectangle,
plus vectorised closest points (the oracle for chordal deviation).

`surface_patch(surface)` adapts a model surface:
- a bare `Revolution` is parameterised by (angle, profile parameter): S(u, v) = a + R_u (C(v) - a), so
  equal steps in u are equal angles (the rational NURBS circle is not uniform in angle);
- a `Plane` by its plane coordinates over a given box;
- every other surface (and every surface carrying trimming curves, which live in rgm's (u, v)) by its
  exact `.nurbs()` form.
NURBS patches and revolution profiles are evaluated in per-span power form
(`rgm.geometry.power_form`: a span lookup and Horner steps, for the many small calls of refinement);
NURBS patches of one degree pair and kind are also evaluated and projected onto together (`PatchStack`,
`evaluate_together`, `project_together`: a part's edges, sampled on many faces at once, cost one call per
kind of surface rather than one per face; the IGES plate of 46 faces in
`benchmarks/bench_mesh.py`: edge sampling 82 -> 52 ms).

`Patch.project(points, uv0)` is Gauss-Newton on |S(u, v) - X|^2 from a starting guess (Piegl & Tiller
§6.1, point inversion), clamped to the domain; `Patch.closest(points)` first picks the nearest nodes of a
dense parameter grid (KD-tree) as guesses, so it finds the global closest point for points near the
surface (within the grid spacing of it); a revolution adds a guess at the point's own angle about the
axis (near a pole the nearest nodes are all the pole, where Gauss-Newton cannot turn).
"""
from __future__ import annotations

import numpy as np

from rgm.geometry.inversion import gauss_newton_step
from rgm.geometry.power_form import SurfaceStack, key, power_form


class Patch:
    """A parametric surface over `domain` ((u0, u1), (v0, v1)) with `breaks_u`/`breaks_v` (knots: the
    derivative may jump there). Subclasses give `d1(u, v) -> (S, Su, Sv)`, each (m, 3)."""

    domain: tuple
    breaks_u: np.ndarray
    breaks_v: np.ndarray

    creases_u = creases_v = np.zeros(0)
    #: the patch over its surface's whole domain, when this one is a `restrict`ed part of it
    base = None

    @property
    def whole(self) -> "Patch":
        """The patch over the whole surface (self unless restricted): it evaluates every sub-patch's
        (u, v) alike, so that evaluations for several sub-patches can be made in one call."""
        return self.base or self

    def d1(self, u, v):
        raise NotImplementedError

    def restrict(self, domain) -> "Patch":
        """The same surface over a sub-rectangle `domain` (closest points then stay inside it)."""
        import copy

        sub = copy.copy(self)
        sub.base = self.whole
        sub.domain = tuple(tuple(map(float, d)) for d in domain)
        (u0, u1), (v0, v1) = sub.domain
        sub.breaks_u = np.unique(np.concatenate([[u0, u1], self.breaks_u[(self.breaks_u > u0) & (self.breaks_u < u1)]]))
        sub.breaks_v = np.unique(np.concatenate([[v0, v1], self.breaks_v[(self.breaks_v > v0) & (self.breaks_v < v1)]]))
        sub._seeds_of = {}
        return sub

    def pieces(self) -> list:
        """Sub-patches between creases (C0 knot lines): each is smooth, so it is meshed on its own."""
        (u0, u1), (v0, v1) = self.domain
        cu = np.unique(np.concatenate([[u0, u1], self.creases_u[(self.creases_u > u0) & (self.creases_u < u1)]]))
        cv = np.unique(np.concatenate([[v0, v1], self.creases_v[(self.creases_v > v0) & (self.creases_v < v1)]]))
        if len(cu) == 2 and len(cv) == 2:
            return [self]
        return [self.restrict(((a, b), (c, d))) for a, b in zip(cu[:-1], cu[1:]) for c, d in zip(cv[:-1], cv[1:])]

    def evaluate(self, u, v) -> np.ndarray:
        return self.d1(u, v)[0]

    def clamp(self, uv: np.ndarray) -> np.ndarray:
        """Parameters uv (m, 2) clamped into the domain (np.minimum/np.maximum with the corners: np.clip's
        dispatch costs more than the work on the small arrays of refinement)."""
        (u0, u1), (v0, v1) = self.domain
        return np.minimum(np.maximum(uv, (u0, v0)), (u1, v1))

    def normal(self, u, v) -> np.ndarray:
        """Unit normals Su x Sv (m, 3), taken a relative 1e-9 inside the domain: on a patch restricted
        between creases the derivatives on its edges are then the one-sided ones of this patch (not of
        its neighbour across the crease), and at a pole the limit normal along that parameter line.
        Zero rows where the surface is degenerate even so."""
        (u0, u1), (v0, v1) = self.domain
        eu, ev = 1e-9 * (u1 - u0), 1e-9 * (v1 - v0)
        _, su, sv = self.d1(np.clip(u, u0 + eu, u1 - eu), np.clip(v, v0 + ev, v1 - ev))
        n = np.cross(su, sv)
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 1e-300)

    def project(self, points, uv0, iterations: int = 6):
        """Gauss-Newton closest points from guesses uv0 (m, 2): (uv (m, 2), distance (m,)). Stops early
        once no step moves a parameter by more than 1e-14 of the domain (converged: the steps left
        would be round-off)."""
        (u0, u1), (v0, v1) = self.domain
        return _gauss_newton(self.d1, self.evaluate, self.clamp, np.asarray(points, float), np.asarray(uv0, float),
                             1e-14 * np.array([u1 - u0, v1 - v0]), iterations)

    def closest(self, points, grid: int = 96, starts: int = 4):
        """Global closest points: `project` from each seed (`_seeds`), keeping the nearest result."""
        return closest_together([self], [points], grid, starts)[0]

    def _seeds(self, x, grid, starts):
        """(m, starts, 2): the `starts` nodes of a grid x grid parameter grid nearest to each point
        (KD-tree over the nodes' points, built once)."""
        from scipy.spatial import cKDTree

        cache = self.__dict__.setdefault("_seeds_of", {})   # per domain: `restrict` starts a new one
        if grid not in cache:
            (u0, u1), (v0, v1) = self.domain
            gu = np.unique(np.concatenate([np.linspace(u0, u1, grid), self.breaks_u]))
            gv = np.unique(np.concatenate([np.linspace(v0, v1, grid), self.breaks_v]))
            uu, vv = np.meshgrid(gu, gv, indexing="ij")
            nodes = np.column_stack([uu.ravel(), vv.ravel()])
            cache[grid] = (cKDTree(self.evaluate(nodes[:, 0], nodes[:, 1])), nodes)
        tree, nodes = cache[grid]
        return nodes[tree.query(x, k=starts)[1].reshape(len(x), starts)]


def _gauss_newton(d1, evaluate, clamp, x, uv, still, iterations):
    """Gauss-Newton on |S(u, v) - x|^2 from uv (m, 2), clamped into the domain after each step, stopping
    early once no step exceeds `still` (per parameter: the steps left would be round-off)."""
    uv = clamp(uv)
    for k in range(iterations):
        s, su, sv = d1(uv[:, 0], uv[:, 1])
        du, dv = gauss_newton_step(su, sv, x - s)
        step = np.column_stack([du, dv])
        uv = clamp(uv + step)
        if k + 1 < iterations and (np.abs(step) <= still).all():
            break
    return uv, np.linalg.norm(x - evaluate(uv[:, 0], uv[:, 1]), axis=1)


def _creases(knots, degree) -> np.ndarray:
    """Interior knots of multiplicity >= degree: the curve/surface is only C0 there."""
    values, counts = np.unique(np.asarray(knots, float), return_counts=True)
    return values[1:-1][counts[1:-1] >= degree]


class NurbsPatch(Patch):
    """A NurbsSurface as a patch (its own (u, v))."""

    def __init__(self, nurbs):
        self.nurbs = nurbs
        self.domain = nurbs.domain
        self.breaks_u = np.unique(nurbs.knots_u[nurbs.degree_u:len(nurbs.knots_u) - nurbs.degree_u])
        self.breaks_v = np.unique(nurbs.knots_v[nurbs.degree_v:len(nurbs.knots_v) - nurbs.degree_v])
        self.creases_u = _creases(nurbs.knots_u, nurbs.degree_u)
        self.creases_v = _creases(nurbs.knots_v, nurbs.degree_v)
        self.power = power_form(nurbs)

    def d1(self, u, v):
        if self.power is not None:
            return self.power.d(u, v, 1)
        d = self.nurbs.derivatives(np.asarray(u, float), np.asarray(v, float), 1)
        return d[0, 0], d[1, 0], d[0, 1]

    def evaluate(self, u, v):
        if self.power is not None:
            return self.power.d(u, v, 0)[0]
        return self.nurbs.evaluate(np.asarray(u, float), np.asarray(v, float))


class RevolutionPatch(Patch):
    """A `Revolution` by angle u in [start, end] and profile parameter v: S = a + R_u (C(v) - a).

    The profile is kept in the axis frame (e1, e2, k) with the axis point as origin, so the rotation
    by u is a plane rotation of its first two coordinates and one product with the frame gives world
    coordinates (points, Su = k x (S - a) and Sv together)."""

    def __init__(self, rev):
        self.profile = rev.profile.nurbs()
        self.a = np.asarray(rev.axis_point, float)
        self.k = np.asarray(rev.axis_dir, float)
        self.domain = ((rev.start, rev.end), self.profile.domain)
        k = self.k
        e1 = np.cross(k, np.eye(3)[int(np.argmin(np.abs(k)))])
        e1 /= np.linalg.norm(e1)
        self.frame = np.array([e1, np.cross(k, e1), k])                   # rows: frame axes in world
        to_frame = np.eye(4)
        to_frame[:3, :3], to_frame[:3, 3] = self.frame, -self.frame @ self.a
        self.local = self.profile.transform(to_frame)                     # the profile in frame coordinates
        p = self.profile
        self.breaks_u = np.array([rev.start, rev.end])
        self.breaks_v = np.unique(p.knots[p.degree:len(p.knots) - p.degree])
        self.creases_v = _creases(p.knots, p.degree)
        self.power = power_form(self.local)

    def _profile(self, v, order):
        """The profile in frame coordinates at v (clipped into the domain) and, for order 1, its derivative."""
        v0, v1 = self.domain[1]
        v = np.minimum(np.maximum(np.asarray(v, float), v0), v1)
        if self.power is not None:
            return self.power.d(v, order)
        c = self.local.derivatives(v, order) if order else self.local.evaluate(v)[None]
        return c[0], (c[1] if order else None)

    def d1(self, u, v):
        u = np.asarray(u, float)
        c, dc = self._profile(v, 1)
        cos, sin = np.cos(u), np.sin(u)
        x = c[:, 0] * cos - c[:, 1] * sin
        y = c[:, 0] * sin + c[:, 1] * cos
        zero = np.zeros_like(x)
        local = np.stack([np.stack([x, y, c[:, 2]], axis=1), np.stack([-y, x, zero], axis=1),
                          np.stack([dc[:, 0] * cos - dc[:, 1] * sin, dc[:, 0] * sin + dc[:, 1] * cos, dc[:, 2]], axis=1)])
        s, su, sv = local @ self.frame
        return s + self.a, su, sv

    def _seeds(self, x, grid, starts):
        """The grid's seeds and one from the meridian: u the point's angle about the axis (less the
        profile's own), v the nearest of 8 grid profile samples in (distance from the axis, height).
        Near a pole every grid node nearest to a point is the pole itself, from which Gauss-Newton
        cannot turn (Su = 0 there); the meridian seed starts at the point's own angle."""
        from scipy.spatial import cKDTree

        generic = super()._seeds(x, grid, starts)
        cache = self._seeds_of
        if "meridian" not in cache:
            (v0, v1) = self.domain[1]
            vs = np.unique(np.concatenate([np.linspace(v0, v1, 8 * grid + 1), self.breaks_v]))
            c, _ = self._profile(vs, 0)
            rho = np.hypot(c[:, 0], c[:, 1])
            theta = np.arctan2(c[:, 1], c[:, 0])
            off = rho > 1e-12 * (rho.max() + np.abs(c[:, 2]).max())   # on the axis: the nearest sample's angle
            if off.any():
                k, i = np.flatnonzero(off), np.arange(len(vs))
                right = k[np.minimum(np.searchsorted(k, i), len(k) - 1)]
                left = k[np.maximum(np.searchsorted(k, i, side="right") - 1, 0)]
                theta = theta[np.where(np.abs(i - left) <= np.abs(right - i), left, right)]
            cache["meridian"] = (cKDTree(np.column_stack([rho, c[:, 2]])), vs, theta)
        tree, vs, theta = cache["meridian"]
        local = (x - self.a) @ self.frame.T
        j = tree.query(np.column_stack([np.hypot(local[:, 0], local[:, 1]), local[:, 2]]))[1]
        u = np.arctan2(local[:, 1], local[:, 0]) - theta[j]
        u += 2 * np.pi * np.round((0.5 * sum(self.domain[0]) - u) / (2 * np.pi))   # the turn nearest the domain
        return np.concatenate([generic, np.column_stack([u, vs[j]])[:, None]], axis=1)

    def evaluate(self, u, v):
        u = np.asarray(u, float)
        c, _ = self._profile(v, 0)
        cos, sin = np.cos(u), np.sin(u)
        local = np.stack([c[:, 0] * cos - c[:, 1] * sin, c[:, 0] * sin + c[:, 1] * cos, c[:, 2]], axis=1)
        return local @ self.frame + self.a


class PlanePatch(Patch):
    """A `Plane` by its plane coordinates over the box `domain` (S = origin + u x + v y)."""

    def __init__(self, plane, domain):
        self.o, self.x, self.y = (np.asarray(a, float) for a in (plane.origin, plane.x_dir, plane.y_dir))
        self.domain = domain
        self.breaks_u = np.array(domain[0], float)
        self.breaks_v = np.array(domain[1], float)

    def d1(self, u, v):
        u, v = np.asarray(u, float), np.asarray(v, float)
        s = self.o + u[:, None] * self.x + v[:, None] * self.y
        return s, np.broadcast_to(self.x, s.shape), np.broadcast_to(self.y, s.shape)


class PatchStack:
    """NURBS patches of one degree pair and kind (`stack_key`), evaluated and projected onto together:
    each point names its patch (`which`), and one power-form call (`rgm.geometry.power_form.SurfaceStack`)
    serves them all, so a part's many small faces (a plate's holes) cost one Gauss-Newton run, not one
    each. Restricted patches share their whole surface's form and keep their own domains."""

    def __init__(self, patches):
        wholes = tuple({id(p.whole): p.whole for p in patches}.values())
        slot = {id(w): i for i, w in enumerate(wholes)}
        self.surface = np.array([slot[id(p.whole)] for p in patches], np.intp)
        self.form = _surface_stack(wholes)
        self.lo = np.array([(p.domain[0][0], p.domain[1][0]) for p in patches])
        self.hi = np.array([(p.domain[0][1], p.domain[1][1]) for p in patches])

    def project(self, which, points, uv0, iterations: int = 6):
        """`Patch.project` of points (m, 3) onto patches `which` (m,) from guesses uv0 (m, 2)."""
        lo, hi, s = self.lo[which], self.hi[which], self.surface[which]
        return _gauss_newton(lambda u, v: self.form.d(s, u, v, 1), lambda u, v: self.form.d(s, u, v, 0)[0],
                             lambda uv: np.minimum(np.maximum(uv, lo), hi), np.asarray(points, float),
                             np.asarray(uv0, float), 1e-14 * (hi - lo), iterations)

    def evaluate(self, which, u, v) -> np.ndarray:
        return self.form.d(self.surface[which], u, v, 0)[0]


#: a SurfaceStack whose coefficients take at most this many bytes is kept for the next call on the same
#: surfaces (refinement passes ask for the same sets again and again; setting one up costs ~0.1 ms, as
#: much as evaluating a small face); larger ones are built each time (copies of big nets would add up)
_KEEP_STACK_BYTES = 1 << 20


def _surface_stack(wholes: tuple) -> SurfaceStack:
    """The SurfaceStack of whole patches `wholes`, kept with the first of them when it is small."""
    kept = wholes[0].__dict__.setdefault("_stacks_kept", {})
    stack = kept.get(wholes)
    if stack is None:
        stack = SurfaceStack([w.power for w in wholes])
        if stack.flat_t.nbytes <= _KEEP_STACK_BYTES:
            kept[wholes] = stack
    return stack


def stack_key(patch):
    """Patches with one key are evaluated together (`PatchStack`): NURBS patches in power form, by degrees
    and kind; None for the rest (each its own)."""
    whole = patch.whole
    if isinstance(whole, NurbsPatch) and whole.power is not None:
        return key(whole.power)
    return None


def _stacks(patches, whole: bool):
    """[(indices into patches, PatchStack or None)]: the patches by `stack_key`; the others by patch (by
    surface when `whole`: for evaluation, where a sub-patch's domain does not matter), with None."""
    groups = {}
    for i, p in enumerate(patches):
        k = stack_key(p)
        groups.setdefault(("stack", k) if k is not None else ("alone", id(p.whole if whole else p)), []).append(i)
    return [(idx, PatchStack([patches[i] for i in idx]) if kind == "stack" else None)
            for (kind, _), idx in groups.items()]


def project_together(patches, points, guesses, iterations: int):
    """[(uv (k_i, 2), distances (k_i,))]: `Patch.project` of points[i] (k_i, 3) from guesses[i] onto
    patches[i], every stack of them (`PatchStack`) in one run."""
    out = [None] * len(patches)
    for idx, stack in _stacks(patches, whole=False):
        x = np.concatenate([points[i] for i in idx])
        g = np.concatenate([guesses[i] for i in idx])
        if stack is None:
            uv, dist = patches[idx[0]].project(x, g, iterations=iterations)
        else:
            uv, dist = stack.project(np.repeat(np.arange(len(idx)), [len(points[i]) for i in idx]), x, g, iterations)
        cut = np.cumsum([len(points[i]) for i in idx[:-1]])
        for i, a, b in zip(idx, np.split(uv, cut), np.split(dist, cut)):
            out[i] = (a, b)
    return out


def closest_together(patches, points, grid: int = 96, starts: int = 4) -> list:
    """[(uv (k_i, 2), distances (k_i,))]: `Patch.closest` of points[i] (k_i, 3) on patches[i], the
    Gauss-Newton runs from every seed of every patch together (`project_together`)."""
    xs = [np.asarray(x, float) for x in points]
    seeds = [p._seeds(x, grid, starts) for p, x in zip(patches, xs)]          # (k_i, seeds, 2)
    found = project_together(patches, [np.repeat(x, s.shape[1], axis=0) for x, s in zip(xs, seeds)],
                             [s.reshape(-1, 2) for s in seeds], 10)
    out = []
    for x, s, (uv, dist) in zip(xs, seeds, found):
        k = s.shape[1]
        pick = np.arange(len(x)) * k + np.argmin(dist.reshape(-1, k), axis=1)
        out.append((uv[pick], dist[pick]))
    return out


def evaluate_together(patches, uv) -> list:
    """[points (k_i, 3)] of patches[i] at uv[i] (k_i, 2), every stack of them (`PatchStack`) and every
    group of sub-patches of one surface in one call."""
    out = [None] * len(patches)
    for idx, stack in _stacks(patches, whole=True):
        every = np.concatenate([uv[i] for i in idx])
        if stack is None:
            xyz = patches[idx[0]].whole.evaluate(every[:, 0], every[:, 1])
        else:
            xyz = stack.evaluate(np.repeat(np.arange(len(idx)), [len(uv[i]) for i in idx]), every[:, 0], every[:, 1])
        for i, part in zip(idx, np.split(xyz, np.cumsum([len(uv[i]) for i in idx[:-1]]))):
            out[i] = part
    return out


def surface_patch(surface, trimmed: bool, plane_box=None) -> Patch:
    """The patch the mesher uses for a model surface (see the module docstring)."""
    from rgm.model import Plane, Revolution

    if isinstance(surface, Plane):
        return PlanePatch(surface, plane_box)
    if isinstance(surface, Revolution) and not trimmed:
        return RevolutionPatch(surface)
    return NurbsPatch(surface.nurbs())
