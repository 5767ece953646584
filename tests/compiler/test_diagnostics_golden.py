"""Golden diagnostics: one small `.rgm` file per situation in tests/compiler/golden/.

Each file starts with `# expect: CODE [LINE:COL]` (and optionally `# args: -D name=value ...`); the test
checks that this diagnostic is reported at that position, then compares every diagnostic, rendered in
the long form with carets, to the snapshot `<name>.out` beside it (code, position, message, label,
notes and help all pinned; for syntax errors only the expected one, so that the parser's recovery may
improve without touching these files). Set RGM_UPDATE_GOLDEN=1 to rewrite the snapshots after a deliberate change,
and review the diff.
"""
import os
import re
import shlex
from pathlib import Path

import pytest

from rgm.commands.check import check_source, parse_defines
from rgm.compiler.diagnostics import render, summary

GOLDEN = Path(__file__).parent / "golden"
CASES = sorted(GOLDEN.glob("*.rgm"))
HEADER = re.compile(r"^# expect: (?P<code>[EW]\d{4})(?: (?P<line>\d+):(?P<col>\d+))?$")


def _run(path: Path):
    text = path.read_text()
    lines = text.splitlines()
    m = HEADER.match(lines[0])
    assert m, f"{path.name}: first line must be `# expect: CODE [LINE:COL]`"
    args = lines[1][len("# args:"):] if lines[1].startswith("# args:") else ""
    tokens = shlex.split(args)
    defines = [tokens[i + 1] for i, t in enumerate(tokens) if t == "-D"]
    name = f"golden/{path.name}"
    diags = check_source(text, name, parse_defines(defines))
    if m["code"].startswith("E000"):   # syntax: pin the parser's diagnostic, not how its recovery goes on
        diags = [d for d in diags if d.code == m["code"]]
    rendered = "\n\n".join(render(d, {name: text}) for d in diags) + f"\n\n{summary(diags)}\n"
    return m, diags, rendered


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_golden(path):
    m, diags, rendered = _run(path)
    out = path.with_suffix(".out")
    if os.environ.get("RGM_UPDATE_GOLDEN"):
        out.write_text(rendered)
    hits = [d for d in diags if d.code == m["code"]]
    assert hits, f"expected {m['code']}, got {[(d.code, d.message) for d in diags]}"
    if m["line"]:
        where = [(d.span.line, d.span.col) for d in hits if d.span]
        assert (int(m["line"]), int(m["col"])) in where, where
    else:
        assert any(d.span is None for d in hits)
    assert out.exists(), f"no snapshot {out.name}; run with RGM_UPDATE_GOLDEN=1 and review it"
    assert rendered == out.read_text()


def test_at_least_25_distinct_situations():
    codes = {HEADER.match(p.read_text().splitlines()[0])["code"] for p in CASES}
    assert len(CASES) >= 25 and len(codes) >= 25, (len(CASES), sorted(codes))
