"""Tolerant parser of fixed-format ASCII IGES (the reader side of `rgm.backends.iges_format`).

`parse_iges(text) -> IgesData`: the Start text, the Global section, every Directory Entry and the
parameter tokens of every entity, by DE number. Tolerant of what real writers do (CR/LF endings,
blank lines, D exponents, defaulted Global delimiters, blanks inside fields, comments after the
record delimiter); a malformed record raises IgesFormatError naming it (`D 17 (line 23)`, `P 5`).
A file of 80-column records is viewed as one uint8 array (no per-line work), each entity's
parameter text is one slice of the P data, records without Hollerith strings are split by the C
string methods, and runs of reals are converted by `float` once per distinct text.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .iges_format import GlobalSection, IgesFormatError

__all__ = ["DirectoryEntry", "IgesData", "Hollerith", "parse_iges"]


class Hollerith(str):
    """A parameter that was a Hollerith string in the file (as opposed to a number or an empty field)."""


@dataclass
class DirectoryEntry:
    """The 20 DE fields of one entity as read (blank numeric fields are 0)."""

    de: int
    type: int
    pd_pointer: int
    structure: int
    line_font: int
    level: int
    view: int
    transform: int
    label_display: int
    blank: int
    subordinate: int
    use: int
    hierarchy: int
    line_weight: int
    color: int
    pd_count: int
    form: int
    label: str
    subscript: int

    def where(self) -> str:
        return f"entity {self.type} (form {self.form}) at DE {self.de}"


@dataclass
class IgesData:
    """A parsed IGES file: start text, Global section, DEs by DE number, parameter tokens by DE number.

    Parameter tokens are strings: `Hollerith` for strings, '' for a defaulted field, otherwise the
    number's text; `params[de][0]` is the entity type.
    """

    start: str
    global_section: GlobalSection
    entries: dict
    params: dict

    def ints(self, de: int, first: int, count: int) -> list[int]:
        return [self.int(de, i) for i in range(first, first + count)]

    def token(self, de: int, index: int) -> str:
        toks = self.params[de]
        if index >= len(toks):
            raise IgesFormatError(f"{self.entries[de].where()}: parameter {index} is missing "
                                  f"(the record has {len(toks) - 1})")
        return toks[index]

    def int(self, de: int, index: int, default: int | None = 0) -> int:
        tok = self.token(de, index) if index < len(self.params[de]) or default is None else ""
        if default is not None and not tok.strip():
            return default
        try:
            return _to_int(tok)
        except ValueError:
            raise IgesFormatError(f"{self.entries[de].where()}: parameter {index} `{tok}` is not an integer") from None

    def real(self, de: int, index: int, default: float | None = 0.0) -> float:
        tok = self.token(de, index) if index < len(self.params[de]) or default is None else ""
        if default is not None and not tok.strip():
            return default
        try:
            return _to_real(tok)
        except ValueError:
            raise IgesFormatError(f"{self.entries[de].where()}: parameter {index} `{tok}` is not a number") from None

    def reals(self, de: int, first: int, count: int) -> np.ndarray:
        """(count,) float64 parameters first .. first+count-1 (vectorised: nets can be large)."""
        toks = self.params[de]
        if first + count > len(toks):
            raise IgesFormatError(f"{self.entries[de].where()}: expected {first + count - 1} parameters, "
                                  f"the record has {len(toks) - 1}")
        chunk = toks[first:first + count]
        distinct = dict.fromkeys(chunk)  # each distinct text converted once: nets repeat weights, grid values
        try:
            value = dict(zip(distinct, map(float, distinct)))
        except ValueError:  # D exponents, blanks inside the number, or not a number at all
            try:
                value = {t: _to_real(t) for t in distinct}
            except ValueError as exc:
                raise IgesFormatError(f"{self.entries[de].where()}: {exc}") from None
        return _finite(np.fromiter(map(value.__getitem__, chunk), dtype=np.float64, count=count), self.entries[de])

    def string(self, de: int, index: int) -> str:
        toks = self.params[de]
        return str(toks[index]) if index < len(toks) else ""


def _finite(values: np.ndarray, entry) -> np.ndarray:
    if not np.all(np.isfinite(values)):
        raise IgesFormatError(f"{entry.where()}: a parameter is not a finite number")
    return values


def _to_int(tok: str) -> int:
    tok = tok.strip()
    try:
        return int(tok)
    except ValueError:
        value = _to_real(tok)
        if value != int(value):
            raise ValueError(tok) from None
        return int(value)


def _to_real(tok: str) -> float:
    t = tok.strip().upper().replace("D", "E")
    if not t or isinstance(tok, Hollerith):
        raise ValueError(f"`{tok}` is not a number")
    try:
        value = float(t)
    except ValueError:
        raise ValueError(f"`{tok}` is not a number") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"`{tok}` is not a finite number")
    return value


_HOLLERITH_START = re.compile(r"[0-9]\s*H")


def _split_params(text: str, pdelim: str, rdelim: str, where) -> list[str]:
    """Tokens of a free-format parameter string up to the record delimiter (Hollerith aware; a record
    without any `nH` is split by the C string methods, which is what large nets take)."""
    if "H" not in text or not _HOLLERITH_START.search(text):
        head, found, _rest = text.partition(rdelim)
        return head.split(pdelim) if found or head.strip() else []  # tokens keep their blanks
    out: list[str] = []
    i, n = 0, len(text)
    while i < n:
        while i < n and text[i] == " ":
            i += 1
        m = re.match(r"([0-9]+)H", text[i:i + 12])
        if m:
            count = int(m.group(1))
            begin = i + len(m.group(0))
            if begin + count > n:
                raise IgesFormatError(f"{where()}: Hollerith string {m.group(0)} runs past the end of the data")
            out.append(Hollerith(text[begin:begin + count]))
            i = begin + count
            while i < n and text[i] == " ":
                i += 1
            if i < n and text[i] not in (pdelim, rdelim):
                raise IgesFormatError(f"{where()}: text after the Hollerith string `{out[-1]}` "
                                      f"before the delimiter")
        else:
            j = i
            while j < n and text[j] not in (pdelim, rdelim):
                j += 1
            out.append(text[i:j].strip())
            i = j
        if i >= n:
            break
        if text[i] == rdelim:
            return out
        i += 1
        if i >= n:
            out.append("")
    return out


def _global_delimiters(text: str) -> tuple[str, str]:
    """Parameters 1 and 2 of the Global section: written `1H,` / `1H;` or defaulted (empty)."""
    pdelim, rest = ",", text
    if rest.startswith("1H"):
        pdelim, rest = rest[2], rest[3:]
    elif rest.startswith(","):
        pdelim, rest = ",", rest
    rest = rest[1:]  # the delimiter after parameter 1
    rdelim = ";"
    if rest.startswith("1H"):
        rdelim = rest[2]
    return pdelim, rdelim


def _parse_global(text: str, record: str) -> GlobalSection:
    g = GlobalSection()
    if not text.strip():
        return g
    pdelim, rdelim = _global_delimiters(text)
    toks = _split_params(text, pdelim, rdelim, lambda: f"Global section ({record})")
    fields = list(g.__dataclass_fields__.values())
    for f, tok in zip(fields[2:], toks[2:]):
        if not tok.strip() and not isinstance(tok, Hollerith):   # a defaulted parameter (`1H ` is a blank string)
            continue
        try:
            value = str(tok) if f.type == "str" else (_to_int(tok) if f.type == "int" else _to_real(tok))
        except ValueError:
            raise IgesFormatError(f"Global section ({record}): parameter {f.name} `{tok}` is malformed") from None
        setattr(g, f.name, value)
    g.param_delimiter, g.record_delimiter = pdelim, rdelim
    return g


def _de_int(text: str, record: str, what: str) -> int:
    t = text.strip()
    if not t:
        return 0
    try:
        return int(t)
    except ValueError:
        raise IgesFormatError(f"record {record}: directory field {what} `{t}` is not an integer") from None


_DE_FIELDS1 = ("type", "pd_pointer", "structure", "line_font", "level", "view", "transform", "label_display")
_DE_FIELDS2 = ("type2", "line_weight", "color", "pd_count", "form")
_LETTERS = np.frombuffer(b"SGDPT", dtype=np.uint8)


def _rows(text: str) -> tuple[np.ndarray, np.ndarray]:
    """(the non-blank records as rows (n, 80) of latin-1 bytes, cut or blank-padded to 80 columns;
    their line numbers (n,)). A file of 80-column records ended by '\\n' with valid section letters
    (rgm's, OpenCASCADE's) is viewed as an array as it is; anything else is split into lines, and
    the first bad record raises IgesFormatError naming its line."""
    raw = text.encode("latin-1", "replace")
    n = len(raw) // 81
    if n and len(raw) == 81 * n and raw.count(b"\n") == n:
        rows = np.frombuffer(raw, dtype=np.uint8).reshape(n, 81)
        if (rows[:, 80] == ord("\n")).all() and np.isin(rows[:, 72], _LETTERS).all():
            return rows[:, :80], np.arange(1, n + 1)
    numbered = [(k, line) for k, line in enumerate(raw.splitlines(), 1) if line.strip()]
    for lineno, line in numbered:
        letter = line[72:73]
        if len(line) < 73:
            raise IgesFormatError(f"line {lineno}: record is {len(line)} columns long; IGES records have "
                                  f"80 (section letter in column 73)")
        if letter == b"C":
            raise IgesFormatError(f"line {lineno}: compressed IGES is not supported")
        if letter not in b"SGDPT":
            raise IgesFormatError(f"line {lineno}: unknown section letter `{letter.decode('latin-1')}` in column 73")
    rows = np.frombuffer(b"".join(line[:80].ljust(80) for _k, line in numbered), dtype=np.uint8)
    return rows.reshape(-1, 80), np.array([k for k, _line in numbered], dtype=np.int64)


def parse_iges(text: str) -> IgesData:
    """Parse the fixed-format ASCII IGES text into `IgesData`.

    Tolerant of what real writers do (CR/LF endings, short records padded, blank lines, D exponents,
    defaulted Global delimiters, comments after the record delimiter); a malformed record raises
    IgesFormatError naming it (`D 17` is the 17th Directory record).
    """
    rows, linenos = _rows(text)
    letters = rows[:, 72]

    def section(letter: str, columns: int) -> str:
        return rows[letters == ord(letter), :columns].tobytes().decode("latin-1")

    stext, gtext, dtext, pdata = section("S", 72), section("G", 72), section("D", 80), section("P", 64)
    d_lines = linenos[letters == ord("D")].tolist()
    if not dtext and not gtext:
        raise IgesFormatError("not an IGES file: no Global or Directory Entry records")
    start = "\n".join(stext[i:i + 72].rstrip() for i in range(0, len(stext), 72))
    g = _parse_global(gtext.rstrip(), f"G 1-{len(gtext) // 72}")
    d = [(n, dtext[80 * k:80 * k + 80]) for k, n in enumerate(d_lines)]
    p_count = len(pdata) // 64
    if len(d) % 2:
        raise IgesFormatError(f"D {len(d)} (line {d[-1][0]}): the Directory Entry section has an odd number of "
                              f"records; every entity takes two")
    entries: dict[int, DirectoryEntry] = {}
    params: dict[int, list[str]] = {}
    for k in range(0, len(d), 2):
        de = k + 1
        (n1, l1), l2 = d[k], d[k + 1][1]
        rec = f"D {de} (line {n1})"
        f1 = [_de_int(l1[8 * i:8 * i + 8], rec, name) for i, name in enumerate(_DE_FIELDS1)]
        f2 = [_de_int(l2[8 * i:8 * i + 8], f"D {de + 1}", name) for i, name in enumerate(_DE_FIELDS2)]
        status = l1[64:72].replace(" ", "0")
        if not status.isdigit():
            raise IgesFormatError(f"{rec}: status number `{l1[64:72]}` is not numeric")
        st = [int(status[i:i + 2]) for i in range(0, 8, 2)]
        entry = DirectoryEntry(de, f1[0], f1[1], f1[2], f1[3], f1[4], f1[5], f1[6], f1[7], *st,
                               f2[1], f2[2], f2[3], f2[4], l2[56:64].strip(), _de_int(l2[64:72], f"D {de + 1}",
                                                                                       "subscript"))
        if f2[0] != f1[0]:
            raise IgesFormatError(f"{rec}: the two Directory records disagree on the entity type "
                                  f"({f1[0]} and {f2[0]})")
        entries[de] = entry
        if entry.type == 0:
            params[de] = ["0"]
            continue
        first, count = entry.pd_pointer, max(entry.pd_count, 1)
        if first < 1 or first + count - 1 > p_count:
            raise IgesFormatError(f"{rec}: parameter pointer {first} (+{count} records) lies outside the "
                                  f"P section of {p_count} records")
        body = pdata[64 * (first - 1):64 * (first - 1 + count)]
        toks = _split_params(body, g.param_delimiter, g.record_delimiter, lambda: f"P {first} ({entry.where()})")
        if not toks or _de_int(toks[0], f"P {first}", "entity type") != entry.type:
            raise IgesFormatError(f"P {first} ({entry.where()}): the parameter record starts with "
                                  f"`{toks[0] if toks else ''}`, not the entity type {entry.type}")
        params[de] = toks
    return IgesData(start, g, entries, params)
