"""Reading the dense numeric form `net 40 x 40 [x y z, x y z, ...]` in one piece.

The lexer hands the whole net over as a single token; `read_net` checks and converts its body. Two
readers share the work:
  * the exact reader (`_entries`, `_convert`): plain Python over the text, `str.split` per entry and
    `float` per number. It finds every problem with its offsets, and small bodies (the many 4 x 4 nets
    of a statement-heavy file) use it directly, since it has no fixed cost;
  * the vectorised reader (`_fast_read`) for large bodies: numpy passes over the bytes, no Python loop
    per number. It declines (returns None) whenever anything is off, and the exact reader then gives
    the diagnostic, so both report the same errors. Its number conversion is described in `_decimals`.
Errors come back as `NetError(message, start, end, hint)` with offsets into the token text.
"""
from __future__ import annotations

import math
import re
from itertools import chain
from dataclasses import dataclass

import numpy as np

_HEAD = re.compile(r"net\s+([0-9]+)(?:\s*x\s*([0-9]+))?\s*\[")
_BAD_CHAR = re.compile(r"[^0-9eE+\-.,\t\n\r\f\v ]")
_TOKEN = re.compile(r"[^\s,]+")
MAX_WIDTH = 4
_INF = float("inf")
#: bodies at least this long go to the vectorised reader (below it numpy's fixed costs dominate)
FAST_MIN = 20_000


@dataclass
class NetError(Exception):
    message: str
    start: int           # offsets into the token text, end exclusive
    end: int
    hint: str | None = None


def read_net(text: str) -> tuple[tuple[int, ...], int, np.ndarray]:
    """Parse the text of one NET token -> (shape, width, data of shape `shape + (width,)`, read-only).

    Raises NetError for a zero dimension, a stray character, an empty or ragged body, an entry width
    outside 1..4, a count of entries different from the declared shape, or a malformed or non-finite
    number (checked in that order).
    """
    head = _HEAD.match(text)
    shape = tuple(int(g) for g in head.groups() if g is not None)
    body_start, body_end = head.end(), len(text) - 1
    if 0 in shape or max(shape) > 10**8:
        raise NetError(f"a net needs between 1 and 10^8 rows and columns, not `{' x '.join(map(str, shape))}`",
                       0, head.end() - 1)
    fast = _fast_read(text, body_start, body_end) if body_end - body_start >= FAST_MIN else None
    if fast is not None:
        data, width, count = fast
    else:
        body = text[body_start:body_end]
        entries = _entries(body, body_start)
        width, count = len(entries[0]), len(entries)
    if width > MAX_WIDTH:
        raise NetError(f"entries of a net hold 1 to {MAX_WIDTH} numbers, these hold {width}",
                       0, len(text), "is a `,` missing between entries?")
    expected = math.prod(shape)
    if count != expected:
        dims = " x ".join(map(str, shape))
        raise NetError(f"`net {dims}` needs {expected} entries, found {count}", 0, len(text),
                       "one entry per control point, row after row, separated by `,`")
    if fast is None:
        data = _convert(entries, body, body_start)
    data = data.reshape(shape + (width,))
    data.flags.writeable = False
    return shape, width, data


# ------------------------------------------------------------------------------------ exact reader

def _entries(body: str, body_start: int) -> list[list[str]]:
    """The body split into entries of number texts; raises NetError for a stray character, an empty
    body or an entry whose count differs from the first one's (a trailing comma is allowed)."""
    bad = _BAD_CHAR.search(body)
    if bad:
        ch, at = bad.group(), body_start + bad.start()
        if ch == "#":
            raise NetError("a comment cannot go inside a net", at, at + 1,
                           "put the comment on the line before the binding")
        shown = ch if ch.isprintable() else f"U+{ord(ch):04X}"
        hint = ("is the net's closing `]` missing before this?" if ch in ";=:([" else
                "write each entry as `x y z` and separate entries with `,`")
        raise NetError(f"`{shown}` cannot appear in a net: only numbers separated by spaces, and commas "
                       "between entries", at, at + 1, hint)
    texts = body.split(",")
    entries = list(map(str.split, texts))
    if len(entries) > 1 and not entries[-1]:
        entries.pop()
    width = len(entries[0])
    if not any(entries):
        raise NetError("this net holds no numbers", 0, len(body) + body_start + 1,
                       "write entries such as `[0 0 0, 1 0 0]`")
    if len(set(map(len, entries))) > 1:
        k = next(k for k, entry in enumerate(entries) if len(entry) != width)
        a = body_start + sum(len(t) + 1 for t in texts[:k])
        seg = texts[k]
        lead, core = len(seg) - len(seg.lstrip()), seg.strip()
        a, b = (a + lead, a + lead + len(core)) if core else (a, a + 1)
        got = len(entries[k])
        raise NetError(f"entry {k + 1} of this net has {got} number{'s' * (got != 1)}, "
                       f"but the first entry has {width}", a, b,
                       "every entry has the same count: `x y z` for points, `x y z w` with weights")
    return entries


