"""The canonical text of a `.rgm` program (what `rgmc fmt` prints).

Rules, chosen so that `parse(format_program(p)) == p` exactly and formatting is idempotent:
  * headers (`units`, `tolerance`) first, in source order, then a blank line, then the other
    statements in source order; one statement per line; a blank line in the source between two
    statements is kept (one at most);
  * comments survive: a statement's leading comments go on the lines above it (above its
    annotations), its trailing comment after its `;`, comments after the last statement at the end;
  * spacing: `a := b;`, `f(a, b, key: c)`, `[a, b]`, binary operators with a space either side,
    parentheses only where precedence needs them;
  * a call, list or annotation longer than 100 columns is broken one argument per line, indented by
    4 spaces, with a trailing comma, and its closing bracket on its own line;
  * numbers: integers as written, other values by Python's shortest round-trip repr (`0.1`, `1e-07`);
  * a 2-D net is printed one row per line; a 1-D net packs entries up to the line width.
"""
from __future__ import annotations

from . import ast as A
from .diagnostics import Diagnostic, error

WIDTH = 100
INDENT = "    "
_PREC = {"+": 1, "-": 1, "*": 2, "/": 2}


def format_source(text: str | bytes, filename: str = "<input>") -> tuple[str | None, list[Diagnostic]]:
    """Parse and format; (None, diagnostics) when the text has syntax errors."""
    from .parser import parse

    program, diags = parse(text, filename)
    if program is None or any(d.is_error for d in diags):
        return None, diags
    try:
        return format_program(program), diags
    except RecursionError:   # thousands of nested operators: report, do not crash
        return None, diags + [error("E0009", "this file is nested too deeply to format", program.span)]


def format_program(program: A.Program) -> str:
    """Canonical text of `program`, ending with one newline ("" for an empty program)."""
    headers = [s for s in program.statements if isinstance(s, (A.Units, A.Tolerance))]
    others = [s for s in program.statements if not isinstance(s, (A.Units, A.Tolerance))]
    lines: list[str] = []
    for i, stmt in enumerate(headers + others):
        if lines and (stmt.blank_before and i >= len(headers) or i == len(headers)):
            lines.append("")
        lines.extend(stmt.leading)
        for ann in getattr(stmt, "annotations", ()):
            lines.append(_annotation(ann))
        text = _statement(stmt)
        if stmt.trailing:
            text += "  " + stmt.trailing
        lines.append(text)
    if program.end_comments:
        if lines:
            lines.append("")
        lines.extend(program.end_comments)
    return "\n".join(lines) + "\n" if lines else ""


def format_expr(expr: A.Expr, indent: int = 0, column: int = 0) -> str:
    """Text of one expression starting at `column`, on a line indented by `indent` spaces."""
    return _expr(expr, indent, column)


# ------------------------------------------------------------------------------------------ statements

def _statement(stmt) -> str:
    if isinstance(stmt, A.Units):
        return f"units {stmt.unit};"
    if isinstance(stmt, A.Tolerance):
        return f"tolerance {_number(stmt.value)};"
    if isinstance(stmt, A.Binding):
        head = f"{'param ' if stmt.is_param else ''}{stmt.name} := "
        return head + _expr(stmt.expr, 0, len(head)) + ";"
    if isinstance(stmt, A.FnDef):
        params = ", ".join(f"{p.name}: {p.type}" for p in stmt.params)
        head = f"fn {stmt.name}({params}) := "
        return head + _expr(stmt.body, 0, len(head)) + ";"
    if isinstance(stmt, A.Export):
        return "export " + ", ".join(n.id for n in stmt.names) + ";"
    raise TypeError(f"not a statement: {stmt!r}")


def _annotation(ann: A.Annotation) -> str:
    if not ann.args:
        return f"@{ann.name}"
    return _bracketed(f"@{ann.name}(", [_Arg(k, e) for k, e in ann.args], ")", 0, 0)


# ----------------------------------------------------------------------------------------- expressions

class _Arg:
    """An item in brackets: `key: expr` or a bare expression."""

    __slots__ = ("key", "expr")

    def __init__(self, key, expr):
        self.key, self.expr = key, expr

    def text(self, indent: int, column: int) -> str:
        head = f"{self.key}: " if self.key is not None else ""
        return head + _expr(self.expr, indent, column + len(head))


def _bracketed(open_: str, items: list[_Arg], close: str, indent: int, column: int) -> str:
    """`open_ a, b close` on one line when it fits, else one item per line with a trailing comma."""
    flat = _flat_items(open_, items, close, WIDTH - column - 1)   # - 1: the `,` or `;` after it
    if flat is not None:
        return flat
    if not items:
        return open_ + close
    inner = indent + len(INDENT)
    body = [" " * inner + it.text(inner, inner) + "," for it in items]
    return open_ + "\n" + "\n".join(body) + "\n" + " " * indent + close


def _flat_items(open_: str, items: list[_Arg], close: str, room: int) -> str | None:
    """`open_ a, b close` on one line if that is at most `room` columns, else None."""
    parts, used = [], len(open_) + len(close) + 2 * max(len(items) - 1, 0)
    for it in items:
        head = f"{it.key}: " if it.key is not None else ""
        text = _flat(it.expr, room - used - len(head))
        if text is None:
            return None
        parts.append(head + text)
        used += len(head) + len(text)
    return open_ + ", ".join(parts) + close if used <= room else None


