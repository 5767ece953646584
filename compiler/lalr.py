"""A fast driver for lark's LALR(1) tables: the fast path of `rgm.compiler.parser.parse`.

lark computes the LALR(1) parse table of grammar/rgm.lark; lark's own parse loop, token objects,
lexer classes and callback wrappers cost about 20 µs per token in CPython. This module uses the same
table and the same tree-building callbacks (so it builds the same AST), at a fraction of the cost:
  * one regex `findall` (a single C call per 64 KB piece, see `_pieces`) splits the text into
    (blanks, net, token) triples; a
    token's kind is looked up by its spelling, and lines and columns are counted along the way. A
    NAME that spells a keyword (`units`, `param`, ...) becomes the keyword only where the table
    accepts it, which is exactly what lark's contextual lexer does;
  * the table is run per *statement shape*, the sequence of token kinds up to its `;` (`run`). The
    first statements of a shape are built while the table runs (`_Direct`); then the run is written
    out as a Python function of the statement's tokens that makes the same builder calls in the same
    order (`_Source`), compiled once and called for every later statement of that shape: no table
    look-ups, no parse stack. Generated files repeat a few shapes thousands of times; a file whose
    every statement differs costs about what a plain table-driven loop would.
A reduction pops the rule's symbols, drops anonymous punctuation, splices `_helper` rules into their
parent and passes `?rule` single children through, as lark's ChildFilter/ExpandSingleChild do, then
calls the builder method named by the rule's alias or origin (`_Rule`).
It does no error recovery: on the first unexpected character or token it returns False and the
caller re-parses with lark's own parser, whose interactive state the recovery needs.
"""
from __future__ import annotations

import functools
import re
from typing import NamedTuple

from lark import Lark
from lark.parsers.lalr_analysis import Shift

# master regex order: first match wins, so longer/higher-priority forms come first (NET first: see splitter)
_ORDER = ("NET", "COMMENT", "NUMBER", "STRING", "ANNOTATION", "NAME", "DEFINE")
_BLANK = "[ \t\f\r\n]"
_KIND_CACHE = 200_000   # distinct token spellings remembered between parses
_SHAPE_CACHE = 20_000   # statement shapes remembered between parses
_PIECE = 1 << 16        # characters lexed by one findall (a list per piece, not one for the whole text)
_COMPILE_AFTER = 2      # a shape is compiled on its 3rd statement (compiling costs about 3 table runs)


class Tok(NamedTuple):
    """A token as the builder sees it: type, text and position (named like Span's fields), without
    the cost of lark's Token (a str subclass). A tuple, made by `_tuple_new` without a Python call;
    `from_lark` converts a lark Token."""

    type: str
    value: str
    start_pos: int
    end_pos: int
    line: int
    col: int
    end_line: int
    end_col: int

    def __str__(self):
        return self.value

    @classmethod
    def from_lark(cls, t) -> "Tok":
        return cls(t.type, t.value, t.start_pos, t.end_pos, t.line, t.column, t.end_line, t.end_column)


_tuple_new = tuple.__new__
# what the lexer loop does with a token: keep it, drop it (punctuation no rule keeps), hand a comment
# over, stop at an error, or end the statement (`;`)
_KEPT, _DROPPED, _COMMENT, _ERROR, _END = "kept", "dropped", "comment", "error", "end"


