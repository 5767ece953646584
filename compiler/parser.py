"""`.rgm` text -> typed AST (rgm.compiler.ast) plus syntax diagnostics; never raises.

The grammar (grammar/rgm.lark) is compiled by lark into LALR(1) tables (cached on disk by lark's
`cache=True`, so a new process builds the parser in milliseconds). The AST is built *during* parsing
by the callbacks of `_Builder`, so no parse tree is ever materialised, and a dense control net is one
token handed to numpy (rgm.compiler.netbody). Valid text goes through a fast driver over lark's
table (rgm.compiler.lalr, about five times as fast as lark's loop); text with a syntax error is parsed
again by lark's own LALR parser with the contextual lexer (`transformer=` the same builder), whose
interactive state the recovery below needs. Both build identical trees (tested).

Error recovery, so that one run reports several mistakes:
  * a missing `;` at the end of a line is reported (E0005) and inserted, and parsing goes on;
  * a stray character is reported (E0002) and skipped; `=` where `:=` belongs is replaced;
  * an unterminated string (E0003) is closed at the end of its line;
  * any other unexpected token (E0001) drops the statement: parsing restarts after the next `;`
    (found by a scanner that skips strings, comments and nets), with the text before it blanked so
    that every position stays where it was.
Value problems found while building nodes (a bad net body E0004, a number too large E0006, a
positional argument after a named one E0007, an unknown unit E0008) drop their statement too.

Codes: E0001 unexpected token, E0002 unexpected character, E0003 unterminated string, E0004 bad net,
E0005 missing `;`, E0006 number out of range, E0007 positional after named argument, E0008 unknown
units, E0009 too many syntax errors (parsing stopped).
"""
from __future__ import annotations

import functools
import re
import threading
from dataclasses import fields, replace

from lark import Lark, Token, Transformer, Tree
from lark.exceptions import UnexpectedCharacters, UnexpectedInput, UnexpectedToken

from rgm.grammar import GRAMMAR_PATH

from . import ast as A
from . import gcpause
from .diagnostics import Diagnostic, Span, error
from .lalr import Code, FastLALR, Tok

MAX_ERRORS = 40

_LABELS = {
    "SEMI": "`;`", "DEFINE": "`:=`", "NAME": "a name", "NUMBER": "a number", "STRING": "a string",
    "NET": "a net", "LSQB": "`[`", "RSQB": "`]`", "LPAR": "`(`", "RPAR": "`)`", "COMMA": "`,`",
    "COLON": "`:`", "DOT": "`.`", "PLUS": "`+`", "MINUS": "`-`", "STAR": "`*`", "SLASH": "`/`",
    "UNITS": "`units`", "TOLERANCE": "`tolerance`", "PARAM": "`param`", "FN": "`fn`",
    "EXPORT": "`export`", "ANNOTATION": "an annotation such as `@fit(...)`", "$END": "the end of the file",
}
_KEYWORDS = {"UNITS", "TOLERANCE", "PARAM", "FN", "EXPORT"}
_OPERATORS = {"PLUS", "MINUS", "STAR", "SLASH"}
_EXPR_START = {"NAME", "NUMBER", "STRING", "LSQB", "LPAR", "NET", "MINUS"}
_STMT_START = {"UNITS", "TOLERANCE", "PARAM", "FN", "EXPORT", "ANNOTATION"}
_UNIT_SUFFIXES = ("mm", "cm", "deg", "rad", "in", "m")
_INF = float("inf")       # a NUMBER token has no sign: the only non-finite value it reads as
# skips strings, comments and nets while looking for the `;` that ends a broken statement
_SYNC = re.compile(r'"(?:[^"\\\n]|\\.)*"?|#[^\n]*|net\s+[0-9]+(?:\s*x\s*[0-9]+)?\s*\[[^\]]*\]|;')
_NEWLINE_GAP = re.compile(r"\n[ \t\f\r]*\n")
_ESCAPES = {"n": "\n", "t": "\t", '"': '"', "\\": "\\"}


def parse(text: str | bytes, filename: str = "<input>", *, fast: bool = True
          ) -> tuple[A.Program | None, list[Diagnostic]]:
    """Parse `.rgm` source. Returns (program, diagnostics); the program is always built (None only if
    the text could not be read at all), holding the statements that parsed. Bytes are decoded as
    UTF-8 with replacement characters. Whatever the input, this function does not raise.
    `fast=False` skips the fast driver (rgm.compiler.lalr) and uses lark's own parse loop: both build
    the same tree, which the tests check."""
    if isinstance(text, (bytes, bytearray)):
        text = bytes(text).decode("utf-8", errors="replace")
    with _LOCK, gcpause.paused():    # the tree has no cycles (rgm.compiler.gcpause)
        run = _Run(text, filename)
        try:
            try:
                run.parse(fast)
            except RecursionError:
                run.diags.append(error("E0009", "this expression is nested too deeply to read", run.span(0, 1)))
            return run.program(), run.diags
        finally:
            _BUILDER.run = None   # the tree is the caller's: freeing it must not wait for the next parse


