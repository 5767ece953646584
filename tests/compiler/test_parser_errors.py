"""Syntax diagnostics: codes, positions, labels and hints for each kind of mistake, several errors per
run, and robustness: random byte-, token- and line-level mutations of the examples give diagnostics,
never an exception, and every diagnostic points inside the text."""
import random
import re
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from rgm.compiler.diagnostics import render
from rgm.compiler.parser import parse

EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "examples").glob("*.rgm"))
SOURCES = [p.read_text() for p in EXAMPLES]


def diags_of(text):
    program, diags = parse(text, "t.rgm")
    return program, [(d.code, d.span.line, d.span.col) for d in diags], diags


# (source, [(code, line, col)], a fragment of the first message or label or hint)
CASES = [
    ("a := 1\nb := 2;\n", [("E0005", 1, 7)], "expected `;` here"),
    ("a := f(1 2);\n", [("E0001", 1, 10)], "is a `,` missing?"),
    ('a := "abc\n', [("E0003", 1, 6)], "unterminated string"),
    ("a = 3;\n", [("E0002", 1, 3)], "bindings are written `name := value;`"),
    ("a := 4 $ 5;\n", [("E0002", 1, 8)], "unexpected character `$`"),
    ("a := [1, 2;\n", [("E0001", 1, 11)], "expected `,`, `]` or an operator"),
    ("units := 3;\n", [("E0001", 1, 7)], "`units` is a keyword"),
    ("a := f(x: 1, 2);\n", [("E0007", 1, 14)], "positional argument"),
    ("n := net 2 x 2 [1 2 3, 4 5 6, 7 8 9];\n", [("E0004", 1, 6)], "needs 4 entries, found 3"),
    ("n := net 2 [1 2 3, 4 5];\n", [("E0004", 1, 20)], "entry 2 of this net has 2 numbers"),
    ("n := net 2 [1 2 3, 4 z 6];\n", [("E0004", 1, 22)], "`z` cannot appear in a net"),
    ("n := net 2 [1 2 3, 4 5 6 # c\n];\n", [("E0004", 1, 26)], "a comment cannot go inside a net"),
    ("n := net 2 [1 2 3, 4 5.5.5 6];\n", [("E0004", 1, 22)], "`5.5.5` is not a number"),
    ("n := net 1 [1 2 3 4 5];\n", [("E0004", 1, 6)], "1 to 4 numbers"),
    ("n := net 0 x 2 [];\n", [("E0004", 1, 6)], "between 1 and 10^8"),
    ("n := net 4 x 4 [1 2 3, 4 5 6\n", [("E0004", 1, 10)], "malformed net"),
    ("n := net 2 [1 2 3, 4 5 6;\nm := [1];\n", [("E0004", 1, 25)],
     "closing `]` missing"),
    ("n := net 1 [1e999 0 0];\n", [("E0004", 1, 13)], "too large"),
    ("a := 1e999;\n", [("E0006", 1, 6)], "too large for a 64-bit float"),
    ("units furlongs;\n", [("E0008", 1, 7)], "unknown units `furlongs`"),
    ("a := (1 + 2;\n", [("E0001", 1, 12)], "expected `)`"),
    ("a := ;\n", [("E0001", 1, 6)], "an expression"),
    ("a := 1", [("E0005", 1, 7)], "missing `;`"),
    ("fn f(a) := a;\n", [("E0001", 1, 7)], "expected `:`"),
    ("@fit(points 3)\na := 1;\n", [("E0001", 1, 13)], "expected `:`"),
    ("export;\n", [("E0001", 1, 7)], "expected a name"),
    ("a := b.;\n", [("E0001", 1, 8)], "expected a name"),
    ("a := 1 +\n", [("E0001", 1, 8)], "unexpected end of file"),
    ("a := 3 4mm;\n", [("E0001", 1, 8)], "expected `;`"),
]


@pytest.mark.parametrize("source,expected,fragment", CASES, ids=[c[0][:18] for c in CASES])
def test_each_mistake_is_reported_at_its_place(source, expected, fragment):
    _, found, diags = diags_of(source)
    assert found[: len(expected)] == expected, [render(d, {"t.rgm": source}) for d in diags]
    text = " ".join(f"{d.message} {d.label} {d.hint or ''}" for d in diags)
    assert fragment in text


