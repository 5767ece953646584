"""Constant values the checker can know before evaluation, and the rules they must obey.

The checker folds literal and constant expressions (numbers with units, lists, points, nets, the knot
helpers `clamped`/`uniform`/`knots`) into the small values below, then applies the validity rules of
a B-spline (Piegl & Tiller, *The NURBS Book*, 2nd ed., section 2.2 and 3.2): a knot vector is
non-decreasing, has n + p + 1 values for n control points of degree p, no interior knot repeats more
than p times, weights are positive and control nets are rectangular. Each rule returns a `Problem`
naming the offending piece so the caller can put the caret on the right argument.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Knots:
    """A folded knot vector. `degree` is the degree a helper built it for (`clamped(3)`), else None;
    `helper` is the helper's name ("clamped", "uniform", "knots")."""

    values: tuple[float, ...]
    degree: int | None = None
    helper: str = "knots"


@dataclass(frozen=True)
class Problem:
    """A violated rule: `code`, `message`, and `index` of the offending element (None: the whole value)."""

    code: str
    message: str
    index: int | None = None
    hint: str | None = None


def clamped_knots(degree: int, interior) -> Knots:
    """p+1 zeros, the interior values, p+1 ones: a clamped (open) knot vector on [0, 1]."""
    return Knots((0.0,) * (degree + 1) + tuple(float(t) for t in interior) + (1.0,) * (degree + 1), degree, "clamped")


def uniform_knots(degree: int, count: int) -> Knots:
    """The clamped knot vector on [0, 1] with uniformly spaced interior knots for `count` control points."""
    inner = count - degree - 1
    interior = tuple((i + 1) / (inner + 1) for i in range(max(inner, 0)))
    return Knots((0.0,) * (degree + 1) + interior + (1.0,) * (degree + 1), degree, "uniform")


def ordinal(i: int) -> str:
    """1 -> "1st", 2 -> "2nd", 11 -> "11th"."""
    suffix = "th" if 10 <= i % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(i % 10, "th")
    return f"{i}{suffix}"


def _fmt(x: float) -> str:
    return f"{x:g}"


def degree_problem(degree: int) -> Problem | None:
    if degree < 1:
        return Problem("E0401", f"degree must be at least 1, found {degree}")
    return None


def knot_order_problem(values) -> Problem | None:
    """The first place where the knot vector decreases."""
    v = np.asarray(values, dtype=float)
    bad = np.flatnonzero(np.diff(v) < 0)
    if bad.size:
        i = int(bad[0]) + 1
        return Problem("E0402", f"knot vector decreases at its {ordinal(i + 1)} value: "
                                f"{_fmt(v[i])} after {_fmt(v[i - 1])}", i,
                       "knots must be non-decreasing")
    return None


def multiplicity_problem(values, degree: int) -> Problem | None:
    """An interior knot repeated more than `degree` times (the curve would break apart there), or an
    end knot more than degree + 1 times."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return None
    uniq, first, counts = np.unique(v, return_index=True, return_counts=True)
    for value, start, count in zip(uniq, first, counts):
        end = value in (v[0], v[-1])
        limit = degree + 1 if end else degree
        if count > limit:
            where = "end" if end else "interior"
            return Problem("E0404", f"{where} knot {_fmt(value)} appears {count} times; "
                                    f"a degree-{degree} spline allows at most {limit}", int(start))
    return None


def count_problem(n_knots: int, degree: int, n_ctrl: int, what: str = "control points") -> Problem | None:
    """len(knots) must be n + degree + 1 (P&T eq. 2.4 / 3.1: m + 1 = n + p + 2 with n + 1 points)."""
    need = n_ctrl + degree + 1
    if n_knots != need:
        return Problem("E0403", f"knot vector has {n_knots} values but degree {degree} with {n_ctrl} {what} "
                                f"needs {need} (points + degree + 1)",
                       hint=f"with {n_knots} knots, degree {degree} takes {n_knots - degree - 1} {what}"
                       if n_knots - degree - 1 >= 1 else None)
    return None


def too_few_points_problem(n_ctrl: int, degree: int, what: str = "control points") -> Problem | None:
    if n_ctrl < degree + 1:
        return Problem("E0409", f"degree {degree} needs at least {degree + 1} {what}, found {n_ctrl}")
    return None


def weight_problem(weights) -> Problem | None:
    """The first weight that is not strictly positive (a rational B-spline needs w > 0, P&T 4.2)."""
    w = np.asarray(weights, dtype=float).ravel()
    bad = np.flatnonzero(~(w > 0))
    if bad.size:
        i = int(bad[0])
        return Problem("E0405", f"weights must be positive, the {ordinal(i + 1)} is {_fmt(w[i])}", i)
    return None


def ragged_problem(row_lengths: list[int]) -> Problem | None:
    """Rows of a control net given as nested lists must all have the same length."""
    for i, n in enumerate(row_lengths):
        if n != row_lengths[0]:
            return Problem("E0406", f"control net is ragged: row 1 has {row_lengths[0]} points "
                                    f"but row {i + 1} has {n}", i)
    return None


def knot_vector_problems(knots: Knots, degree: int | None, n_ctrl: int | None, what: str = "control points"):
    """Every rule for a knot vector used by a spline of `degree` over `n_ctrl` points (either may be
    unknown: None). Returns a list of Problems, most basic first."""
    out = [knot_order_problem(knots.values)]
    if degree is not None and degree >= 1:
        if out[0] is None:
            out.append(multiplicity_problem(knots.values, degree))
        if n_ctrl is not None:
            prob = count_problem(len(knots.values), degree, n_ctrl, what)
            if prob is not None and knots.degree is not None and knots.degree != degree:
                prob = Problem(prob.code, prob.message, None,
                               f"these knots were built by `{knots.helper}` for degree {knots.degree}; "
                               f"use {knots.helper}({degree}, ...)")
            out.append(prob)
    return [p for p in out if p is not None]