# ------------------------------------------------------------------------------------------------ AST

def _twin(cls):
    """A plain class with the slots of the frozen, slotted dataclass `cls`: an instance of it, its
    slots set by ordinary assignment, becomes a `cls` by `__class__` assignment (allowed between
    classes of the same layout). Several times as fast as the generated __init__, whose every field
    goes through `object.__setattr__` past the frozen __setattr__; the result is the same object."""
    names = tuple(f.name for f in fields(cls))
    assert cls.__slots__ == names, cls
    twin = type(cls.__name__, (), {"__slots__": names})
    probe = object.__new__(twin)
    probe.__class__ = cls       # raises now, at import, if the layouts ever differ
    return twin


def _maker(cls):
    """A constructor for the frozen dataclass `cls` taking every field in order (see `_twin`): spans
    and nodes are most of the objects a parse creates."""
    names = [f.name for f in fields(cls)]
    assert not any(n.endswith("_") for n in names)
    source = (f"def make({', '.join(names)}):\n    made_ = twin_()\n"   # no field ends with `_`
              + "".join(f"    made_.{n} = {n}\n" for n in names)
              + "    made_.__class__ = cls_\n    return made_\n")
    namespace = {"twin_": _twin(cls), "cls_": cls}
    exec(source, namespace)
    return namespace["make"]


_SPAN, _NUMBER, _STRING, _NAME, _CALL, _LIST, _BINOP, _NEG, _MEMBER, _NET = map(_maker, (
    Span, A.Number, A.String, A.Name, A.Call, A.ListExpr, A.BinOp, A.Neg, A.Member, A.Net))
_TYPEREF, _PARAM, _ANNOTATION, _UNITS, _TOLERANCE, _BINDING, _FNDEF, _EXPORT, _COMMENT = map(_maker, (
    A.TypeRef, A.Param, A.Annotation, A.Units, A.Tolerance, A.Binding, A.FnDef, A.Export, A.Comment))


def _read_number(text: str) -> tuple[float, str | None, bool]:
    """(value, unit, is_int) of a NUMBER token's spelling."""
    unit = None
    if text[-1] > "9":                 # a letter: a unit suffix
        for suffix in _UNIT_SUFFIXES:
            if text.endswith(suffix):
                text, unit = text[: -len(suffix)], suffix
                break
    return float(text), unit, text.isdigit()


#: spelling -> `_read_number(spelling)`: files repeat their numbers (cleared when it grows large);
#: only finite values (an infinite one is an error, reported each time)
_NUMBERS: dict[str, tuple[float, str | None, bool]] = {}


def _unescape(raw: str) -> str:
    return re.sub(r"\\(.)", lambda m: _ESCAPES.get(m.group(1), m.group(1)), raw)


@functools.cache
def _netbody():
    from . import netbody   # numpy is loaded only when a file has a net
    return netbody


