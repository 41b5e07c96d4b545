"""Parameters and expressions of LinuxCNC (rs274ngc) and Fanuc custom macro B.

A line is first *packed* the way rs274ngc reads it: comments removed, blanks removed,
letters lower-cased, while every packed character remembers its column in the source
line (for error messages and for rewriting a word's value in place). Expressions are
then parsed into small tuples and evaluated against an environment that owns the
parameters (:class:`Env`, implemented by the expander).

LinuxCNC semantics follow ``interp_read.cc`` / ``interp_execute.cc``:

- binary operators, left-associative, by precedence: ``**`` (6); ``* / MOD`` (5);
  ``+ -`` (4); ``EQ NE GT GE LT LE`` (3); ``AND OR XOR`` (2); ``EQ``/``NE`` compare
  within :data:`LINUXCNC_EQUAL_TOLERANCE`;
- ``MOD`` is ``fmod`` made non-negative, ``FIX``/``FUP`` are floor/ceiling, ``ROUND``
  rounds halves away from zero, trigonometry is in degrees, ``ATAN[y]/[x]`` is atan2;
- a value is a number, ``[expr]``, ``#n`` / ``#[expr]`` / ``#<name>``, a unary
  function, or ``+``/``-`` followed by a value.

Fanuc macro B (Fanuc/Haas manuals, "Arithmetic and logic operation"):

- precedence: functions; ``* / AND MOD``; ``+ - OR XOR``; then ``EQ NE GT GE LT LE``
  (conditions only); AND/OR/XOR work bit by bit on integers;
- ``FIX`` truncates towards zero, ``FUP`` away from zero, ``ROUND``/``ROUN`` rounds
  halves away from zero, ``ATAN`` gives 0..360 degrees, ``POW[a,b]``;
- a vacant variable (``#0``, unset locals and common variables) is :data:`NULL`:
  it counts as 0 in arithmetic, but ``EQ``/``NE`` tell it apart from 0, a plain
  ``#i = #j`` copies it, and an address given a vacant value is left out of the block.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from postproc.errors import GcodeSyntaxError, PostprocError
from postproc.gcode import numfmt

# rs274ngc TOLERANCE_EQUAL (interp_internal.hh): EQ/NE compare within this.
LINUXCNC_EQUAL_TOLERANCE = 0.0001
# rs274ngc read_integer_value: a value within this of an integer is taken as that integer.
INTEGER_TOLERANCE = 0.0001
# Brackets, functions and signs nested in one expression: parsing takes three Python frames
# a level, so this keeps a hostile line far from the interpreter's recursion limit. No
# controller reads more: Fanuc nests brackets 5 deep, LinuxCNC reads 256 characters a line.
MAX_EXPRESSION_NESTING = 64
# Height of an expression's tree (nesting plus the operators of a chain, which evaluation
# walks one frame a level): a 256-character LinuxCNC line holds at most ~128 operators.
MAX_EXPRESSION_DEPTH = 256


class _Null:
    """Fanuc's vacant value (``#0``)."""

    _inst = None

    def __new__(cls):
        if cls._inst is None:
            cls._inst = super().__new__(cls)
        return cls._inst

    def __repr__(self) -> str:
        return "NULL"


NULL = _Null()


@dataclass(slots=True)
class Packed:
    """A line as rs274ngc reads it: no blanks or comments, lower case.

    ``cols[i]`` is the 0-based index in the source line of ``text[i]``;
    ``comments`` holds ``(start, end)`` spans of the comments in the source line.
    """

    text: str
    cols: list[int]
    comments: list[tuple[int, int]]
    end: int  # index in the source line where the content ends (before the line ending)

    def col(self, i: int) -> int:
        """1-based source column of packed index ``i`` (end of line past the end)."""
        if i < len(self.cols):
            return self.cols[i] + 1
        return self.end + 1

    def span(self, i: int, j: int) -> tuple[int, int]:
        """Source span ``[a, b)`` covering packed characters ``i..j-1``."""
        return self.cols[i], self.cols[j - 1] + 1


