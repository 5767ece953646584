"""The fast paths of the front end give what the general paths give: compiled statement shapes (the
builder's work written out by rgm.compiler.parser._Inliner) against lark's own parse loop, on the
unusual statements where a template declines or takes a slow path; lexing piece by piece around
nets that span the cut; the collector pause of rgm.compiler.gcpause."""
import gc

import pytest

from rgm.compiler import ast as A
from rgm.compiler import gcpause, lalr
from rgm.compiler.check import check
from rgm.compiler.parser import parse

STATEMENTS = [
    'a := pt(1mm, -2, 3.5e1);',
    'param r := 2.5in;',
    'b := f(x: 1, 2);',                                  # E0007: positional after named (template declines)
    'c := 1e999 + 2;',                                   # E0006: out of range (slow number path)
    's := "a \\"quoted\\" \\\\ text\\n";',               # escapes
    'm := (p - q).length * -(2 / 3);',                   # member, neg, parentheses
    'l := [pt(0, 0, 0), pt(1, 1, 1),];',
    'n := net 2 x 2 [0 0 0, 1 0 0, 0 1 0, 1 1 1];',
    'e := net 2 x 2 [0 0 0, 1 0 0, 0 1 0];',             # E0004: wrong count (statement dropped)
    'u := net 2 [1 2 x];',                               # E0004: stray character
    '@classified\n@fit(points: 10, max: 0.1mm,)\nk := revolve(c, axis, from: 0deg, to: 90deg);',
    'fn g(x: num, y: list[point3]) := x * 2;',
    'export a, b, k,;',
    'units mm;',
    'tolerance 0.01;',
]


def _spans(program):
    return [(type(n).__name__, n.span) for n in A.walk(program) if hasattr(n, "span")]


@pytest.mark.parametrize("stmt", STATEMENTS)
def test_compiled_shape_matches_lark(stmt):
    """Each statement four times over (the third and fourth go through its compiled shape): the same
    tree, spans, diagnostics and check diagnostics as lark's loop."""
    text = "# head\n" + "\n".join(f"{stmt}  # after {i}" for i in range(4)) + "\n# tail\n"
    fast, d1 = parse(text, "f.rgm")
    slow, d2 = parse(text, "f.rgm", fast=False)
    assert d1 == d2
    assert fast == slow
    assert _spans(fast) == _spans(slow)
    assert [c.span for c in fast.comments] == [c.span for c in slow.comments]
    if not any(d.is_error for d in d1):
        assert check(fast).diagnostics == check(slow).diagnostics


def test_pieces_around_nets_spanning_the_cut():
    """Nets over many lines placed across the 64 KB cuts of the lexer: the same tree and spans as
    lark's loop (whose lexer reads the text whole)."""
    rows = ",\n      ".join(f"{i} 0 {i % 7}, {i} 1 0, {i} 2 1" for i in range(40))
    net = f"s{{i}} := bsurface(degree_u: 1, degree_v: 1, knots_u: uniform(1, 40), knots_v: uniform(1, 3),\n" \
          f"  net: net 40 x 3 [\n      {rows}]);\n"
    text = "".join("".join(f"x{i}_{j} := pt({j}, 0, 0);  # filler\n" for j in range(150 + 53 * i % 300))
                   + net.replace("{i}", str(i)) for i in range(40))
    nets = [(text.index("net 40", k), text.index("]", text.index("net 40", k)))
            for k in range(len(text)) if text.startswith("net 40", k)]
    first_newlines = [text.find("\n", k * lalr._PIECE) for k in range(1, len(text) // lalr._PIECE + 1)]
    assert any(a < nl < b for nl in first_newlines for a, b in nets), "no cut falls inside a net"
    fast, d1 = parse(text, "big.rgm")
    slow, d2 = parse(text, "big.rgm", fast=False)
    assert d1 == d2 == []
    assert fast == slow and _spans(fast) == _spans(slow)


def test_cut_is_never_inside_a_net():
    text = "a := 1;\n" * 10 + "n := net 3 [1,\n2,\n3];\n" + "b := 2;\n" * 10
    start = text.index("net 3")
    for at in range(len(text)):
        cut = lalr._cut(text, 0, at)
        assert cut == len(text) or text[cut - 1] == "\n"
        assert not start < cut < text.index("];") + 1


def test_gc_pause_restores_the_collector():
    assert gc.isenabled()
    with gcpause.paused():
        assert not gc.isenabled()
        garbage = [[] for _ in range(1000)]
    del garbage
    assert gc.isenabled() and gc.get_freeze_count() == 0
    gc.disable()
    try:
        with gcpause.paused():
            pass
        assert not gc.isenabled()       # a caller that had it off keeps it off
    finally:
        gc.enable()


@pytest.mark.parametrize("text", [
    "a := 1;\n(", "a := 1; ,", "a := 1;\n:\n", "a := 1;(  \n  ", "a := f(\n", "a := 1; # c\n,",
    "a := f(  ,\n  :x);", "a := f(x\n  : 1,\n(2));", "a :\n= 1;", "a ::= 1;", "a := f(,(", "a := pt(1,2,3)\n,,\n",
])
def test_punctuation_read_with_the_blanks(text):
    """`(`, `,` and `:` are read by the fast lexer with the blanks before a token (a gap); a gap that
    no token follows (at the end of the file) is still an error, and the result is lark's."""
    fast, d1 = parse(text, "g.rgm")
    slow, d2 = parse(text, "g.rgm", fast=False)
    assert d1 == d2
    assert fast == slow and _spans(fast) == _spans(slow)


def test_gaps_and_newlines_across_pieces():
    """Gaps holding newlines and dropped punctuation on both sides of the lexer's 64 KB cuts: the same
    lines and columns as lark's loop."""
    stmt = "v{i} := f(\n    a,\n  (b)  ,\n  c: (1),\n);  # n{i}\n"
    text = "".join(stmt.format(i=i) for i in range(2 * lalr._PIECE // len(stmt) + 50))
    fast, d1 = parse(text, "h.rgm")
    slow, d2 = parse(text, "h.rgm", fast=False)
    assert d1 == d2
    assert _spans(fast) == _spans(slow)
    assert [c.span for c in fast.comments] == [c.span for c in slow.comments]


@pytest.mark.parametrize("text, order", [
    ("a := 1; b := a + 1; c := b * a;", ["a", "b", "c"]),             # only earlier names: the source order
    ("c := b * a; b := a + 1; a := 1;", ["a", "b", "c"]),             # later names: dependencies first
    ("a := 1; fn f(x: num) := x + a; b := f(2); c := b;", ["a", "b", "c"]),
    ("a := 1; b := f(2); fn f(x: num) := x + a; c := b;", ["a", "b", "c"]),
    ("a := b; b := a; c := 1;", ["c"]),                                # a cycle (E0103) is left out
])
def test_evaluation_order(text, order):
    program, _ = parse(text, "o.rgm")
    assert check(program).order == order