class FastLALR:
    """Drive `lark_obj`'s LALR table with the callbacks of `builder` (a lark Transformer)."""

    def __init__(self, lark_obj: Lark, builder, inliner=None):
        self.inliner = inliner     # writes reductions out in compiled statements (see `_Source`)
        frontend = lark_obj.parser.parser.parser
        table = frontend.parse_table
        self.states = table.states
        self.start_state = table.start_states["start"]
        terms = {t.name: t for t in lark_obj.terminals}
        name_re = re.compile(terms["NAME"].pattern.to_regexp())
        self.keywords = {str(t.pattern.value): str(t.name) for t in terms.values()
                         if t.pattern.type == "str" and name_re.fullmatch(t.pattern.value)}
        rest = sorted((n for n in terms if n not in _ORDER + ("WS",) and n not in self.keywords.values()),
                      key=lambda n: -len(terms[n].pattern.value))
        order = _ORDER + tuple(rest)
        # any other character is an _ERROR token, so nothing is passed over silently
        alternatives = [terms[n].pattern.to_regexp() for n in order] + [f"(?!{_BLANK})."]
        # punctuation that no rule keeps (`(`, `,`, `:`, `.`) needs no token object
        kept = {sym.name for rule in frontend.callbacks for sym in rule.expansion
                if sym.is_term and not sym.filter_out}
        self.dropped = frozenset(n for n in terms if n not in kept and n not in ("COMMENT", "WS"))
        # ... and most of it is read with the blanks before a token, as its *gap* (`, `, `(`, `: `):
        # a gap's spelling tells its dropped tokens' kinds and its newlines (`gaps`, `learn_gap`). A
        # character that starts another token stays a token of its own (`.`: `.5`), or is read
        # only where the other token does not follow (`:` but not `:=`)
        spelled = [str(t.pattern.value) for t in terms.values() if t.pattern.type == "str"]
        self.gap_kinds = {}
        simple, guarded = [], []       # gap characters, and those read only before something else
        for n in sorted(self.dropped):
            c = str(terms[n].pattern.value) if terms[n].pattern.type == "str" else ""
            patterns = [terms[m].pattern.to_regexp() for m in terms if terms[m].pattern.type != "str"]
            if len(c) != 1 or any(re.match(a, c + probe) for a in patterns for probe in "0a_\" "):
                continue           # not a single character, or one that starts a number, a name, ...
            longer = [t[1:] for t in spelled if len(t) > 1 and t[0] == c]
            if longer:
                guarded.append(re.escape(c) + f"(?!{'|'.join(map(re.escape, longer))})")
            else:
                simple.append(re.escape(c))
            self.gap_kinds[c] = n
        run = f"[{_BLANK[1:-1]}{''.join(simple)}]*+"
        gap = run + (f"(?:(?:{'|'.join(guarded)}){run})*+" if guarded else "")
        # one C call splits the text into (gap, net, token) triples (trailing gaps simply end it; the
        # caller checks what is left): a net (the first alternative) has a group of its own, so that
        # its kind needs no look-up ...
        others = "|".join(f"(?:{a})" for a in alternatives[1:])
        self.splitter = re.compile(f"({gap})(?:({alternatives[0]})|({others}))", re.DOTALL)
        # ... and any other token's kind is found once per distinct spelling: the first alternative
        # that matches it whole is the one that matched it in the text (terminals have no lookahead)
        self.classify = re.compile("|".join(f"(?P<{n}>{a})" for n, a in zip(order + ("_ERROR",), alternatives)),
                                   re.DOTALL).fullmatch
        self.kinds: dict[str, tuple[str, str, str]] = {}   # spelling -> `learn(spelling)`
        self.gaps: dict[str, tuple] = {}                   # gap spelling -> `learn_gap(spelling)`
        rules = {rule: _Rule(rule) for rule in frontend.callbacks}
        # state -> {symbol: shift/goto target (int) | the rule to reduce}
        self.actions = [None] * (max(self.states) + 1)
        for state, row in self.states.items():
            self.actions[state] = {str(sym): (arg if what is Shift else rules[arg]) for sym, (what, arg) in row.items()}
        self.methods = {r.method: getattr(builder, r.method) for r in rules.values()
                        if r.method and hasattr(builder, r.method)}
        # compiled statements by shape, for the first statement of a file and for the others (the
        # stack below a statement differs); the stack between statements, once known
        self.shapes: tuple[dict, dict] = ({}, {})
        self.between: list[int] | None = None

    def parse(self, text: str, on_comment) -> bool:
        """Parse `text`, calling the builder as lark would; False at the first error (nothing is
        undone: the caller discards what was built and re-parses with lark). Lines and columns are
        counted along the way: only gaps and nets can hold a newline."""
        kinds = self.kinds
        if len(kinds) > _KIND_CACHE:
            kinds.clear()
        for cache in self.shapes:
            if len(cache) > _SHAPE_CACHE:
                cache.clear()
        shapes = self.shapes[0]
        gaps = self.gaps
        if len(gaps) > _KIND_CACHE:
            gaps.clear()
        toks: list[tuple] = []   # the kept tokens of the statement being read (Tok's fields, as a tuple)
        shape: list[str] = []    # the kinds of all its tokens (keyword spellings as themselves)
        keep, note, note_gap = toks.append, shape.append, shape.extend
        pos, line, bol = 0, 1, 0           # offset after the last token, its line, where that line begins
        findall = self.splitter.findall
        for _, end in _pieces(text):
            for gap, net, value in findall(text, pos, end):
                if gap:
                    known = gaps.get(gap)
                    if known is None:
                        known = gaps[gap] = self.learn_gap(gap)
                    dropped, newlines, tail = known
                    start = pos + len(gap)
                    if dropped:
                        note_gap(dropped)
                    if newlines:
                        line += newlines
                        bol = start - tail
                else:
                    start = pos
                if net:
                    value, kind, key, role = net, "NET", "NET", _KEPT
                    pos = start + len(value)
                    col, first_line = start - bol + 1, line
                    if "\n" in value:
                        line += value.count("\n")
                        bol = start + value.rindex("\n") + 1
                    tok = (kind, value, start, pos, first_line, col, line, pos - bol + 1)
                else:
                    pos = start + len(value)
                    known = kinds.get(value)
                    if known is None:
                        known = kinds[value] = self.learn(value)
                    kind, key, role = known
                    if role is not _KEPT:
                        if role is _DROPPED:
                            note(key)
                            continue
                        if role is _COMMENT:
                            on_comment(_tuple_new(Tok, (kind, value, start, pos, line, start - bol + 1, line,
                                                        pos - bol + 1)))
                            continue
                        if role is _ERROR:
                            return False
                        keep((kind, value, start, pos, line, start - bol + 1, line, pos - bol + 1))
                        note(key)       # the `;` that ends the statement
                        key = tuple(shape)
                        build = shapes.get(key, 0)
                        if type(build) is int:     # built `build` times: run the table, compile once it repeats
                            first = shapes is self.shapes[0]
                            if build < _COMPILE_AFTER:
                                if not self.direct(key, first, toks):
                                    return False
                                shapes[key] = build + 1
                                build = None
                            else:              # a shape that has built statements: it compiles
                                direct = functools.partial(self.direct, key, first)
                                build = shapes[key] = self.run(key, first, _Source(self.methods, direct, self.inliner))
                        if build is not None:
                            build(toks)
                        shapes = self.shapes[1]
                        toks.clear()     # nothing keeps the lists: the next statement reuses them
                        shape.clear()
                        continue
                    tok = (kind, value, start, pos, line, start - bol + 1, line, pos - bol + 1)
                keep(tok)
                note(key)
        # text after the last `;` is an unfinished statement, and so is punctuation after the last
        # token (a gap that no token follows is not matched)
        return not shape and not text[pos:].strip(" \t\f\r\n")

    def learn_gap(self, gap: str) -> tuple[tuple[str, ...], int, int]:
        """(the kinds of the dropped tokens in a gap, its newlines, the characters after the last)."""
        newlines = gap.count("\n")
        return (tuple(self.gap_kinds[c] for c in gap if c in self.gap_kinds), newlines,
                len(gap) - gap.rindex("\n") - 1 if newlines else 0)

    def learn(self, value: str) -> tuple[str, str, str]:
        """(kind, shape key, role) of a token spelling: the key is the kind, or the spelling itself
        for a NAME that spells a keyword (`run` decides, by the table, which it is)."""
        kind = self.classify(value).lastgroup
        key = value if kind == "NAME" and value in self.keywords else kind
        role = (_DROPPED if kind in self.dropped else _COMMENT if kind == "COMMENT" else
                _ERROR if kind == "_ERROR" else _END if kind == "SEMI" else _KEPT)
        return kind, key, role

    def direct(self, shape: tuple[str, ...], first: bool, toks: list) -> bool:
        """Build one statement of `shape` from its kept tokens while the table runs."""
        return self.run(shape, first, _Direct(toks, self.methods))

    def run(self, shape: tuple[str, ...], first: bool, out):
        """Run the table over one statement shape (with `$END` after it), building through `out`
        (`_Direct`: the statement itself; `_Source`: a function that builds such statements). The run
        stops before the reduction that would add the statement to the file's list. Returns what
        `out.done` gives, or False when the shape is not a statement."""
        actions, keywords, dropped = self.actions, self.keywords, self.dropped
        states = [self.start_state] if first else list(self.between)
        depth = len(states)
        values: list = [None] * depth
        kept = 0
        for kind in shape + ("$END",):
            if kind in keywords:           # a NAME spelling a keyword
                if keywords[kind] in actions[states[-1]]:
                    kind = keywords[kind]
                    out.retype(kept, kind)
                else:
                    kind = "NAME"
            while True:
                action = actions[states[-1]].get(kind)
                if action is None:
                    return False
                if type(action) is int:
                    states.append(action)
                    if kind in dropped:
                        values.append(None)
                    else:
                        values.append(out.token(kept, kind))
                        kept += 1
                    break
                size = action.size
                if size > len(states) - depth or action.origin == "start":
                    if first:
                        self.between = states
                    return out.done([x for v in values[depth:] for x in (v if isinstance(v, list) else [v])])
                if action.unit:            # `?rule: child`: the value stays, only the state changes
                    states[-1] = actions[states[-2]][action.origin]
                    continue
                if size:
                    popped = values[-size:]
                    del values[-size:]
                    del states[-size:]
                else:
                    popped = []
                states.append(actions[states[-1]][action.origin])
                values.append(action.reduce(popped, out.node))