def _convert(entries: list[list[str]], body: str, body_start: int) -> np.ndarray:
    """The numbers of `entries` as one flat float64 array; NetError names the first bad number."""
    try:
        values = list(map(float, chain.from_iterable(entries)))
    except ValueError:
        m = next(m for m in _TOKEN.finditer(body) if not _is_float(m.group()))
        raise NetError(f"`{m.group()}` is not a number", body_start + m.start(), body_start + m.end()) from None
    if _INF in values or -_INF in values:     # the only non-finite values a number of digits reads as
        m = next(m for m in _TOKEN.finditer(body) if not np.isfinite(float(m.group())))
        raise NetError(f"`{m.group()}` is too large for a 64-bit float", body_start + m.start(),
                       body_start + m.end())
    return np.array(values, dtype=float)


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


# ------------------------------------------------------------------------------------ vectorised reader

_PAD = 16      # blanks before each chunk, so that a number's 16-byte window stays inside it
_CHUNK = 1 << 18   # characters per chunk: its temporaries stay small enough to be reused
_BLANK, _NUMBER, _COMMA, _OTHER = 0, 1, 2, 3
_CLASSES = bytes(_NUMBER if c in b"0123456789eE+-." else _COMMA if c == ord(",") else
                 _BLANK if c in b" \t\n\r\f\v" else _OTHER for c in range(256))


def _fast_read(text: str, start: int, end: int) -> tuple[np.ndarray, int, int] | None:
    """(flat data, width, entry count) of the well-formed body text[start:end], or None for anything
    the exact reader should look at: a stray character, a ragged or empty body, a number that does
    not read. The body goes in chunks of about 256 kB that end just after a comma: each holds whole
    entries, so every check stays inside a chunk, and the chunks' buffers are reused (fresh memory
    costs a page fault per 4 kB, and a 23 MB net read in one piece spent more on those than on reading)."""
    if not text.isascii():
        return None
    parts, width, count = [], None, 0
    while start < end:
        stop = text.find(",", min(start + _CHUNK, end), end) + 1 or end
        chunk = _read_chunk(text[start:stop], width)
        if chunk is None:
            return None
        values, width, entries = chunk
        parts.append(values)
        count += entries
        start = stop
    data = np.concatenate(parts) if len(parts) > 1 else parts[0] if parts else None
    if data is None or not np.isfinite(data).all():
        return None
    return data, width, count


def _read_chunk(piece: str, width: int | None) -> tuple[np.ndarray, int, int] | None:
    """(values, width, entry count) of whole entries; `width` is the first chunk's (None: find it)."""
    raw = (" " * _PAD + piece + " ").encode("ascii")
    cls = np.frombuffer(raw.translate(_CLASSES), dtype=np.uint8)
    if cls.max() == _OTHER:
        return None
    number = cls == _NUMBER
    edges = np.flatnonzero(number[1:] != number[:-1]) + 1    # the blanks around make them come in pairs
    starts, ends = edges[0::2], edges[1::2]
    commas = np.flatnonzero(cls == _COMMA)
    if width is None:
        width = int(np.searchsorted(starts, commas[0])) if commas.size else int(starts.size)
        if width == 0:
            return None
    # every entry holds `width` numbers: comma j follows number (j + 1) * width - 1 and precedes
    # number (j + 1) * width; only the body's last entry has no comma after it (or one, trailing)
    entries = commas.size + bool(starts.size and (not commas.size or ends[-1] > commas[-1]))
    if starts.size != entries * width:
        return None
    after = np.arange(1, commas.size + 1) * width
    inner = after < starts.size
    if not ((ends[after - 1] <= commas).all() and (commas[inner] < starts[after[inner]]).all()):
        return None
    values = _decimals(raw, starts, ends) if starts.size else np.empty(0)   # only blanks after the last comma
    return None if values is None else (values, width, entries)


_U64 = np.uint64
_ALL, _BYTES, _HIGH = _U64(2**64 - 1), _U64(0x0101010101010101), _U64(0xF0F0F0F0F0F0F0F0)
_ZEROS = _U64(0x3030303030303030)
_TAIL = _U64(0x0807060504030201)
#: by s = how many of a word's 8 bytes belong to the number (its top s bytes): the mask that keeps
#: them, and '0' characters for the others
_KEEP = np.array([(2**64 - 1) ^ (2**(64 - 8 * s) - 1) if s else 0 for s in range(9)], dtype=np.uint64)
_FILL = np.array([0x3030303030303030 & (2**(64 - 8 * s) - 1) for s in range(9)], dtype=np.uint64)
#: by c = bytes from the dot to the number's end (0: no dot): the value of one unit of the digits
_SCALE = np.concatenate(([1.0], 10.0 ** np.arange(17)))


