"""The evaluated model (IR): immutable geometric objects with names and source spans.

Back ends, fitters and users read these; see docs/architecture.md for the contract.
"""
from rgm.model.lazy import IntersectionCurve
from rgm.model.objects import (
    GEOMETRY, BSplineCurve, ModelObject, BSplineSurface, Circle, CircularArc, CompositeCurve, Curve, Extrusion, HPoint, Line,
    Loop, Model, Plane, Point, Polyline, Revolution, RuledSurface, Shell, Surface, TrimmedFace, Vector,
    frozen_array,
)
from rgm.model.transform import Transform

__all__ = [
    "GEOMETRY", "BSplineCurve", "BSplineSurface", "Circle", "CircularArc", "CompositeCurve", "Curve", "Extrusion",
    "HPoint", "IntersectionCurve", "Line", "Loop", "Model", "ModelObject", "Plane", "Point", "Polyline", "Revolution",
    "RuledSurface", "Shell", "Surface", "Transform", "TrimmedFace", "Vector", "frozen_array",
]
