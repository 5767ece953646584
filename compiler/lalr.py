"""A tight driver for lark's LALR(1) tables: the fast path of `rgm.compiler.parser.parse`.

lark computes the LALR(1) parse table of grammar/rgm.lark; lark's own parse loop, token objects,
lexer classes and callback wrappers cost about 20 µs per token in CPython. This module runs the
same table with the same tree-building callbacks (so it builds the same AST) from one loop:
  * one master regex (`re.finditer` with named groups) replaces the contextual lexer; a NAME that
    spells a keyword (`units`, `param`, ...) becomes the keyword only where the table accepts it,
    which is exactly what lark's contextual lexer does;
  * a reduction pops the rule's symbols, drops anonymous punctuation, splices `_helper` rules into
    their parent and passes `?rule` single children through, as lark's ChildFilter/ExpandSingleChild
    do, then calls the builder method named by the rule's alias or origin.
It does no error recovery: on the first unexpected character or token it returns None and the
caller re-parses with lark's own parser, whose interactive state the recovery needs.
"""
from __future__ import annotations

import re

from lark import Lark
from lark.parsers.lalr_analysis import Shift

# master regex order: first match wins, so longer/higher-priority forms come first
_ORDER = ("NET", "COMMENT", "NUMBER", "STRING", "ANNOTATION", "NAME", "DEFINE")
_BLANK = "[ \t\f\r\n]"


_KIND_CACHE = 200_000   # distinct token spellings remembered between parses


class Tok:
    """A token as the builder sees it: type, text and position (named like Span's fields), without
    the cost of lark's Token (a str subclass). `from_lark` converts one of those."""

    __slots__ = ("type", "value", "start_pos", "end_pos", "line", "col", "end_line", "end_col")

    def __init__(self, type_, value, start_pos, end_pos, line, col, end_line, end_col):
        self.type, self.value, self.start_pos, self.end_pos = type_, value, start_pos, end_pos
        self.line, self.col, self.end_line, self.end_col = line, col, end_line, end_col

    def __str__(self):
        return self.value

    @classmethod
    def from_lark(cls, t) -> "Tok":
        return cls(t.type, t.value, t.start_pos, t.end_pos, t.line, t.column, t.end_line, t.end_column)


