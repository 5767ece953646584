"""Units of the `.rgm` language: lengths (mm, cm, m, in) and angles (deg, rad).

A number literal may carry a unit suffix (`10mm`, `90deg`); the suffix fixes its dimension. Lengths
are converted to the model's units (`units mm;`, the default), angles to radians, so that everything
after the front end is a plain float in model units or radians (docs/architecture.md, Conventions).
"""
from __future__ import annotations

import math

#: millimetres per unit of length
LENGTH_UNITS: dict[str, float] = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: radians per unit of angle
ANGLE_UNITS: dict[str, float] = {"deg": math.pi / 180.0, "rad": 1.0}
#: every unit suffix the language knows
ALL_UNITS: tuple[str, ...] = tuple(LENGTH_UNITS) + tuple(ANGLE_UNITS)
DEFAULT_MODEL_UNITS = "mm"


def dimension(unit: str | None) -> str | None:
    """The dimension of a literal with this suffix: "length", "angle", "num" (no suffix), None (unknown unit)."""
    if unit is None or unit == "":
        return "num"
    if unit in LENGTH_UNITS:
        return "length"
    if unit in ANGLE_UNITS:
        return "angle"
    return None


def length_factor(unit: str, model_units: str = DEFAULT_MODEL_UNITS) -> float:
    """How many model units one `unit` is (1in in a `units mm;` model is 25.4)."""
    return LENGTH_UNITS[unit] / LENGTH_UNITS[model_units]


def to_model(value: float, unit: str | None, model_units: str = DEFAULT_MODEL_UNITS) -> float:
    """A literal's value in model units (lengths) or radians (angles); unitless values are returned as is.

    Raises KeyError for an unknown unit: the checker reports those before anything is converted.
    """
    if unit is None or unit == "":
        return float(value)
    if unit in ANGLE_UNITS:
        return float(value) * ANGLE_UNITS[unit]
    return float(value) * length_factor(unit, model_units)
