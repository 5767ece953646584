"""The dense net form: one token, read by numpy in one piece; shapes, widths, layout and errors."""
import numpy as np
from hypothesis import given, settings, strategies as st

from rgm.compiler.netbody import NetError, read_net
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
