"""`rgmc check FILE... [-D name=value]... [--format text|short|json]`: parse, resolve and type-check.

Exit codes: 0 clean (warnings allowed), 1 errors, 2 usage (bad option, unreadable file). Diagnostics go
to stdout in the chosen format, the summary line ("2 errors, 1 warning") to stderr. Whatever the input,
no Python traceback: a crash inside the compiler is reported as an internal-error diagnostic (E0999).
Every `-D` applies to every file given, so naming a param one of them lacks is an error (E0108).
Imports only the front end (lark, no geometry kernels), so it starts fast.
"""
from __future__ import annotations

import json
import re
import sys
from dataclasses import replace

from rgm.compiler.diagnostics import Diagnostic, error, render, short, sort_and_dedupe, summary, to_dict

INTERNAL = "E0999"


def add_arguments(parser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE", help=".rgm files to check")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE",
                        help="override `param NAME` with VALUE (e.g. -D radius=30mm); repeatable")
    parser.add_argument("--format", choices=("text", "short", "json"), default="text",
                        help="long diagnostics with source lines (default), one line each, or JSON")


def parse_defines(defines: list[str]) -> dict[str, str]:
    """`["radius=30mm"]` -> {"radius": "30mm"}; raises ValueError with a usage message."""
    params: dict[str, str] = {}
    for item in defines:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise ValueError(f"-D expects NAME=VALUE, got `{item}`")
        params[name.strip()] = value.strip()
    return params


def read_sources(files: list[str]) -> dict[str, str]:
    """File name -> text; raises ValueError naming the file that cannot be read."""
    sources = {}
    for name in files:
        try:
            with open(name, encoding="utf-8") as fh:
                sources[name] = fh.read()
        except FileNotFoundError:
            raise ValueError(f"no such file: {name}") from None
        except IsADirectoryError:
            raise ValueError(f"{name} is a directory, not a .rgm file") from None
        except UnicodeDecodeError as exc:
            raise ValueError(f"{name} is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
        except OSError as exc:
            raise ValueError(f"cannot read {name}: {exc.strerror}") from None
    return sources


def internal_error(filename: str, exc: BaseException) -> Diagnostic:
    """The last resort: a compiler crash reported as a diagnostic instead of a traceback."""
    return error(INTERNAL, f"internal compiler error while checking {filename}: {type(exc).__name__}: {exc}", None,
                 hint="this is a bug in rgmc, not in your file; please report it with the file attached")


_DEFINED = re.compile(r"^[ \t]*(?:param[ \t]+)?([A-Za-z_]\w*)[ \t]*:=|^[ \t]*fn[ \t]+([A-Za-z_]\w*)", re.MULTILINE)


def lost_names(text: str, program) -> set[str]:
    """Names the text defines (`name :=`, `fn name(`) that the parsed program lacks: their statements were
    dropped by syntax errors, so "undefined name" reports about them would only repeat those errors."""
    bound = {s.name for s in program.statements if hasattr(s, "name")}
    return {a or b for a, b in _DEFINED.findall(text)} - bound


def check_source(text: str, filename: str, params: dict[str, str] | None) -> list[Diagnostic]:
    """Every diagnostic of one file: syntax, then (if it parsed) names, types and values."""
    from rgm.compiler.check import check
    from rgm.compiler.parser import parse

    try:
        program, diagnostics = parse(text, filename)
        diagnostics = list(diagnostics)
        if program is not None:
            if any(d.is_error for d in diagnostics):
                program = replace(program, broken=program.broken | lost_names(text, program))
            diagnostics += check(program, params).diagnostics
    except Exception as exc:  # noqa: BLE001 - the documented catch-all, reported as E0999
        return [internal_error(filename, exc)]
    return sort_and_dedupe(diagnostics)


def emit(diagnostics: list[Diagnostic], sources: dict[str, str], fmt: str, out=None) -> None:
    out = out or sys.stdout
    if fmt == "json":
        json.dump([to_dict(d) for d in diagnostics], out, indent=2)
        out.write("\n")
    elif fmt == "short":
        for d in diagnostics:
            out.write(short(d) + "\n")
    else:
        for d in diagnostics:
            out.write(render(d, sources) + "\n\n")


def run(args) -> int:
    try:
        params = parse_defines(args.defines)
        sources = read_sources(args.files)
    except ValueError as exc:
        print(f"rgmc check: error: {exc}", file=sys.stderr)
        return 2
    diagnostics: list[Diagnostic] = []
    for name, text in sources.items():
        diagnostics += check_source(text, name, params)
    emit(diagnostics, sources, args.format)
    print(summary(diagnostics), file=sys.stderr)
    return 1 if any(d.is_error for d in diagnostics) else 0


def canonical_checked(text: str, filename: str):
    """(canonical text, '', [rendered warnings]) when the text formats (`rgmc fmt`) and the formatted text
    has no error under `rgmc check` (syntax, names, types, values); else (None, what failed with the
    rendered diagnostics, []). What `rgmc fit` and `rgmc import` pass every generated file through before
    writing it: a generator bug is reported, never written."""
    from rgm.commands.fmt import canonical

    formatted, diagnostics = canonical(text, filename)
    if formatted is None:
        return None, "format:\n" + "\n".join(render(d, {filename: text}) for d in diagnostics), []
    diagnostics = check_source(formatted, filename, None)
    errors = [render(d, {filename: formatted}) for d in diagnostics if d.is_error]
    if errors:
        return None, "check:\n" + "\n".join(errors), []
    return formatted, "", [render(d, {filename: formatted}) for d in diagnostics]
