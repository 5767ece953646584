"""`rgmc compile FILE -t TARGET -o OUT [-D name=value]... [--tol T] [--angle A] [--verify] [--force]
[--option key=value]...`: evaluate a `.rgm` file and lower it with one back end.

Diagnostics print as in `rgmc check`; any error exits 1 before a back end is loaded. The back end
is imported only for its target (so a STEP-less machine can still write IGES), and every writer
writes atomically and raises `rgm.errors.BackendError` on failure: the message is printed, the exit
code is 1, and no output file is left behind. The input file is never overwritten unless `--force`.

Exit codes: 0 written, 1 errors (input or back end), 2 usage.
"""
from __future__ import annotations

import importlib
import math
import os
import sys
from pathlib import Path

#: target -> (back-end module, writer function, extra keyword arguments)
TARGETS = {
    "iges": ("rgm.backends.iges", "write_iges", {}),
    "alpha1": ("rgm.backends.alpha1", "write_alpha1", {}),
    "step": ("rgm.backends.occ", "write_step", {}),
    "brep": ("rgm.backends.occ", "write_brep", {}),
    **{fmt: ("rgm.backends.mesh", "write_mesh", {"fmt": fmt}) for fmt in ("stl", "obj", "ply", "glb")},
}
MESH_TARGETS = ("stl", "obj", "ply", "glb")


def add_arguments(parser) -> None:
    parser.add_argument("file", metavar="FILE", help="the .rgm file to compile")
    parser.add_argument("-t", "--target", required=True, choices=tuple(TARGETS), help="output format")
    parser.add_argument("-o", "--output", required=True, metavar="OUT", help="output file (written atomically)")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="NAME=VALUE",
                        help="override `param NAME` with VALUE (e.g. -D radius=30mm); repeatable")
    parser.add_argument("--tol", type=_positive, default=None, metavar="T",
                        help="chordal tolerance in model units (meshes, intersection curves); default: the model's")
    parser.add_argument("--angle", type=_angle, default=None, metavar="A",
                        help="angular tolerance for meshes, degrees (or with a deg/rad suffix)")
    parser.add_argument("--verify", action="store_true", help="read the written file back and compare it")
    parser.add_argument("--force", action="store_true", help="allow OUT to be the input file itself")
    parser.add_argument("--option", dest="options", action="append", default=[], metavar="KEY=VALUE",
                        help="a back-end option (see docs/backends.md); repeatable")