def _pieces(text: str):
    """Where to cut `text` for lexing piece by piece: yields (0, end), (0, end), ..., each end just
    after a newline that no token spans (the caller lexes from where its last token ended, so the
    start is not used). Lexing piece by piece gives the same tokens as one findall over the text,
    and a list of a few thousand triples at a time instead of millions."""
    n, end = len(text), 0
    while end < n:
        end = _cut(text, end, end + _PIECE)
        yield 0, end


def _cut(text: str, lo: int, at: int) -> int:
    """The offset just after the first newline from `at` on that no token spans (or the text's end);
    `lo` is a token boundary before `at`. Only a net can span a newline, and none spans one with a
    `]` between the last `net` before it and it (a net's head holds no `n`, its body no `]`); when
    that fails, the first newline after the next `]` is tried (linear time, however long the net)."""
    n = len(text)
    cut = text.find("\n", at)
    while cut >= 0:
        last_net = text.rfind("net", lo, cut)
        if last_net < 0 or text.find("]", last_net, cut) >= 0:
            return cut + 1
        close = text.find("]", cut)
        if close < 0:
            return n
        cut = text.find("\n", close)
    return n


class _Direct:
    """Builds one statement while the table runs: tokens and builder calls as they come."""

    def __init__(self, toks: list, methods: dict):
        self.toks, self.methods = toks, methods

    def token(self, k: int, kind: str) -> Tok:
        return _tuple_new(Tok, self.toks[k])

    def retype(self, k: int, kind: str) -> None:
        self.toks[k] = (kind, *self.toks[k][1:])

    def node(self, method: str, children: list):
        return self.methods[method](children)

    def done(self, built: list) -> bool:
        return True