class _Builder(Transformer):
    """Lark callbacks: children (named tokens and already-built nodes) -> AST nodes with spans.
    One instance serves every parse (under _LOCK); `run` is the parse in progress. Tokens are Tok
    (the fast driver) or lark Tokens (lark's loop), converted where their position is read."""

    run: "_Run"

    def __default__(self, data, children, meta):
        """Helper rules (`_args`, `_items`, ...): a Tree that lark splices into its parent's children."""
        return Tree(data, children)

    # -- spans
    def _span(self, first, last) -> Span:
        """From the start of `first` to the end of `last`, each a token or a node."""
        a = first if first.__class__ is Tok else first.span if first.__class__ is not Token else Tok.from_lark(first)
        b = last if last.__class__ is Tok else last.span if last.__class__ is not Token else Tok.from_lark(last)
        return _SPAN(self.run.filename, a.line, a.col, b.end_line, b.end_col, a.start_pos, b.end_pos)

    def _token_span(self, tok) -> Span:
        _, _, start, end, line, col, end_line, end_col = tok if tok.__class__ is Tok else Tok.from_lark(tok)
        return _SPAN(self.run.filename, line, col, end_line, end_col, start, end)

    # -- expressions (the hottest callbacks build their token's span inline)
    def number(self, c):
        return self._number(c[0])

    def _number(self, tok) -> A.Number:
        _, text, start, end, line, col, end_line, end_col = tok if tok.__class__ is Tok else Tok.from_lark(tok)
        known = _NUMBERS.get(text)
        if known is None:
            if len(_NUMBERS) > 100_000:
                _NUMBERS.clear()
            known = _read_number(text)
            if known[0] != _INF:       # the compiled statements take what the cache holds as valid
                _NUMBERS[text] = known
        value, unit, is_int = known
        span = _SPAN(self.run.filename, line, col, end_line, end_col, start, end)
        if value == _INF:
            self.run.value_error(error("E0006", f"`{text}` is too large for a 64-bit float", span,
                                       "out of range", hint="the largest number is about 1.8e308"))
            value = 0.0
        return _NUMBER(value, unit, is_int, span)

    def string(self, c):
        raw = c[0].value[1:-1]
        return _STRING(_unescape(raw) if "\\" in raw else raw, self._token_span(c[0]))

    def name(self, c):
        _, text, start, end, line, col, end_line, end_col = c[0] if c[0].__class__ is Tok else Tok.from_lark(c[0])
        return _NAME(text, _SPAN(self.run.filename, line, col, end_line, end_col, start, end))

    def call(self, c):
        func = _NAME(c[0].value, self._token_span(c[0]))
        args, kwargs = [], []
        for item in c[1:-1]:
            if item.__class__ is tuple:
                kwargs.append(item)
            elif kwargs:
                self.run.value_error(error(
                    "E0007", "a positional argument cannot follow a named one", item.span,
                    "positional argument after `" + kwargs[-1][0] + ":`",
                    hint="move it before the named arguments, or give it its name"))
            else:
                args.append(item)
        return _CALL(func, tuple(args), tuple(kwargs), self._span(c[0], c[-1]))

    def kwarg(self, c):
        return (c[0].value, c[1])

    def listexpr(self, c):
        return _LIST(tuple(c[1:-1]), self._span(c[0], c[-1]))

    def binop(self, c):
        return _BINOP(c[1].value, c[0], c[2], self._span(c[0], c[2]))

    def neg(self, c):
        return _NEG(c[1], self._span(c[0], c[1]))

    def member(self, c):
        return _MEMBER(c[0], c[1].value, self._span(c[0], c[1]))

    def net(self, c):
        tok = c[0]
        netbody = _netbody()
        try:
            shape, width, data = netbody.read_net(tok.value)
        except netbody.NetError as e:
            self.run.value_error(error("E0004", e.message, self.run.span(tok.start_pos + e.start, tok.start_pos + e.end),
                                       hint=e.hint))
            shape, width, data = (1,), 1, netbody.np.zeros((1, 1))   # a stand-in: the statement is dropped
        return _NET(shape, width, data, self._token_span(tok))

    # -- declarations
    def type(self, c):
        return _TYPEREF(c[0].value, tuple(x for x in c[1:] if isinstance(x, A.TypeRef)), self._span(c[0], c[-1]))

    def param(self, c):
        return _PARAM(c[0].value, c[1], self._span(c[0], c[1]))

    def annotation(self, c):
        args = tuple(x for x in c[1:] if x.__class__ is tuple)
        return _ANNOTATION(c[0].value[1:], args, self._span(c[0], c[-1]))

    # -- statements
    def units(self, c):
        unit = c[1].value
        if unit not in A.LENGTH_UNITS:
            self.run.value_error(error("E0008", f"unknown units `{unit}`", self._token_span(c[1]),
                                       "expected mm, cm, m or in", hint="write `units mm;`"))
        return self.run.statement(_UNITS(unit, (), None, False, self._span(c[0], c[-1])))

    def tolerance(self, c):
        return self.run.statement(_TOLERANCE(self._number(c[1]), (), None, False, self._span(c[0], c[-1])))

    def binding(self, c):
        n = 0                              # annotations come first
        while c[n].__class__ is A.Annotation:
            n += 1
        is_param = c[n].__class__ in _TOKENS and c[n].type == "PARAM"
        name = c[n + 1] if is_param else c[n]
        stmt = _BINDING(name.value, c[-2], is_param, tuple(c[:n]), (), None, False, self._span(c[0], c[-1]),
                        self._token_span(name))
        return self.run.statement(stmt)

    def fndef(self, c):
        annotations = tuple(x for x in c if isinstance(x, A.Annotation))
        name = c[len(annotations) + 1]
        params = tuple(x for x in c if isinstance(x, A.Param))
        stmt = _FNDEF(name.value, params, c[-2], annotations, (), None, False, self._span(c[0], c[-1]),
                      self._token_span(name))
        return self.run.statement(stmt)

    def export(self, c):
        names = tuple(_NAME(t.value, self._token_span(t)) for t in c[1:-1])
        return self.run.statement(_EXPORT(names, (), None, False, self._span(c[0], c[-1])))

    def start(self, c):
        return None


