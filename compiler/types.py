"""The types of the `.rgm` language and the rules that relate them.

Types are small immutable values: primitives (`num`, `length`, `point3`, ...), `list[T]`, unions
(`curve2 | curve3`, used for what a parameter accepts) and type variables (`G`, "any geometry",
for transforms that return the type of their first argument). `ANY` is the type of an expression
that already has an error: it is accepted everywhere, so one mistake gives one diagnostic.

Rules (docs/architecture.md, "The language"):
- a plain number (`num`, `int`) is accepted where a `length` is expected (model units), an `int`
  where a `num` is; an `angle` needs `deg` or `rad`;
- `plane` is usable wherever a `surface` is;
- arithmetic: point - point = vec, point +/- vec = point, vec +/- vec, scalar * vec, vec / num,
  length * num = length, length / length = num, angle +/- angle, and transform * transform =
  transform, the composition `t2 * t1` that applies t1 first (see `binary`).
"""
from __future__ import annotations


class Type:
    """A language type. `kind` is "prim", "list" (args = (element,)), "union" (args = options) or
    "var" (name = variable, args = (bound,)).

    Types are interned: constructing the same type twice gives the same object, so equality is
    identity, which keeps the checker's many comparisons cheap on large files.
    """

    __slots__ = ("name", "kind", "args")
    _interned: dict = {}

    def __new__(cls, name: str, kind: str = "prim", args: tuple = ()):
        key = (name, kind, args)
        t = cls._interned.get(key)
        if t is None:
            t = object.__new__(cls)
            for slot, value in zip(cls.__slots__, key):
                object.__setattr__(t, slot, value)
            cls._interned[key] = t
        return t

    def __setattr__(self, key, value):
        raise AttributeError("types are immutable")

    def __reduce__(self):
        return Type, (self.name, self.kind, self.args)

    def __repr__(self) -> str:
        return f"Type({self})"

    def __str__(self) -> str:
        if self.kind == "list":
            return f"list[{self.args[0]}]"
        if self.kind == "union":
            return " | ".join(str(a) for a in self.args)
        return self.name

    @property
    def elem(self) -> "Type":
        """The element type of a list (ANY for anything else)."""
        return self.args[0] if self.kind == "list" else ANY


def _prim(name: str) -> Type:
    return Type(name)


NUM, LENGTH, ANGLE, INT, BOOL, STR = map(_prim, ("num", "length", "angle", "int", "bool", "str"))
POINT2, POINT3, VEC, HPOINT = map(_prim, ("point2", "point3", "vec", "hpoint"))
KNOTS, NET = _prim("knots"), _prim("net")
CURVE2, CURVE3, SURFACE, PLANE = map(_prim, ("curve2", "curve3", "surface", "plane"))
FACE, LOOP, SHELL, TRANSFORM = map(_prim, ("face", "loop", "shell", "transform"))
#: the type of an expression that already has a diagnostic; accepted everywhere
ANY = Type("unknown")
#: the type of the `none` default of optional parameters
NONE = Type("none")

PRIMITIVES: dict[str, Type] = {t.name: t for t in (
    NUM, LENGTH, ANGLE, INT, BOOL, STR, POINT2, POINT3, VEC, HPOINT, KNOTS, NET,
    CURVE2, CURVE3, SURFACE, PLANE, FACE, LOOP, SHELL, TRANSFORM)}
#: friendlier spellings accepted in `fn` parameter annotations
ALIASES: dict[str, Type] = {"point": POINT3, "curve": CURVE3, "number": NUM}


def list_of(elem: Type) -> Type:
    return Type("list", "list", (elem,))


def union(*options: Type) -> Type:
    """A union with nested unions flattened and duplicates removed (order kept, for messages)."""
    flat: list[Type] = []
    for opt in options:
        for o in (opt.args if opt.kind == "union" else (opt,)):
            if o not in flat:
                flat.append(o)
    return flat[0] if len(flat) == 1 else Type("union", "union", tuple(flat))


def var(name: str, bound: Type) -> Type:
    return Type(name, "var", (bound,))


#: what transforms accept and give back unchanged: any geometry placed in 3-D space
GEOMETRY = union(POINT3, VEC, HPOINT, CURVE3, SURFACE, PLANE, FACE, LOOP, SHELL)
#: what `export` may name: anything a back end can emit
EXPORTABLE = union(POINT3, HPOINT, CURVE2, CURVE3, SURFACE, PLANE, FACE, LOOP, SHELL)

_SCALAR_NUM = (INT, NUM)


def parse_type_name(text: str) -> Type | None:
    """`"length"` -> LENGTH, `"list[point3]"` -> list_of(POINT3), `"curve2 | curve3"` -> union; None if unknown."""
    text = text.strip()
    if "|" in text:
        parts = [parse_type_name(p) for p in _split_top(text, "|")]
        return None if any(p is None for p in parts) or not parts else union(*parts)
    if text.startswith("list[") and text.endswith("]"):
        inner = parse_type_name(text[5:-1])
        return None if inner is None else list_of(inner)
    return PRIMITIVES.get(text) or ALIASES.get(text)