def pack(line: str, *, path: str | None, lineno: int, nested_comments: bool = True) -> Packed:
    """Pack ``line`` (one line, with or without its ending).

    With ``nested_comments`` a ``(`` inside a comment opens a nested one that its own
    ``)`` closes (as simulators and some controls read them); without it a ``(``
    inside a comment is an error, as in LinuxCNC.
    """
    end = len(line.rstrip("\r\n"))
    text: list[str] = []
    cols: list[int] = []
    comments: list[tuple[int, int]] = []
    i = 1 if line.startswith("\ufeff") else 0  # a UTF-8 byte order mark before the first line
    while i < end:
        c = line[i]
        if c == "(":
            depth = 0
            j = i
            while j < end:
                if line[j] == "(":
                    if depth and not nested_comments:
                        raise GcodeSyntaxError(
                            "nested comment: '(' inside a comment", path=path, lineno=lineno,
                            col=j + 1, hint="LinuxCNC does not nest comments; remove the inner '('")
                    depth += 1
                elif line[j] == ")":
                    depth -= 1
                    if depth == 0:
                        break
                j += 1
            if j >= end:
                raise GcodeSyntaxError(
                    "comment opened with '(' is not closed on this line",
                    path=path, lineno=lineno, col=i + 1,
                    hint="close the comment with ')' before the end of the line",
                )
            comments.append((i, j + 1))
            i = j + 1
            continue
        if c == ";":
            comments.append((i, end))
            break
        if c in " \t":
            i += 1
            continue
        text.append(c.lower())
        cols.append(i)
        i += 1
    return Packed("".join(text), cols, comments, end)


# ---------------------------------------------------------------------------
# Expression trees (plain tuples, evaluated by :func:`evaluate`)
#   ("num", value)                     a literal
#   ("par", index_node, col)           #n, #[expr], ##n
#   ("name", name, col)                #<name>
#   ("neg", node) / ("pos", node)      unary sign
#   ("fn", name, arg, col)             unary function
#   ("atan", y, x, col)                ATAN[y]/[x] (or ATAN[y,x] in Fanuc)
#   ("pow", a, b, col)                 Fanuc POW[a,b]
#   ("exists", name, col)              LinuxCNC EXISTS[#<name>]
#   ("bin", op, left, right, col)      binary operator
# ---------------------------------------------------------------------------

_LCNC_PREC = {
    "**": 6, "*": 5, "/": 5, "mod": 5, "+": 4, "-": 4,
    "eq": 3, "ne": 3, "gt": 3, "ge": 3, "lt": 3, "le": 3,
    "and": 2, "or": 2, "xor": 2,
}
_FANUC_PREC = {
    "*": 5, "/": 5, "and": 5, "mod": 5, "+": 4, "-": 4, "or": 4, "xor": 4,
    "eq": 3, "ne": 3, "gt": 3, "ge": 3, "lt": 3, "le": 3,
}
_WORD_OPS = ("mod", "and", "xor", "eq", "ne", "gt", "ge", "lt", "le", "or")
_LCNC_FUNCS = ("abs", "acos", "asin", "atan", "cos", "exp", "fix", "fup", "round",
               "ln", "sin", "sqrt", "tan", "exists")
_FANUC_FUNCS = ("abs", "acos", "asin", "atan", "atn", "cos", "exp", "fix", "fup",
                "round", "roun", "ln", "sin", "sqrt", "sqr", "tan", "pow")


