"""Diagnostics: what the compiler tells a user about their `.rgm` text.

A diagnostic has a code (`E0xx` errors, `W0xx` warnings), a message, the span it is about, what was
expected, and optional notes and a hint. `render` prints the long form with the source line and a
caret under the span; `short` prints `path:line:col: error[E0301]: message` for editors.
This module imports nothing heavy: back ends and the model use `Span` from here.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Span:
    """A region of source text: 1-based line and column, end exclusive; `file` is the path as given."""

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