def _digits8(v: np.ndarray) -> np.ndarray:
    """The 8-digit integer of each word whose bytes are digit values 0..9, first byte most significant:
    three multiply-shift steps (SIMD within a register, D. Lemire, "Fast number parsing", 2021)."""
    v = (v * _U64(2561)) >> _U64(8)
    v = ((v & _U64(0x00FF00FF00FF00FF)) * _U64(6553601)) >> _U64(16)
    return ((v & _U64(0x0000FFFF0000FFFF)) * _U64(42949672960001)) >> _U64(32)


def _decimals(raw: bytes, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """The numbers at raw[starts:ends] as float64, exactly as strtod reads them; None if one is not a number.

    Plain decimals `-?ddd.ddd` of at most 16 characters after the sign are converted without a Python
    loop: each is read as the one or two 8-byte words that end where it ends (bytes before it become
    '0'), its dot is taken out by shifting the bytes before it up by one, and each word's digits
    combine into an integer (`_digits8`). The integer M and 10^k are exact doubles (M <= 2^53), so
    M / 10^k is the correctly rounded value (Clinger's fast path). Anything else (exponents, `+`,
    longer numbers) goes to float() one by one, or to numpy's strtod loop when they are many.
    """
    negative = np.frombuffer(raw, dtype=np.uint8).take(starts) == ord("-")
    length = ends - starts - negative                 # characters after the sign
    nwords = 2 if length.max() > 8 else 1
    every = np.ndarray((len(raw) - 7,), dtype="<u8", buffer=raw, strides=(1,))   # a word at every offset
    words, dots = [], []
    for k in range(nwords):                           # word k holds window bytes 8k .. 8k + 7
        inside = np.clip(length - 8 * (nwords - 1 - k), 0, 8) if k < nwords - 1 else np.minimum(length, 8)
        w = (every[ends - 8 * (nwords - k)] & _KEEP.take(inside)) | _FILL.take(inside)
        words.append(w)
        dots.append((w.view(np.uint8) == ord(".")).view(np.uint64))    # 1 in each byte that is a dot
    # with one dot at byte j of a word: d * 0x0101.. has a 1 in each byte from j on (its top byte
    # counts the word's dots), and the top byte of d * 0x0807..01 is 8 - j, the bytes from the dot on
    after = [d * _BYTES for d in dots]
    ndots = after[-1] >> _U64(56)
    c = (dots[-1] * _TAIL) >> _U64(56)
    if nwords == 2:                                   # a dot in the first word: all of the second is after it
        first = after[0] >> _U64(56)
        ndots = ndots + first
        c = c + ((dots[0] * _TAIL) >> _U64(56)) + (first != 0) * _U64(8)
        after[1] |= (first != 0) * _BYTES
    undotted = (ndots == 0) * _ALL
    mantissa, carry, bad = None, 0, (ndots > 1) | (length > 8 * nwords) | (length <= ndots)
    for w, d, a in zip(words, dots, after):
        v = (w ^ _ZEROS) & ~(d * _U64(255))            # digit values; the dot is 0, others keep high bits
        bad |= (v & _HIGH) != 0
        keep = a * _U64(255) | undotted                # bytes from the dot on stay, the rest move up
        moved = v & ~keep
        v = (v & keep) | (moved << _U64(8))
        if mantissa is not None:                      # the second word: the first one's top byte moves in
            v |= carry
        carry = moved >> _U64(56)
        mantissa = _digits8(v) if mantissa is None else mantissa * _U64(10**8) + _digits8(v)
    if nwords == 2:                                   # (8 digits, below 2^27, are always exact)
        bad |= mantissa > _U64(2**53)
    values = mantissa.view(np.int64) / _SCALE.take(c)   # int64 converts to float faster than uint64
    np.negative(values, where=negative, out=values)
    redo = np.flatnonzero(bad)
    if redo.size > values.size // 8:        # mostly other forms (say, 17-digit reprs): strtod over all
        try:
            values = np.fromstring(raw.replace(b",", b" "), dtype=float, sep=" ")
        except ValueError:
            return None
        return values if values.size == starts.size else None   # "1-2" reads as two numbers
    for i in redo.tolist():
        try:
            values[i] = float(raw[starts[i]:ends[i]])
        except ValueError:
            return None
    return values
