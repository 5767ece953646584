"""B-spline validity rules on folded constants (Piegl & Tiller 2.2): oracles from the definitions."""
import numpy as np
from hypothesis import given, settings, strategies as st

from rgm.compiler import values as V


@given(st.integers(1, 5), st.integers(0, 12))
@settings(max_examples=40, deadline=None)
def test_uniform_knots_are_valid_for_their_own_count(degree, extra):
    count = degree + 1 + extra
    k = V.uniform_knots(degree, count)
    assert len(k.values) == count + degree + 1
    assert V.knot_vector_problems(k, degree, count) == []
    inner = np.diff(k.values[degree:len(k.values) - degree])
    assert np.allclose(inner, inner[0])                        # uniform interior spacing


@given(st.lists(st.floats(0, 1), max_size=10), st.integers(1, 4))
@settings(max_examples=50, deadline=None)
def test_order_and_multiplicity_agree_with_a_direct_count(interior, degree):
    k = V.clamped_knots(degree, interior)
    problems = V.knot_vector_problems(k, degree, None)
    decreasing = any(b < a for a, b in zip(k.values, k.values[1:]))
    counts = {v: k.values.count(v) for v in k.values}
    too_many = any(c > (degree + 1 if v in (0.0, 1.0) else degree) for v, c in counts.items())
    codes = [p.code for p in problems]
    assert ("E0402" in codes) == decreasing
    if not decreasing:
        assert ("E0404" in codes) == too_many


def test_messages_point_at_the_offending_element():
    p = V.knot_order_problem([0, 0, 0.7, 0.5, 1, 1])
    assert p.index == 3 and "0.5 after 0.7" in p.message and "4th" in p.message
    assert V.weight_problem([1, 2, 0, -1]).index == 2
    assert V.ragged_problem([3, 3, 2]).index == 2
    assert V.multiplicity_problem([0, 0, 0.5, 0.5, 0.5, 1, 1], 2).message.startswith("interior knot 0.5 appears 3 times")
    assert V.degree_problem(0).code == "E0401" and V.degree_problem(2) is None


def test_count_rule_names_the_helper_degree():
    probs = V.knot_vector_problems(V.clamped_knots(2, []), 3, 4)
    assert [p.code for p in probs] == ["E0403"]
    assert "needs 8" in probs[0].message and "built by `clamped` for degree 2" in probs[0].hint


def test_ordinals():
    assert [V.ordinal(i) for i in (1, 2, 3, 4, 11, 12, 13, 21, 22, 101)] == \
        ["1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "101st"]
