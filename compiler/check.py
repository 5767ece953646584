"""The type checker: `check(program, params) -> CheckResult`, every diagnostic in one run.

After name resolution (`rgm.compiler.resolve`) each binding, `fn` body and annotation is typed
against the builtin signature table (`rgm.compiler.builtins`). Mismatches say *why* a type was
expected, Elm-style ("the 2nd argument of `revolve` (`axis`) expects a curve3, found a surface"),
point at the offending argument and print the signature as a note. Calls that type-check then get
value checks on their constant arguments (`rgm.compiler.valuecheck`: knot vectors, nets, weights).
An expression with an error has type `unknown`, accepted everywhere, so one mistake gives one error.

For the evaluator: `CheckResult.order` lists bindings with dependencies first; a call `f(...)` is a
user fn when `f in result.fns`, else a builtin; a param's value is `result.expr_of(name)` (the `-D`
override when there is one); `result.types` maps `id(expr)` and binding names to their Type.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field

from . import ast as A
from . import gcpause
from . import types as T
from .builtins import ANNOTATIONS, FRACTIONS, FUNCTIONS, Param, Signature
from .diagnostics import Diagnostic, Span, error, sort_and_dedupe, warning
from .format import format_expr
from .resolve import Resolution, resolve
from .suggest import did_you_mean, suggest
from .units import to_model
from .valuecheck import RULES as VALUE_RULES
from .valuecheck import Arg, ValueChecker
from .values import Folder, ordinal


@dataclass
class CheckResult:
    diagnostics: list[Diagnostic]
    types: dict = field(default_factory=dict)          # id(expr) or binding name -> Type
    order: list[str] = field(default_factory=list)     # bindings, dependencies first
    fns: dict[str, A.FnDef] = field(default_factory=dict)
    bindings: dict[str, A.Binding] = field(default_factory=dict)
    overrides: dict[str, A.Expr] = field(default_factory=dict)   # -D values replacing param expressions
    exports: tuple[str, ...] = ()
    units: str = "mm"
    tolerance: float | None = None                     # model units; None when the file gives none

    @property
    def ok(self) -> bool:
        return not any(d.is_error for d in self.diagnostics)

    def expr_of(self, name: str) -> A.Expr:
        """The expression that defines binding `name`, after `-D` overrides."""
        return self.overrides.get(name, self.bindings[name].expr)


_NO_LOCALS: frozenset = frozenset()
_ANGLE_UNITS = ("deg", "rad")
_BINARY: dict = {}      # (op, left, right) -> T.binary(op, left, right)
_EXPORTABLE: dict = {}  # type -> T.accepts(T.EXPORTABLE, type)
_NEGATED: dict = {}     # type -> T.unary("-", type)
_NO_ENV: dict = {}      # the (never written) environment outside fns
#: recursion limit for a second attempt on very deep expressions (about 4 frames per level)
DEEP_LIMIT = 100_000
ARITHMETIC = ("arithmetic: point - point = vec, point ± vec = point, vec ± vec, number × vec, vec / number, "
              "length × number = length, length / length = number, angle ± angle")
COMPOSITION = "transform × transform = transform: `t2 * t1` applies t1 first"
_MAKE_TRANSFORM = "make one with `translation`, `rotation`, `scaling`, `mirroring` or `frame`"
_VERBS = {"+": "add {l} and {r}", "-": "subtract {r} from {l}", "*": "multiply {l} by {r}", "/": "divide {l} by {r}"}


def _literal(num: A.Number, unit: str) -> str:
    value = int(num.value) if num.value.is_integer() else num.value
    return f"{value}{unit}"


def _callee(fname: str, annotation: bool) -> str:
    return f"`@{fname}`" if annotation else f"`{fname}`"


def _why(fname: str, pname: str, pos: int | None, annotation: bool = False) -> str:
    callee = _callee(fname, annotation)
    if pos is not None:
        return f"the {ordinal(pos + 1)} argument of {callee} (`{pname}`)"
    return f"`{pname}` of {callee}"


def _quote(expr, limit: int = 80) -> str | None:
    """The canonical text of `expr` for a hint; None when it is too long to quote on one line."""
    text = format_expr(expr)
    return text if len(text) <= limit and "\n" not in text else None


def _hint(expected: T.Type, actual: T.Type, expr, units: str) -> str | None:
    """A concrete repair for a common mismatch, or None."""
    if isinstance(expr, A.Number):
        if expected == T.ANGLE and actual in (T.INT, T.NUM, T.LENGTH):
            return f"did you mean `{_literal(expr, 'deg')}`?"
        if expected == T.LENGTH and actual == T.ANGLE:
            return f"did you mean `{_literal(expr, units)}`?"
        if expected == T.INT and actual == T.NUM and expr.value.is_integer():
            return f"write `{int(expr.value)}`: an integer has no decimal point"
    if expected.kind == "list" and T.accepts(expected.elem, actual):
        return "wrap it in a list: `[...]`"
    if expected == T.KNOTS and actual.kind == "list":
        return "make a knot vector with `knots([...])`, `clamped(degree, [...])` or `uniform(degree, count)`"
    if expected == T.POINT3 and actual == T.POINT2:
        return "`uv(u, v)` is a point of a surface's parameter space; a 3-D point is `pt(x, y, z)`"
    if expected == T.CURVE3 and actual == T.CURVE2:
        return "this curve lies in a surface's parameter space (it is built from `uv` points)"
    if expected == T.VEC and actual == T.POINT3:
        return "a direction is `vec(x, y, z)`; the difference `b - a` of two points is a vec"
    if expected == T.TRANSFORM:
        text = _quote(expr) if actual == T.VEC else None
        return f"a vec is a displacement: did you mean `translation({text})`?" if text else _MAKE_TRANSFORM
    if actual == T.TRANSFORM:
        return "a transform is not geometry: `place(g, t)` moves the geometry g by it"
    return None


class _Checker:
    def __init__(self, program: A.Program, res: Resolution):
        self.program, self.res = program, res
        self.diags: list[Diagnostic] = []
        self.types: dict = {}
        self.busy: set[str] = set()
        self.fn_results: dict[str, T.Type] = {}
        self.fn_sigs: dict[str, Signature] = {}
        self.calls: dict[tuple, tuple[T.Type, tuple]] = {}   # see `call`
        self.fitting: set[tuple] = set()                      # see `annotations`
        self.folder = Folder(res.bindings, res.overrides, res.units, res.fns, self.types)
        self.values = ValueChecker(self.folder, self.diags.append)

    # ------------------------------------------------------------------------------------ statements
    def run(self) -> None:
        for stmt in self.program.statements:
            if isinstance(stmt, A.Binding):
                self.binding_type(stmt.name)
                self.annotations(stmt.annotations)
            elif isinstance(stmt, A.FnDef) and self.res.fns.get(stmt.name) is stmt:
                self.fn_result(stmt.name)
                self.annotations(stmt.annotations)
            elif isinstance(stmt, A.Tolerance) and stmt is self.res.tolerance:
                self.tolerance(stmt)
            elif isinstance(stmt, A.Export):
                self.export(stmt)

    def binding_type(self, name: str) -> T.Type:
        if name in self.types:
            return self.types[name]
        if name in self.busy or name in self.res.cyclic or name not in self.res.bindings:
            return T.ANY
        self.busy.add(name)
        binding = self.res.bindings[name]
        t = self.infer(binding.expr, _NO_ENV)
        override = self.res.overrides.get(name)
        if override is not None:
            given = self.infer(override, _NO_ENV)
            if not T.accepts(t, given):
                self.diags.append(error(
                    "E0116", f"`-D {name}`: param `{name}` is {T.describe(t)}, the value given is {T.describe(given)}",
                    None, notes=[f"param `{name}` is declared on line {binding.span.line}"] if binding.span else [],
                    hint=_hint(t, given, override.operand if isinstance(override, A.Neg) else override,
                               self.res.units)))
                self.types[id(override)] = T.ANY   # never folded into value checks
        self.busy.discard(name)
        self.types[name] = t
        return t

    def tolerance(self, stmt: A.Tolerance) -> None:
        num = stmt.value
        if num.unit in ("deg", "rad"):
            self.diags.append(error("E0204", "the tolerance is a length, found an angle", num.span, "an angle",
                                    hint=f"did you mean `{_literal(num, self.res.units)}`?"))
        elif num.value <= 0:
            self.diags.append(error("E0203", f"the tolerance must be positive, found {num.value:g}", num.span,
                                    "not positive", hint="a typical value is `tolerance 0.01;`"))

    def export(self, stmt: A.Export) -> None:
        for name in stmt.names:
            if name.id in self.res.bindings:
                t = self.binding_type(name.id)
                ok = _EXPORTABLE.get(t)
                if ok is None:
                    ok = _EXPORTABLE[t] = T.accepts(T.EXPORTABLE, t)
                if not ok:
                    hint = "export what it moves: `placed := place(g, t);`" if t == T.TRANSFORM else None
                    self.diags.append(error("E0310", f"cannot export `{name.id}`: it is {T.describe(t)}, not geometry",
                                            name.span, f"{T.describe(t)}", [f"exportable: {T.EXPORTABLE}"], hint))

    def annotations(self, annotations) -> None:
        for ann in annotations:
            builtin = ANNOTATIONS.get(ann.name)
            if builtin is None:
                near = suggest(ann.name, ANNOTATIONS)
                self.diags.append(warning("W0102", f"unknown annotation `@{ann.name}` (kept, not checked)", ann.span,
                                          "unknown", [f"known annotations: {', '.join('@' + a for a in ANNOTATIONS)}"],
                                          f"did you mean `@{near[0]}`?" if near else None))
                for _k, e in ann.args:
                    self.infer(e, _NO_ENV)
                continue
            sig = builtin.overloads[0]
            kwargs = [(k, e, self.infer(e, _NO_ENV)) for k, e in ann.args]
            key = (ann.name, tuple([(k, t) for k, _, t in kwargs]))
            if key in self.fitting:        # these fields with these types were found to fit (so each once)
                for field_name, e, _ in kwargs:
                    if (ann.name, field_name) in FRACTIONS:
                        self.values.fraction(ann.name, field_name, e)
                continue
            clean = len(self.diags)
            bound = self.bind(ann.name, sig, [], kwargs, ann.span, builtin.notes, annotation=True)
            for field_name, args in bound.items():
                param = sig.param(field_name)
                expected = param.type if param else sig.extra
                self.mismatch(ann.name, field_name, expected, args[0], builtin.notes, annotation=True)
            if len(self.diags) == clean:
                self.fitting.add(key)
            for field_name, args in bound.items():
                if (ann.name, field_name) in FRACTIONS:
                    self.values.fraction(ann.name, field_name, args[0].expr)

    # ------------------------------------------------------------------------------------ expressions
    def infer(self, expr, env: dict[str, T.Type]) -> T.Type:
        cls = expr.__class__
        if cls is A.Number:     # the most common nodes are typed here, as `number` and `name` do
            unit = expr.unit
            t = (T.ANGLE if unit in _ANGLE_UNITS else T.LENGTH) if unit else (T.INT if expr.is_int else T.NUM)
        elif cls is A.Name:
            name = expr.id
            if env and name in env:
                t = env[name]
            else:
                t = self.types.get(name) or self.binding_type(name)   # a binding's type is kept by its name
        else:
            rule = self._RULES.get(cls)
            t = rule(self, expr, env) if rule else T.ANY
        self.types[id(expr)] = t
        return t

    def number(self, expr: A.Number, env) -> T.Type:
        unit = expr.unit
        if unit in ("deg", "rad"):
            return T.ANGLE
        return T.LENGTH if unit else (T.INT if expr.is_int else T.NUM)

    def name(self, expr: A.Name, env) -> T.Type:
        return env[expr.id] if expr.id in env else self.binding_type(expr.id)

    def list_expr(self, expr: A.ListExpr, env) -> T.Type:
        if not expr.items:
            return T.list_of(T.ANY)
        items = [self.infer(e, env) for e in expr.items]
        elem = items[0]
        for it in items[1:]:
            if it is not elem:
                elem = T.join(elem, it)
        return T.list_of(elem)

    def neg(self, expr: A.Neg, env) -> T.Type:
        operand = self.infer(expr.operand, env)
        t = _NEGATED.get(operand, _NEGATED)
        if t is _NEGATED:        # T.unary of an interned type, worked out once per type
            t = _NEGATED[operand] = T.unary("-", operand)
        if t is None:
            self.diags.append(error("E0306", f"cannot negate {T.describe(operand)}", expr.span,
                                    f"this is {T.describe(operand)}", [ARITHMETIC]))
        return t or T.ANY

    def binop(self, expr: A.BinOp, env) -> T.Type:
        left, right = self.infer(expr.left, env), self.infer(expr.right, env)
        key = (expr.op, left, right)
        t = _BINARY.get(key, _BINARY)
        if t is _BINARY:         # T.binary of interned types, worked out once per combination
            t = _BINARY[key] = T.binary(expr.op, left, right)
        if t is None:
            hint = None
            lit = expr.right if isinstance(expr.right, A.Number) else expr.left
            if T.ANGLE in (left, right) and isinstance(lit, A.Number) and lit.unit is None:
                hint = f"an angle needs `deg` or `rad`: did you mean `{_literal(lit, 'deg')}`?"
            elif left == right == T.LENGTH and expr.op == "*":
                hint = "there is no area type; scale a length by a plain number"
            elif left == right == T.POINT3 and expr.op == "+":
                hint = "move a point by a vec: `a + (b - a) / 2` is the midpoint"
            elif T.TRANSFORM in (left, right):
                hint = "`place(g, t)` moves geometry g by a transform t; transforms compose with `*`"
            verb = _VERBS[expr.op].format(l=T.describe(left), r=T.describe(right))
            notes = [ARITHMETIC, COMPOSITION] if T.TRANSFORM in (left, right) else [ARITHMETIC]
            self.diags.append(error("E0306", f"cannot {verb}", expr.span, f"{left} {expr.op} {right}", notes, hint))
            return T.ANY
        if expr.op == "/":
            self.values.division(expr, env)
        return t

    def member(self, expr: A.Member, env) -> T.Type:
        obj = self.infer(expr.obj, env)
        t = T.member(obj, expr.attr)
        if t is None:
            members = T.MEMBERS.get(obj.name, {}) if obj.kind == "prim" else {}
            notes = [f"members of {obj}: {', '.join(members)}"] if members else [f"{T.describe(obj)} has no members"]
            self.diags.append(error("E0307", f"{T.describe(obj)} has no member `{expr.attr}`", expr.span,
                                    f"this is {T.describe(obj)}", notes, did_you_mean(expr.attr, members)))
            return T.ANY
        return t

    # ------------------------------------------------------------------------------------ calls
    def call(self, call: A.Call, env) -> T.Type:
        infer = self.infer
        arg_types = tuple([infer(e, env) for e in call.args])
        kw_types = tuple([(k, infer(e, env)) for k, e in call.kwargs]) if call.kwargs else ()
        name = call.func.id
        user = name in self.res.fns
        builtin = None if user else FUNCTIONS.get(name)
        if not user and builtin is None:
            return T.ANY   # reported by resolve
        # calls of a builtin with the same argument types bind the same way: looked up once
        key = (name, arg_types, kw_types)
        known = None if user else self.calls.get(key)
        if known is None:
            args = list(zip(call.args, arg_types))
            kwargs = [(k, e, t) for (k, e), (_, t) in zip(call.kwargs, kw_types)]
            if user:
                sig = self.fn_signature(name)
                bound = self.bind(name, sig, args, kwargs, call.span, (str(sig),))
                bad = [(p, a[0]) for p, a in ((sig.param(k), v) for k, v in bound.items())
                       if not T.accepts(p.type, a[0].type)]
                if not self.swapped(name, bad, (str(sig),), call):
                    for param, arg in bad:
                        self.mismatch(name, param.name, param.type, arg, (str(sig),))
                return self.fn_result(name)
            known = self.overload(name, builtin, args, kwargs, call)
            if known[1] is not None:
                self.calls[key] = known
        result, slots = known
        if slots is not None and name in VALUE_RULES:   # value checks only on calls whose arguments fit
            exprs = [*call.args, *[e for _, e in call.kwargs]]
            local = frozenset(env) if env else _NO_LOCALS
            result = self.values.check(name, call, {p: exprs[i] for p, i in slots}, local) or result
        return result

    def overload(self, name: str, builtin, args, kwargs, call: A.Call) -> tuple[T.Type, tuple | None]:
        """Bind a builtin call, choose its overload and report what does not fit. Returns the result
        type and, when nothing was reported, the parameters given exactly one argument as (name,
        index into the positional then named arguments) pairs; None otherwise."""
        notes = builtin.notes
        clean = len(self.diags)
        bound = self.bind(name, builtin.overloads[0], args, kwargs, call.span, notes)
        chosen, best, best_bad = None, None, None
        for sig in builtin.overloads:
            bad = [(p, a) for p in sig.params for a in bound.get(p.name, ()) if not T.accepts(p.type, a.type)]
            if not bad:
                chosen = sig
                break
            if best_bad is None or len(bad) < len(best_bad):
                best, best_bad = sig, bad
        if chosen is None:
            if self.swapped(name, best_bad, notes, call):
                return T.ANY, None
            for param, arg in best_bad:
                others = [] if param.variadic else [   # what the other overloads would take here
                    s.param(param.name).type for s in builtin.overloads
                    if all(T.accepts(p.type, a.type) for p in s.params if p.name != param.name
                           for a in bound.get(p.name, ()))]
                expected = T.union(*others) if others else param.type
                self.mismatch(name, param.name, expected, arg, notes)
            chosen = best
        result = self.result_type(chosen, bound)
        if len(self.diags) != clean:
            return result, None
        index = {id(e): i for i, e in enumerate([e for e, _ in args] + [e for _, e, _ in kwargs])}
        return result, tuple((p, index[id(v[0].expr)]) for p, v in bound.items() if len(v) == 1)

    def result_type(self, sig: Signature, bound: dict[str, list[Arg]]) -> T.Type:
        if sig.result.kind != "var":
            return sig.result
        param = next(p for p in sig.params if p.type == sig.result)
        args = bound.get(param.name)
        return args[0].type if args and T.accepts(param.type, args[0].type) else T.ANY   # no cascade

    def bind(self, fname: str, sig: Signature, args, kwargs, span, notes, annotation=False) -> dict[str, list[Arg]]:
        """Match positional and named arguments to parameters, reporting arity (E0302), unknown (E0304),
        repeated (E0305) and missing (E0303) arguments. Returns parameter name -> its argument(s)."""
        bound: dict[str, list[Arg]] = {}
        params = sig.params
        n = len(params)
        first_variadic = n - 1 if n and params[-1].variadic else n   # positions from here go to `pieces...`
        for i, (expr, t) in enumerate(args):
            if i >= first_variadic and first_variadic < n:
                bound.setdefault(params[-1].name, []).append(Arg(expr, t, i))
            elif i < n:
                bound[params[i].name] = [Arg(expr, t, i)]
            else:
                self.diags.append(error("E0302", f"{_callee(fname, annotation)} takes {n} argument{'s' * (n != 1)} "
                                        f"but {len(args)} were given", expr.span, f"unexpected {ordinal(i + 1)} argument",
                                        notes))
        by_name = sig.by_name
        for key, expr, t in kwargs:
            param = by_name.get(key)
            if key in bound:
                self.diags.append(error("E0305", f"`{key}` of {_callee(fname, annotation)} is given twice", expr.span,
                                        "given again here", notes))
            elif param is None and sig.extra is None or param is not None and param.variadic:
                names = [p.name for p in params if not p.variadic]
                self.diags.append(error("E0304", f"{_callee(fname, annotation)} has no parameter `{key}`", expr.span,
                                        f"unknown `{key}:`", notes, did_you_mean(key, names)))
            else:
                bound[key] = [Arg(expr, t, None)]
        for param in params:
            if param.name in bound:
                continue
            if param.required:
                self.diags.append(error("E0303", f"{_callee(fname, annotation)} is missing its argument "
                                        f"`{param.name}` ({param.type})", span, f"`{param.name}` missing", notes))
            elif param.variadic:
                self.diags.append(error("E0303", f"{_callee(fname, annotation)} needs at least one of "
                                        f"`{param.name}` ({param.type})", span, "nothing given", notes))
        return bound

    def swapped(self, fname: str, bad: list, notes, call: A.Call) -> bool:
        """Two positional arguments that each miss their own parameter but fit each other's
        (`place(t, ring)`): reported once as arguments in the wrong order (E0312), not as two E0301."""
        if len(bad) != 2:
            return False
        (p1, a1), (p2, a2) = sorted(bad, key=lambda b: -1 if b[1].pos is None else b[1].pos)
        if (a1.pos is None or p1 is p2 or not T.accepts(p1.type, a2.type) or not T.accepts(p2.type, a1.type)):
            return False
        s1, s2 = a1.expr.span, a2.expr.span
        span = s1 and s2 and Span(s1.file, s1.line, s1.col, s2.end_line, s2.end_col, s1.start_pos, s2.end_pos)
        args = list(call.args)
        args[a1.pos], args[a2.pos] = a2.expr, a1.expr
        fixed = _quote(A.Call(call.func, tuple(args), call.kwargs))
        fix = f"swap them: `{fixed}`" if fixed else "swap them"
        self.diags.append(error(
            "E0312", f"the {ordinal(a1.pos + 1)} and {ordinal(a2.pos + 1)} arguments of `{fname}` are in the wrong "
            f"order: `{p1.name}` expects {T.describe(p1.type)}, `{p2.name}` {T.describe(p2.type)}", span,
            f"{T.describe(a1.type)}, then {T.describe(a2.type)}", notes, fix))
        return True

    def mismatch(self, fname, pname, expected, arg: Arg, notes, annotation=False) -> None:
        if expected is None or T.accepts(expected, arg.type):
            return
        label = (f"`{arg.expr.id}` is {T.describe(arg.type)}" if isinstance(arg.expr, A.Name)
                 else f"this is {T.describe(arg.type)}")
        self.diags.append(error("E0301", f"{_why(fname, pname, arg.pos, annotation)} expects {T.describe(expected)}, "
                                f"found {T.describe(arg.type)}", arg.expr.span, label, notes,
                                _hint(expected, arg.type, arg.expr, self.res.units)))

    # ------------------------------------------------------------------------------------ user fns
    def fn_signature(self, name: str) -> Signature:
        if name not in self.fn_sigs:
            fn = self.res.fns[name]
            params = tuple(Param(p.name, self.type_ref(p.type)) for p in fn.params)
            self.fn_sigs[name] = Signature(name, params, T.ANY)
        return self.fn_sigs[name]

    def fn_result(self, name: str) -> T.Type:
        if name in self.fn_results:
            return self.fn_results[name]
        if name in self.res.cyclic or name in self.busy:
            return T.ANY
        self.busy.add(name)
        sig = self.fn_signature(name)
        t = self.infer(self.res.fns[name].body, {p.name: p.type for p in sig.params})
        self.busy.discard(name)
        self.fn_results[name] = t
        self.fn_sigs[name] = Signature(name, sig.params, t)
        return t

    def type_ref(self, ref: A.TypeRef) -> T.Type:
        if ref.name == "list" and len(ref.args) == 1:
            inner = self.type_ref(ref.args[0])
            return T.list_of(inner)
        t = None if ref.args else (T.PRIMITIVES.get(ref.name) or T.ALIASES.get(ref.name))
        if t is None:
            known = list(T.PRIMITIVES) + list(T.ALIASES) + ["list"]
            self.diags.append(error("E0117", f"unknown type `{ref}`", ref.span, "not a type",
                                    [f"types: {', '.join(T.PRIMITIVES)}, list[T]"], did_you_mean(ref.name, known)))
            return T.ANY
        return t


_Checker._RULES = {
    A.Number: _Checker.number, A.String: lambda self, e, env: T.STR, A.Net: lambda self, e, env: T.NET,
    A.Name: _Checker.name, A.ListExpr: _Checker.list_expr, A.Neg: _Checker.neg, A.BinOp: _Checker.binop,
    A.Member: _Checker.member, A.Call: _Checker.call,
}


def check(program: A.Program, params: dict[str, str] | None = None) -> CheckResult:
    """Resolve names, check types and constant values of `program`; `params` are `-D name=value` texts.

    The cyclic garbage collector is paused meanwhile (rgm.compiler.gcpause): the checker allocates many
    small objects that live as long as the AST, and on a large file collector passes over the tree
    cost more than the checking itself (measured: 2.7x on 20 000 statements)."""
    limit = sys.getrecursionlimit()
    with gcpause.paused():
        try:
            return _check(program, params)
        except RecursionError:   # a long chain such as 1 + 1 + ... + 1: Python frames are heap-allocated
            sys.setrecursionlimit(max(limit, DEEP_LIMIT))
            try:
                return _check(program, params)
            except RecursionError:
                return CheckResult([error("E0311", f"an expression is nested more than {DEEP_LIMIT // 4} levels "
                                          "deep; split it into bindings", program.span)])
        finally:
            sys.setrecursionlimit(limit)


def _check(program: A.Program, params: dict[str, str] | None) -> CheckResult:
    res = resolve(program, params)
    checker = _Checker(program, res)
    checker.run()
    tol = res.tolerance
    tolerance = None
    if tol is not None and tol.value.unit not in ("deg", "rad") and tol.value.value > 0:
        tolerance = to_model(tol.value.value, tol.value.unit, res.units)
    types = checker.types      # the checker's own table (nothing else keeps it), not a copy
    return CheckResult(sort_and_dedupe(res.diagnostics + checker.diags), types, res.order, res.fns, res.bindings, res.overrides,
                       res.exports, res.units, tolerance)
