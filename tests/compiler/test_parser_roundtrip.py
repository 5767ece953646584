"""parse(format(tree)) == tree for generated well-typed programs, formatting is idempotent, and the fast
LALR driver builds exactly the tree that lark's own parse loop builds."""
import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from rgm.compiler import ast as A
from rgm.compiler.format import format_program
from rgm.compiler.parser import _BUILDER, _Run, fast_parser, parse

from strategies import net, programs

SETTINGS = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _parse_ok(text):
    program, diags = parse(text, "gen.rgm")
    assert [d for d in diags if d.is_error] == [], (text, diags)
    return program


@SETTINGS
@given(programs())
def test_parse_of_format_is_the_tree(program):
    text = format_program(program)
    assert _parse_ok(text) == program, text


@SETTINGS
@given(programs())
def test_format_is_idempotent(program):
    text = format_program(program)
    assert format_program(_parse_ok(text)) == text


@SETTINGS
@given(programs())
def test_fast_driver_builds_the_same_tree_and_spans_as_lark(program):
    text = format_program(program)
    run = _Run(text, "gen.rgm")
    _BUILDER.run = run
    assert fast_parser().parse(text, run.comments.append), "the fast driver fell back on valid text"
    fast, d1 = parse(text, "gen.rgm")
    slow, d2 = parse(text, "gen.rgm", fast=False)
    assert fast == slow and d1 == d2
    spans = lambda p: [n.span for n in A.walk(p) if hasattr(n, "span")]
    assert spans(fast) == spans(slow)


@SETTINGS
@given(programs())
def test_compiled_statement_shapes_build_what_the_table_builds(program):
    """The program four times over: a statement shape is first built by running the table, then by
    the function compiled from it (rgm.compiler.lalr); both must give lark's tree and spans."""
    text = format_program(program) * 4
    fast, d1 = parse(text, "gen.rgm")
    slow, d2 = parse(text, "gen.rgm", fast=False)
    assert fast == slow and d1 == d2
    spans = lambda p: [n.span for n in A.walk(p) if hasattr(n, "span")]
    assert spans(fast) == spans(slow)


def test_statements_too_deep_to_compile_are_built_by_the_table():
    """Python's compiler refuses ~200 nested calls; such a shape keeps being built by running the table."""
    deep = "f(" * 300 + "1" + ")" * 300
    chain = " + ".join(["1"] * 3000)
    text = "".join(f"x{i} := {deep};\ny{i} := {chain};\n" for i in range(5))
    fast, d1 = parse(text, "deep.rgm")
    slow, d2 = parse(text, "deep.rgm", fast=False)
    assert d1 == d2 == [] and len(fast.statements) == 10   # (== on the trees would recurse too deeply)
    assert [(s.name, s.span) for s in fast.statements] == [(s.name, s.span) for s in slow.statements]


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(1, 6), st.integers(1, 4), st.data())
def test_net_values_round_trip_exactly(rows, cols, width, data):
    node = data.draw(net(rows, cols, width))
    program = A.Program((A.Binding("n", node),))
    back = _parse_ok(format_program(program)).statements[0].expr
    assert back.shape == (rows, cols) and back.width == width
    assert back.data.tobytes() == node.data.tobytes() or np.array_equal(back.data, node.data)


def test_spans_point_at_the_source():
    text = "units mm;\np := pt(1mm, 2, 3);\nq := p + vec(0, 0, 1);\n"
    program = _parse_ok(text)
    b = program.statements[2]
    assert (b.span.line, b.span.col, b.span.end_line, b.span.end_col) == (3, 1, 3, 23)
    assert (b.name_span.col, b.name_span.end_col) == (1, 2)
    right = b.expr.right
    assert text[right.span.start_pos:right.span.end_pos] == "vec(0, 0, 1)"
    assert (right.span.line, right.span.col) == (3, 10)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs())
def test_generated_programs_are_well_typed(program):
    """The strategies' contract: the checker finds no error in what they draw."""
    from rgm.compiler.check import check

    result = check(_parse_ok(format_program(program)))
    assert [d for d in result.diagnostics if d.is_error] == []
