"""The program generator (strategies.py) held to the language's tables: every builtin of the signature
table, every member of the member table, every fn parameter kind and every value only `_`-names hold
heads some generated program, and generated programs use every operator, unit, annotation, node and
comment position. Each of those programs round-trips through the formatter and checks without
errors; generated programs also evaluate (and validate) without an exception: what evaluation finds
is a diagnostic with a span inside the file."""
import typing

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from rgm import model as M
from rgm.compiler import ast as A
from rgm.compiler.api import compile_text
from rgm.compiler.builtins import ANNOTATIONS, FUNCTIONS
from rgm.compiler.check import check
from rgm.compiler.format import format_program
from rgm.compiler.parser import parse
from rgm.compiler.types import MEMBERS

from strategies import FN_PARAMS, OTHER_VALUES, features, programs

#: (last, focus, alternatives): generated programs headed so, each using one feature of every alternative
CASES = ([(name, None, ({f"call:{name}"},)) for name in sorted(FUNCTIONS)]
         + [("member", f"{kind}.{attr}", ({f"member:{attr}"},)) for kind in sorted(MEMBERS) for attr in MEMBERS[kind]]
         + [("fn", kind, ({f"fn-param:{spelled}" for spelled in FN_PARAMS[kind]}, {"call:fn"}))
            for kind in sorted(FN_PARAMS)]
         + [("other", value, ({"net:1d" if value == "net1" else "net:2d" if value == "net" else "string"},))
            for value in OTHER_VALUES])
#: what every batch of generated programs uses between them (fns: see CASES)
CONSTRUCTS = ({f"@{name}" for name in ANNOTATIONS} | {f"op:{op}" for op in "+-*/"} | {f"unit:{u}" for u in A.UNITS}
              | {f"node:{c.__name__}" for c in typing.get_args(A.Expr) + typing.get_args(A.Stmt) + (A.Annotation,)
                 if c is not A.FnDef}
              | {"param", "kwarg", "comment:leading", "comment:trailing", "comment:end"})


def _round_trip_and_check(program: A.Program) -> str:
    text = format_program(program)
    parsed, diags = parse(text, "gen.rgm")
    assert [d for d in diags if d.is_error] == [], text
    assert parsed == program, text
    assert format_program(parsed) == text
    assert [d for d in check(parsed).diagnostics if d.is_error] == [], text
    return text


@pytest.mark.parametrize("last, focus, wanted", CASES, ids=[f"{c[0]}-{c[1]}" if c[1] else c[0] for c in CASES])
@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_every_builtin_member_and_fn_parameter_kind_is_generated(last, focus, wanted, data):
    program = data.draw(programs(max_bindings=3, last=last, focus=focus))
    used = features(program)
    assert all(options & used for options in wanted), (wanted, format_program(program))
    _round_trip_and_check(program)


def test_generated_programs_use_every_construct():
    seen: set[str] = set()

    # enough examples that every construct turns up whichever order the suite runs in (40 missed `rad` once)
    @settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(programs())
    def collect(program):
        seen.update(features(program))

    collect()
    assert CONSTRUCTS - seen == set()


# nets hold any finite double (1e308) for the formatter's sake: moving one may overflow to inf
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs())
def test_generated_programs_evaluate_or_give_diagnostics(program):
    text = _round_trip_and_check(program)
    model, diagnostics = compile_text(text, "gen.rgm")
    n_lines = text.count("\n") + 1
    for d in diagnostics:
        assert d.code.startswith(("E05", "W05")) or not d.is_error, d   # checked clean: only evaluation finds more
        assert d.span is None or 1 <= d.span.line <= n_lines, d
    if model is None:
        assert any(d.is_error for d in diagnostics)
        return
    for name in model.exports:
        assert model[name].name == name and model[name].span is not None
    for name, value in model.objects.items():
        if isinstance(value, M.Transform):
            assert value.matrix.shape == (4, 4) and value.span is not None
