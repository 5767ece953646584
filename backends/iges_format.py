"""The IGES 5.3 file as data: Start, Global, Directory Entry, Parameter Data and Terminate sections.

Writer (`IgesFile.to_text`) and tolerant parser (`parse_iges`) of the fixed 80-column ASCII form
(IGES 5.3, ch. 2; layouts follow OpenCASCADE's IGESData_IGESWriter, see
/work/shared/reference/alpha1-iges-step-notes.md §2):

- every record is 80 columns, section letter in column 73, sequence number (restarting per section)
  in columns 74-80;
- Global (G) and Start (S) data in columns 1-72; Parameter Data (P) in columns 1-64, column 65 blank,
  the owning entity's odd DE number in columns 66-72;
- a Directory Entry is two records of nine 8-column fields; pointers are DE sequence numbers (odd);
- strings are Hollerith `nH...`; reals are Python's shortest round-trip `repr` with a Fortran-readable
  exponent (`1e-05` is written `1.E-05`), so every float reads back bit-exact; no token except an
  over-long Hollerith string is ever split across records.

Nothing here knows about geometry: `rgm.backends.iges` lowers a model to `Entity` records and
`rgm.backends.iges_read` builds model objects from a parsed `IgesData`.
"""
from __future__ import annotations

import bisect
import re
import time
from dataclasses import dataclass, field

import numpy as np

from rgm.errors import BackendError

__all__ = ["IgesFormatError", "GlobalSection", "Entity", "IgesFile", "DirectoryEntry", "IgesData",
           "Hollerith", "parse_iges", "format_reals", "hollerith", "UNIT_FLAGS", "iges_date"]


class IgesFormatError(BackendError):
    """A malformed IGES file; the message names the record (section letter and sequence number)."""


#: model units -> IGES Global unit flag (parameter 14) and unit name (parameter 15).
UNIT_FLAGS = {"in": (1, "INCH"), "mm": (2, "MM"), "ft": (4, "FT"), "mi": (5, "MI"), "m": (6, "M"),
              "km": (7, "KM"), "mil": (8, "MIL"), "um": (9, "UM"), "cm": (10, "CM"), "uin": (11, "UIN")}
_FLAG_UNITS = {flag: unit for unit, (flag, _name) in UNIT_FLAGS.items()}
_NAME_UNITS = {name: unit for unit, (_flag, name) in UNIT_FLAGS.items()} | {"IN": "in", "MILLIMETER": "mm"}


# --- tokens --------------------------------------------------------------------------------------

_EXP_NO_POINT = re.compile(r"(?<![0-9.])(-?[0-9]+)E")
_SEP = "\x00"  # token separator while a record is built (never in a token: Hollerith text is cleaned)


_ORJSON_SMALL = re.compile(r"(?<![0-9.])(-?)0\.(0{4,5})([1-9][0-9]*)")
_POINT_EXP = re.compile(r"\.(?![0-9])")
_SHORT_EXP = re.compile(r"e([+-])([0-9])(?![0-9])")

try:  # optional accelerator: shortest round-trip digits (Ryu) ~15x faster than repr, same text after
    import orjson as _orjson  # the normalisation below (tests compare both paths)
except ImportError:  # pragma: no cover - depends on the environment
    _orjson = None


def _sci(m: re.Match) -> str:
    """orjson writes 1e-5 and 1e-6 magnitudes positionally (0.00001); repr writes them as 1e-05."""
    sign, zeros, digits = m.groups()
    digits = digits.rstrip("0") or "0"
    mantissa = digits[0] + ("." + digits[1:] if len(digits) > 1 else "")
    return f"{sign}{mantissa}e-{len(zeros) + 1:02d}"


def _repr_text(arr: np.ndarray, sep: str) -> str:
    """The floats' `repr`s joined by `sep` (orjson's output rewritten to exactly that when present)."""
    flat = np.ascontiguousarray(arr, dtype=np.float64).ravel()
    if _orjson is None or flat.size < 64:
        return sep.join(map(repr, flat.tolist()))
    text = _orjson.dumps(flat, option=_orjson.OPT_SERIALIZE_NUMPY).decode("ascii")[1:-1]
    if "0.0000" in text:
        text = _ORJSON_SMALL.sub(_sci, text)
    if "e" in text:
        text = _SHORT_EXP.sub(r"e\g<1>0\2", text)
    return text if sep == "," else text.replace(",", sep)


