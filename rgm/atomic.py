"""Atomic output: a file is either the old one or the complete new one, never half-written."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _publish_mode(tmp) -> None:
    """mkstemp creates 0600 files; an output gets the usual 0666 & ~umask like any file a tool writes."""
    os.chmod(tmp, 0o666 & ~_umask())


class OutputExists(Exception):
    """Refusing to overwrite an existing file (an input, say) without an explicit request."""


def write_atomic(path, data, *, overwrite: bool = True) -> Path:
    """Write `data` (str or bytes) to `path` through a temporary file in the same folder and a rename.

    With `overwrite=False` an existing `path` is left untouched and `OutputExists` is raised.
    """
    path = Path(path)
    if not overwrite and path.exists():
        raise OutputExists(f"{path} exists; pass --force to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = "wb" if isinstance(data, (bytes, bytearray, memoryview)) else "w"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **({} if mode == "wb" else {"encoding": "utf-8", "newline": "\n"})) as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        _publish_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def temp_path_beside(path) -> Path:
    """A fresh temporary path in `path`'s folder, for writers that need a file name (OpenCASCADE).

    The caller renames it over `path` with `os.replace` when the output is complete and verified.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    _publish_mode(tmp)
    return Path(tmp)
