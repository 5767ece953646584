"""`rgmc import FILE.igs|FILE.iges|FILE.a1 [-o OUT.rgm] [--force]`: an IGES or Alpha_1 file as an
editable `.rgm` procedure, in canonical layout (`rgmc fmt --check` passes) and checked (`rgmc check`
finds no error) before it is written.

Entities the reader does not support are listed on stderr by type, form and DE number (the rest is
imported); a malformed file is an error naming the record. Without `-o` the text goes to stdout.
Exit codes: 0 imported (possibly with unsupported entities reported), 1 unreadable input or nothing
importable, 2 usage.
"""
from __future__ import annotations

import sys
from pathlib import Path


def add_arguments(parser) -> None:
    parser.add_argument("file", metavar="FILE", help="IGES (.igs, .iges) or Alpha_1 text (.a1) file")
    parser.add_argument("-o", "--output", metavar="OUT", help="the .rgm file to write (default: stdout)")
    parser.add_argument("--force", action="store_true", help="overwrite OUT if it exists")


def _read(path: Path):
    """(model, messages) of an IGES or Alpha_1 file."""
    if path.suffix.lower() == ".a1":
        from rgm.backends.alpha1 import read_alpha1

        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise _Fail(f"{path}: cannot read ({exc})") from None
        return read_alpha1(text, source=str(path)), []
    from rgm.backends.iges_read import read_iges_file

    result = read_iges_file(path)
    return result.model, result.messages()


class _Fail(Exception):
    pass


def run(args) -> int:
    from rgm.atomic import OutputExists, write_atomic
    from rgm.backends.rgm_source import model_to_rgm
    from rgm.commands.check import canonical_checked
    from rgm.errors import RgmError

    path = Path(args.file)
    try:
        model, messages = _read(path)
        for line in messages:
            print(f"{path}: warning: {line}", file=sys.stderr)
        if not model.objects:
            print(f"{path}: error: nothing to import", file=sys.stderr)
            return 1
        name = args.output or "<stdout>"
        text, problems, warnings = canonical_checked(
            model_to_rgm(model, header=f"imported from {path.name} by rgmc import"), name)
        if text is None:
            print(f"rgmc import: internal error (a bug in rgmc import, nothing written): the generated "
                  f"{name} does not {problems}", file=sys.stderr)
            return 1
        for warning in warnings:
            print(f"rgmc import: warning in the generated {name}:\n{warning}", file=sys.stderr)
        if args.output:
            out = Path(args.output)
            if out.resolve() == path.resolve():
                print(f"rgmc import: error: refusing to overwrite the input {path}", file=sys.stderr)
                return 1
            write_atomic(out, text, overwrite=args.force)
        else:
            sys.stdout.write(text)
    except OutputExists as exc:
        print(f"rgmc import: error: {exc}", file=sys.stderr)
        return 1
    except (_Fail, RgmError) as exc:
        print(f"rgmc import: error: {exc}", file=sys.stderr)
        return 1
    return 0