class Code:
    """A value of the statement being written by `_Source`: `src` is the Python expression that holds
    it in the function (`t[3]` for the 4th kept token, `n5` for a node); `kind` is a token's kind
    (after keyword retyping), the node class an inliner made (`"Number"`, `"kwarg"`, ...), or None
    when nothing is known (a builder method called as such); `tok` is a token's index; `span` holds
    the expressions of (line, col, start_pos, end_line, end_col, end_pos) where they are known."""

    __slots__ = ("src", "kind", "tok", "span")

    def __init__(self, src: str, kind: str | None, tok: int | None = None, span: tuple | None = None):
        self.src, self.kind, self.tok, self.span = src, kind, tok, span

    def __repr__(self):
        return f"Code({self.src!r}, {self.kind!r})"


class _Source:
    """Writes what the table does as Python source, `def build(t): ...` over the kept tokens `t`, and
    compiles it: one line per reduction, in the order the reductions ran, so the builder calls run in
    the same order. The tokens come as plain tuples of Tok's fields (a builder method called as such
    gets a Tok, `Tok_(t[3])`); every kept token is unpacked once at the top (`_, v3, s3, e3, l3, c3,
    m3, d3 = t[3]`: value, start, end, line, col, end line, end col). A reduction is written by
    `inliner.emit` when it has a template for it (the builder's work written out in place: no call, no
    children list), else as a call of the builder method. A function Python cannot compile is left to
    `fallback`."""

    def __init__(self, methods: dict, fallback, inliner=None):
        self.methods, self.fallback, self.inliner = methods, fallback, inliner
        self.lines: list[str] = []
        self.count = 0       # kept tokens
        self.fresh = 0       # node variables

    def token(self, k: int, kind: str) -> Code:
        self.count = max(self.count, k + 1)
        return Code(f"Tok_(t[{k}])", kind, k, (f"l{k}", f"c{k}", f"s{k}", f"m{k}", f"d{k}", f"e{k}"))

    def retype(self, k: int, kind: str) -> None:
        self.lines.append(f"t[{k}] = ({kind!r}, *t[{k}][1:])")

    def var(self) -> str:
        self.fresh += 1
        return f"n{self.fresh}"

    def node(self, method: str, children: list) -> Code:
        if self.inliner is not None:
            made = self.inliner.emit(self, method, children)
            if made is not None:
                return made
        return self.call(method, children)

    def call(self, method: str, children: list, kind: str | None = None, span: tuple | None = None) -> Code:
        """`nK = method([children])`: the builder method itself."""
        var = self.var()
        self.lines.append(f"{var} = {method}([{', '.join(c.src for c in children)}])")
        return Code(var, kind, None, span)

    def done(self, built: list):
        head = list(self.inliner.prologue) if self.inliner is not None else []
        head += [f"_, v{k}, s{k}, e{k}, l{k}, c{k}, m{k}, d{k} = t[{k}]" for k in range(self.count)]
        body = head + self.lines + [c.src for c in built if isinstance(c, Code) and c.tok is None and not c.src.isidentifier()]
        source = "def build(t):\n" + "".join(f"    {line}\n" for line in body or ["pass"])
        namespace = dict(self.methods)
        namespace["Tok_"] = functools.partial(_tuple_new, Tok)
        if self.inliner is not None:
            namespace.update(self.inliner.namespace)
        try:
            exec(compile(source, "<statement>", "exec"), namespace)
        except (SyntaxError, RecursionError, MemoryError):   # "too many nested parentheses"
            return self.fallback
        return namespace["build"]