def _reals_text(arr: np.ndarray, sep: str = _SEP) -> str:
    """Shortest round-trip forms (Python's `repr`) of the floats of `arr` joined by `sep`, with
    exponents made Fortran-readable (`1e-05` -> `1.E-05`)."""
    if not np.all(np.isfinite(arr)):
        raise BackendError("IGES cannot represent a non-finite number (inf or nan) in the model")
    text = _repr_text(arr, sep)
    if "e" in text:
        text = _EXP_NO_POINT.sub(r"\1.E", text.replace("e", "E"))
    return text


def format_reals(values) -> list[str]:
    """Shortest round-trip decimal forms (`repr`) of floats (k,), with an upper-case exponent and a
    decimal point always in the mantissa (`1e-05` -> `1.E-05`), which Fortran-style readers need.

    Raises BackendError for inf/nan: IGES has no spelling for them.
    """
    arr = np.asarray(values, dtype=np.float64).ravel()
    return _reals_text(arr).split(_SEP) if arr.size else []


def hollerith(text: str) -> str:
    """`nH...`: n counts the characters; non-ASCII characters become '?' (IGES text is ASCII)."""
    text = text.encode("ascii", "replace").decode("ascii")
    text = text.replace("\n", " ").replace("\r", " ").replace(_SEP, " ")
    return f"{len(text)}H{text}"


def iges_date(epoch: float | None = None) -> str:
    """`YYYYMMDD.HHNNSS` (UTC) of `epoch` seconds (IGES 5.x date form)."""
    return time.strftime("%Y%m%d.%H%M%S", time.gmtime(epoch))


class Hollerith(str):
    """A parameter that was a Hollerith string in the file (as opposed to a number or an empty field)."""


def _tokens(values) -> list[str]:
    """Formatted parameter tokens of a list mixing ints, floats, str (Hollerith), None (default, an
    empty field) and float arrays (each element one real). A float array stays one chunk of
    `_SEP`-separated tokens (see `_spans`), so large nets never become a Python list of strings."""
    out: list[str] = []
    for v in values:
        if isinstance(v, np.ndarray):
            if v.size:
                out.append(_reals_text(v) if v.dtype.kind == "f" else _SEP.join(map(str, v.ravel().tolist())))
        elif isinstance(v, (bool, np.bool_)):
            out.append("1" if v else "0")
        elif isinstance(v, (int, np.integer)):
            out.append(str(int(v)))
        elif isinstance(v, (float, np.floating)):
            out.extend(format_reals([v]))
        elif isinstance(v, str):
            out.append(hollerith(v))
        elif v is None:
            out.append("")
        else:
            raise BackendError(f"cannot write {type(v).__name__} as an IGES parameter")
    return out


def _spans(tokens: list[str], width: int, pdelim: str, rdelim: str):
    """(record text `tok1,tok2,...;` as ASCII bytes, start offsets (k,), end offsets (k,)) of its
    records of at most `width` columns, filled greedily with whole tokens (each with its delimiter);
    a token longer than a record (a long Hollerith string) starts a record and fills full ones.

    The greedy breaks are the orbit of token 0 under next(i) = the first token that does not fit on
    a record starting at token i, computed for all i with one `searchsorted`."""
    text = (_SEP.join(tokens) + _SEP).encode("ascii")
    cum = np.flatnonzero(np.frombuffer(text, dtype=np.uint8) == 0) + 1   # token ends, delimiter included
    text = text[:-1].replace(_SEP.encode(), pdelim.encode("ascii")) + rdelim.encode("ascii")
    prev = np.concatenate([[0], cum[:-1]])
    if np.any(cum - prev > width):
        starts, ends, i, n = [], [], 0, len(cum)
        cum_list = cum.tolist()
        base = 0
        while i < n:
            j = bisect.bisect_right(cum_list, base + width, i)
            if j == i:
                bounds = list(range(base, cum_list[i], width)) + [cum_list[i]]
                starts += bounds[:-1]
                ends += bounds[1:]
                j = i + 1
            else:
                starts.append(base)
                ends.append(cum_list[j - 1])
            base, i = cum_list[j - 1], j
        return text, np.array(starts, dtype=np.int64), np.array(ends, dtype=np.int64)
    nxt = np.searchsorted(cum, prev + width, side="right").tolist()
    first, i, n = [], 0, len(nxt)
    while i < n:
        first.append(i)
        i = nxt[i]
    first = np.array(first, dtype=np.int64)
    return text, prev[first], np.append(prev[first[1:]], cum[-1])


