"""`rgmc`: the command line.

Each subcommand lives in `rgm/commands/<name>.py` with `add_arguments(parser)` and `run(args) -> int`,
and is imported only when it runs, so `rgmc check` and `rgmc fmt` never load the heavy back ends.
Exit codes: 0 success, 1 errors in the input, 2 usage errors.
"""
from __future__ import annotations

import argparse
import importlib
import sys

#: subcommand -> (module under rgm.commands, one-line help)
COMMANDS = {
    "check": ("check", "parse and type-check .rgm files"),
    "fmt": ("fmt", "print .rgm files in canonical form"),
    "compile": ("compile", "evaluate a .rgm file and lower it to iges, alpha1, step, brep, stl, obj, ply or glb"),
    "import": ("import_", "turn an IGES or Alpha_1 file into an editable .rgm procedure"),
    "register": ("register", "register several scan views into one frame (ICP)"),
    "triangulate": ("triangulate", "triangulate a scan to a tolerance"),
    "fit": ("fit", "fit scans and write the .rgm procedure that builds the part"),
    "verify": ("verify", "re-measure a .rgm model against scans and check its certificates"),
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rgmc", description="rgm: scans to procedural CAD models")
    parser.add_argument("--version", action="version", version="rgmc 0.1.0")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_module, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    top = _parser()
    if not argv or argv[0] not in COMMANDS:
        if argv and argv[0] in ("-h", "--help", "--version"):
            top.parse_args(argv)
        top.print_usage(sys.stderr)
        if argv:
            print(f"rgmc: error: unknown command `{argv[0]}` (choose from {', '.join(COMMANDS)})", file=sys.stderr)
        return 2
    name, rest = argv[0], argv[1:]
    module = importlib.import_module(f"rgm.commands.{COMMANDS[name][0]}")
    parser = argparse.ArgumentParser(prog=f"rgmc {name}", description=COMMANDS[name][1])
    module.add_arguments(parser)
    try:
        args = parser.parse_args(rest)
    except SystemExit as exc:  # argparse exits 2 on usage errors, 0 on --help
        return int(exc.code or 0)
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        print("rgmc: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
