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

import time
from dataclasses import dataclass, field

import numpy as np

from rgm.errors import BackendError

from .iges_records import (
    delimit, digits, file_rows, format_reals, hollerith, lay_records, printable, record_bounds, token_stream,
)

__all__ = ["IgesFormatError", "GlobalSection", "Entity", "IgesFile", "format_reals", "hollerith", "UNIT_FLAGS",
           "iges_date"]


class IgesFormatError(BackendError):
    """A malformed IGES file; the message names the record (section letter and sequence number)."""


#: model units -> IGES Global unit flag (parameter 14) and unit name (parameter 15).
UNIT_FLAGS = {"in": (1, "INCH"), "mm": (2, "MM"), "ft": (4, "FT"), "mi": (5, "MI"), "m": (6, "M"),
              "km": (7, "KM"), "mil": (8, "MIL"), "um": (9, "UM"), "cm": (10, "CM"), "uin": (11, "UIN")}
_FLAG_UNITS = {flag: unit for unit, (flag, _name) in UNIT_FLAGS.items()}
_NAME_UNITS = {name: unit for unit, (_flag, name) in UNIT_FLAGS.items()} | {"IN": "in", "MILLIMETER": "mm"}


def iges_date(epoch: float | None = None) -> str:
    """`YYYYMMDD.HHNNSS` (UTC) of `epoch` seconds (IGES 5.x date form)."""
    return time.strftime("%Y%m%d.%H%M%S", time.gmtime(epoch))


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
    """An IGES file under construction: `add` entities children first, then `to_text()` or `to_bytes()`."""

    global_section: GlobalSection
    start: str = "rgm IGES 5.3"
    entities: list = field(default_factory=list)

    def add(self, entity: Entity) -> int:
        """Append `entity`; returns its DE number (the pointer other entities use)."""
        self.entities.append(entity)
        return 2 * len(self.entities) - 1

    def to_text(self) -> str:
        """The whole file: S, G, D, P records and the T record, '\\n'-terminated, 80 columns each."""
        return self.to_bytes().decode("ascii")

    def to_bytes(self) -> bytes:
        """`to_text` as the file's (ASCII) bytes, which are built directly."""
        g = self.global_section
        start = printable(self.start).encode("ascii")
        start = start.ljust(max(1, -(-len(start) // 72)) * 72)
        gvals = g.values()
        gvals = gvals[:2] + [None if v == "" else v for v in gvals[2:]]   # empty strings are defaulted
        g_stream = token_stream([gvals])
        g_bounds = record_bounds(g_stream, 72)[0]
        groups = []
        for e in self.entities:
            values = [e.type, *e.params]
            if e.properties:
                values += [0, len(e.properties), *e.properties]
            groups.append(values)
        p_stream = token_stream(groups)
        p_bounds, owner = record_bounds(p_stream, 64)
        counts = np.bincount(owner, minlength=len(groups)).tolist()
        d_lines, pseq = [], 1                                   # (each entry: the entity's two DE records)
        for e, count in zip(self.entities, counts):
            status = f"{e.blank:02d}{e.subordinate:02d}{e.use:02d}{e.hierarchy:02d}"
            label = printable(e.label)[:8]
            d_lines.append(f"{e.type:8d}{pseq:8d}{0:8d}{1:8d}{0:8d}{0:8d}{e.transform:8d}{0:8d}{status:>8}"
                           f"{e.type:8d}{0:8d}{e.color:8d}{count:8d}{e.form:8d}{'':8}{'':8}{label:>8}{e.subscript:8d}")
            pseq += count
        d_text = "".join(d_lines).encode("ascii")
        buf, s_rows, g_rows, d_rows, p_rows, t_rows = file_rows(
            [("S", len(start) // 72), ("G", len(g_bounds) - 1), ("D", 2 * len(d_lines)), ("P", len(owner)), ("T", 1)])
        s_rows[:, :72] = np.frombuffer(start, dtype=np.uint8).reshape(-1, 72)
        lay_records(g_rows[:, :72], delimit(g_stream, g.param_delimiter, g.record_delimiter), g_bounds)
        d_rows[:, :72] = np.frombuffer(d_text, dtype=np.uint8).reshape(-1, 72)
        lay_records(p_rows[:, :64], delimit(p_stream, g.param_delimiter, g.record_delimiter), p_bounds)
        p_rows[:, 65:72] = digits(2 * owner + 1)
        t_rows[0, :72] = np.frombuffer(f"S{len(s_rows):7d}G{len(g_rows):7d}D{len(d_rows):7d}P{len(p_rows):7d}"
                                       f"{'':40}".encode("ascii"), dtype=np.uint8)
        return buf.tobytes()