# --------------------------------------------------------------------------- compiled statements

def _tuple_src(items: list[str]) -> str:
    return f"({items[0]},)" if len(items) == 1 else f"({', '.join(items)})"


class _Inliner:
    """Templates for the statements the fast driver compiles (rgm.compiler.lalr._Source): each writes
    out, as Python source, what the `_Builder` method of its name does with Tok tokens, making the same
    nodes and spans, in the same order, without the method call, the children list or the unpacking
    of tokens per node (the tokens are unpacked once; spans are assembled from their fields). A
    template declines (returns None: the method itself is called) on anything unusual, such as a
    positional argument after a named one (E0007) or a child it knows nothing about; a number the
    cache does not hold yet (or that is out of range, E0006) goes through `_Builder._number`, and a
    net through `_Builder.net`."""

    prologue = ("R_ = B_.run", "F_ = R_.filename")
    _CLASSES = (Span, A.Number, A.String, A.Name, A.Call, A.ListExpr, A.BinOp, A.Neg, A.Member,
                A.Annotation, A.Binding, A.Export)

    def __init__(self, builder: _Builder):
        self.namespace = {"B_": builder, "NUMS_get": _NUMBERS.get, "unescape_": _unescape}
        self.fields = {}
        for cls in self._CLASSES:
            self.namespace["C_" + cls.__name__] = cls
            self.namespace["T_" + cls.__name__] = _twin(cls)
            self.fields[cls.__name__] = [f.name for f in fields(cls)]

    def emit(self, out, method: str, c: list[Code]) -> Code | None:
        template = getattr(self, "t_" + method, None)
        return None if template is None else template(out, c)

    # -- writing
    def new(self, out, cls: str, values: list[str], indent: str = "", var: str | None = None) -> str:
        """`var = <a cls with these field values, in field order>` (made as `_maker` makes it)."""
        var = var or out.var()
        out.lines.append(f"{indent}{var} = T_{cls}()")
        out.lines += [f"{indent}{var}.{k} = {v}" for k, v in zip(self.fields[cls], values, strict=True)]
        out.lines.append(f"{indent}{var}.__class__ = C_{cls}")
        return var

    def span(self, out, first: Code, last: Code, indent: str = "") -> str:
        """A Span from the start of `first` to the end of `last` (as `_Builder._span`)."""
        (line, col, start, _, _, _), (_, _, _, end_line, end_col, end) = first.span, last.span
        return self.new(out, "Span", ["F_", line, col, end_line, end_col, start, end], indent)

    @staticmethod
    def known(*codes: Code) -> bool:
        return all(c.kind is not None and c.span is not None for c in codes)

    # -- expressions
    def t_number(self, out, c):
        tok = c[0]
        k, var = tok.tok, out.var()
        out.lines += [f"k_ = NUMS_get(v{k})", "if k_ is None:", f"    {var} = number([{tok.src}])", "else:"]
        sp = self.span(out, tok, tok, "    ")
        self.new(out, "Number", ["k_[0]", "k_[1]", "k_[2]", sp], "    ", var)
        return Code(var, "Number", None, tok.span)

    def t_string(self, out, c):
        tok = c[0]
        out.lines += [f"x_ = v{tok.tok}[1:-1]", 'if "\\\\" in x_:', "    x_ = unescape_(x_)"]
        return Code(self.new(out, "String", ["x_", self.span(out, tok, tok)]), "String", None, tok.span)

    def t_name(self, out, c):
        tok = c[0]
        return Code(self.new(out, "Name", [f"v{tok.tok}", self.span(out, tok, tok)]), "Name", None, tok.span)

    def t_kwarg(self, out, c):
        return Code(f"(v{c[0].tok}, {c[1].src})", "kwarg", None, None)

    def t_call(self, out, c):
        items = c[1:-1]
        if any(i.kind is None for i in items):
            return None
        kinds = [i.kind == "kwarg" for i in items]
        if kinds != sorted(kinds):     # a positional argument after a named one: E0007
            return None
        func = self.new(out, "Name", [f"v{c[0].tok}", self.span(out, c[0], c[0])])
        args = _tuple_src([i.src for i in items if i.kind != "kwarg"])
        kwargs = _tuple_src([i.src for i in items if i.kind == "kwarg"])
        sp = self.span(out, c[0], c[-1])
        return Code(self.new(out, "Call", [func, args, kwargs, sp]), "Call", None, (*c[0].span[:3], *c[-1].span[3:]))

    def t_listexpr(self, out, c):
        sp = self.span(out, c[0], c[-1])
        items = _tuple_src([i.src for i in c[1:-1]])
        return Code(self.new(out, "ListExpr", [items, sp]), "ListExpr", None, (*c[0].span[:3], *c[-1].span[3:]))

    def t_binop(self, out, c):
        left, op, right = c
        if not self.known(left, right):
            return None
        sp = self.span(out, left, right)
        var = self.new(out, "BinOp", [f"v{op.tok}", left.src, right.src, sp])
        return Code(var, "BinOp", None, (*left.span[:3], *right.span[3:]))

    def t_neg(self, out, c):
        minus, operand = c
        if not self.known(operand):
            return None
        var = self.new(out, "Neg", [operand.src, self.span(out, minus, operand)])
        return Code(var, "Neg", None, (*minus.span[:3], *operand.span[3:]))

    def t_member(self, out, c):
        obj, attr = c
        if not self.known(obj):
            return None
        var = self.new(out, "Member", [obj.src, f"v{attr.tok}", self.span(out, obj, attr)])
        return Code(var, "Member", None, (*obj.span[:3], *attr.span[3:]))

    def t_net(self, out, c):
        return out.call("net", c, "Net", c[0].span)

    # -- declarations and statements
    def t_annotation(self, out, c):
        if any(x.kind is None for x in c[1:]) or any(x.tok is None and x.kind != "kwarg" for x in c[1:]):
            return None
        args = _tuple_src([x.src for x in c[1:] if x.kind == "kwarg"])
        var = self.new(out, "Annotation", [f"v{c[0].tok}[1:]", args, self.span(out, c[0], c[-1])])
        return Code(var, "Annotation", None, (*c[0].span[:3], *c[-1].span[3:]))

    def statement(self, out, var: str, kind: str, c) -> Code:
        out.lines += ["if R_.bad_positions:", f"    R_.statement({var})", "else:", f"    R_.statements.append({var})"]
        return Code(var, kind, None, (*c[0].span[:3], *c[-1].span[3:]))

    def t_binding(self, out, c):
        if not self.known(*c):
            return None
        n = 0
        while c[n].kind == "Annotation":
            n += 1
        is_param = c[n].tok is not None and c[n].kind == "PARAM"
        name = c[n + 1] if is_param else c[n]
        if name.tok is None:
            return None
        sp = self.span(out, c[0], c[-1])
        name_span = self.span(out, name, name)
        var = self.new(out, "Binding", [f"v{name.tok}", c[-2].src, str(is_param),
                                        _tuple_src([a.src for a in c[:n]]), "()", "None", "False", sp, name_span])
        return self.statement(out, var, "Binding", c)

    def t_export(self, out, c):
        if any(x.tok is None for x in c):
            return None
        names = [self.new(out, "Name", [f"v{x.tok}", self.span(out, x, x)]) for x in c[1:-1]]
        sp = self.span(out, c[0], c[-1])
        var = self.new(out, "Export", [_tuple_src(names), "()", "None", "False", sp])
        return self.statement(out, var, "Export", c)