class ExprParser:
    """Recursive-descent reader over one packed line."""

    def __init__(self, packed: Packed, *, fanuc: bool, path: str | None, lineno: int):
        self.p = packed
        self.s = packed.text
        self.fanuc = fanuc
        self.path = path
        self.lineno = lineno
        self.prec = _FANUC_PREC if fanuc else _LCNC_PREC
        self.funcs = _FANUC_FUNCS if fanuc else _LCNC_FUNCS
        self.nesting = 0  # values being read, one inside the other
        self.height = 0  # height of the tree the last value() or expression() returned

    # -- errors -------------------------------------------------------------
    def error(self, i: int, message: str, hint: str | None = None) -> GcodeSyntaxError:
        return GcodeSyntaxError(message, path=self.path, lineno=self.lineno,
                                col=self.p.col(i), hint=hint)

    def peek(self, i: int) -> str:
        return self.s[i] if i < len(self.s) else ""

    def expect(self, i: int, ch: str, what: str) -> int:
        if self.peek(i) != ch:
            got = repr(self.s[i]) if i < len(self.s) else "the end of the line"
            raise self.error(i, f"expected '{ch}' {what}, found {got}")
        return i + 1

    # -- values -------------------------------------------------------------
    def number(self, i: int) -> tuple[tuple, int]:
        s = self.s
        j = i
        if self.peek(j) in "+-":
            j += 1
        k = j
        while k < len(s) and "0" <= s[k] <= "9":  # ASCII digits: str.isdigit() takes '١' too
            k += 1
        if self.peek(k) == ".":
            k += 1
            while k < len(s) and "0" <= s[k] <= "9":
                k += 1
        digits = s[j:k].replace(".", "")
        if not digits:
            got = repr(s[i]) if i < len(s) else "the end of the line"
            raise self.error(i, f"expected a number or expression, found {got}")
        return ("num", float(s[i:k])), k

    def value(self, i: int) -> tuple[tuple, int]:
        """A real value as rs274ngc ``read_real_value`` (or a Fanuc operand)."""
        if self.nesting >= MAX_EXPRESSION_NESTING:
            raise self.error(i, f"expression nested more than {MAX_EXPRESSION_NESTING} levels deep (brackets, "
                             "functions, signs and parameters inside each other)",
                             hint="no controller reads such an expression (Fanuc nests brackets 5 deep): "
                             "compute it in steps with parameters")
        self.nesting += 1
        self.height = 0
        try:
            node, j = self._value(i)
        finally:
            self.nesting -= 1
        self.height = _height(node, self.height)
        return node, j

    def _value(self, i: int) -> tuple[tuple, int]:
        c = self.peek(i)
        if c == "[":
            return self.bracket(i)
        if c == "#":
            return self.param(i)
        if c in "+-":
            c1 = self.peek(i + 1)
            if c1 and not "0" <= c1 <= "9" and c1 != ".":
                node, j = self.value(i + 1)
                return (("neg", node) if c == "-" else ("pos", node)), j
            return self.number(i)
        if c.isalpha():
            return self.function(i)
        return self.number(i)

    def bracket(self, i: int) -> tuple[tuple, int]:
        i = self.expect(i, "[", "to open an expression")
        node, i = self.expression(i, closing="]")
        return node, self.expect(i, "]", "to close the expression")

    def expression(self, i: int, closing: str) -> tuple[tuple, int]:
        """``value (op value)*`` up to ``closing`` (not consumed), by precedence."""
        values = []
        heights = []  # height of each tree in values
        ops: list[tuple[str, int]] = []
        node, i = self.value(i)
        values.append(node)
        heights.append(self.height)
        while True:
            c = self.peek(i)
            if c == "" or c in closing:
                break
            op, j = self.operator(i)
            prec = self.prec[op]
            while ops and self.prec[ops[-1][0]] >= prec:
                self._reduce(values, heights, ops, i)
            ops.append((op, self.p.col(i)))
            node, i = self.value(j)
            values.append(node)
            heights.append(self.height)
        while ops:
            self._reduce(values, heights, ops, i)
        self.height = heights[0]
        return values[0], i

    def _reduce(self, values: list, heights: list[int], ops: list, i: int) -> None:
        op, col = ops.pop()
        right = values.pop()
        left = values.pop()
        values.append(("bin", op, left, right, col))
        heights.append(max(heights.pop(), heights.pop()) + 1)
        if heights[-1] > MAX_EXPRESSION_DEPTH:
            raise self.error(i, f"expression more than {MAX_EXPRESSION_DEPTH} operations deep",
                             hint="no controller reads such an expression (LinuxCNC reads 256 characters "
                             "a line): compute it in steps with parameters")

    def operator(self, i: int) -> tuple[str, int]:
        s = self.s
        if s.startswith("**", i) and not self.fanuc:
            return "**", i + 2
        c = self.peek(i)
        if c in "*/+-":
            return c, i + 1
        for word in _WORD_OPS:
            if s.startswith(word, i) and word in self.prec:
                return word, i + len(word)
        raise self.error(i, f"expected an operator or ']', found {s[i:i + 8]!r}")

    def function(self, i: int) -> tuple[tuple, int]:
        s = self.s
        col = self.p.col(i)
        for name in sorted(self.funcs, key=len, reverse=True):
            if s.startswith(name, i) and self.peek(i + len(name)) == "[":
                break
        else:
            j = i
            while j < len(s) and s[j].isalpha():
                j += 1
            raise self.error(i, f"unknown function or stray letters {s[i:j].upper()!r} in an expression")
        i += len(name)
        if name == "exists":
            i = self.expect(i, "[", "after EXISTS")
            if not s.startswith("#<", i):
                raise self.error(i, "EXISTS takes a named parameter: EXISTS[#<name>]")
            pname, i = self.param_name(i + 2)
            return ("exists", pname, col), self.expect(i, "]", "to close EXISTS")
        if name in ("atan", "atn"):
            i = self.expect(i, "[", "after ATAN")
            y, i = self.expression(i, closing="]," if self.fanuc else "]")
            hy = self.height
            if self.fanuc and self.peek(i) == ",":
                x, i = self.expression(i + 1, closing="]")
                self.height = max(hy, self.height)
                return ("atan", y, x, col), self.expect(i, "]", "to close ATAN")
            i = self.expect(i, "]", "to close ATAN")
            if self.peek(i) != "/":
                raise self.error(i, "ATAN needs two arguments: ATAN[y]/[x]")
            x, i = self.bracket(i + 1)
            self.height = max(hy, self.height)
            return ("atan", y, x, col), i
        if name == "pow":
            i = self.expect(i, "[", "after POW")
            a, i = self.expression(i, closing=",")
            ha = self.height
            i = self.expect(i, ",", "between the arguments of POW")
            b, i = self.expression(i, closing="]")
            self.height = max(ha, self.height)
            return ("pow", a, b, col), self.expect(i, "]", "to close POW")
        arg, i = self.bracket(i)
        return ("fn", name, arg, col), i

    def param_name(self, i: int) -> tuple[str, int]:
        j = self.s.find(">", i)
        if j < 0:
            raise self.error(i, "named parameter '#<' is not closed with '>'")
        name = self.s[i:j]
        if not name:
            raise self.error(i, "empty parameter name '#<>'")
        return name, j + 1

    def param(self, i: int) -> tuple[tuple, int]:
        col = self.p.col(i)
        i = self.expect(i, "#", "")
        if self.s.startswith("<", i):
            if self.fanuc:
                raise self.error(i, "named parameters #<...> are LinuxCNC syntax, not Fanuc macro B")
            name, i = self.param_name(i + 1)
            return ("name", name, col), i
        if self.fanuc:
            if self.peek(i) in ("[", "#"):
                idx, i = self.value(i)  # #[expr] or ##n, nested through value()'s bound
            else:
                idx, i = self.number(i)
            return ("par", idx, col), i
        idx, i = self.value(i)
        return ("par", idx, col), i