def _flat(e, room: int) -> str | None:
    """The one-line text of `e` (what `_expr` prints when it fits) if at most `room` columns, else None
    (a 2-D net is never one line). The work stops at `room`: deciding whether a call fits costs the
    width of a line, not a render of its whole subtree at each level of nesting."""
    if room < 0:
        return None
    if isinstance(e, (A.Number, A.Name, A.String)):
        text = _expr(e, 0, 0)
    elif isinstance(e, A.Call):
        return _flat_items(e.func.id + "(", [_Arg(None, a) for a in e.args] + [_Arg(k, v) for k, v in e.kwargs],
                           ")", room)
    elif isinstance(e, A.ListExpr):
        return _flat_items("[", [_Arg(None, a) for a in e.items], "]", room)
    elif isinstance(e, A.BinOp):
        p = _PREC[e.op]
        left = _flat_wrap(e.left, _prec(e.left) < p, room)
        right = None if left is None else _flat_wrap(e.right, _prec(e.right) <= p, room - len(left) - len(e.op) - 2)
        text = None if right is None else f"{left} {e.op} {right}"
    elif isinstance(e, A.Neg):
        inner = _flat_wrap(e.operand, _prec(e.operand) < 3, room - 1)
        text = None if inner is None else "-" + inner
    elif isinstance(e, A.Member):
        obj = _flat_wrap(e.obj, _prec(e.obj) < 4 or isinstance(e.obj, A.Number), room - len(e.attr) - 1)
        text = None if obj is None else f"{obj}.{e.attr}"
    elif isinstance(e, A.Net):
        text = _expr(e, 0, 0) if len(e.shape) == 1 and e.data.size <= room else None
        text = None if text is None or "\n" in text else text
    else:
        raise TypeError(f"not an expression: {e!r}")
    return text if text is not None and len(text) <= room else None


def _flat_wrap(e, paren: bool, room: int) -> str | None:
    if not paren:
        return _flat(e, room)
    inner = _flat(e, room - 2)
    return None if inner is None else "(" + inner + ")"


def _prec(e) -> int:
    if isinstance(e, A.BinOp):
        return _PREC[e.op]
    if isinstance(e, A.Neg):
        return 3
    return 4


def _last_col(text: str, column: int) -> int:
    nl = text.rfind("\n")
    return column + len(text) if nl < 0 else len(text) - nl - 1


def _expr(e, indent: int, column: int) -> str:
    if isinstance(e, A.Number):
        return _number(e)
    if isinstance(e, A.Name):
        return e.id
    if isinstance(e, A.String):
        return _string(e.value)
    if isinstance(e, A.Call):
        items = [_Arg(None, a) for a in e.args] + [_Arg(k, v) for k, v in e.kwargs]
        return _bracketed(e.func.id + "(", items, ")", indent, column)
    if isinstance(e, A.ListExpr):
        return _bracketed("[", [_Arg(None, a) for a in e.items], "]", indent, column)
    if isinstance(e, A.BinOp):
        p = _PREC[e.op]
        left = _wrap(e.left, _prec(e.left) < p, indent, column)
        col = _last_col(left, column) + len(e.op) + 2
        right = _wrap(e.right, _prec(e.right) <= p, indent, col)
        return f"{left} {e.op} {right}"
    if isinstance(e, A.Neg):
        return "-" + _wrap(e.operand, _prec(e.operand) < 3, indent, column + 1)
    if isinstance(e, A.Member):
        obj = _wrap(e.obj, _prec(e.obj) < 4 or isinstance(e.obj, A.Number), indent, column)
        return f"{obj}.{e.attr}"
    if isinstance(e, A.Net):
        return _net(e, indent, column)
    raise TypeError(f"not an expression: {e!r}")


def _wrap(e, paren: bool, indent: int, column: int) -> str:
    return "(" + _expr(e, indent, column + 1) + ")" if paren else _expr(e, indent, column)


def _number(n: A.Number) -> str:
    if n.is_int and float(n.value).is_integer():
        text = str(int(n.value))
    else:
        text = repr(float(n.value))
    return text + (n.unit or "")


def _string(value: str) -> str:
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t") + '"'


def _float(v: float) -> str:
    text = repr(v)
    return text[:-2] if text.endswith(".0") else text


def _net(net: A.Net, indent: int, column: int) -> str:
    """`net R x C [` then one row per line (2-D), or entries packed to the width (1-D)."""
    values = [_float(v) for v in net.data.reshape(-1).tolist()]
    w = net.width
    entries = [" ".join(values[i:i + w]) for i in range(0, len(values), w)]
    head = "net " + " x ".join(map(str, net.shape)) + " ["
    inner = " " * (indent + len(INDENT))
    if len(net.shape) == 1:
        flat = head + ", ".join(entries) + "]"
        if column + len(flat) <= WIDTH:
            return flat
        rows, line = [], []
        for entry in entries:
            if line and len(inner) + len(", ".join(line + [entry])) + 1 > WIDTH:
                rows.append(", ".join(line))
                line = []
            line.append(entry)
        rows.append(", ".join(line))
    else:
        cols = net.shape[1]
        rows = [", ".join(entries[i:i + cols]) for i in range(0, len(entries), cols)]
    return head + "\n" + ",\n".join(inner + r for r in rows) + "\n" + " " * indent + "]"