def _split_top(text: str, sep: str) -> list[str]:
    """Split on `sep` outside brackets."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        depth += ch == "["
        depth -= ch == "]"
        if ch == sep and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return parts + [cur]


def accepts(expected: Type, actual: Type) -> bool:
    """Whether a value of type `actual` may be passed where `expected` is required."""
    if expected is actual or actual is ANY or expected is ANY:
        return True
    if actual.kind == "union":
        return all(accepts(expected, a) for a in actual.args)
    if expected.kind == "union":
        return any(accepts(e, actual) for e in expected.args)
    if expected.kind == "var":
        return accepts(expected.args[0], actual)
    if expected.kind == "list":
        return actual.kind == "list" and accepts(expected.args[0], actual.args[0])
    if expected == LENGTH:
        return actual in _SCALAR_NUM
    if expected == NUM:
        return actual == INT
    if expected == SURFACE:
        return actual == PLANE
    return False


def join(a: Type, b: Type) -> Type:
    """The type of a list holding both an `a` and a `b`: the wider of the two, else their union."""
    if accepts(a, b):
        return a
    if accepts(b, a):
        return b
    return union(a, b)


def is_numeric(t: Type) -> bool:
    """num, int, length or angle."""
    return t in (INT, NUM, LENGTH, ANGLE)


def binary(op: str, left: Type, right: Type) -> Type | None:
    """The result type of `left op right` for op in + - * /, or None when the operation is not defined."""
    if ANY in (left, right):
        return ANY
    if is_numeric(left) and is_numeric(right):
        return _scalar(op, left, right)
    scalar = (INT, NUM, LENGTH)
    if op in "+-":
        if left == POINT3 and right == POINT3 and op == "-":
            return VEC
        if left == POINT3 and right == VEC:
            return POINT3
        if left == VEC and right == POINT3 and op == "+":
            return POINT3
        if left == VEC and right == VEC:
            return VEC
        return None
    if op == "*":
        if left in scalar and right == VEC or left == VEC and right in scalar:
            return VEC
        if left == right == TRANSFORM:
            return TRANSFORM
        return None
    if op == "/" and left == VEC and right in _SCALAR_NUM:
        return VEC
    return None


def _scalar(op: str, left: Type, right: Type) -> Type | None:
    """Dimensional analysis of + - * / on num, int, length and angle."""
    def dim(t: Type) -> str:
        return "num" if t in _SCALAR_NUM else t.name

    dl, dr = dim(left), dim(right)
    if op in "+-":
        if dl == dr == "num":
            return INT if left == right == INT else NUM
        if {dl, dr} <= {"length", "num"}:
            return LENGTH      # a plain number is a length in model units
        if dl == dr == "angle":
            return ANGLE
        return None
    if op == "*":
        if dl == dr == "num":
            return INT if left == right == INT else NUM
        if "num" in (dl, dr):
            return left if dr == "num" else right
        return None
    if op == "/":
        if dr == "num":
            return NUM if dl == "num" else left
        if dl == dr:
            return NUM
        return None
    return None


def unary(op: str, operand: Type) -> Type | None:
    """The type of `-x` / `+x`: any scalar or a vec keeps its type."""
    if operand == ANY or is_numeric(operand) or operand == VEC:
        return operand
    return None


#: member access: type name -> member -> type (docs/architecture.md, "members")
MEMBERS: dict[str, dict[str, Type]] = {
    "point3": {"x": LENGTH, "y": LENGTH, "z": LENGTH},
    "point2": {"u": NUM, "v": NUM, "x": NUM, "y": NUM},
    "vec": {"x": LENGTH, "y": LENGTH, "z": LENGTH, "length": LENGTH},
    "hpoint": {"x": LENGTH, "y": LENGTH, "z": LENGTH, "w": NUM},
    "curve2": {"start": POINT2, "end": POINT2},
    "curve3": {"start": POINT3, "end": POINT3},
    "surface": {"domain": list_of(NUM)},
    "plane": {"domain": list_of(NUM), "origin": POINT3, "normal": VEC},
    "face": {"surface": SURFACE},
}


def member(t: Type, name: str) -> Type | None:
    """The type of `value.name` for a value of type `t`, or None when it has no such member."""
    if t == ANY:
        return ANY
    return MEMBERS.get(t.name, {}).get(name) if t.kind == "prim" else None


def describe(t: Type) -> str:
    """`t` with an article, for messages: "an angle", "a length", "a plain number", "a list of point3"."""
    if t == NUM:
        return "a plain number"
    if t == INT:
        return "an integer"
    if t == STR:
        return "a string"
    if t == NONE:
        return "nothing"
    if t.kind == "list":
        return "an empty list" if t.args[0] == ANY else f"a list of {t.args[0]}"
    if t.kind == "union":
        opts = [describe(o) for o in t.args]
        return ", ".join(opts[:-1]) + " or " + opts[-1]
    if t.kind == "var":
        return "any geometry" if t.args[0] == GEOMETRY else describe(t.args[0])
    text = str(t)
    return ("an " if text[0] in "aeiou" else "a ") + text