def _height(node: tuple, inner: int) -> int:
    """Height of the tree ``node`` whose tallest child is ``inner`` high (a leaf: 1)."""
    return 1 if node[0] in ("num", "name", "exists") else inner + 1


# ---------------------------------------------------------------------------
# Evaluation
# ---------------------------------------------------------------------------


class Env:
    """What an expression needs from the program's state (implemented by the expander)."""

    fanuc: bool = False

    def read_numbered(self, index: int, col: int):  # pragma: no cover - interface
        raise NotImplementedError

    def read_named(self, name: str, col: int):  # pragma: no cover - interface
        raise NotImplementedError

    def exists_named(self, name: str) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def error(self, col: int, message: str, hint: str | None = None) -> PostprocError:  # pragma: no cover
        raise NotImplementedError


def to_index(env: Env, value, col: int) -> int:
    """An integer as rs274ngc ``read_integer_value`` takes it (within 1e-4)."""
    if value is NULL:
        raise env.error(col, "a vacant variable (#0) cannot be used as a variable number")
    n = math.floor(value)
    if value - n > 1 - INTEGER_TOLERANCE:
        n = math.ceil(value)
    elif value - n > INTEGER_TOLERANCE:
        raise env.error(col, f"parameter number {value!r} is not an integer")
    return int(n)


def _num(v) -> float:
    return 0.0 if v is NULL else v


def _round_half_away(v: float) -> float:
    return float(math.floor(v + 0.5)) if v >= 0 else float(math.ceil(v - 0.5))


def evaluate(node: tuple, env: Env):
    """Value of ``node`` (a float, or :data:`NULL` for a vacant Fanuc variable)."""
    kind = node[0]
    if kind == "num":
        return node[1]
    if kind == "par":
        idx = evaluate(node[1], env)
        return env.read_numbered(to_index(env, idx, node[2]), node[2])
    if kind == "name":
        return env.read_named(node[1], node[2])
    if kind == "neg":
        return -_num(evaluate(node[1], env))
    if kind == "pos":
        return _num(evaluate(node[1], env))
    if kind == "exists":
        return 1.0 if env.exists_named(node[1]) else 0.0
    if kind == "bin":
        return _binary(node[1], evaluate(node[2], env), evaluate(node[3], env), env, node[4])
    if kind == "atan":
        y = _num(evaluate(node[1], env))
        x = _num(evaluate(node[2], env))
        deg = math.degrees(math.atan2(y, x))
        if env.fanuc and deg < 0:
            deg += 360.0
        return deg
    if kind == "pow":
        return _binary("**", _num(evaluate(node[1], env)), _num(evaluate(node[2], env)), env, node[3])
    if kind == "fn":
        return _unary(node[1], _num(evaluate(node[2], env)), env, node[3])
    raise AssertionError(kind)  # pragma: no cover


