"""IGES parameter tokens and fixed-column records, built for a whole section at once.

The writer's hot path (`rgm.backends.iges_format.IgesFile.to_text`): a file of 100 surfaces with
50 x 50 nets has a million reals and 280 000 records, so nothing here loops in Python per number or
per byte:

- `format_reals` / `token_stream`: every real of a section is formatted in one call of Python's
  shortest round-trip `repr` (on a list, so at C speed), once per distinct value (polynomial weights,
  knots and grid coordinates repeat), and the one spelling a Fortran-style reader rejects (an
  exponent without a decimal point, `1e-05` -> `1.E-05`) is fixed by one vectorised pass over that
  text; the tokens are then gathered into place as fixed-width byte rows. Every real reads back
  bit-exact.
- `record_bounds`: greedy packing of whole tokens into records of at most `width` columns, by one
  `searchsorted` for every possible record start and a walk along the chosen starts; a token
  longer than a record (a long Hollerith string) starts a record and is cut at the record width,
  the only token ever split (IGES 5.3 §2.2.4.5).
- `file_rows` / `lay_records`: the whole file is one uint8 array of 81-byte rows (80 columns and
  the newline) with section letters and sequence numbers, into which the records are laid.

Streams are ASCII bytes in which every token ends with `\\x00` (parameter delimiter) or `\\x01`
(the last token of a parameter list); `delimit` turns those into the file's delimiters once the
records are known. Hollerith text is cleaned of control characters, so the markers are unambiguous.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import BackendError

__all__ = ["format_reals", "printable", "hollerith", "token_stream", "record_bounds", "delimit", "lay_records",
           "digits", "file_rows"]

_UPPER_E = bytes.maketrans(b"e", b"E")
_CONTROL = {c: " " for c in range(32)}   # control characters (and the stream markers) -> blank
_REALS = object()                         # an item of `_items`: the next chunk of reals


def _real_stream(values) -> tuple[bytes, np.ndarray]:
    """(the reals of `values` as Fortran-readable shortest round-trip text, each followed by
    `\\x00`, as one bytes object; byte offset of the start of each real, and the total, (k+1,)).

    Distinct values are formatted once (`np.unique` on the bit patterns, so -0.0 stays -0.0) by
    `repr` of their list, exponents fixed in place, and gathered back through a fixed-width table."""
    flat = np.ascontiguousarray(values, dtype=np.float64).ravel()
    if not np.isfinite(flat).all():
        raise BackendError("IGES cannot represent a non-finite number (inf or nan) in the model")
    if not flat.size:
        return b"", np.zeros(1, dtype=np.int64)
    distinct, inverse = np.unique(flat.view(np.int64), return_inverse=True)
    raw = b", " + repr(distinct.view(np.float64).tolist())[1:-1].encode("ascii").translate(_UPPER_E) + b", "
    codes = np.frombuffer(raw, dtype=np.uint8)                    # ", 1.5, 1E-05, -0.0, "
    exp = np.flatnonzero(codes == ord("E"))
    if exp.size:  # repr's exponent form has one digit before the point, or no point: 1E-05 -> 1.E-05
        before = codes[exp - 2]
        codes = np.insert(codes, exp[(before == ord(" ")) | (before == ord("-"))], ord("."))
    lengths = np.diff(np.flatnonzero(codes == ord(","))) - 2
    width = int(lengths.max()) + 1                                # + the delimiter
    table = np.full((distinct.size, width), 0xFF, dtype=np.uint8)  # 0xFF: filler, deleted below
    table[np.arange(width) < lengths[:, None]] = codes[(codes != ord(",")) & (codes != ord(" "))]
    table[np.arange(distinct.size), lengths] = 0
    inverse = inverse.ravel()
    out = table.view(f"S{width}").ravel()[inverse].tobytes().translate(None, b"\xff")
    return out, np.concatenate([[0], np.cumsum(lengths[inverse] + 1)])


def format_reals(values) -> list[str]:
    """Shortest round-trip decimal forms (`repr`) of floats (k,), with an upper-case exponent and a
    decimal point always in the mantissa (`1e-05` -> `1.E-05`), which Fortran-style readers need.

    Raises BackendError for inf/nan: IGES has no spelling for them.
    """
    return _real_stream(values)[0].decode("ascii").split("\x00")[:-1]


def printable(text: str) -> str:
    """`text` as IGES text (printable ASCII): non-ASCII characters become '?', control characters
    (line breaks, and so the stream markers) blanks."""
    return text.encode("ascii", "replace").decode("ascii").translate(_CONTROL)


def hollerith(text: str) -> str:
    """`nH...` of `printable(text)`: n counts the characters."""
    text = printable(text)
    return f"{len(text)}H{text}"


def _items(values, reals: list) -> list:
    """Tokens of one parameter list mixing ints, floats, str (Hollerith), None (default, an empty
    field) and arrays (each element one parameter): ASCII bytes each ending with `\\x00`, or
    `_REALS` where the next chunk of reals (appended to `reals`) goes."""
    out: list = []
    for v in values:
        if isinstance(v, np.ndarray):
            if v.dtype.kind == "f":
                if v.size:
                    reals.append(v.ravel())
                    out.append(_REALS)
            elif v.size:
                out.append("".join(f"{int(x)}\x00" for x in v.ravel().tolist()).encode("ascii"))
        elif isinstance(v, (bool, np.bool_)):
            out.append(b"1\x00" if v else b"0\x00")
        elif isinstance(v, (int, np.integer)):
            out.append(b"%d\x00" % int(v))
        elif isinstance(v, (float, np.floating)):
            reals.append(np.array([v], dtype=np.float64))
            out.append(_REALS)
        elif isinstance(v, str):
            out.append(hollerith(v).encode("ascii") + b"\x00")
        elif v is None:
            out.append(b"\x00")
        else:
            raise BackendError(f"cannot write {type(v).__name__} as an IGES parameter")
    return out


def token_stream(groups) -> bytes:
    """The stream (module docstring) of parameter lists `groups` (see `_items` for the values); all
    their reals are formatted in one `_real_stream` call."""
    if not groups:
        return b""
    reals: list = []
    encoded = [_items(values, reals) for values in groups]
    text, offsets = _real_stream(np.concatenate(reals) if reals else np.zeros(0))
    at = offsets[np.cumsum([0] + [r.size for r in reals])].tolist()
    text, pieces, k = memoryview(text), [], 0                    # (views: the stream is copied once, by join)
    for items in encoded:
        start = len(pieces)
        for item in items:
            if item is _REALS:
                pieces.append(text[at[k]:at[k + 1]])
                k += 1
            else:
                pieces.append(item)
        if len(pieces) > start:
            pieces[-1] = pieces[-1][:-1]                          # the last token ends the list
        pieces.append(b"\x01")
    return b"".join(pieces)


def record_bounds(stream: bytes, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(byte offsets (n+1,) of the records of `stream` (first 0, last len(stream)), index of the
    parameter list each record belongs to (n,)): records of at most `width` bytes filled greedily
    with whole tokens, never two lists in one record; over-long tokens are cut every `width` bytes.

    The record that starts at token i ends before the first token that does not fit; that is found
    for every i with one `searchsorted`, and the records are the orbit of token 0 under that map,
    walked in steps of 8 records (the map composed with itself) so the Python loop stays short."""
    if not stream:
        return np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64)
    codes = np.frombuffer(stream, dtype=np.uint8)
    marks = np.flatnonzero(codes < 2)
    ends = marks + 1                                              # token ends, delimiter included
    list_ends = ends[codes[marks] == 1]
    begins = np.concatenate([[0], ends[:-1]])
    long = np.flatnonzero(ends - begins > width)
    if long.size:
        cuts = np.concatenate([np.arange(begins[i] + width, ends[i], width) for i in long.tolist()])
        ends = np.sort(np.concatenate([ends, cuts]))
        begins = np.concatenate([[0], ends[:-1]])
    limit = np.minimum(begins + width, list_ends[np.searchsorted(list_ends, begins, side="right")])
    nxt = np.searchsorted(ends, limit, side="right")             # first token of the next record
    n = len(nxt)
    jumps = [np.append(nxt, n)]                                   # jumps[l][i]: 2**l records on (n: past the end)
    for _ in range(3):
        jumps.append(jumps[-1][jumps[-1]])
    step, first, i = memoryview(jumps.pop()), [], 0               # walk 8 records at a time ...
    while i < n:
        first.append(i)
        i = step[i]
    first = np.array(first, dtype=np.int64)
    for jump in reversed(jumps):                                  # ... and fill in the records between
        first = np.column_stack([first, jump[first]]).ravel()
    starts = begins[first[first < n]]
    return np.append(starts, len(stream)), np.searchsorted(list_ends, starts, side="right")


