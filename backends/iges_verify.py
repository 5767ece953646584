"""`write_iges(verify=True)`: read the written file back and measure it against the model.

Two independent readers: rgm's own (`iges_read`), compared point for point at the same parameters
(the mapping keeps parametrisations), and OpenCASCADE's IGESControl_Reader (every root transferred,
no fail message, model sample points within tolerance of the transferred shape).
"""
from __future__ import annotations

import numpy as np

from rgm.errors import BackendError
from rgm.geometry import NurbsCurve
from rgm.model import CompositeCurve, Curve, IntersectionCurve, Plane, Shell, Surface, TrimmedFace
from rgm.model.validate import loop_stretches

from .iges_curves import surface_points
from .iges_read import read_iges_file

__all__ = ["verify_iges", "sample_object"]

_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}


def _curve_points(curve, tol, surface=None, count: int = 17) -> np.ndarray:
    if isinstance(curve, CompositeCurve):  # piece by piece (the joined form may be reparametrised)
        return np.concatenate([_curve_points(p, tol, surface, count) for p in curve.pieces])
    nurbs = curve if isinstance(curve, NurbsCurve) else curve.nurbs(tol) if isinstance(curve, IntersectionCurve) \
        else curve.nurbs()
    t = np.linspace(*nurbs.domain, count)
    p = nurbs.evaluate(t)
    if p.shape[1] == 2:
        p = surface_points(surface, p[:, 0], p[:, 1]) if surface is not None else np.column_stack([p, 0 * t])
    return p


def sample_object(obj, tol: float, count: int = 9) -> np.ndarray:
    """Points (k, 3) on a model object at fixed parameters: curves along their domain, surfaces on a
    count x count grid, trimmed faces on their surface and along every loop piece (mapped to 3-D)."""
    if isinstance(obj, Shell):
        return np.concatenate([sample_object(f, tol, count) for f in obj.faces])
    if isinstance(obj, TrimmedFace):
        parts = [sample_object(obj.surface, tol, count)]
        for loop in obj.loops():   # an intersection piece as the loop takes it (`loop_stretches`)
            stretches = loop_stretches(loop, obj.surface, tol)
            parts += [_curve_points(stretches[k][1] if k in stretches else p, tol, obj.surface)
                      for k, p in enumerate(loop.pieces)]
        return np.concatenate(parts)
    if isinstance(obj, Plane):
        g = np.linspace(-1.0, 1.0, count)
        u, v = np.meshgrid(g, g, indexing="ij")
        return surface_points(obj, u.ravel(), v.ravel())
    if isinstance(obj, Surface):
        s = obj.nurbs()
        (u0, u1), (v0, v1) = s.domain
        return s.evaluate_grid(np.linspace(u0, u1, count), np.linspace(v0, v1, count)).reshape(-1, 3)
    if isinstance(obj, Curve):
        return _curve_points(obj, tol)
    return np.asarray(getattr(obj, "xyz", np.zeros(3)), float).reshape(-1, 3)


def _rgm_deviation(model, path, tol: float) -> float:
    back = read_iges_file(path)
    if not back.ok:
        raise BackendError(f"{path}: rgm's IGES reader reports: {'; '.join(back.messages())}")
    ours, theirs = model.exported(), back.model.exported()
    if len(ours) != len(theirs):
        raise BackendError(f"{path}: wrote {len(ours)} objects, rgm's reader found {len(theirs)}")
    worst = 0.0
    for a, b in zip(ours, theirs):
        pa, pb = sample_object(a, tol), sample_object(b, tol)
        if pa.shape != pb.shape:
            raise BackendError(f"{path}: `{a.name}` reads back as a different kind of object")
        worst = max(worst, float(np.linalg.norm(pa - pb, axis=1).max()))
    return worst


def verify_iges(model, path, *, tol: float | None = None) -> dict:
    """Check the IGES file `path` against `model`; BackendError when a reader fails or a deviation
    exceeds `tol` (model units; default the model tolerance). Returns the measured deviations."""
    from rgm.backends.occ import distances_to_shape

    from .iges_occ_check import occ_read_iges

    tol = float(model.tolerance if tol is None else tol)
    rgm_dev = _rgm_deviation(model, path, tol)
    if not rgm_dev <= tol:
        raise BackendError(f"{path}: read back by rgm, the file deviates {rgm_dev:.3g} from the model "
                           f"(tolerance {tol:g})")
    occ = occ_read_iges(path)
    if occ.fails or occ.shape is None:
        raise BackendError(f"{path}: OpenCASCADE reports: {'; '.join(occ.fails) or 'no shape'}")
    if occ.transferred < occ.roots:
        raise BackendError(f"{path}: OpenCASCADE transferred {occ.transferred} of {occ.roots} roots")
    from rgm.backends.mesh import face_samples

    objs = model.exported()
    parts = [sample_object(o, tol, 5) for o in objs if isinstance(o, Curve)]
    if any(not isinstance(o, Curve) for o in objs):  # trimmed faces: points inside the trim only
        parts.append(face_samples([o for o in objs if not isinstance(o, Curve)], 30)[0])
    pts = np.concatenate(parts) * _MM.get(model.units, 1.0)   # OpenCASCADE reads IGES in mm
    occ_dev = float(distances_to_shape(pts, occ.shape).max()) / _MM.get(model.units, 1.0)
    if not occ_dev <= tol:
        raise BackendError(f"{path}: read back by OpenCASCADE, the file deviates {occ_dev:.3g} from the "
                           f"model (tolerance {tol:g})")
    return {"rgm": rgm_dev, "occ": occ_dev, "tol": tol}