def test_several_errors_in_one_run_and_the_rest_still_parses():
    source = "a := 1\nb := f(1 2);\nc := [1, 2;\nd := pt(1, 2, 3);\ne := 3 $;\nf := d;\n"
    program, found, _ = diags_of(source)
    assert [c for c, _, _ in found] == ["E0005", "E0001", "E0001", "E0002"]
    assert [s.name for s in program.statements] == ["a", "d", "e", "f"]   # `$` skipped, `e := 3;` kept


def test_broken_bindings_are_named_for_the_checker():
    program, _, _ = diags_of("n := net 2 [1 2 3];\ng := f(a: 1, 2);\nok := 1;\n")
    assert program.broken == {"n", "g"}
    assert [s.name for s in program.statements] == ["ok"]


def test_a_run_of_junk_is_one_diagnostic():
    _, found, diags = diags_of("a := 1 \x00\x01\x02\x03 + 2;\n")
    assert [c for c, _, _ in found] == ["E0002"]
    assert diags[0].message == "unexpected characters" and diags[0].span.end_col - diags[0].span.col == 4


def test_too_many_errors_stops_with_a_note():
    _, found, _ = diags_of("a := ;\n" * 200)
    assert found[-1][0] == "E0009" and len(found) <= 41


def test_bytes_are_decoded_with_replacement():
    program, found, _ = diags_of(b"a := 1;\n\xff\xfe := 2;\n")
    assert found[0][0] == "E0002" and [s.name for s in program.statements] == ["a"]


def test_deep_nesting_is_a_diagnostic_not_a_crash():
    _, found, _ = diags_of("a := " + "(" * 5000 + "1" + ")" * 5000 + ";\n")
    assert found == [] or found[0][0] in ("E0009", "E0001")


def _check_never_raises(text):
    program, diags = parse(text, "m.rgm")
    n = len(text)
    for d in diags:
        assert d.span is not None and 0 <= d.span.start_pos <= d.span.end_pos <= n, d
        assert d.span.line >= 1 and d.span.col >= 1
        render(d, {"m.rgm": text})
    assert program is not None


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(SOURCES), st.lists(st.tuples(st.floats(0, 1), st.binary(min_size=0, max_size=4)),
                                          min_size=1, max_size=4))
def test_byte_mutations_never_raise(source, edits):
    data = bytearray(source.encode())
    for where, junk in edits:
        i = int(where * len(data))
        data[i:i + len(junk) // 2 + 1] = junk
    _check_never_raises(bytes(data).decode("utf-8", errors="replace"))


TOKEN = re.compile(r'"[^"\n]*"|[A-Za-z_][A-Za-z0-9_]*|[0-9.]+[a-z]*|:=|\S')
JUNK = [";", ",", "(", ")", "[", "]", ":=", ":", "@fit", "net 2 x 2 [", "]", '"', "#", "param", "-", ".", "x"]


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(SOURCES), st.randoms(use_true_random=False), st.integers(1, 5))
def test_token_mutations_never_raise(source, rnd: random.Random, count):
    tokens = [m.group() for m in TOKEN.finditer(source)]
    for _ in range(count):
        i = rnd.randrange(len(tokens))
        op = rnd.choice(["drop", "dup", "swap", "junk"])
        if op == "drop":
            del tokens[i]
        elif op == "dup":
            tokens.insert(i, tokens[i])
        elif op == "swap" and i + 1 < len(tokens):
            tokens[i], tokens[i + 1] = tokens[i + 1], tokens[i]
        else:
            tokens.insert(i, rnd.choice(JUNK))
    _check_never_raises(" ".join(tokens))


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(SOURCES), st.randoms(use_true_random=False), st.integers(1, 4))
def test_line_mutations_never_raise(source, rnd: random.Random, count):
    lines = source.splitlines()
    for _ in range(count):
        i = rnd.randrange(len(lines))
        op = rnd.choice(["drop", "dup", "cut"])
        if op == "drop":
            del lines[i]
        elif op == "dup":
            lines.insert(i, lines[i])
        else:
            lines[i] = lines[i][: rnd.randrange(len(lines[i]) + 1)]
    _check_never_raises("\n".join(lines))