def delimit(stream: bytes, param_delimiter: str, record_delimiter: str) -> bytes:
    """`stream` with its token markers replaced by the file's delimiters."""
    return stream.translate(bytes.maketrans(b"\x00\x01", (param_delimiter + record_delimiter).encode("ascii")))


def lay_records(out: np.ndarray, data: bytes, bounds: np.ndarray) -> None:
    """Write record k = data[bounds[k]:bounds[k+1]] left-justified into row k of `out` (n, width)
    (a view of the file's rows, blank already), all records in one masked assignment."""
    out[np.arange(out.shape[1]) < np.diff(bounds)[:, None]] = np.frombuffer(data, dtype=np.uint8)


_RJUST = np.frombuffer("".join(f"{i:4d}" for i in range(10_000)).encode("ascii"), dtype=np.uint8).reshape(-1, 4)
_ZFILL = np.frombuffer("".join(f"{i:04d}" for i in range(10_000)).encode("ascii"), dtype=np.uint8).reshape(-1, 4)


def digits(values) -> np.ndarray:
    """(k, 7) uint8 ASCII of non-negative ints right-justified in 7 columns (a sequence number or
    pointer field), from tables of the 4-digit groups."""
    v = np.asarray(values, dtype=np.int64)
    if v.size and not 0 <= int(v.min()) <= int(v.max()) <= 9_999_999:
        raise BackendError(f"IGES: {int(v.max())} does not fit a 7-column field (too many records)")
    hi, lo = np.divmod(v, 10_000)
    out = np.empty((v.size, 7), dtype=np.uint8)
    out[:, :3] = np.where((hi > 0)[:, None], _RJUST[hi, 1:], ord(" "))
    out[:, 3:] = np.where((hi > 0)[:, None], _ZFILL[lo], _RJUST[lo])
    return out


def file_rows(counts: list[tuple[str, int]]) -> list[np.ndarray]:
    """Blank 80-column records of a file with `counts` (section letter, number of records), as one
    uint8 array (rows, 81) whose columns 73-81 hold the section letter, the sequence number
    (restarting at 1 in each section) and a newline; returns it and the views (n, 81) of its
    sections, whose columns 1-72 the caller fills."""
    sizes = [n for _letter, n in counts]
    buf = np.full((sum(sizes), 81), ord(" "), dtype=np.uint8)
    buf[:, 72] = np.repeat(np.frombuffer("".join(c for c, _n in counts).encode("ascii"), dtype=np.uint8), sizes)
    buf[:, 73:80] = digits(np.concatenate([np.arange(1, n + 1) for n in sizes]))
    buf[:, 80] = ord("\n")
    return [buf, *np.split(buf, np.cumsum(sizes)[:-1])]