def _pack(tokens: list[str], width: int, pdelim: str = ",", rdelim: str = ";") -> list[str]:
    """Record contents (see `_spans`) of one parameter list."""
    text, starts, ends = _spans(tokens, width, pdelim, rdelim)
    return [text[a:b].decode("ascii") for a, b in zip(starts.tolist(), ends.tolist())]


def _digits(values: np.ndarray, width: int = 7) -> np.ndarray:
    """(k, width) uint8 ASCII of non-negative ints right-justified in `width` columns (vectorised)."""
    values = np.asarray(values, dtype=np.int64)
    powers = 10 ** np.arange(width - 1, -1, -1, dtype=np.int64)
    d = (values[:, None] // powers) % 10
    out = (d + ord("0")).astype(np.uint8)
    lead = np.cumsum(d != 0, axis=1) == 0
    lead[:, -1] = False
    out[lead] = ord(" ")
    return out


def _p_section(texts: list[bytes], starts: list, ends: list, des: list[int]) -> str:
    """P records: each entity's records (`_spans`) laid into 80-column rows (columns 1-64 data, 66-72
    the owning DE number, 73 'P', 74-80 the sequence number), built as one uint8 array."""
    counts = np.array([len(s) for s in starts], dtype=np.int64)
    n = int(counts.sum())
    if n == 0:
        return ""
    offsets = np.cumsum([0] + [len(t) for t in texts[:-1]])
    data = b"".join(texts)
    lo = np.concatenate([s + o for s, o in zip(starts, offsets)]).tolist()
    hi = np.concatenate([e + o for e, o in zip(ends, offsets)]).tolist()
    buf = np.full((n, 81), ord(" "), dtype=np.uint8)
    cols = np.array([data[a:b] for a, b in zip(lo, hi)], dtype="S64").view(np.uint8).reshape(n, 64)
    buf[:, :64] = np.where(cols == 0, ord(" "), cols)
    buf[:, 65:72] = _digits(np.repeat(np.asarray(des, dtype=np.int64), counts))
    buf[:, 72] = ord("P")
    buf[:, 73:80] = _digits(np.arange(1, n + 1))
    buf[:, 80] = ord("\n")
    return buf.tobytes().decode("ascii")


# --- Global section ------------------------------------------------------------------------------

@dataclass
class GlobalSection:
    """The 26 Global parameters of IGES 5.3 (table in the research notes §2.2), with rgm's defaults."""

    param_delimiter: str = ","
    record_delimiter: str = ";"
    product_id: str = ""
    file_name: str = ""
    system_id: str = "rgm"
    preprocessor_version: str = "rgm 0.1.0"
    integer_bits: int = 32
    single_max_power: int = 38
    single_digits: int = 6
    double_max_power: int = 308
    double_digits: int = 15
    receiver_product_id: str = ""
    model_scale: float = 1.0
    unit_flag: int = 2
    unit_name: str = "MM"
    line_weight_gradations: int = 1
    max_line_weight: float = 0.01
    date: str = "19700101.000000"
    resolution: float = 1e-6
    max_coordinate: float = 0.0
    author: str = ""
    organization: str = ""
    version: int = 11
    drafting_standard: int = 0
    modified_date: str = "19700101.000000"
    protocol: str = ""

    def values(self) -> list:
        return [getattr(self, f) for f in self.__dataclass_fields__]

    @property
    def units(self) -> str | None:
        """Model units ('mm', 'in', ...) named by the unit flag, or by the unit name for flag 3."""
        unit = _FLAG_UNITS.get(self.unit_flag)
        if unit is None or self.unit_flag == 3:
            unit = _NAME_UNITS.get(self.unit_name.strip().upper().lstrip("0123456789H"))
        return unit


# --- entities (writer side) ----------------------------------------------------------------------

#: subordinate switch values of the status number (IGES 5.3 §2.2.4.4.9)
INDEPENDENT, PHYSICAL, LOGICAL = 0, 1, 2
#: use flag values
USE_GEOMETRY, USE_DEFINITION, USE_PARAMETRIC = 0, 2, 5


@dataclass
class Entity:
    """One entity to write: its type, form, parameters (ints, floats, str, None, float arrays; pointers
    are DE numbers as ints) and Directory Entry fields. `properties` are DE numbers of property
    entities (406 form 15 names) appended as the "additional pointers" of the parameter record."""

    type: int
    params: list
    form: int = 0
    subordinate: int = INDEPENDENT
    use: int = USE_GEOMETRY
    hierarchy: int = 1
    blank: int = 0
    transform: int = 0
    color: int = 0
    label: str = ""
    subscript: int = 0
    properties: list = field(default_factory=list)


@dataclass
class IgesFile:
    """An IGES file under construction: `add` entities children first, then `to_text()`."""

    global_section: GlobalSection
    start: str = "rgm IGES 5.3"
    entities: list = field(default_factory=list)

    def add(self, entity: Entity) -> int:
        """Append `entity`; returns its DE number (the pointer other entities use)."""
        self.entities.append(entity)
        return 2 * len(self.entities) - 1

    def to_text(self) -> str:
        """The whole file: S, G, D, P records and the T record, '\\n'-terminated, 80 columns each."""
        g = self.global_section
        start = [self.start[k:k + 72] for k in range(0, max(len(self.start), 1), 72)]
        s_lines = [f"{t:<72}S{i:7d}" for i, t in enumerate(start, 1)]
        gvals = g.values()
        gtok = [hollerith(gvals[0]), hollerith(gvals[1])] + _tokens(gvals[2:])
        gtok = [t if t != "0H" else "" for t in gtok]
        g_lines = [f"{t:<72}G{i:7d}" for i, t in enumerate(_pack(gtok, 72, g.param_delimiter,
                                                                  g.record_delimiter), 1)]
        d_lines, texts, starts, ends = [], [], [], []
        pseq = 1
        for k, e in enumerate(self.entities):
            de = 2 * k + 1
            values = [e.type, *e.params]
            if e.properties:
                values += [0, len(e.properties), *e.properties]
            text, first, last = _spans(_tokens(values), 64, g.param_delimiter, g.record_delimiter)
            texts.append(text)
            starts.append(first)
            ends.append(last)
            records = first
            status = f"{e.blank:02d}{e.subordinate:02d}{e.use:02d}{e.hierarchy:02d}"
            d_lines.append(f"{e.type:8d}{pseq:8d}{0:8d}{1:8d}{0:8d}{0:8d}{e.transform:8d}{0:8d}"
                           f"{status:>8}D{de:7d}")
            label = e.label.encode("ascii", "replace").decode("ascii")[:8]
            d_lines.append(f"{e.type:8d}{0:8d}{e.color:8d}{len(records):8d}{e.form:8d}{'':8}{'':8}"
                           f"{label:>8}{e.subscript:8d}D{de + 1:7d}")
            pseq += len(records)
        p_count = pseq - 1
        t_line = f"S{len(s_lines):7d}G{len(g_lines):7d}D{len(d_lines):7d}P{p_count:7d}{'':40}T{1:7d}"
        return ("\n".join(s_lines + g_lines + d_lines) + "\n" + _p_section(texts, starts, ends, list(range(1, 2 * len(
            self.entities), 2))) + t_line + "\n")


# --- parsed file (reader side) -------------------------------------------------------------------

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
                return np.array(_orjson.loads("[" + text + "]"), dtype=np.float64)
            except (ValueError, TypeError):
                pass  # not JSON-shaped numbers (".5", "+1.", ...): the general path below
        try:
            return np.fromiter(map(float, chunk), dtype=np.float64, count=count)
        except ValueError:
            try:
                return np.array([_to_real(t) for t in chunk], dtype=np.float64)
            except ValueError as exc:
                raise IgesFormatError(f"{self.entries[de].where()}: {exc}") from None

    def string(self, de: int, index: int) -> str:
        toks = self.params[de]
        return str(toks[index]) if index < len(toks) else ""


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
        (n1, l1), (_n2, l2) = d[k], d[k + 1]
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
