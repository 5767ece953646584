"""The dense net form: one token, read by numpy in one piece; shapes, widths, layout and errors."""
import random

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from rgm.compiler import netbody
from rgm.compiler.netbody import _CHUNK as CHUNK
from rgm.compiler.netbody import FAST_MIN, NetError, _fast_read, read_net
from rgm.compiler.parser import parse


def test_rows_are_u_and_entries_in_a_row_are_v():
    shape, width, data = read_net("net 2 x 3 [0 0 0, 1 0 0, 2 0 0,\n 0 1 5, 1 1 5, 2 1 5]")
    assert shape == (2, 3) and width == 3 and data.shape == (2, 3, 3)
    assert data[1, 2].tolist() == [2, 1, 5] and not data.flags.writeable


def test_widths_one_to_four_and_a_trailing_comma():
    for width in (1, 2, 3, 4):
        entry = " ".join(["1.5"] * width)
        shape, w, data = read_net(f"net 3 [{entry}, {entry}, {entry},]")
        assert (shape, w) == ((3,), width) and np.all(data == 1.5)


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 30), st.integers(1, 30), st.integers(1, 4), st.randoms(use_true_random=False))
def test_agrees_with_a_python_reading(rows, cols, width, rnd):
    values = [[[rnd.uniform(-1e3, 1e3) for _ in range(width)] for _ in range(cols)] for _ in range(rows)]
    seps = [",", " ,", ",\n", " ,\n\t "]
    text = "net %d x %d [" % (rows, cols) + rnd.choice(seps).join(
        " ".join(repr(v) for v in entry) for row in values for entry in row) + "]"
    shape, w, data = read_net(text)
    assert shape == (rows, cols) and w == width
    assert data.tolist() == values


def test_errors_have_offsets_into_the_token():
    text = "net 2 [1 2 3, 4 5]"
    try:
        read_net(text)
    except NetError as e:
        assert text[e.start:e.end] == "4 5" and "entry 2" in e.message
    else:
        raise AssertionError("ragged net accepted")


def test_a_large_net_is_one_token_and_positions_after_it_hold():
    n = 300
    rows = ",\n".join(", ".join(f"{i} {j} {i * j % 7}" for j in range(n)) for i in range(n))
    text = f"s := net {n} x {n} [\n{rows}\n];\nafter := 1;\n"
    program, diags = parse(text, "big.rgm")
    assert diags == []
    net = program.statements[0].expr
    assert net.data.shape == (n, n, 3) and net.data[299, 5].tolist() == [299, 5, 299 * 5 % 7]
    after = program.statements[1]
    assert (after.span.line, after.span.col) == (n + 3, 1)
    assert (net.span.end_line, net.span.end_col) == (n + 2, 2)


_FORMS = ["1e5", "+3", "-0", "0.", ".5", "-.5", "5.", "1E-3", "00012.5000", "12345678.12345678",
          "9999999999999999", "0.000000000000001", "-1234.5678", "0.30000000000000004", "7",
          "1.234567891", "-0.12345678901234", "1234567890123456", "12345678.9"]   # dots in either word


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(1, 4), st.integers(0, 2**32))
def test_the_vectorised_reader_reads_what_float_reads(width, seed):
    """Large bodies take the numpy path (`_fast_read`); it must give float()'s doubles bit for bit,
    also for forms it hands back to float() (exponents, `+`, long mantissas)."""
    rnd = random.Random(seed)

    def number():
        k = rnd.random()
        if k < 0.3:
            return repr(rnd.uniform(-1e4, 1e4))
        if k < 0.6:
            return f"{rnd.uniform(-1e5, 1e5):.{rnd.randint(0, 6)}f}"
        return rnd.choice(_FORMS) if k < 0.7 else str(rnd.randint(-10**9, 10**9))
    n = rnd.randint(FAST_MIN // (8 * width), FAST_MIN // (2 * width))
    entries = [[number() for _ in range(width)] for _ in range(n)]
    body = rnd.choice([", ", ",\n  ", " ,", ","]).join(" ".join(e) for e in entries) + rnd.choice(["", ",", " ,\n"])
    assert len(body) >= FAST_MIN
    netbody._CHUNK = rnd.choice([64, 4096, 1 << 18])     # chunks end after a comma, several per body
    try:
        data, w, count = _fast_read(body, 0, len(body))
    finally:
        netbody._CHUNK = CHUNK
    assert (w, count) == (width, n)
    assert data.tobytes() == np.array([float(x) for e in entries for x in e]).tobytes()


@given(st.sampled_from(["1 2 3, 4 5", "1.2.3 4 5", "1 2 3,, 4 5 6", "- 1 2", "1-2 3 4", "1 2 3 ; 4", ",1 2 3",
                        "1e 2 3", ". 1 2", "1 2 3, 4 5 6 7", "1 2 3, 1e999 0 0", "1 2 3 # no"]),
       st.integers(0, 3000))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_both_readers_report_the_same_error(mistake, at):
    """A large net with one mistake: the numpy path declines and the exact reader reports it, so the
    diagnostic (message and offsets) is the one a small net would get."""
    good = ["0.5 1 2"] * 3000
    good[at:at + 1] = [mistake]
    text = f"net {len(good) + mistake.count(',')} [" + ", ".join(good) + "]"
    assert len(text) >= FAST_MIN
    errors = []
    for limit, chunk in ((FAST_MIN, CHUNK), (FAST_MIN, 100), (10**12, CHUNK)):   # vectorised, then exact
        netbody.FAST_MIN, netbody._CHUNK = limit, chunk
        try:
            read_net(text)
            errors.append(None)
        except NetError as e:
            errors.append((e.message, e.start, e.end, e.hint))
        finally:
            netbody.FAST_MIN, netbody._CHUNK = FAST_MIN, CHUNK
    assert errors[0] == errors[1] == errors[2] and errors[0] is not None
