"""Reading the dense numeric form `net 40 x 40 [x y z, x y z, ...]` in one piece with numpy.

The lexer hands the whole net over as a single token; this module checks and converts its body with
a few vectorised passes over the characters (no Python loop per number), so a 1000 x 1000 control net
of 30 MB costs about one `str.split` plus one float conversion:
  1. a 256-entry lookup table classifies every byte of the body (number character, comma, blank,
     anything else: an error);
  2. number starts (a number character after a non-number one) are counted per entry (entries are
     separated by commas) with np.bincount: every entry must hold the same count `width`;
  3. the numbers are converted by numpy's C reader (`np.fromstring(body.replace(',', ' '), sep=' ')`),
     which is strict on malformed numbers; any doubt is settled token by token with float().
Errors come back as `NetError(message, start, end, hint)` with offsets into the token text.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

_HEAD = re.compile(r"net\s+([0-9]+)(?:\s*x\s*([0-9]+))?\s*\[")
_BAD_CHAR = re.compile(r"[^0-9eE+\-.,\t\n\r\f\v ]")
_TOKEN = re.compile(r"[^\s,]+")
MAX_WIDTH = 4


@dataclass
class NetError(Exception):
    message: str
    start: int           # offsets into the token text, end exclusive
    end: int
    hint: str | None = None


def read_net(text: str) -> tuple[tuple[int, ...], int, np.ndarray]:
    """Parse the text of one NET token -> (shape, width, data of shape `shape + (width,)`, read-only).

    Raises NetError for a zero dimension, a stray character, an empty or ragged body, an entry width
    outside 1..4, a count of entries different from the declared shape, or a non-finite number.
    """
    head = _HEAD.match(text)
    shape = tuple(int(g) for g in head.groups() if g is not None)
    body_start, body = head.end(), text[head.end():-1]
    if 0 in shape or max(shape) > 10**8:
        raise NetError(f"a net needs between 1 and 10^8 rows and columns, not `{' x '.join(map(str, shape))}`",
                       0, head.end() - 1)
    codes = _classify(body)
    bad_at = int(np.argmax(codes == _BAD)) if (codes == _BAD).any() else -1
    if bad_at >= 0:
        bad = _BAD_CHAR.search(body)           # the character (not byte) offset, for the message
        ch = bad.group()
        at = body_start + bad.start()
        if ch == "#":
            raise NetError("a comment cannot go inside a net", at, at + 1,
                           "put the comment on the line before the binding")
        shown = ch if ch.isprintable() else f"U+{ord(ch):04X}"
        hint = ("is the net's closing `]` missing before this?" if ch in ";=:([" else
                "write each entry as `x y z` and separate entries with `,`")
        raise NetError(f"`{shown}` cannot appear in a net: only numbers separated by spaces, and commas "
                       "between entries", at, at + 1, hint)
    counts, entry_starts = _entry_counts(codes)
    if counts.size == 0 or not counts.any():
        raise NetError("this net holds no numbers", 0, len(text), "write entries such as `[0 0 0, 1 0 0]`")
    width = int(counts[0])
    ragged = np.flatnonzero(counts != width)
    if ragged.size:
        k = int(ragged[0])
        got = int(counts[k])
        a, b = _entry_range(body, entry_starts, k)
        raise NetError(f"entry {k + 1} of this net has {got} number{'s' * (got != 1)}, "
                       f"but the first entry has {width}", body_start + a, body_start + b,
                       "every entry has the same count: `x y z` for points, `x y z w` with weights")
    if width > MAX_WIDTH:
        raise NetError(f"entries of a net hold 1 to {MAX_WIDTH} numbers, these hold {width}",
                       0, len(text), "is a `,` missing between entries?")
    expected = int(np.prod(shape))
    if counts.size != expected:
        dims = " x ".join(map(str, shape))
        raise NetError(f"`net {dims}` needs {expected} entries, found {counts.size}", 0, len(text),
                       "one entry per control point, row after row, separated by `,`")
    try:
        # numpy's C reader raises on anything strtod cannot read up to a blank ("1.2.3", "1e", "-");
        # the size check catches a token read as two numbers ("1-2")
        data = np.fromstring(body.replace(",", " "), dtype=float, sep=" ")
        if data.size != int(counts.sum()):
            raise ValueError("a token was read as several numbers")
    except ValueError:
        for m in _TOKEN.finditer(body):
            try:
                float(m.group())
            except ValueError:
                raise NetError(f"`{m.group()}` is not a number", body_start + m.start(),
                               body_start + m.end()) from None
        # not expected (every token float() accepts, numpy reads as one number); never a traceback
        raise NetError("the numbers of this net could not be read", 0, len(text)) from None
    if not np.isfinite(data).all():
        m = next(m for m in _TOKEN.finditer(body) if not np.isfinite(float(m.group())))
        raise NetError(f"`{m.group()}` is too large for a 64-bit float", body_start + m.start(),
                       body_start + m.end())
    data = data.reshape(shape + (width,))
    data.flags.writeable = False
    return shape, width, data


_BAD, _NUMBER, _COMMA, _BLANK = 0, 1, 2, 3
_CLASSES = np.zeros(256, dtype=np.uint8)
_CLASSES[np.frombuffer(b"0123456789eE+-.", dtype=np.uint8)] = _NUMBER
_CLASSES[ord(",")] = _COMMA
_CLASSES[np.frombuffer(b" \t\n\r\f\v", dtype=np.uint8)] = _BLANK


def _classify(body: str) -> np.ndarray:
    """One class per byte of the body (number character, comma, blank, or anything else), by a
    256-entry lookup table: a single vectorised pass instead of one regex scan per question."""
    return _CLASSES[np.frombuffer(body.encode("utf-8", errors="replace"), dtype=np.uint8)]


def _entry_counts(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Numbers per entry (a trailing comma is allowed) and the byte offset where each entry begins.
    Valid bodies are ASCII, so byte offsets are character offsets."""
    commas = np.flatnonzero(codes == _COMMA)
    number = codes == _NUMBER
    starts = np.flatnonzero(number & ~np.concatenate(([False], number[:-1])))
    # the entry of a number is the count of commas before it (a bool cumsum is slow: search instead)
    counts = np.bincount(np.searchsorted(commas, starts), minlength=commas.size + 1)
    entry_starts = np.concatenate(([0], commas + 1))
    if counts.size > 1 and counts[-1] == 0:
        counts, entry_starts = counts[:-1], entry_starts[:-1]
    return counts, entry_starts


def _entry_range(body: str, entry_starts: np.ndarray, k: int) -> tuple[int, int]:
    """Offsets of entry k with its surrounding spaces trimmed (at least one character)."""
    a = int(entry_starts[k])
    b = int(entry_starts[k + 1]) - 1 if k + 1 < entry_starts.size else len(body)
    seg = body[a:b]
    lead = len(seg) - len(seg.lstrip())
    a2, b2 = a + lead, a + len(seg.rstrip())
    return (a2, b2) if b2 > a2 else (a, a + 1)
