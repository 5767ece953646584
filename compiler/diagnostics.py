"""Diagnostics: what the compiler tells a user about their `.rgm` text.

A diagnostic has a code (`E0xx` errors, `W0xx` warnings), a message, the span it is about, what was
expected, and optional notes and a hint. `render` prints the long form with the source line and a
caret under the span; `short` prints `path:line:col: error[E0301]: message` for editors.
This module imports nothing heavy: back ends and the model use `Span` from here.

Codes, by stage: E00xx syntax (rgm.compiler.parser), E01xx names and declarations
(rgm.compiler.resolve), E02xx units and tolerance, E03xx types (rgm.compiler.check), E04xx constant
values: knot vectors, nets, weights, degenerate geometry (rgm.compiler.valuecheck), E05xx evaluation
(rgm.compiler.evaluate), E0999 an internal compiler error; W01xx warnings (unused names, unknown
annotations, repeated exports). tests/compiler/golden/ holds an example of each.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class Span:
    """A region of source text: 1-based line and column, end exclusive; `file` is the path as given.
    (Slotted: a parse makes one per node, and a dict each would triple the tree's memory.)"""

    file: str
    line: int
    col: int
    end_line: int
    end_col: int
    start_pos: int = 0
    end_pos: int = 0

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


@dataclass(frozen=True)
class Diagnostic:
    code: str
    message: str
    span: Span | None
    severity: str = "error"  # "error" | "warning"
    label: str = ""          # text printed after the carets ("this is a length")
    notes: tuple[str, ...] = field(default_factory=tuple)
    hint: str | None = None

    @property
    def is_error(self) -> bool:
        return self.severity == "error"


class CompileError(Exception):
    """Raised by the API (`rgm.load`) when a file has errors; carries every diagnostic."""

    def __init__(self, diagnostics, sources=None):
        self.diagnostics = list(diagnostics)
        self.sources = sources or {}
        errors = [d for d in self.diagnostics if d.is_error]
        first = errors[0] if errors else (self.diagnostics[0] if self.diagnostics else None)
        head = f"{first.span}: {first.message}" if first and first.span else (first.message if first else "")
        super().__init__(f"{len(errors)} error(s); first: {head}")


def error(code: str, message: str, span: Span | None, label: str = "", notes=(), hint: str | None = None) -> Diagnostic:
    return Diagnostic(code, message, span, "error", label, tuple(notes), hint)


def warning(code: str, message: str, span: Span | None, label: str = "", notes=(), hint: str | None = None) -> Diagnostic:
    return Diagnostic(code, message, span, "warning", label, tuple(notes), hint)


def sort_and_dedupe(diagnostics) -> list[Diagnostic]:
    """Diagnostics ordered by file and position (errors before warnings at one place), one per span.

    When two diagnostics share a span the first one reported is kept: later ones are nearly always
    consequences of it (CUE keeps one error per position for the same reason).
    """
    seen: set = set()
    unique = []
    for d in diagnostics:
        key = (d.span.file, d.span.line, d.span.col, d.span.end_line, d.span.end_col) if d.span else (d.code, d.message)
        if key not in seen:
            seen.add(key)
            unique.append(d)

    def order(d: Diagnostic):
        s = d.span
        return (s is not None, s.file if s else "", s.line if s else 0, s.col if s else 0, not d.is_error)

    return sorted(unique, key=order)


def short(diag: Diagnostic) -> str:
    """`path:line:col: error[E0301]: message`, the one-line form editors understand."""
    where = f"{diag.span}: " if diag.span else ""
    return f"{where}{diag.severity}[{diag.code}]: {diag.message}"


def render(diag: Diagnostic, sources: dict | None = None) -> str:
    """The long form: header, `-->` location, the source line with `^^^` under the span and its label,
    then `= note:` and `= help:` lines. `sources` maps a span's file to its text; a file that is not
    there (or a span past its end) is rendered without the snippet.
    """
    out = [f"{diag.severity}[{diag.code}]: {diag.message}"]
    span = diag.span
    text = (sources or {}).get(span.file) if span else None
    lines = text.splitlines() if text is not None else []
    gutter = " " * len(str(span.line)) if span else ""
    if span:
        out.append(f"{gutter}--> {span}")
    if span and 1 <= span.line <= len(lines):
        line = lines[span.line - 1]
        start = max(span.col - 1, 0)
        stop = span.end_col - 1 if span.end_line == span.line else len(line)
        stop = min(max(stop, start + 1), max(len(line), start + 1))
        # copy tabs from the source so the carets line up however the terminal expands them
        pad = "".join(ch if ch == "\t" else " " for ch in line[:start])
        label = f" {diag.label}" if diag.label else ""
        out += [f"{gutter} |", f"{span.line} | {line}", f"{gutter} | {pad}{'^' * (stop - start)}{label}"]
    elif span and diag.label:
        out.append(f"{gutter} = {diag.label}")
    out += [f"{gutter} = note: {n}" for n in diag.notes]
    if diag.hint:
        out.append(f"{gutter} = help: {diag.hint}")
    return "\n".join(out)


def to_dict(diag: Diagnostic) -> dict:
    """A JSON-ready dict for `--format json` (positions 1-based, end exclusive)."""
    s = diag.span
    return {"code": diag.code, "severity": diag.severity, "message": diag.message,
            "file": s.file if s else None, "line": s.line if s else None, "col": s.col if s else None,
            "end_line": s.end_line if s else None, "end_col": s.end_col if s else None,
            "label": diag.label, "notes": list(diag.notes), "hint": diag.hint}


def summary(diagnostics) -> str:
    """"2 errors, 1 warning"."""
    diagnostics = list(diagnostics)
    errors = sum(1 for d in diagnostics if d.is_error)
    warnings = len(diagnostics) - errors
    return f"{errors} error{'s' * (errors != 1)}, {warnings} warning{'s' * (warnings != 1)}"
