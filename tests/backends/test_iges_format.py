"""The IGES file model: number spelling, Hollerith strings, record layout, the Global section, and the
tolerant parser's errors (which name the record)."""
from __future__ import annotations

import math
import re
import struct

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from rgm.backends.iges_format import Entity, GlobalSection, IgesFile, IgesFormatError, format_reals, hollerith
from rgm.backends.iges_parse import parse_iges
from rgm.backends.iges_records import record_bounds
from rgm.errors import BackendError

FORTRAN_REAL = re.compile(r"^-?[0-9]+\.[0-9]*(E[+-][0-9]+)?$")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=40))
def test_reals_read_back_bit_exact_in_fortran_form(values):
    texts = format_reals(values)
    for v, t in zip(values, texts):
        assert FORTRAN_REAL.match(t), t
        assert float(t) == v and math.copysign(1, float(t)) == math.copysign(1, v)
        assert float(t.replace("E", "D").replace("D", "E")) == v


def test_exponent_without_point_gets_one():
    assert format_reals([1e-5, 5e-324, 1e16, -2e22]) == ["1.E-05", "5.E-324", "1.E+16", "-2.E+22"]


@pytest.mark.parametrize("bad", [float("inf"), float("-inf"), float("nan")])
def test_non_finite_numbers_are_refused(bad):
    with pytest.raises(BackendError, match="non-finite"):
        format_reals([1.0, bad])


def test_hollerith_counts_characters():
    assert hollerith("a b,c;") == "6Ha b,c;"
    assert hollerith("é") == "1H?"


def _file(params_list, names=()):
    f = IgesFile(GlobalSection(product_id="p", file_name="x.igs", date="20240101.000000"))
    for i, params in enumerate(params_list):
        f.add(Entity(126 if len(params) > 20 else 110, params, label=names[i] if i < len(names) else ""))
    return f.to_text()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.lists(st.floats(-1e300, 1e300), min_size=6, max_size=60), min_size=1, max_size=6),
       st.text(alphabet="abcdefghij ,;H0123456789", min_size=0, max_size=150))
@example(rows=[[0.0] * 6], long_string=" ")   # `1H ` was read as a defaulted parameter (found by explore)
def test_records_are_80_columns_with_pointers_and_counts(rows, long_string):
    f = IgesFile(GlobalSection(author=long_string))
    for r in rows:
        f.add(Entity(110, [np.array(r)]))
    text = f.to_text()
    lines = text.splitlines()
    assert text.endswith("\n") and all(len(l) == 80 for l in lines)
    counts = {k: [l for l in lines if l[72] == k] for k in "SGDPT"}
    for k in "SGDP":  # sequence numbers restart at 1 in each section and count up
        assert [int(l[73:]) for l in counts[k]] == list(range(1, len(counts[k]) + 1))
    t = counts["T"][0]
    assert t.startswith(f"S{len(counts['S']):7d}G{len(counts['G']):7d}D{len(counts['D']):7d}P{len(counts['P']):7d}")
    d = counts["D"]
    for k in range(0, len(d), 2):  # DE: PD pointer and line count; P back-pointers to the odd DE number
        ptr, count = int(d[k][8:16]), int(d[k + 1][24:32])
        owned = counts["P"][ptr - 1:ptr - 1 + count]
        assert all(int(l[65:72]) == k + 1 and l[64] == " " for l in owned)
        assert owned[-1][:64].rstrip().endswith(";")
    parsed = parse_iges(text)
    assert parsed.global_section.author == long_string
    for k, r in enumerate(rows):
        assert np.array_equal(parsed.reals(2 * k + 1, 1, len(r)), r)


def test_global_section_has_26_parameters_and_units():
    g = GlobalSection(unit_flag=1, unit_name="INCH", resolution=1e-4, max_coordinate=12.5)
    text = IgesFile(g).to_text()
    parsed = parse_iges(text)
    assert parsed.global_section == g
    assert parsed.global_section.units == "in"
    gtext = "".join(l[:72] for l in text.splitlines() if l[72] == "G")
    assert gtext.startswith("1H,,1H;,") and gtext.rstrip().endswith(";")
    assert len(g.values()) == 26


def _sample(tmp=None):
    return _file([[0.0, 0, 0, 1, 1, 1]])


