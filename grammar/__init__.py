"""The LALR grammar of `.rgm` (grammar/rgm.lark); `rgm.compiler.parser` builds the parser from it."""
from __future__ import annotations

from pathlib import Path

GRAMMAR_PATH = Path(__file__).with_name("rgm.lark")


def grammar_text() -> str:
    """The grammar source, for lark.Lark(...) or for tools that print it."""
    return GRAMMAR_PATH.read_text(encoding="utf-8")
