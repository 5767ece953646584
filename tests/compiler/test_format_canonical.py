"""The formatter's canonical layout: headers first, comments kept where they were written, long calls
broken one argument per line, nets one row per line, parentheses only where precedence needs them;
the bundled examples are already canonical."""
from pathlib import Path

import numpy as np
import pytest

from rgm.compiler import ast as A
from rgm.compiler.format import format_program, format_source
from rgm.compiler.parser import parse

EXAMPLES = sorted((Path(__file__).resolve().parents[2] / "examples").glob("*.rgm"))


def fmt(text):
    out, diags = format_source(text, "f.rgm")
    assert out is not None, diags
    return out


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_examples_are_canonical(path):
    text = path.read_text()
    assert fmt(text) == text


def test_spacing_and_headers_first():
    src = "a:=f( 1,2 ,k :3 ) ;tolerance 0.01 ;\nunits   mm;export a ;"
    assert fmt(src) == "tolerance 0.01;\nunits mm;\n\na := f(1, 2, k: 3);\nexport a;\n"   # headers in source order


def test_comments_survive_in_place():
    src = ("# provenance\n# second line\nunits mm;  # the model's units\n\n# the axis\n"
           "axis := line(pt(0, 0, 0),  # origin\n   pt(0, 1, 0));  # y\n\n# the end\n")
    out = fmt(src)
    assert out == ("# provenance\n# second line\nunits mm;  # the model's units\n\n# the axis\n# origin\n"
                   "axis := line(pt(0, 0, 0), pt(0, 1, 0));  # y\n\n# the end\n")
    assert fmt(out) == out


def test_annotations_stay_with_their_binding():
    src = '@fit(points: 3, max: 0.1mm)\n@classified(as: "cylinder")\np := 1;\n'
    program, _ = parse(src, "f.rgm")
    assert [a.name for a in program.statements[0].annotations] == ["fit", "classified"]
    assert fmt(src) == src


def test_long_calls_break_one_argument_per_line():
    args = ", ".join(f"pt({i}, {i}, {i})" for i in range(12))
    out = fmt(f"p := polyline([{args}]);\n")
    lines = out.splitlines()
    assert lines[0] == "p := polyline(" and lines[1] == "    [" and lines[2] == "        pt(0, 0, 0),"
    assert lines[-2:] == ["    ],", ");"]
    assert all(len(line) <= 100 for line in lines)


def test_nets_are_printed_one_row_per_line():
    out = fmt("s := net 2 x 3 [0 0 0, 1 0 0, 2 0 0, 0 1 0, 1 1 0, 2 1.5 0];\n")
    assert out == "s := net 2 x 3 [\n    0 0 0, 1 0 0, 2 0 0,\n    0 1 0, 1 1 0, 2 1.5 0\n];\n"


def test_one_dimensional_nets_pack_to_the_width():
    out = fmt("k := net 3 [1, 2, 3];\nw := net 60 [" + ", ".join(["0.125"] * 60) + "];\n")
    assert out.startswith("k := net 3 [1, 2, 3];\nw := net 60 [\n")
    assert all(len(line) <= 100 for line in out.splitlines())
    assert parse(out, "f")[0].statements[1].expr.data.shape == (60, 1)


def test_floats_use_the_shortest_exact_form():
    values = np.array([[0.1, 1e-300, 5e-324], [1.7976931348623157e308, -0.0, 2.5]]).reshape(1, 2, 3)
    program = A.Program((A.Binding("n", A.Net((1, 2), 3, values)),))
    text = format_program(program)
    assert "0.1 1e-300 5e-324, 1.7976931348623157e+308 -0 2.5" in text
    assert parse(text, "f")[0].statements[0].expr.data.tobytes() == values.tobytes()


@pytest.mark.parametrize("src,canon", [
    ("a := (1 + 2) + 3;", "a := 1 + 2 + 3;"),
    ("a := 1 + (2 + 3);", "a := 1 + (2 + 3);"),
    ("a := 1 - (2 - 3);", "a := 1 - (2 - 3);"),
    ("a := (1 * 2) + 3 / (4 * 5);", "a := 1 * 2 + 3 / (4 * 5);"),
    ("a := -(1 + 2) * -3;", "a := -(1 + 2) * -3;"),
    ("a := - - b;", "a := --b;"),
    ("a := (p - q).length;", "a := (p - q).length;"),
    ("a := (2).x;", "a := (2).x;"),
    ("a := 1.50mm + 2e3 + 0007 + .5deg;", "a := 1.5mm + 2000.0 + 7 + 0.5deg;"),
    ('a := "say \\"hi\\"\\n\\tok\\\\";', 'a := "say \\"hi\\"\\n\\tok\\\\";'),
    ("fn f(a: num, b: list[point3],) := a;", "fn f(a: num, b: list[point3]) := a;"),
    ("@source\na := [ ];", "@source\na := [];"),
])
def test_parentheses_numbers_and_strings(src, canon):
    assert fmt(src) == canon + "\n"


def test_format_source_refuses_text_with_errors():
    out, diags = format_source("a := ;\n", "f.rgm")
    assert out is None and diags[0].code == "E0001"


def test_empty_program_formats_to_nothing():
    assert fmt("") == "" and fmt("# only a comment\n") == "# only a comment\n"


def test_absurd_nesting_is_reported_not_raised():
    out, diags = format_source("a := " + "-" * 20000 + "1;", "f.rgm")
    assert out is None and diags[-1].code == "E0009"
