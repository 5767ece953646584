"""Surface-plane, surface-surface and curve-plane intersections by marching (work in progress)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class IntersectionBranch:
    """One connected branch of an intersection.

    curve: 3-D NurbsCurve; uv_a / uv_b: 2-D NurbsCurves over the same parameter interval in the
    parameter spaces of the first / second surface (uv_b None when the second operand is a bare
    plane given by origin and normal); max_error: measured max distance (model units) of the 3-D curve
    and of both surface images of the uv curves from the true intersection, <= the requested tol.
    """

    curve: object
    uv_a: object
    uv_b: object | None
    max_error: float
    closed: bool = False