_BUILDER = _Builder()
_LOCK = threading.RLock()
_PARSER: Lark | None = None
_FAST: FastLALR | None = None
_TOKENS = (Token, Tok)


def lark_parser() -> Lark:
    """The shared LALR parser that builds the AST while parsing (for the benchmark and tests)."""
    global _PARSER
    if _PARSER is None:
        _PARSER = Lark(GRAMMAR_PATH.read_text(encoding="utf-8"), parser="lalr", lexer="contextual",
                       transformer=_BUILDER, maybe_placeholders=False, cache=True,
                       lexer_callbacks={"COMMENT": _on_comment})
    return _PARSER


def fast_parser() -> FastLALR:
    """The tight driver over the same LALR table (rgm.compiler.lalr), used first by `parse`."""
    global _FAST
    if _FAST is None:
        _FAST = FastLALR(lark_parser(), _BUILDER, _Inliner(_BUILDER))
    return _FAST


def _on_comment(tok: Token):
    _BUILDER.run.comments.append(tok)
    return tok


# -------------------------------------------------------------------------------------------- a parse

class _Run:
    """The state of one call to `parse`: statements built so far, diagnostics, comments."""

    def __init__(self, text: str, filename: str):
        self.text, self.filename = text, filename
        self.diags: list[Diagnostic] = []
        self.statements: list = []
        self.comments: list[Token] = []
        self.broken: set[str] = set()
        self.bad_positions: list[int] = []    # starts of value errors not yet charged to a statement
        self.last_bad_char: tuple[int, int] | None = None   # (diag index, end offset) of the last E0002

    # -- positions
    def span(self, start: int, end: int) -> Span:
        """Span of text[start:end] (offsets clipped to the text)."""
        n = len(self.text)
        start = max(0, min(start, n))
        end = max(start, min(end, n))
        line = self.text.count("\n", 0, start) + 1
        col = start - (self.text.rfind("\n", 0, start) + 1) + 1
        end_line = line + self.text.count("\n", start, end)
        end_col = end - (self.text.rfind("\n", 0, end) + 1) + 1
        return Span(self.filename, line, col, end_line, end_col, start, end)

    # -- callbacks from the builder
    def value_error(self, diag: Diagnostic):
        self.diags.append(diag)
        self.bad_positions.append(diag.span.start_pos)

    def statement(self, stmt):
        start = stmt.span.start_pos
        if self.bad_positions and self.bad_positions[-1] >= start:
            self.bad_positions = [p for p in self.bad_positions if p < start]
            if isinstance(stmt, (A.Binding, A.FnDef)):
                self.broken.add(stmt.name)
        else:
            self.statements.append(stmt)
        return stmt

    # -- the parse loop
    def parse(self, fast: bool = True):
        """The fast driver first; on a syntax error, start again with lark's parser and recover."""
        _BUILDER.run = self
        if fast:
            if fast_parser().parse(self.text, self.comments.append):
                return
            self.__init__(self.text, self.filename)
            _BUILDER.run = self
        parser = lark_parser()
        start = 0
        while True:
            src = self.text if start == 0 else _blank(self.text, start)
            try:
                parser.parse(src, on_error=self.on_error)
                return
            except UnexpectedInput as e:
                resume = self.recover(e)
            if resume is None or len(self.diags) >= MAX_ERRORS:
                if len(self.diags) >= MAX_ERRORS:
                    self.diags.append(error("E0009", f"too many syntax errors; stopped after {MAX_ERRORS}",
                                            self.span(len(self.text), len(self.text))))
                return
            start = resume

    def on_error(self, e: UnexpectedInput) -> bool:
        """lark's error hook: fix what can be fixed in place (return True to go on parsing)."""
        if len(self.diags) >= MAX_ERRORS:
            return False
        if isinstance(e, UnexpectedCharacters):
            return self.bad_character(e)
        if isinstance(e, UnexpectedToken) and "SEMI" in e.expected and self.first_on_line(e.token):
            at = _code_end(self.text, e.token.start_pos if e.token.type != "$END" else len(self.text))
            if not self.explained(at):
                self.diags.append(error("E0005", "missing `;` after this statement", self.span(at, at + 1),
                                        "expected `;` here", hint="every statement ends with `;`"))
            try:
                ip = e.interactive_parser
                ip.feed_token(self.token("SEMI", ";", at, at))
                if e.token.type != "$END":
                    ip.feed_token(e.token)
                return True
            except UnexpectedInput:
                return False
        return False

    def explained(self, pos: int) -> bool:
        """True when the last diagnostic is a lexical error on the line of `pos`: a token error right
        after it is its consequence (`4 $ 5` is one mistake, not two)."""
        if not self.diags or self.diags[-1].code not in ("E0002", "E0003"):
            return False
        return self.diags[-1].span.line == self.text.count("\n", 0, pos) + 1

    def first_on_line(self, tok: Token) -> bool:
        if tok.type == "$END":
            return True
        line_start = self.text.rfind("\n", 0, tok.start_pos) + 1
        return not self.text[line_start:tok.start_pos].strip()

    def bad_character(self, e: UnexpectedCharacters) -> bool:
        pos = e.pos_in_stream
        ch = self.text[pos] if pos < len(self.text) else ""
        state = e.interactive_parser.lexer_thread.state
        if ch == '"':
            eol = self.text.find("\n", pos)
            eol = len(self.text) if eol < 0 else eol
            self.diags.append(error("E0003", "unterminated string", self.span(pos, eol), "this string is not closed",
                                    hint='close it with `"` on the same line'))
            state.line_ctr.feed(self.text[pos:eol])
            return self.feed(e, "STRING", '""', pos)
        if ch == "=" and "DEFINE" in (e.allowed or ()):
            self.diags.append(error("E0002", "unexpected `=`", self.span(pos, pos + 1), "expected `:=`",
                                    hint="bindings are written `name := value;`"))
            state.line_ctr.feed(ch)
            return self.feed(e, "DEFINE", ":=", pos)
        if self.last_bad_char and self.last_bad_char[1] == pos:   # one diagnostic per run of junk
            i = self.last_bad_char[0]
            d = self.diags[i]
            self.diags[i] = replace(d, message="unexpected characters",
                                    span=self.span(d.span.start_pos, pos + 1))
        else:
            try:
                allowed = set(e.interactive_parser.accepts()) - {"$END"} or e.allowed
            except UnexpectedInput:
                allowed = e.allowed
            shown = ch if ch.isprintable() and not ch.isspace() else f"U+{ord(ch):04X}" if ch else "end of file"
            hint = "comments start with `#`" if ch in "/;" else None
            self.diags.append(error("E0002", f"unexpected character `{shown}`", self.span(pos, pos + 1),
                                    "not part of the language" + (f"; expected {_expected(allowed)}" if allowed else ""),
                                    hint=hint))
        self.last_bad_char = (len(self.diags) - 1, pos + 1)
        return True

    def feed(self, e: UnexpectedInput, kind: str, value: str, pos: int) -> bool:
        """Give the parser a stand-in token after a lexical error; False when it does not fit."""
        try:
            e.interactive_parser.feed_token(self.token(kind, value, pos, pos + 1))
            return True
        except UnexpectedInput:
            return True  # the lexer already moved past; the next token reports what is wrong

    def token(self, kind: str, value: str, start: int, end: int) -> Token:
        """A stand-in lark Token over text[start:end] (an inserted `;`, a closed string)."""
        sp = self.span(start, end)
        return Token(kind, value, start, sp.line, sp.col, sp.end_line, sp.end_col, end)

    def recover(self, e: UnexpectedInput) -> int | None:
        """Report an error the hook could not fix, keep the statements completed before it, and
        return the offset after the next `;` to restart from (None: give up)."""
        if isinstance(e, UnexpectedToken):
            self.unexpected_token(e)
            try:   # a statement just completed (the error is on the next token): reduce it
                e.interactive_parser.feed_eof()   # not a copy: lark's deepcopy drops token end positions
            except (UnexpectedInput, AttributeError, AssertionError):
                pass
            if e.token.type == "$END":
                return None
            pos = e.token.start_pos
        else:
            pos = getattr(e, "pos_in_stream", None) or len(self.text)
        for m in _SYNC.finditer(self.text, pos):
            if m.group() == ";":
                return m.end()
        return None

    def unexpected_token(self, e: UnexpectedToken):
        tok = e.token
        expected = set(e.expected or ())
        if tok.type == "$END":
            at = _code_end(self.text, len(self.text))
            self.diags.append(error("E0001", "unexpected end of file", self.span(max(at - 1, 0), at),
                                    f"expected {_expected(expected)} after this"))
            return
        if self.explained(tok.start_pos):
            return
        try:
            expected = set(e.interactive_parser.accepts()) or expected
        except UnexpectedInput:   # accepts() replays the parser; a failure only loses precision
            pass
        span = self.span(tok.start_pos, tok.end_pos)
        before = self.text[max(0, tok.start_pos - 40):tok.start_pos]
        if tok.type == "NUMBER" and re.search(r"(?<![A-Za-z0-9_])net\s*$", before):
            self.diags.append(error("E0004", "malformed net", span, "expected `x` and a bracketed list of entries",
                                    hint="write `net ROWS x COLS [x y z, x y z, ...]` with a closing `]`"))
            return
        hint = None
        if tok.type in _KEYWORDS and "NAME" in expected:
            hint = f"`{tok}` is a keyword; choose another name"
        elif tok.type == "DEFINE" and (kw := re.search(r"(?<![A-Za-z0-9_])(units|tolerance|param|fn|export)\s*$", before)):
            hint = f"`{kw.group(1)}` is a keyword and cannot be a binding name"
        elif tok.type == "COLON" and "DEFINE" in expected:
            hint = "bindings are written `name := value;`"
        elif tok.type in ("NAME", "NUMBER", "STRING", "NET") and "COMMA" in expected:
            hint = "is a `,` missing?"
        self.diags.append(error("E0001", f"unexpected {_describe(tok)}", span, f"expected {_expected(expected)}",
                                hint=hint))

    # -- the result
    def program(self) -> A.Program:
        comments = sorted({t.start_pos: t if t.__class__ is Tok else Tok.from_lark(t) for t in self.comments}.values(),
                          key=lambda t: t.start_pos)
        stmts, end_comments = _attach_comments(self.text, self.statements, comments)
        return A.Program(tuple(stmts), tuple(end_comments),
                         tuple(_COMMENT(t.value.rstrip(), _SPAN(self.filename, t.line, t.col, t.end_line,
                                                                t.end_col, t.start_pos, t.end_pos))
                               for t in comments),
                         frozenset(self.broken), self.span(0, len(self.text)))