@pytest.mark.parametrize("mutate, message", [
    (lambda ls: ls[:5] + [ls[5][:40]] + ls[6:], "line 6: record is 40 columns"),
    (lambda ls: ls[:5] + [ls[5][:72] + "X" + ls[5][73:]] + ls[6:], "unknown section letter `X`"),
    (lambda ls: [l for l in ls if not l.endswith("D      2")], "odd number of records"),
    (lambda ls: [l.replace("     110       1", "     110       9") if l.endswith("D      1") else l for l in ls],
     "D 1 .*parameter pointer 9"),
    (lambda ls: [l.replace("110,0.0", "110,x.0") if l[72] == "P" else l for l in ls], "DE 1.*not a number"),
    (lambda ls: [l.replace("110,", "112,") if l[72] == "P" else l for l in ls], "P 1.*not the entity type 110"),
])
def test_malformed_files_name_the_record(mutate, message):
    lines = _sample().splitlines()
    text = "\n".join(mutate(lines)) + "\n"
    with pytest.raises(IgesFormatError, match=message):
        from rgm.backends.iges_read import read_iges

        result = read_iges(text)
        raise IgesFormatError("; ".join(result.problems))


def test_parser_accepts_crlf_d_exponents_and_defaulted_delimiters():
    text = _sample().replace("1H,,1H;,", ",,      ").replace("1.0,1.0;", "1.D0,1.;")
    text = text.replace("\n", "\r\n")
    data = parse_iges(text)
    assert data.global_section.param_delimiter == "," and data.reals(1, 1, 6).tolist() == [0, 0, 0, 1, 1, 1]


def test_not_iges_is_a_clear_error():
    with pytest.raises(IgesFormatError, match="record is|not an IGES"):
        parse_iges("hello\nworld\n")


def _reference_real(v: float) -> str:
    """The spelling rule, one value at a time: repr, upper-case exponent, a point before it."""
    return re.sub(r"^(-?[0-9]+)E", r"\1.E", repr(v).replace("e", "E"))


_EDGE_FLOATS = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308, 1.7976931348623157e308,
                -1.7976931348623157e308, 1e16, 9999999999999998.0, 1e-4, 1e-5, 0.0001, 1e22, 1e23, 1.0, -1.0, 3.0]
_FLOATS = st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.sampled_from(_EDGE_FLOATS),
                    st.integers(-2**63, 2**63).map(float), st.floats(-1e-300, 1e-300), st.floats(-1e30, 1e30))


@settings(max_examples=150, deadline=None)
@given(st.lists(_FLOATS, min_size=0, max_size=200), st.integers(0, 3))
def test_bulk_formatting_equals_the_one_value_rule(values, repeat):
    """`format_reals` formats whole arrays at once, each distinct value once (the bit pattern: -0.0
    is not 0.0); the result must be exactly the per-value rule, in order, repeats included."""
    values = values + values[::2] * repeat
    texts = format_reals(np.array(values, dtype=np.float64))
    assert texts == [_reference_real(v) for v in values]
    assert [struct.pack("<d", float(t)) for t in texts] == [struct.pack("<d", v) for v in values]


def _reference_records(lists: list[list[str]], width: int) -> list[tuple[int, str]]:
    """Greedy packing, token by token: whole tokens while they fit; a token longer than a record
    starts one and is cut into full records, its remainder opening the next."""
    out = []
    for owner, tokens in enumerate(lists):
        current = ""
        for k, token in enumerate(tokens):
            token += "\x01" if k == len(tokens) - 1 else "\x00"
            if len(current) + len(token) <= width:
                current += token
                continue
            if current:
                out.append((owner, current))
            pieces = [token[i:i + width] for i in range(0, len(token), width)]
            out += [(owner, p) for p in pieces[:-1]]
            current = pieces[-1]
        out.append((owner, current))
    return out


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(st.text(alphabet="ab", max_size=150), min_size=1, max_size=30), min_size=1, max_size=5),
       st.sampled_from([8, 64, 72]))
def test_record_packing_equals_greedy_token_by_token(lists, width):
    stream = b"\x01".join(b"\x00".join(t.encode() for t in tokens) for tokens in lists) + b"\x01"
    bounds, owners = record_bounds(stream, width)
    got = [(int(o), stream[a:b].decode()) for o, a, b in zip(owners, bounds[:-1], bounds[1:])]
    assert got == _reference_records(lists, width)


def test_parser_reads_the_same_data_from_any_line_layout():
    """The fixed-width fast path (80 columns + LF) and the line-by-line path give the same data."""
    text = _file([list(np.linspace(0, 1, 40)), [0.0, 1e-5, -0.0, 1, 1, 1]], names=["curve", "line"])
    lines = text.splitlines()
    variants = [text.replace("\n", "\r\n"), "\n".join(lines[:3] + [""] + lines[3:]) + "\n",
                "\n".join(l + "  " for l in lines)]
    base = parse_iges(text)
    for variant in variants:
        data = parse_iges(variant)
        assert (data.start, data.global_section, data.entries, data.params) == \
            (base.start, base.global_section, base.entries, base.params)
