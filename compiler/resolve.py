"""Name resolution: what every name in a `.rgm` program refers to, and the order to evaluate bindings in.

Two namespaces, as in most CAD scripting: a call `f(...)` names a user `fn` or a builtin function; any
other name is a value: a binding, a `param`, or a parameter of the enclosing `fn`. So `profile :=
polyline(...)` may share its name with the builtin `profile(pieces...)`, but a `fn` may not shadow a
builtin (E0104). Reports undefined names with suggestions (E0101), duplicates (E0102), dependency
cycles with their path (E0103), exports of unknown names (E0105), `units`/`tolerance` given twice,
unknown model units, `-D` overrides of missing or non-param bindings, and unused bindings (W0101:
with an `export`, whatever the exports do not need; names starting with `_` are exempt).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from . import ast as A
from .builtins import ANNOTATIONS, FUNCTIONS
from .diagnostics import Diagnostic, error, warning
from .suggest import did_you_mean, suggest
from .units import LENGTH_UNITS


@dataclass
class Resolution:
    """What `resolve` found. `deps[name]` are the bindings and fns that `name` (a binding or fn) uses
    directly; `order` lists the bindings with every dependency (through fns too) before its user."""

    bindings: dict[str, A.Binding] = field(default_factory=dict)
    fns: dict[str, A.FnDef] = field(default_factory=dict)
    deps: dict[str, list[tuple[str, A.Name]]] = field(default_factory=dict)
    order: list[str] = field(default_factory=list)
    cyclic: set[str] = field(default_factory=set)
    exports: tuple[str, ...] = ()
    units: str = "mm"
    tolerance: A.Tolerance | None = None
    overrides: dict[str, A.Expr] = field(default_factory=dict)
    diagnostics: list[Diagnostic] = field(default_factory=list)


_DEFINE_VALUE = re.compile(r"^(?P<neg>-)?(?P<num>(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)"
                           r"(?P<unit>mm|cm|deg|rad|in|m)?$")


_LEAVES = (A.Number, A.String, A.Net)


def parse_define(text: str) -> A.Expr | None:
    """A `-D` value as an expression: `30`, `-2.5mm`, `90deg` or a "string"; None when it is none of these."""
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] == '"':
        return A.String(text[1:-1])
    m = _DEFINE_VALUE.match(text)
    if not m:
        return None
    num = m["num"]
    lit = A.Number(float(num), m["unit"], is_int=num.isdigit())
    return A.Neg(lit) if m["neg"] else lit


def _line(node) -> str:
    return f"line {node.span.line}" if getattr(node, "span", None) else "elsewhere"


def _span_of(node):
    return getattr(node, "name_span", None) or node.span


class _Resolver:
    def __init__(self, program: A.Program, params: dict[str, str] | None):
        self.program = program
        self.params = params or {}
        self.r = Resolution()
        self.used_locals: set[tuple[str, str]] = set()   # (fn, parameter) pairs that are read
        self.suggested: set[str] = set()                  # names offered by "did you mean"
        self.exported: set[str] = set()                   # every name in an `export`, fns included

    def report(self, diag: Diagnostic) -> None:
        self.r.diagnostics.append(diag)

    # -------------------------------------------------------------------------------- declarations
    def declarations(self) -> None:
        first: dict[str, A.Binding | A.FnDef] = {}
        units_seen = tolerance_seen = None
        exports: list[A.Name] = []
        for stmt in self.program.statements:
            if isinstance(stmt, (A.Binding, A.FnDef)):
                self.declare(stmt, first)
            elif isinstance(stmt, A.Units):
                if units_seen is not None:
                    self.report(error("E0106", "`units` is given twice", stmt.span, "second `units`",
                                      [f"the first is on {_line(units_seen)}"]))
                    continue
                units_seen = stmt
                if stmt.unit in LENGTH_UNITS:
                    self.r.units = stmt.unit
                else:
                    self.report(error("E0201", f"unknown model unit `{stmt.unit}`", stmt.span, "not a length unit",
                                      [f"model units are {', '.join(LENGTH_UNITS)}"],
                                      did_you_mean(stmt.unit, LENGTH_UNITS)))
            elif isinstance(stmt, A.Tolerance):
                if tolerance_seen is not None:
                    self.report(error("E0107", "`tolerance` is given twice", stmt.span, "second `tolerance`",
                                      [f"the first is on {_line(tolerance_seen)}"]))
                    continue
                tolerance_seen = self.r.tolerance = stmt
            elif isinstance(stmt, A.Export):
                exports += stmt.names
        self.exports(exports)

    def declare(self, stmt, first) -> None:
        kind = "fn" if isinstance(stmt, A.FnDef) else ("param" if stmt.is_param else "binding")
        if stmt.name in first:
            prev = first[stmt.name]
            self.report(error("E0102", f"`{stmt.name}` is defined twice", _span_of(stmt), "defined again here",
                              [f"the first definition is on {_line(prev)}"],
                              "every name is bound once; rename one of them"))
            return
        first[stmt.name] = stmt
        if kind == "fn":
            if stmt.name in FUNCTIONS:   # calls keep going to the builtin, so one error, not a cascade
                self.report(error("E0104", f"fn `{stmt.name}` shadows the builtin `{stmt.name}`", _span_of(stmt),
                                  "a builtin has this name", FUNCTIONS[stmt.name].notes,
                                  "calls would be ambiguous; give the fn another name"))
                return
            self.r.fns[stmt.name] = stmt
        else:
            self.r.bindings[stmt.name] = stmt

    def exports(self, names: list[A.Name]) -> None:
        seen: set[str] = set()
        out = []
        for name in names:
            if name.id in seen:
                self.report(warning("W0104", f"`{name.id}` is exported twice", name.span, "already exported"))
                continue
            seen.add(name.id)
            self.exported.add(name.id)
            if name.id in self.r.bindings:
                out.append(name.id)
            elif name.id in self.r.fns:
                self.report(error("E0114", f"`{name.id}` is a fn; only bindings can be exported", name.span,
                                  "a fn", hint=f"export a binding that calls it, e.g. `part := {name.id}(...);`"))
            elif name.id not in self.program.broken:
                self.report(error("E0105", f"cannot export `{name.id}`: no binding has this name", name.span,
                                  "not defined", hint=did_you_mean(name.id, self.r.bindings)))
        self.r.exports = tuple(out)

    # -------------------------------------------------------------------------------- references
    def references(self) -> None:
        no_scope: frozenset[str] = frozenset()
        for name, stmt in {**self.r.bindings, **self.r.fns}.items():
            deps: list[tuple[str, A.Name]] = []
            if isinstance(stmt, A.FnDef):
                scope = {p.name for p in stmt.params}
                for ann in stmt.annotations:
                    for _key, expr in ann.args:
                        self.visit(expr, no_scope, None, deps)
                self.visit(stmt.body, scope, name if scope else None, deps)
            else:     # a binding's annotation values, then its expression: one walk, in that order
                roots = [expr for ann in stmt.annotations for _key, expr in ann.args] if stmt.annotations else []
                roots.append(stmt.expr)
                self.visit(roots, no_scope, None, deps, many=True)
            self.r.deps[name] = deps

    def visit(self, expr, scope, fn: str | None, deps, many: bool = False) -> None:
        """Every name in `expr` (with `many`, in each expression of the list `expr`, one after the
        other): calls to `callee`, values to `value_name` (the common cases, a builtin call and a
        binding's name, are settled inline: a file holds many of them)."""
        bindings, fns = self.r.bindings, self.r.fns
        stack = expr[::-1] if many else [expr]
        while stack:
            node = stack.pop()
            kind = type(node)
            if kind is A.Call:
                func = node.func.id
                if func in fns or func not in FUNCTIONS:
                    self.callee(node.func, deps)
                stack.extend(node.args)
                if node.kwargs:
                    stack.extend([kwarg[1] for kwarg in node.kwargs])
            elif kind is A.Number:
                continue
            elif kind is A.Name:
                if node.id in bindings and node.id not in scope:
                    deps.append((node.id, node))
                else:
                    self.value_name(node, scope, fn, deps)
            elif kind is A.BinOp:
                stack.append(node.left)
                stack.append(node.right)
            elif kind is A.ListExpr:
                stack.extend(node.items)
            elif kind not in _LEAVES:
                stack.extend(A.children(node))

    def callee(self, func: A.Name, deps) -> None:
        name = func.id
        if name in self.r.fns:
            deps.append((name, func))
        elif name in FUNCTIONS:
            return
        elif name in self.r.bindings:
            self.suggested.add(name)
            self.report(error("E0112", f"`{name}` is a binding, not a function", func.span, "called here",
                              [f"`{name}` is defined on {_line(self.r.bindings[name])}"],
                              did_you_mean(name, list(FUNCTIONS) + list(self.r.fns))))
        elif name in ANNOTATIONS:
            self.report(error("E0101", f"undefined function `{name}`", func.span, "not a function",
                              hint=f"`@{name}(...)` is an annotation: write it on the line before a binding"))
        elif name not in self.program.broken:
            self.report(error("E0101", f"undefined function `{name}`", func.span, "not defined",
                              hint=did_you_mean(name, list(FUNCTIONS) + list(self.r.fns))))

    def value_name(self, node: A.Name, scope: set[str], fn: str | None, deps) -> None:
        name = node.id
        if name in scope:
            self.used_locals.add((fn, name))
        elif name in self.r.bindings:
            deps.append((name, node))
        elif name in self.r.fns or name in FUNCTIONS:
            sig = FUNCTIONS[name].notes if name in FUNCTIONS else ()
            self.report(error("E0113", f"`{name}` is a function, not a value", node.span, "used as a value", sig,
                              f"call it: `{name}(...)`"))
        elif name not in self.program.broken:
            near = suggest(name, list(scope) + list(self.r.bindings))
            self.suggested.update(near)   # probably meant: not reported as unused on top of this error
            self.report(error("E0101", f"undefined name `{name}`", node.span, "not defined",
                              hint=f"did you mean `{near[0]}`?" if near else
                              did_you_mean(name, list(FUNCTIONS) + list(self.r.fns))))

    # -------------------------------------------------------------------------------- order, cycles, unused
    def order(self) -> None:
        """Tarjan's strongly connected components over bindings and fns; a component of several nodes
        (or a node using itself) is a cycle. Components come out dependencies first, which is the order."""
        deps_of = self.r.deps
        source_order = list(deps_of)
        rank = {n: i for i, n in enumerate(source_order)}
        for i, name in enumerate(source_order):
            for dep, _ref in deps_of[name]:
                if rank[dep] >= i:
                    break
            else:
                continue
            break
        else:   # every name uses only names before it (most files): no cycle, and the order is the source's
            bindings = self.r.bindings
            self.r.order += [n for n in source_order if n in bindings]
            return
        index: dict[str, int] = {}
        low: dict[str, int] = {}
        on_stack: set[str] = set()
        stack: list[str] = []
        components: list[list[str]] = []

        for root in source_order:
            if root in index:
                continue
            work = [(root, iter(deps_of[root]))]
            index[root] = low[root] = len(index)
            stack.append(root)
            on_stack.add(root)
            while work:
                node, it = work[-1]
                advanced = False
                for dep, _ref in it:
                    if dep not in index:
                        index[dep] = low[dep] = len(index)
                        stack.append(dep)
                        on_stack.add(dep)
                        work.append((dep, iter(deps_of[dep])))
                        advanced = True
                        break
                    if dep in on_stack and index[dep] < low[node]:
                        low[node] = index[dep]
                if advanced:
                    continue
                work.pop()
                if work and low[node] < low[work[-1][0]]:
                    low[work[-1][0]] = low[node]
                if low[node] == index[node]:
                    if stack[-1] == node:      # the usual case: a component of one
                        stack.pop()
                        on_stack.discard(node)
                        components.append([node])
                        continue
                    comp = []
                    while True:
                        top = stack.pop()
                        on_stack.discard(top)
                        comp.append(top)
                        if top == node:
                            break
                    components.append(comp)
        bindings, order = self.r.bindings, self.r.order
        for comp in components:
            first = comp[0]
            if len(comp) > 1 or any(dep == first for dep, _ in deps_of[first]):
                self.cycle(sorted(comp, key=rank.get))
            elif first in bindings:
                order.append(first)

    def cycle(self, comp: list[str]) -> None:
        """Report one cycle through the component, starting at its first name in source order."""
        members = set(comp)
        path, refs = [comp[0]], []
        while True:
            dep, ref = next((d, r) for d, r in self.r.deps[path[-1]] if d in members)
            refs.append(ref)
            if dep in path:
                path = path[path.index(dep):] + [dep]
                refs = refs[len(refs) - (len(path) - 1):]
                break
            path.append(dep)
        self.r.cyclic |= members
        start = self.r.bindings.get(path[0]) or self.r.fns[path[0]]
        notes = [f"`{a}` {'calls' if b in self.r.fns else 'uses'} `{b}` on {_line(ref)}"
                 for a, b, ref in zip(path, path[1:], refs)]
        hint = ("a fn is expanded where it is called, so it cannot call itself, directly or through others"
                if members & set(self.r.fns) else "bindings may come in any order, but not in a circle")
        self.report(error("E0103", f"`{path[0]}` depends on itself: {' -> '.join(path)}", _span_of(start),
                          "part of a cycle", notes, hint))

    def unused(self) -> None:
        has_export = any(isinstance(s, A.Export) for s in self.program.statements)
        roots = set(self.exported) if has_export else set(self.r.bindings)
        roots = [n for n in roots | self.suggested if n in self.r.deps]
        seen, stack = set(roots), list(roots)
        while stack:
            for dep, _ref in self.r.deps.get(stack.pop(), ()):
                if dep not in seen:
                    seen.add(dep)
                    stack.append(dep)
        for name, stmt in {**self.r.bindings, **self.r.fns}.items():
            if name not in seen and not name.startswith("_"):
                what = "fn" if isinstance(stmt, A.FnDef) else ("param" if stmt.is_param else "binding")
                self.report(warning("W0101", f"{what} `{name}` is never used", _span_of(stmt), "unused",
                                    hint="export it, use it, or remove it (names starting with `_` are exempt)"))
        for fn in self.r.fns.values():
            for p in fn.params:
                if (fn.name, p.name) not in self.used_locals and not p.name.startswith("_"):
                    self.report(warning("W0101", f"parameter `{p.name}` of fn `{fn.name}` is never used", p.span,
                                        "unused"))

    # -------------------------------------------------------------------------------- -D overrides
    def overrides(self, filename: str) -> None:
        params = [n for n, b in self.r.bindings.items() if b.is_param]
        for name, text in self.params.items():
            where = f"`-D {name}={text}`"
            binding = self.r.bindings.get(name)
            if binding is None and name in self.program.broken:
                continue   # its statement has a syntax error, already reported
            if binding is None:
                self.report(error("E0108", f"{where}: {filename} has no param `{name}`", None,
                                  notes=[f"its params are {', '.join(params)}" if params else "it declares no params"],
                                  hint=did_you_mean(name, params)))
            elif not binding.is_param:
                self.report(error("E0109", f"{where}: `{name}` is a binding, not a param", _span_of(binding),
                                  "not a param", hint=f"declare it `param {name} := ...;` to make it overridable"))
            else:
                expr = parse_define(text)
                if expr is None:
                    self.report(error("E0110", f"{where}: the value must be a number with an optional unit "
                                      f"(30, 2.5mm, 90deg) or a \"string\"", None))
                else:
                    self.r.overrides[name] = expr


def resolve(program: A.Program, params: dict[str, str] | None = None) -> Resolution:
    """Resolve every name of `program`; `params` are the `-D name=value` overrides as text."""
    rv = _Resolver(program, params)
    rv.declarations()
    rv.references()
    rv.order()
    rv.unused()
    filename = program.span.file if program.span else "the program"
    rv.overrides(filename)
    return rv.r