def _restater(cls):
    """`dataclasses.replace(stmt, leading=..., trailing=..., blank_before=...)` for statements of the
    frozen, slotted class `cls`, made as `_maker` makes nodes (no generated __init__)."""
    names = [f.name for f in fields(cls)]
    changed = {"leading": "leading", "trailing": "trailing", "blank_before": "blank"}
    source = ("def restate(stmt, leading, trailing, blank):\n    made_ = twin_()\n"
              + "".join(f"    made_.{n} = {changed.get(n, 'stmt.' + n)}\n" for n in names)
              + "    made_.__class__ = cls_\n    return made_\n")
    namespace = {"twin_": _twin(cls), "cls_": cls}
    exec(source, namespace)
    return namespace["restate"]


_RESTATE = {cls: _restater(cls) for cls in (A.Units, A.Tolerance, A.Binding, A.FnDef, A.Export)}


def _attach_comments(text: str, statements: list, comments: list[Token]):
    """Give each statement its leading comments (before it, or inside it) and its trailing comment
    (after its `;` on the same line); comments after the last statement are returned apart.
    Also marks `blank_before` where a blank line precedes a statement (or its first comment)."""
    out, ci, prev_end = [], 0, 0
    starts = [t.start_pos for t in comments] + [len(text) + 2]   # a sentinel after every position
    spans = [stmt.span for stmt in statements] + [None]
    gap = _NEWLINE_GAP.search
    last = len(statements) - 1
    for k, stmt in enumerate(statements):
        sp = spans[k]
        end = sp.end_pos
        leading, first_pos = (), sp.start_pos
        if starts[ci] < end:
            first_pos = min(first_pos, starts[ci])
            taken = []
            while starts[ci] < end:
                taken.append(comments[ci].value.rstrip())
                ci += 1
            leading = tuple(taken)
        trailing = None
        next_start = spans[k + 1].start_pos if k < last else len(text) + 1
        if (starts[ci] < next_start and comments[ci].line == sp.end_line
                and "\n" not in text[end:starts[ci]]):
            trailing = comments[ci].value.rstrip()
            ci += 1
        blank = k > 0 and gap(text, prev_end, first_pos) is not None
        if leading or trailing or blank:
            stmt = _RESTATE[stmt.__class__](stmt, leading, trailing, blank)
        out.append(stmt)
        prev_end = end
    return out, [t.value.rstrip() for t in comments[ci:]]


