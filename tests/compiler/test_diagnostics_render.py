"""Rendering of diagnostics: the long form with carets, the short form, JSON, ordering and dedupe."""
import json

from hypothesis import given, settings, strategies as st

from rgm.compiler.diagnostics import Span, error, render, short, sort_and_dedupe, summary, to_dict, warning

SRC = "units mm;\n" * 13 + "pin := revolve(profile, axis, to: 360mm);\n"


def test_long_form_matches_the_style_guide():
    d = error("E0301", "`to` of `revolve` expects an angle, found a length", Span("examples/pin.rgm", 14, 35, 14, 40),
              "this is a length", ["revolve(profile: curve3, axis: curve3, from: angle = 0deg, to: angle = 360deg) -> surface"],
              "did you mean `360deg`?")
    assert render(d, {"examples/pin.rgm": SRC}) == """\
error[E0301]: `to` of `revolve` expects an angle, found a length
  --> examples/pin.rgm:14:35
   |
14 | pin := revolve(profile, axis, to: 360mm);
   |                                   ^^^^^ this is a length
   = note: revolve(profile: curve3, axis: curve3, from: angle = 0deg, to: angle = 360deg) -> surface
   = help: did you mean `360deg`?"""
    assert short(d) == "examples/pin.rgm:14:35: error[E0301]: `to` of `revolve` expects an angle, found a length"


def test_tabs_are_copied_so_carets_line_up():
    d = warning("W0101", "unused", Span("f.rgm", 1, 3, 1, 4))
    lines = render(d, {"f.rgm": "\t\tx := 1;\n"}).splitlines()
    assert lines[-1].endswith("| \t\t^")


def test_multiline_span_underlines_to_end_of_first_line_and_missing_source_is_tolerated():
    d = error("E0103", "cycle", Span("f.rgm", 1, 6, 3, 2))
    assert render(d, {"f.rgm": "a := b(\n1,\n2);"}).splitlines()[-1] == "  |      ^^"
    assert render(d, {}) == "error[E0103]: cycle\n --> f.rgm:1:6"
    assert render(error("E0999", "internal", None)) == "error[E0999]: internal"
    past_end = error("E0001", "unexpected end of file", Span("f.rgm", 2, 1, 2, 1))
    assert render(past_end, {"f.rgm": "x"}).endswith("--> f.rgm:2:1")


def test_json_round_trip():
    d = error("E0101", "undefined name `profiel`", Span("a.rgm", 2, 5, 2, 12), "not defined", (), "did you mean `profile`?")
    data = json.loads(json.dumps([to_dict(d)]))
    assert data[0]["line"] == 2 and data[0]["col"] == 5 and data[0]["hint"] == "did you mean `profile`?"


@given(st.lists(st.tuples(st.sampled_from(["a.rgm", "b.rgm"]), st.integers(1, 5), st.integers(1, 5),
                          st.booleans()), max_size=12))
@settings(max_examples=40, deadline=None)
def test_sorted_by_position_and_one_per_span(entries):
    diags = [(error if err else warning)("E0001", f"m{i}", Span(f, line, col, line, col + 1))
             for i, (f, line, col, err) in enumerate(entries)]
    out = sort_and_dedupe(diags)
    keys = [(d.span.file, d.span.line, d.span.col) for d in out]
    assert keys == sorted(keys) and len(set(keys)) == len(keys)
    assert set(keys) == {(f, line, col) for f, line, col, _ in entries}
    firsts = {}
    for d in diags:
        firsts.setdefault((d.span.file, d.span.line, d.span.col), d.message)
    assert all(firsts[(d.span.file, d.span.line, d.span.col)] == d.message for d in out)


def test_summary_counts():
    s = Span("f", 1, 1, 1, 2)
    assert summary([error("E1", "a", s), warning("W1", "b", s), warning("W1", "c", s)]) == "1 error, 2 warnings"
    assert summary(iter([])) == "0 errors, 0 warnings"
