"""The typed syntax tree of `.rgm` text, as `rgm.compiler.parser.parse` builds it.

Every node is a frozen, slotted dataclass whose last field is `span: Span | None` (where it came
from in the source), excluded from equality and hashing: two trees are equal when they say the same
thing, however they are laid out. That is what lets the property tests check `parse(format(tree)) == tree`.

Statements carry their comments so that the formatter can keep them: `leading` holds the `# ...` lines
written before the statement (and any comments found inside a multi-line statement, which the formatter
moves up front), `trailing` the comment after the statement's `;` on its last line. Both take part in
equality; `blank_before` (a blank line separated the statement from the one before) is layout only.

Expressions:
    Number(value, unit, is_int)   10mm, 2.5in, 90deg, 3        value as written, in `unit` (None: bare)
    String(value)                 "cylinder"                   the decoded text, escapes resolved
    Name(id)                      profile
    Call(func, args, kwargs)      f(a, b, name: c)             func is a Name; kwargs keep their order
    ListExpr(items)               [a, b]
    BinOp(op, left, right)        a + b, a - b, a * b, a / b
    Neg(operand)                  -a
    Member(obj, attr)             c.start
    Net(shape, width, data)       net 4 x 4 [x y z, ...]       data: float64 array, shape + (width,)
Statements:
    Units(unit), Tolerance(value), Binding(name, expr, is_param, annotations), FnDef(name, params, body,
    annotations), Export(names); Program(statements, end_comments) holds them in source order.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator, Union

from .diagnostics import Span

if TYPE_CHECKING:   # numpy is imported lazily (Net.__eq__): `rgmc fmt` without nets never loads it
    import numpy as np

LENGTH_UNITS = ("mm", "cm", "m", "in")
ANGLE_UNITS = ("deg", "rad")
UNITS = LENGTH_UNITS + ANGLE_UNITS


def _span():
    return field(default=None, compare=False, repr=False)


# ----------------------------------------------------------------------------------------- expressions

@dataclass(frozen=True, slots=True)
class Number:
    """A numeric literal. `value` is the number as written, in `unit` (one of UNITS, or None for a bare
    number); conversion to model units/radians is the evaluator's job. `is_int` is True when the literal
    was written without a decimal point or exponent (`3`, not `3.0` or `3e0`): `degree: 3` needs an int.
    """

    value: float
    unit: str | None = None
    is_int: bool = False
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class String:
    """A string literal; `value` is the decoded text (`\\"`, `\\\\`, `\\n`, `\\t` resolved)."""

    value: str
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Name:
    """A reference to a binding, parameter, fn parameter or builtin."""

    id: str
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Call:
    """`func(args..., key: value, ...)`. Positional arguments come first (the parser rejects a positional
    argument after a named one); `kwargs` is a tuple of (name, expr) pairs in source order, so a
    duplicate name is kept for the checker to report."""

    func: Name
    args: tuple["Expr", ...] = ()
    kwargs: tuple[tuple[str, "Expr"], ...] = ()
    span: Span | None = _span()

    def kwarg(self, name: str) -> "Expr | None":
        """The first named argument called `name`, or None."""
        return next((e for k, e in self.kwargs if k == name), None)


@dataclass(frozen=True, slots=True)
class ListExpr:
    """`[a, b, ...]`; may be empty."""

    items: tuple["Expr", ...] = ()
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class BinOp:
    """`left op right` with op one of `+ - * /`; `*` and `/` bind tighter, all are left-associative."""

    op: str
    left: "Expr"
    right: "Expr"
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Neg:
    """Unary minus `-operand`. A negative literal `-2` is Neg(Number(2)), never Number(-2)."""

    operand: "Expr"
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Member:
    """`obj.attr`, e.g. `c.start`, `p.x`, `s.domain`."""

    obj: "Expr"
    attr: str
    span: Span | None = _span()


@dataclass(frozen=True, eq=False, slots=True)
class Net:
    """The dense numeric form `net 40 x 40 [x y z, ...]` (or `net 12 [...]`): a grid of entries of
    `width` numbers (1 to 4: a scalar, a uv, an xyz, or xyz plus weight).

    shape: the declared grid, (nu, nv) or (n,); rows are written one after another, row i_u holding nv
           entries, matching the control-net convention ctrl[i_u, j_v].
    data:  float64 array of shape `shape + (width,)`, read-only, in the file's units (no unit suffix).
    Equality compares shape, width and every number exactly (np.array_equal).
    """

    shape: tuple[int, ...]
    width: int
    data: np.ndarray
    span: Span | None = _span()

    def __eq__(self, other):
        if not isinstance(other, Net):
            return NotImplemented
        import numpy as np   # lazily: `rgmc fmt` on a file without nets never loads numpy

        return (self.shape == other.shape and self.width == other.width
                and self.data.shape == other.data.shape and bool(np.array_equal(self.data, other.data)))

    def __hash__(self):
        return hash((self.shape, self.width, self.data.tobytes()))

    def __repr__(self):
        dims = " x ".join(map(str, self.shape))
        return f"Net({dims}, width={self.width})"


Expr = Union[Number, String, Name, Call, ListExpr, BinOp, Neg, Member, Net]


# ------------------------------------------------------------------------------------------ statements

@dataclass(frozen=True, slots=True)
class Annotation:
    """`@name(key: value, ...)` before a binding: what a fitter knows about it (`@fit`, `@classified`,
    `@source`). `args` is a tuple of (key, expr) in source order; `@name` alone has no args."""

    name: str
    args: tuple[tuple[str, Expr], ...] = ()
    span: Span | None = _span()

    def arg(self, key: str) -> Expr | None:
        return next((e for k, e in self.args if k == key), None)


@dataclass(frozen=True, slots=True)
class TypeRef:
    """A type written in a fn parameter: `num`, `point3`, `list[point3]` (name "list", args (point3,))."""

    name: str
    args: tuple["TypeRef", ...] = ()
    span: Span | None = _span()

    def __str__(self) -> str:
        return self.name + (f"[{', '.join(map(str, self.args))}]" if self.args else "")


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter of a user function: `name: type`."""

    name: str
    type: TypeRef
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Units:
    """`units mm;` (one of LENGTH_UNITS)."""

    unit: str
    leading: tuple[str, ...] = ()
    trailing: str | None = None
    blank_before: bool = field(default=False, compare=False)
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Tolerance:
    """`tolerance 0.001;` (a Number, possibly with a length unit)."""

    value: Number
    leading: tuple[str, ...] = ()
    trailing: str | None = None
    blank_before: bool = field(default=False, compare=False)
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Binding:
    """`name := expr;` or, with `is_param`, `param name := expr;` (overridable with `-D name=value`).
    `name_span` is the span of the bound name alone."""

    name: str
    expr: Expr
    is_param: bool = False
    annotations: tuple[Annotation, ...] = ()
    leading: tuple[str, ...] = ()
    trailing: str | None = None
    blank_before: bool = field(default=False, compare=False)
    span: Span | None = _span()
    name_span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class FnDef:
    """`fn name(a: num, p: point3) := body;` a small user function, expanded where it is called."""

    name: str
    params: tuple[Param, ...]
    body: Expr
    annotations: tuple[Annotation, ...] = ()
    leading: tuple[str, ...] = ()
    trailing: str | None = None
    blank_before: bool = field(default=False, compare=False)
    span: Span | None = _span()
    name_span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Export:
    """`export a, b;`: the bindings the back ends emit (Name nodes, for their spans)."""

    names: tuple[Name, ...]
    leading: tuple[str, ...] = ()
    trailing: str | None = None
    blank_before: bool = field(default=False, compare=False)
    span: Span | None = _span()