def _blank(text: str, start: int) -> str:
    """`text` with everything before `start` turned into spaces (newlines kept, so positions hold)."""
    return re.sub(r"[^\n]", " ", text[:start]) + text[start:]


def _code_end(text: str, pos: int) -> int:
    """Offset just after the last code character before `pos` (skipping blanks and comment lines)."""
    for _ in range(10_000):
        line_start = text.rfind("\n", 0, pos) + 1
        seg = text[line_start:pos]
        if "#" in seg and '"' not in seg:
            seg = seg[: seg.index("#")]
        seg = seg.rstrip()
        if seg or line_start == 0:
            return line_start + len(seg)
        pos = line_start - 1
    return pos


def _describe(tok: Token) -> str:
    if tok.type == "NAME":
        return f"name `{tok}`"
    if tok.type == "NUMBER":
        return f"number `{tok}`"
    if tok.type == "STRING":
        return "string"
    if tok.type == "NET":
        return "net"
    if tok.type == "ANNOTATION":
        return f"annotation `{tok}`"
    if tok.type in _KEYWORDS:
        return f"keyword `{tok}`"
    return f"`{tok}`"


def _expected(terminals) -> str:
    """Human labels for a set of lark terminal names: 'an expression', '`;` or an operator', ..."""
    terms = set(terminals)
    parts = []
    if _STMT_START <= terms:
        parts.append("a statement")
        terms -= _STMT_START | {"NAME"}
    if len(_EXPR_START & terms) >= 5:
        parts.append("an expression")
        terms -= _EXPR_START
    if terms & _OPERATORS:
        terms -= _OPERATORS
        parts.append("an operator")
    order = ["SEMI", "DEFINE", "COMMA", "RPAR", "RSQB", "COLON", "LPAR", "LSQB", "DOT", "NAME", "NUMBER"]
    labels = [_LABELS[t] for t in sorted(terms, key=lambda t: (order.index(t) if t in order else 99, t))
              if t in _LABELS] + parts
    if not labels:
        return "something else"
    labels = labels[:6]
    return labels[0] if len(labels) == 1 else ", ".join(labels[:-1]) + " or " + labels[-1]
