"""The IGES file model: number spelling, Hollerith strings, record layout, the Global section, and the
tolerant parser's errors (which name the record)."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.backends.iges_format import Entity, GlobalSection, IgesFile, IgesFormatError, format_reals, hollerith
from rgm.backends.iges_parse import parse_iges
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


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=64, max_size=300),
       st.sampled_from([1.0, 1e-5, 1e-6, 1e-7, 1e15, 1e16]))
def test_accelerated_formatting_gives_the_same_text_as_repr(values, scale):
    """With orjson installed the reals are formatted by it (Ryu); the file must not depend on that."""
    import rgm.backends.iges_format as F

    if F._orjson is None:
        pytest.skip("orjson not installed: only the repr path exists")
    with np.errstate(over="ignore"):
        arr = np.array(values) * scale
    arr = arr[np.isfinite(arr)]
    fast = F._reals_text(arr, ",")
    saved, F._orjson = F._orjson, None
    try:
        assert fast == F._reals_text(arr, ",")
    finally:
        F._orjson = saved