def _unary(name: str, v: float, env: Env, col: int) -> float:
    fn = _UNARY.get(name)
    if fn is None:  # pragma: no cover - ATAN, EXISTS and POW are parsed as nodes of their own
        raise AssertionError(name)
    return fn(v, env, col)


def _inverse_trig(name: str, v: float, env: Env, col: int) -> float:
    if v < -1.0 or v > 1.0:
        raise env.error(col, f"argument {v!r} of {name.upper()} is outside [-1, 1]")
    return math.degrees(math.acos(v) if name == "acos" else math.asin(v))


def _exp(v: float, env: Env, col: int) -> float:
    try:
        return math.exp(v)
    except OverflowError:
        raise env.error(col, f"EXP[{v!r}] overflows") from None


def _ln(v: float, env: Env, col: int) -> float:
    if v <= 0.0:
        raise env.error(col, f"LN of a zero or negative number ({v!r})")
    return math.log(v)


def _sqrt(v: float, env: Env, col: int) -> float:
    if v < 0.0:
        raise env.error(col, f"SQRT of a negative number ({v!r})")
    return math.sqrt(v)


def _fix(v: float, env: Env, col: int) -> float:
    return float(math.trunc(v)) if env.fanuc else float(math.floor(v))


def _fup(v: float, env: Env, col: int) -> float:
    if env.fanuc:  # away from zero (Fanuc: FUP[-1.2] = -2)
        return float(math.ceil(v)) if v >= 0 else float(math.floor(v))
    return float(math.ceil(v))


# unary function name -> its value at v (trigonometry in degrees)
_UNARY: dict[str, Callable[[float, Env, int], float]] = {
    "abs": lambda v, env, col: abs(v),
    "acos": lambda v, env, col: _inverse_trig("acos", v, env, col),
    "asin": lambda v, env, col: _inverse_trig("asin", v, env, col),
    "cos": lambda v, env, col: math.cos(math.radians(v)),
    "sin": lambda v, env, col: math.sin(math.radians(v)),
    "tan": lambda v, env, col: math.tan(math.radians(v)),
    "exp": _exp,
    "ln": _ln,
    "sqrt": _sqrt,
    "sqr": _sqrt,
    "fix": _fix,
    "fup": _fup,
    "round": lambda v, env, col: _round_half_away(v),
    "roun": lambda v, env, col: _round_half_away(v),
}


def _bits(env: Env, v: float, col: int, op: str) -> int:
    if v != math.floor(v):
        raise env.error(col, f"{op.upper()} works bit by bit on integers; {v!r} is not one")
    return int(v)


def _binary(op: str, a, b, env: Env, col: int):
    if env.fanuc:
        if op == "eq" or op == "ne":
            return _fanuc_equal(op == "eq", a, b)
        return _FANUC_BINARY[op](_num(a), _num(b), env, col)
    return _LINUXCNC_BINARY[op](_num(a), _num(b), env, col)


def _fanuc_equal(eq: bool, a, b) -> float:
    """Fanuc EQ (``eq``) or NE: exact, and a vacant value equals only a vacant one."""
    if a is NULL or b is NULL:
        return 1.0 if (a is b) == eq else 0.0
    return 1.0 if (a == b) == eq else 0.0


def _divide(a: float, b: float, env: Env, col: int) -> float:
    if b == 0.0:
        raise env.error(col, "division by zero")
    return a / b


def _mod_fanuc(a: float, b: float, env: Env, col: int) -> float:
    if b == 0.0:
        raise env.error(col, "MOD by zero")
    return math.fmod(a, b)


def _mod_linuxcnc(a: float, b: float, env: Env, col: int) -> float:
    """``fmod`` made non-negative."""
    if b == 0.0:
        raise env.error(col, "MOD by zero")
    r = math.fmod(a, b)
    return r + abs(b) if r < 0.0 else r