Stmt = Union[Units, Tolerance, Binding, FnDef, Export]


@dataclass(frozen=True, slots=True)
class Comment:
    """One `# ...` comment; `text` includes the `#` and has no trailing newline."""

    text: str
    span: Span | None = _span()


@dataclass(frozen=True, slots=True)
class Program:
    """A whole file. `statements` in source order; `end_comments` are the comment lines after the last
    statement. `comments` lists every comment with its span (for tools; not compared).
    When the parser reports syntax errors, `statements` holds only those that parsed, and `broken` the
    names bound by the statements that did not, so a checker can avoid "undefined name" noise."""

    statements: tuple[Stmt, ...] = ()
    end_comments: tuple[str, ...] = ()
    comments: tuple[Comment, ...] = field(default=(), compare=False)
    broken: frozenset[str] = field(default=frozenset(), compare=False)
    span: Span | None = _span()

    @property
    def bindings(self) -> list[Binding]:
        return [s for s in self.statements if isinstance(s, Binding)]


Node = Union[Expr, Stmt, Annotation, TypeRef, Param, Program]


def children(node) -> Iterator:
    """The direct sub-nodes of `node` (expressions, annotations, params, statements), in source order."""
    if isinstance(node, Call):
        yield node.func
        yield from node.args
        yield from (e for _, e in node.kwargs)
    elif isinstance(node, ListExpr):
        yield from node.items
    elif isinstance(node, BinOp):
        yield node.left
        yield node.right
    elif isinstance(node, Neg):
        yield node.operand
    elif isinstance(node, Member):
        yield node.obj
    elif isinstance(node, Annotation):
        yield from (e for _, e in node.args)
    elif isinstance(node, Binding):
        yield from node.annotations
        yield node.expr
    elif isinstance(node, FnDef):
        yield from node.annotations
        yield from node.params
        yield node.body
    elif isinstance(node, Export):
        yield from node.names
    elif isinstance(node, Tolerance):
        yield node.value
    elif isinstance(node, Program):
        yield from node.statements


def walk(node) -> Iterator:
    """`node` and all its descendants, depth first, in source order."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(reversed(list(children(n))))