def _positive(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got `{text}`") from None
    if not value > 0 or not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a positive number, got `{text}`")
    return value


def _angle(text: str) -> float:
    """`15`, `15deg` -> radians; `0.2rad` -> 0.2."""
    import argparse

    unit = "rad" if text.endswith("rad") else "deg"
    value = _positive(text[: -len(unit)] if text.endswith(unit) else text)
    radians = value if unit == "rad" else math.radians(value)
    if radians >= math.pi:
        raise argparse.ArgumentTypeError(f"angle tolerance must be below 180deg, got `{text}`")
    return radians


def parse_options(items: list[str]) -> dict:
    """`["units=mm", "schema=AP214", "binary=true", "n=3"]` -> typed values; raises ValueError."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key.isidentifier():
            raise ValueError(f"--option expects KEY=VALUE, got `{item}`")
        out[key] = _typed(value.strip())
    return out


def _typed(text: str):
    lowered = text.lower()
    if lowered in ("true", "yes", "on"):
        return True
    if lowered in ("false", "no", "off"):
        return False
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def _writer(target: str):
    """The writer function of a target, or a ValueError saying why it is not available."""
    module_name, func_name, _ = TARGETS[target]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and (exc.name == module_name or module_name.startswith(exc.name + ".")):
            raise ValueError(f"the {target} back end ({module_name}) is not installed in this build") from None
        raise ValueError(f"the {target} back end needs `{exc.name}`, which is not installed"
                         + (" (pip install cadquery)" if exc.name in ("OCP", "cadquery") else "")) from None
    writer = getattr(module, func_name, None)
    if writer is None:
        raise ValueError(f"the {target} back end ({module_name}) has no `{func_name}` yet")
    return writer


def _keywords(writer) -> set:
    """The keyword arguments a writer takes by name (its options), without `model`, `path` and **extras."""
    import inspect

    params = inspect.signature(writer).parameters.values()
    return {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)} - {"model", "path"}


def run(args) -> int:
    from rgm.commands.check import emit, internal_error, parse_defines, read_sources
    from rgm.compiler.diagnostics import summary

    try:
        params = parse_defines(args.defines)
        options = parse_options(args.options)
        text = read_sources([args.file])[args.file]
    except ValueError as exc:
        print(f"rgmc compile: error: {exc}", file=sys.stderr)
        return 2
    source, out = Path(args.file), Path(args.output)
    if _same_file(out, source) and not args.force:
        print(f"rgmc compile: error: refusing to overwrite the input file {args.file} (pass --force to allow it)",
              file=sys.stderr)
        return 1
    if out.is_dir():
        print(f"rgmc compile: error: {out} is a directory; give a file name with -o", file=sys.stderr)
        return 2

    from rgm.compiler.api import compile_text

    try:
        model, diagnostics = compile_text(text, args.file, params)
    except Exception as exc:  # noqa: BLE001 - a compiler crash is reported, never a traceback
        model, diagnostics = None, [internal_error(args.file, exc)]
    if model is not None:  # loops with intersections are checked once those are approximated
        diagnostics = diagnostics + _lazy_diagnostics(model, args.tol)
        if any(d.is_error for d in diagnostics):
            model = None
    if diagnostics:
        emit(diagnostics, {args.file: text}, "text")
        print(summary(diagnostics), file=sys.stderr)
    if model is None:
        return 1

    try:
        writer = _writer(args.target)
    except ValueError as exc:
        print(f"rgmc compile: error: {exc}", file=sys.stderr)
        return 1
    kwargs = dict(TARGETS[args.target][2])
    asked = {"tol": args.tol, "angle_tol": args.angle, "verify": args.verify or None}
    accepted = _keywords(writer)
    for key, value in asked.items():
        if value is None:
            continue
        if key not in accepted:
            flag = {"tol": "--tol", "angle_tol": "--angle", "verify": "--verify"}[key]
            print(f"rgmc compile: error: -t {args.target} does not take {flag}", file=sys.stderr)
            return 2
        kwargs[key] = value
    unknown = sorted((set(options) - accepted) | ({"report"} & set(options)))
    if unknown:
        known = ", ".join(sorted(accepted - {"tol", "angle_tol", "verify", "fmt", "report"})) or "none"
        print(f"rgmc compile: error: -t {args.target} has no option {', '.join(unknown)} (its options: {known})",
              file=sys.stderr)
        return 2
    kwargs.update(options)
    if "report" in accepted:   # what the writer measured (verification, mesh size) is printed
        kwargs["report"] = lambda line: print(line, file=sys.stderr)
    existed = out.exists()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"rgmc compile: error: cannot create {out.parent}: {exc.strerror}", file=sys.stderr)
        return 1
    return _write(writer, model, out, kwargs, args.target, existed)


def _lazy_diagnostics(model, tol) -> list:
    from rgm.errors import RgmError
    from rgm.model.validate import validate_lazy

    try:
        return validate_lazy(model, tol)
    except RgmError as exc:
        from rgm.compiler.diagnostics import error

        return [error("E0508", f"an intersection could not be approximated: {exc}", None)]


def _write(writer, model, out: Path, kwargs: dict, target: str, existed: bool) -> int:
    from rgm.errors import RgmError

    try:
        writer(model, out, **kwargs)
    except Exception as exc:  # noqa: BLE001 - reported with a message, never a traceback
        if not existed and out.exists():
            out.unlink()  # a writer that failed must leave nothing behind
        if isinstance(exc, RgmError):
            kind = f"{target} back end"
        elif isinstance(exc, OSError):
            kind = "cannot write the output"
        else:
            kind = f"internal error in the {target} back end ({type(exc).__name__}; please report it)"
        print(f"rgmc compile: error: {kind}: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({target})", file=sys.stderr)
    return 0
