"""The Python API behind `rgm.load`: parse -> check -> evaluate -> validate.

    model = rgm.load("examples/pin.rgm", params={"radius": 30})      # or {"radius": "30mm"}

Errors at any stage raise `CompileError` carrying every diagnostic so far (and the source text, so
`rgm.compiler.diagnostics.render` can show the lines); warnings ride along on `model.diagnostics`.
Intersections stay lazy: nothing here marches one.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rgm.compiler.diagnostics import CompileError, Diagnostic, sort_and_dedupe


def _param_texts(params) -> dict[str, str]:
    """-D style texts from API values: 30 -> "30", 2.5 -> "2.5", "30mm" stays."""
    out = {}
    for name, value in (params or {}).items():
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise TypeError(f"param {name!r}: expected a number or a string such as '30mm', got {value!r}")
        out[name] = value if isinstance(value, str) else repr(value)
    return out


def compile_text(text: str, filename: str, params=None):
    """(model or None, diagnostics): every stage that can run does; the model is None on errors."""
    from rgm.compiler.check import check
    from rgm.compiler.evaluate import evaluate
    from rgm.compiler.parser import parse
    from rgm.model.validate import validate

    texts = _param_texts(params)
    program, diagnostics = parse(text, filename)
    diagnostics = list(diagnostics)
    if program is None or any(d.is_error for d in diagnostics):
        return None, sort_and_dedupe(diagnostics)
    checked = check(program, texts)
    diagnostics += checked.diagnostics
    if any(d.is_error for d in diagnostics):
        return None, sort_and_dedupe(diagnostics)
    model, evaluation = evaluate(program, checked, texts, source=filename)
    diagnostics += evaluation
    diagnostics += validate(model)
    diagnostics = sort_and_dedupe(diagnostics)
    if any(d.is_error for d in diagnostics):
        return None, diagnostics
    return replace(model, diagnostics=tuple(diagnostics)), diagnostics


def loads(text: str, params=None, filename: str = "<string>"):
    """Evaluate `.rgm` source text into a `rgm.model.Model`; raises CompileError on errors."""
    model, diagnostics = compile_text(text, filename, params)
    if model is None:
        raise CompileError(diagnostics, {filename: text})
    return model


def load(path, params=None):
    """Evaluate an `.rgm` file into a `rgm.model.Model`; raises CompileError on errors."""
    path = Path(path)
    return loads(path.read_text(encoding="utf-8"), params, filename=str(path))


__all__ = ["load", "loads", "compile_text", "CompileError", "Diagnostic"]