class _Rule:
    """One grammar rule as the shape compiler reduces it: which popped symbols it keeps (anonymous
    punctuation is filtered out), which it splices (`_helper` rules: their children go to the parent),
    whether it is a `?rule` that passes a single child through, and the builder method it calls."""

    def __init__(self, rule):
        expansion = rule.expansion
        self.size = len(expansion)
        self.origin = str(rule.origin.name)
        self.keep = [i for i, sym in enumerate(expansion) if not (sym.is_term and sym.filter_out)]
        self.splice = {i for i in self.keep if not expansion[i].is_term and expansion[i].name.startswith("_")}
        self.helper = self.origin.startswith("_")
        self.passthrough = bool(rule.options.expand1) and rule.alias is None
        self.method = None if self.helper else str(rule.alias or self.origin)
        # a left-recursive list helper (`_x_star: _x_star "," item`) appends to the list built so far
        # instead of copying it, which would make a list of n items cost n^2
        first = self.keep[0] if self.keep else None
        self.grows = first in self.splice and expansion[first].name == rule.origin.name
        self.unit = self.passthrough and self.size == 1 and self.keep == [0] and not self.splice
        self.whole = not self.splice and len(self.keep) == self.size   # the popped list is the children

    def reduce(self, popped: list, node):
        """The value of the reduction: the children list of a helper, the single child of a
        pass-through `?rule`, else `node(method, children)`."""
        children = popped if self.whole else self._children(popped)
        if self.helper:
            return children
        if self.passthrough and len(children) == 1:
            return children[0]
        return node(self.method, children)

    def _children(self, popped: list) -> list:
        """The kept symbols, helpers' lists spliced in."""
        keep = self.keep
        if self.grows:
            children, keep = popped[keep[0]], keep[1:]
        else:
            children = []
        for i in keep:
            if i in self.splice:
                children.extend(popped[i])
            else:
                children.append(popped[i])
        return children
