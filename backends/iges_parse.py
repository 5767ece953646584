"""Tolerant parser of fixed-format ASCII IGES (the reader side of `rgm.backends.iges_format`).

`parse_iges(text) -> IgesData`: the Start text, the Global section, every Directory Entry and the
parameter tokens of every entity, by DE number. Tolerant of what real writers do (CR/LF endings,
blank lines, D exponents, defaulted Global delimiters, blanks inside fields, comments after the
record delimiter); a malformed record raises IgesFormatError naming it (`D 17 (line 23)`, `P 5`).
Records without Hollerith strings are split by the C string methods, and long runs of reals are
converted in one call (orjson when installed), so 250 000 control points read in about a second.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .iges_format import GlobalSection, IgesFormatError, _orjson

__all__ = ["DirectoryEntry", "IgesData", "Hollerith", "parse_iges"]

_POINT_EXP = re.compile(r"\.(?![0-9])")


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
        if _orjson is not None and count >= 64:
            text = _POINT_EXP.sub(".0", ",".join(chunk))   # JSON wants a digit after the point
            if "D" in text or "d" in text:
                text = text.replace("D", "E").replace("d", "e")
            try:
                return _finite(np.array(_orjson.loads("[" + text + "]"), dtype=np.float64), self.entries[de])
            except (ValueError, TypeError):
                pass  # not JSON-shaped numbers (".5", "+1.", ...): the general path below
        try:
            return _finite(np.fromiter(map(float, chunk), dtype=np.float64, count=count), self.entries[de])
        except ValueError:
            try:
                return np.array([_to_real(t) for t in chunk], dtype=np.float64)
            except ValueError as exc:
                raise IgesFormatError(f"{self.entries[de].where()}: {exc}") from None

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
        if not tok.strip():
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


def parse_iges(text: str) -> IgesData:
    """Parse the fixed-format ASCII IGES text into `IgesData`.

    Tolerant of what real writers do (CR/LF endings, short records padded, blank lines, D exponents,
    defaulted Global delimiters, comments after the record delimiter); a malformed record raises
    IgesFormatError naming it (`D 17` is the 17th Directory record).
    """
    lines = text.splitlines()
    letters = [line[72:73] for line in lines]
    if not set(letters) <= set("SGDPT"):  # also blank lines (letter "")  # find the first bad record for the message
        for lineno, (line, letter) in enumerate(zip(lines, letters), 1):
            if not line.strip() or letter in ("S", "G", "D", "P", "T"):
                continue
            if len(line) < 73:
                raise IgesFormatError(f"line {lineno}: record is {len(line)} columns long; IGES records have "
                                      f"80 (section letter in column 73)")
            if letter == "C":
                raise IgesFormatError(f"line {lineno}: compressed IGES is not supported")
            raise IgesFormatError(f"line {lineno}: unknown section letter `{letter}` in column 73")
    sections: dict[str, list[tuple[int, str]]] = {k: [] for k in "SGDT"}
    p_rows = []
    for lineno, (line, letter) in enumerate(zip(lines, letters), 1):
        if letter == "P":
            p_rows.append(line[:64])
        elif letter:  # (blank lines have none)
            sections[letter].append((lineno, line.ljust(80)))
    if not sections["D"] and not sections["G"]:
        raise IgesFormatError("not an IGES file: no Global or Directory Entry records")
    start = "\n".join(l[:72].rstrip() for _n, l in sections["S"])
    gtext = "".join(l[:72] for _n, l in sections["G"]).rstrip()
    g = _parse_global(gtext, f"G 1-{len(sections['G'])}")
    d = sections["D"]
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
        if first < 1 or first + count - 1 > len(p_rows):
            raise IgesFormatError(f"{rec}: parameter pointer {first} (+{count} records) lies outside the "
                                  f"P section of {len(p_rows)} records")
        body = "".join(p_rows[first - 1:first - 1 + count])
        toks = _split_params(body, g.param_delimiter, g.record_delimiter, lambda: f"P {first} ({entry.where()})")
        if not toks or _de_int(toks[0], f"P {first}", "entity type") != entry.type:
            raise IgesFormatError(f"P {first} ({entry.where()}): the parameter record starts with "
                                  f"`{toks[0] if toks else ''}`, not the entity type {entry.type}")
        params[de] = toks
    return IgesData(start, g, entries, params)