class FastLALR:
    """Drive `lark_obj`'s LALR table with the callbacks of `builder` (a lark Transformer)."""

    def __init__(self, lark_obj: Lark, builder):
        frontend = lark_obj.parser.parser.parser
        table = frontend.parse_table
        self.states = table.states
        self.start_state = table.start_states["start"]
        self.end_state = table.end_states["start"]
        terms = {t.name: t for t in lark_obj.terminals}
        name_re = re.compile(terms["NAME"].pattern.to_regexp())
        self.keywords = {str(t.pattern.value): str(t.name) for t in terms.values()
                         if t.pattern.type == "str" and name_re.fullmatch(t.pattern.value)}
        rest = sorted((n for n in terms if n not in _ORDER + ("WS",) and n not in self.keywords.values()),
                      key=lambda n: -len(terms[n].pattern.value))
        order = _ORDER + tuple(rest)
        # any other character is an _ERROR token, so nothing is passed over silently
        alternatives = [terms[n].pattern.to_regexp() for n in order] + [f"(?!{_BLANK})."]
        # one C call splits the text into (blanks, token) pairs (trailing blanks simply end it) ...
        self.splitter = re.compile(f"({_BLANK}*)(" + "|".join(f"(?:{a})" for a in alternatives) + ")", re.DOTALL)
        # ... and a token's kind is found once per distinct spelling: the first alternative that
        # matches it whole is the one that matched it in the text (terminals have no lookahead)
        self.classify = re.compile("|".join(f"(?P<{n}>{a})" for n, a in zip(order + ("_ERROR",), alternatives)),
                                   re.DOTALL).fullmatch
        self.kinds: dict[str, str] = {}
        # punctuation that no rule keeps (`(`, `,`, `:`, `.`) needs no token object
        kept = {sym.name for rule in frontend.callbacks for sym in rule.expansion
                if sym.is_term and not sym.filter_out}
        self.dropped = frozenset(n for n in terms if n not in kept and n not in ("COMMENT", "WS"))
        reducers = {rule: self._reducer(rule, builder) for rule in frontend.callbacks}
        # state -> {symbol: shift/goto target (int) | reducer (size, origin, function)}
        self.actions = [None] * (max(self.states) + 1)
        for state, row in self.states.items():
            self.actions[state] = {str(sym): (arg if what is Shift else reducers[arg]) for sym, (what, arg) in row.items()}

    @staticmethod
    def _reducer(rule, builder):
        """(size, origin name, function of the popped values) for one grammar rule."""
        size = len(rule.expansion)
        keep = [i for i, sym in enumerate(rule.expansion) if not (sym.is_term and sym.filter_out)]
        splice = {i for i in keep if not rule.expansion[i].is_term and rule.expansion[i].name.startswith("_")}
        name = str(rule.origin.name)
        method = getattr(builder, str(rule.alias or name), None)
        grows = bool(keep) and keep[0] in splice and rule.expansion[keep[0]].name == rule.origin.name
        if grows:
            # a left-recursive list helper (`_x_star: _x_star "," item`): append to the list built
            # so far instead of copying it, which would make a list of n items cost n^2
            first, rest = keep[0], keep[1:]

            def children(values):
                out = values[first]
                for i in rest:
                    if i in splice:
                        out.extend(values[i])
                    else:
                        out.append(values[i])
                return out
        elif splice:
            def children(values):
                out = []
                for i in keep:
                    if i in splice:
                        out.extend(values[i])
                    else:
                        out.append(values[i])
                return out
        elif len(keep) == size:
            children = None                      # every symbol is kept: the popped list as it is
        else:
            def children(values):
                return [values[i] for i in keep]
        if name.startswith("_"):                 # a helper rule: its children go to the parent
            return size, name, children or list
        if rule.options.expand1 and rule.alias is None:
            if not splice and len(keep) == 1 and size == 1:   # `?rule: child`: no call at all
                return size, name, None
            if not splice and len(keep) == 1:    # `?rule` with one kept child: pass it through
                k = keep[0]
                return size, name, lambda values: values[k]

            def passthrough(values):
                c = children(values) if children else values
                return c[0] if len(c) == 1 else method(c)
            return size, name, passthrough
        if children is None:
            return size, name, method
        return size, name, lambda values: method(children(values))

    def parse(self, text: str, on_comment) -> bool:
        """Parse `text`, calling the builder as lark would; False at the first error (nothing is
        undone: the caller discards what was built and re-parses with lark). Lines and columns are
        counted along the way: only blanks and nets can hold a newline."""
        actions, keywords, end_state, dropped = self.actions, self.keywords, self.end_state, self.dropped
        kinds, classify = self.kinds, self.classify
        if len(kinds) > _KIND_CACHE:
            kinds.clear()
        state_stack = [self.start_state]
        values: list = []
        pos, line, bol = 0, 1, 0           # offset after the last token, its line, where that line begins
        pairs = self.splitter.findall(text)
        pairs.append(("", None))
        for blank, value in pairs:
            if value is None:
                tok, kind = None, "$END"
            else:
                start = pos + len(blank)
                pos = start + len(value)
                if "\n" in blank:
                    line += blank.count("\n")
                    bol = start - len(blank) + blank.rindex("\n") + 1
                kind = kinds.get(value)
                if kind is None:
                    kind = kinds[value] = classify(value).lastgroup
                if kind in dropped:
                    tok = None
                elif kind == "NAME":
                    tok = Tok(kind, value, start, pos, line, start - bol + 1, line, pos - bol + 1)
                    if value in keywords and keywords[value] in actions[state_stack[-1]]:
                        kind = tok.type = keywords[value]
                elif kind == "NET":
                    col = start - bol + 1
                    if "\n" in value:
                        end_line = line + value.count("\n")
                        bol = start + value.rindex("\n") + 1
                    else:
                        end_line = line
                    tok = Tok(kind, value, start, pos, line, col, end_line, pos - bol + 1)
                    line = end_line
                else:
                    tok = Tok(kind, value, start, pos, line, start - bol + 1, line, pos - bol + 1)
                    if kind == "COMMENT":
                        on_comment(tok)
                        continue
                    if kind == "_ERROR":
                        return False
            while True:     # reduce while the table says so, then shift
                action = actions[state_stack[-1]].get(kind)
                if action is None:
                    return False
                if type(action) is int:
                    state_stack.append(action)
                    values.append(tok)
                    break
                size, origin, fn = action
                if fn is None:              # a unit rule passing its child through: change state only
                    state_stack[-1] = actions[state_stack[-2]][origin]
                    continue
                if size:
                    value = fn(values[-size:])
                    del values[-size:]
                    del state_stack[-size:]
                else:
                    value = fn([])
                goto = actions[state_stack[-1]][origin]
                state_stack.append(goto)
                values.append(value)
                if goto == end_state and kind == "$END":
                    return True
        return False
