"""`rgmc fmt FILE... [--write | --check]`: print `.rgm` files in canonical form.

Without options the canonical text goes to stdout. `--write` rewrites, atomically, only the files whose
text changes; `--check` changes nothing and exits 1 listing the files that are not canonical (as
`cue fmt --check` does). A file with syntax errors is never rewritten: its diagnostics are printed and
the exit code is 1. Exit 2 is a usage error (unreadable file, both options).
"""
from __future__ import annotations

import sys

from rgm.commands.check import internal_error, read_sources
from rgm.compiler.diagnostics import render, sort_and_dedupe, summary


def add_arguments(parser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE", help=".rgm files to format")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="rewrite files in place (atomically) when they change")
    mode.add_argument("--check", action="store_true", help="exit 1 and list the files that are not canonical")


def canonical(text: str, filename: str):
    """(canonical text or None, diagnostics); never raises (a formatter crash is an E0999 diagnostic)."""
    from rgm.compiler.format import format_source

    try:
        formatted, diags = format_source(text, filename)
    except Exception as exc:  # noqa: BLE001 - reported as an internal-error diagnostic
        return None, [internal_error(filename, exc)]
    return formatted, sort_and_dedupe(diags)


def run(args) -> int:
    try:
        sources = read_sources(args.files)
    except ValueError as exc:
        print(f"rgmc fmt: error: {exc}", file=sys.stderr)
        return 2
    failed = False
    not_canonical = []
    for name, text in sources.items():
        formatted, diags = canonical(text, name)
        if formatted is None:
            failed = True
            for d in diags:
                print(render(d, sources), file=sys.stderr, end="\n\n")
            print(f"{name}: not formatted ({summary(diags)})", file=sys.stderr)
            continue
        if args.check:
            if formatted != text:
                not_canonical.append(name)
                print(name)
        elif args.write:
            if formatted != text:
                from rgm.atomic import write_atomic

                write_atomic(name, formatted)
                print(f"reformatted {name}", file=sys.stderr)
        else:
            sys.stdout.write(formatted)
    if args.check and not_canonical:
        print(f"{len(not_canonical)} file{'s' * (len(not_canonical) != 1)} not in canonical form; "
              f"run `rgmc fmt --write` on {'them' if len(not_canonical) > 1 else 'it'}", file=sys.stderr)
        return 1
    return 1 if failed else 0
