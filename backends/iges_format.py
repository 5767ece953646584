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

Nothing here knows about geometry: `rgm.backends.iges` lowers a model to `Entity` records; the
parser is `rgm.backends.iges_parse`, and `rgm.backends.iges_read` builds model objects from it.
"""
from __future__ import annotations

import bisect
import re
import time
from dataclasses import dataclass, field

import numpy as np

from rgm.errors import BackendError

__all__ = ["IgesFormatError", "GlobalSection", "Entity", "IgesFile", "format_reals", "hollerith", "UNIT_FLAGS",
           "iges_date"]


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
