"""Malformed IGES never gives a traceback: byte, token and line mutations of real files either read
(with unsupported or invalid entities reported) or raise IgesFormatError naming a record."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from iges_model_strategies import make_object
from rgm.backends.iges import iges_text
from rgm.backends.iges_format import IgesFormatError
from rgm.backends.iges_read import read_iges
from rgm.model import Model

CORPUS = Path("/work/shared/data/iges-samples")


def _texts():
    rng = np.random.default_rng(11)
    objs = {k: make_object(k, rng, k) for k in ("trimmed", "revolution", "composite", "arc")}
    out = [iges_text(Model("mm", 1e-3, objs, tuple(objs)))]
    if CORPUS.exists():
        out += [(CORPUS / n).read_text(encoding="latin-1") for n in ("144-000.igs", "f126x.igs", "102-000.igs")]
    return out


TEXTS = _texts()


def _assert_reads_or_refuses(text):
    """The oracle: a mutated file is read (every message naming a DE entry or the tolerance) or refused
    with an IgesFormatError that says something; any other exception fails the test."""
    try:
        result = read_iges(text)
    except IgesFormatError as exc:
        assert str(exc)
        return
    for line in result.messages():
        assert "DE " in line or "tolerance" in line


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(range(len(TEXTS))), st.integers(0, 10**9), st.sampled_from("0123456789 ,;.-EHDPGSx\n"))
def test_byte_mutations(k, where, char):
    text = TEXTS[k]
    i = where % len(text)
    _assert_reads_or_refuses(text[:i] + char + text[i + 1:])


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(range(len(TEXTS))), st.integers(0, 10**9), st.sampled_from(["delete", "duplicate", "swap"]))
def test_line_mutations(k, where, how):
    lines = TEXTS[k].splitlines()
    i = where % len(lines)
    if how == "delete":
        lines = lines[:i] + lines[i + 1:]
    elif how == "duplicate":
        lines = lines[:i + 1] + lines[i:]
    else:
        j = (i + 1) % len(lines)
        lines[i], lines[j] = lines[j], lines[i]
    _assert_reads_or_refuses("\n".join(lines) + "\n")


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(range(len(TEXTS))), st.integers(0, 10**9),
       st.sampled_from(["-1", "0", "99999", "1.5", "", "3H", "1E999", "nan"]))
def test_token_mutations(k, where, token):
    """Replace one numeric token of a P record (pointers, counts, degrees, reals)."""
    lines = TEXTS[k].splitlines()
    p_lines = [n for n, l in enumerate(lines) if len(l) >= 73 and l[72] == "P"]
    n = p_lines[where % len(p_lines)]
    data, rest = lines[n][:64], lines[n][64:]
    parts = data.split(",")
    parts[(where // 7) % len(parts)] = token
    lines[n] = ",".join(parts)[:64].ljust(64) + rest
    _assert_reads_or_refuses("\n".join(lines) + "\n")