def _power(a: float, b: float, env: Env, col: int) -> float:
    if a < 0.0 and b != math.floor(b):
        raise env.error(col, "a negative number raised to a non-integer power")
    if a == 0.0 and b < 0.0:
        raise env.error(col, "zero raised to a negative power")
    try:
        return math.pow(a, b)
    except OverflowError:
        raise env.error(col, "power overflows") from None


def _bitwise(op: str) -> Callable[[float, float, Env, int], float]:
    """Fanuc AND/OR/XOR: bit by bit on integers."""
    combine = {"and": int.__and__, "or": int.__or__, "xor": int.__xor__}[op]

    def apply(a: float, b: float, env: Env, col: int) -> float:
        x = _bits(env, a, col, op)
        y = _bits(env, b, col, op)
        return float(combine(x, y))
    return apply


_BinaryOp = Callable[[float, float, Env, int], float]

# operators that both dialects evaluate alike (on numbers, a vacant value taken as 0)
_COMMON_BINARY: dict[str, _BinaryOp] = {
    "+": lambda a, b, env, col: a + b,
    "-": lambda a, b, env, col: a - b,
    "*": lambda a, b, env, col: a * b,
    "/": _divide,
    "**": _power,
    "gt": lambda a, b, env, col: 1.0 if a > b else 0.0,
    "ge": lambda a, b, env, col: 1.0 if a >= b else 0.0,
    "lt": lambda a, b, env, col: 1.0 if a < b else 0.0,
    "le": lambda a, b, env, col: 1.0 if a <= b else 0.0,
}
_LINUXCNC_BINARY: dict[str, _BinaryOp] = {
    **_COMMON_BINARY,
    "mod": _mod_linuxcnc,
    "eq": lambda a, b, env, col: 1.0 if abs(a - b) < LINUXCNC_EQUAL_TOLERANCE else 0.0,
    "ne": lambda a, b, env, col: 1.0 if abs(a - b) >= LINUXCNC_EQUAL_TOLERANCE else 0.0,
    "and": lambda a, b, env, col: 0.0 if a == 0.0 or b == 0.0 else 1.0,
    "or": lambda a, b, env, col: 1.0 if a != 0.0 or b != 0.0 else 0.0,
    "xor": lambda a, b, env, col: 1.0 if (a == 0.0) != (b == 0.0) else 0.0,
}
# (EQ and NE are _fanuc_equal: they tell a vacant value from 0)
_FANUC_BINARY: dict[str, _BinaryOp] = {
    **_COMMON_BINARY,
    "mod": _mod_fanuc,
    "and": _bitwise("and"),
    "or": _bitwise("or"),
    "xor": _bitwise("xor"),
}


# ---------------------------------------------------------------------------
# Writing numbers back
# ---------------------------------------------------------------------------

# Significant digits kept when a computed value is written: a double holds 15-17, so
# 15 drops the noise of the last bits (0.1+0.2 -> 0.3) and still resolves 1e-9 mm on
# coordinates up to 1e6 mm.
_SIGNIFICANT = 15
# Never more decimals than this: 1e-12 in = 2.5e-11 mm, well inside 1e-9 mm.
_MAX_DECIMALS = 12
# Address letters that take integers (G/M codes, tool, offsets, line numbers, counts,
# program numbers): written without a decimal point when the value is whole, because
# Fanuc controls alarm on a decimal point in these (e.g. M98 P1000.0, G04 P500.0).
INTEGER_LETTERS = frozenset("DGHLMNOPT")


def format_number(value: float, letter: str = "") -> str:
    """Fixed point, no exponent, trailing zeros trimmed, at least one decimal digit: the
    writers' one formatter (:func:`postproc.gcode.numfmt.fmt`) at 15 significant digits.

    Whole values of :data:`INTEGER_LETTERS` are written as integers.
    """
    if not math.isfinite(value):
        raise ValueError(value)
    int_digits = len(str(int(abs(value)))) if abs(value) >= 1 else 0
    decimals = max(1, min(_MAX_DECIMALS, _SIGNIFICANT - int_digits))
    text = numfmt.fmt(value, decimals).rstrip("0")
    if text.endswith("."):
        text += "0"
    if text.lstrip("-").strip("0.") == "":
        text = "0.0"
    if letter.upper() in INTEGER_LETTERS and text.endswith(".0"):
        text = text[:-2]
    return text
