"""Fit certificates: how far the filtered scan points lie from the model, measured, never estimated.

Every figure comes from exact closest-point distances of the points used to the built surface (the
shape's own `distance`: the meridian-plane distance for a full surface of revolution, the box's exact
distance function).  `coverage` is the share of the model's surface that has data: surface samples
(spacing ~ the scan's point spacing) with a scan point within 3 spacings.

Which statistic does the tolerance bound?  On real scans the maximum includes the scanner's noise and
the few outliers that survive filtering, so by default the tolerance bounds the 95th percentile
(`statistic="p95"`); `"max"` and `"p99"` may be asked for.  The certificate states its statistic, and rgm
never chases noise to meet it: a certificate that does not hold is reported, not forced.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Certificate", "certify", "STATISTICS"]

STATISTICS = ("max", "p99", "p95")


@dataclass(frozen=True)
class Certificate:
    """points: count used; max, rms, p95, p99: deviations (model units); coverage in [0, 1];
    tol: the tolerance asked for; statistic: the figure that tol bounds."""

    points: int
    max: float
    rms: float
    p95: float
    p99: float
    coverage: float
    tol: float
    statistic: str

    @property
    def value(self) -> float:
        """The bounded statistic's value."""
        return {"max": self.max, "p99": self.p99, "p95": self.p95}[self.statistic]

    @property
    def holds(self) -> bool:
        return self.value <= self.tol

    def as_dict(self) -> dict:
        return {**asdict(self), "holds": self.holds}


def certify(distances, tol: float, *, statistic: str = "p95", coverage: float = float("nan")) -> Certificate:
    """Certificate from the points' closest-point distances (n,) to the model (model units)."""
    if statistic not in STATISTICS:
        raise ValueError(f"statistic must be one of {', '.join(STATISTICS)}, not {statistic!r}")
    d = np.abs(np.asarray(distances, float))
    if d.size == 0:
        raise ValueError("a certificate needs at least one point")
    p95, p99 = np.percentile(d, [95, 99])
    return Certificate(int(d.size), float(d.max()), float(np.sqrt(np.mean(d * d))), float(p95), float(p99),
                       float(coverage), float(tol), statistic)


def surface_coverage(surface_samples, points, radius: float) -> float:
    """Share of `surface_samples` (m, 3) with a point of `points` (n, 3) within `radius`."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(points).query(surface_samples, k=1, distance_upper_bound=radius)
    return float(np.mean(np.isfinite(d)))
