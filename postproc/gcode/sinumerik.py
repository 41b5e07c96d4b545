"""A Sinumerik 840D block read into the words the interpreter reads.

SINUMERIK 840D sl Programming Manual, Fundamentals: a block holds addresses with a
number (``X10.5``, ``G1``), addresses with ``=`` (``X=10.5``, ``CR=5``, ``T="CUTTER"``,
``X=AC(10)``, ``X=IC(5)``), keywords (``SOFT``, ``BRISK``, ``FFWON``, ``RET``) and calls
(``MSG("...")``, ``CYCLE832(...)``); ``;`` starts the comment. What is read:

- the ISO words the interpreter reads (N, G, M, X Y Z, A B C, I J K, F, S, T, D), with
  the spans of their numbers in the line, so an edited number is written in its place;
- ``CR=r`` as the arc radius R (negative: the arc of more than 180 degrees, as R);
- ``X=AC(v)`` in G90 and ``X=IC(v)`` in G91, which mean what ``Xv`` means there;
  ``I=AC(v) J=AC(w)`` (every centre word of the block absolute): the centre in work
  coordinates, as G90.1 reads it, for that block;
- ``T="name"``, ``MSG()``, ``CYCLE832()``, ``SOFT``/``BRISK``/``DRIVE``/``FFWON``/``FFWOF``,
  the compressors ``COMPON``/``COMPCURV``/``COMPCAD``/``COMPOF``, ``ADIS=``/``ADISPOS=``
  and the like: kept as they are (no geometry);
- ``RET``: the end of the program (as M17 and M30);
- ``DEF REAL|INT|BOOL NAME=value``, ``R1=...``, ``NAME=...`` and words whose value is an
  expression (``X=R1*2``): evaluated in order, a word's number being the expression's
  value, its span the expression's text (which the correction replaces with a number);
- the programmable frame (Fundamentals, "Frames"): ``TRANS``, ``ROT Z=``/``ROT RPL=``,
  ``SCALE``, ``MIRROR`` (replacing it; alone, deleting it) and ``ATRANS``, ``AROT``,
  ``ASCALE``, ``AMIRROR`` (added to it), with their axis words (and RPL=).

Everything else is refused naming the construct in Sinumerik's words (the dialect's
``refused`` list names the cycles, frames, variables and control with what to post instead).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode.lexer import Word

#: addresses read as the interpreter's words (H: an auxiliary function, L/P: subprogram calls)
WORD_LETTERS = frozenset("NGMXYZABCIJKFSTD")
#: keywords that change no geometry: kept as they are
KEPT_KEYWORDS = frozenset({
    "SOFT", "BRISK", "DRIVE", "FFWON", "FFWOF", "CFC", "CFTCP", "CFIN", "STOPRE", "TRAFOOF", "UPATH", "SPATH",
    "WAITM", "COMPOF", "COMPON", "COMPCURV", "COMPCAD", "STOPFIFO", "STARTFIFO", "FIFOCTRL",
    "FNORM", "FLIN", "FCUB",  # the feed's profile over a block (Fundamentals, "Feedrate"): no geometry
})
#: settings given as NAME=value that change no geometry (rounding distances of G641/G642; SPOS,
#: the oriented spindle stop, which a CYCLE86 written as its moves holds)
KEPT_SETTINGS = frozenset({"ADIS", "ADISPOS", "SPOS"})
#: calls that change no geometry: kept as they are
KEPT_CALLS = frozenset({"MSG", "CYCLE832", "SETMS", "WORKPIECE", "TOOLGEOMETRY"})
#: drilling cycles read (Programming Guide Cycles, "Drilling cycles"): their moves are modelled
#: (:mod:`postproc.gcode.sinumerik_cycles`; the tapping cycles CYCLE84 and CYCLE840 are
#: refused by the dialect's list, naming them)
DRILL_CYCLES = frozenset({"CYCLE81", "CYCLE82", "CYCLE83", "CYCLE85", "CYCLE86", "CYCLE87", "CYCLE88", "CYCLE89"})
END_KEYWORDS = frozenset({"RET"})
#: frame instructions read (Fundamentals, "Coordinate transformations (frames)"): TRANS,
#: ROT, SCALE, MIRROR replace the programmable frame (without values: delete it), their A
#: forms add to it in the current coordinates
FRAME_KEYWORDS = frozenset({"TRANS", "ATRANS", "ROT", "AROT", "SCALE", "ASCALE", "MIRROR", "AMIRROR"})
_NUMBER_CHARS = "0123456789.+-"


@dataclass
class SinumerikBlock:
    """What one block holds for the interpreter."""

    words: list[Word] = field(default_factory=list)
    block_delete: bool = False
    ends: bool = False  # RET
    absolute: list[tuple[str, int]] = field(default_factory=list)  # (letter, col) given as =AC()
    incremental: list[tuple[str, int]] = field(default_factory=list)  # (letter, col) given as =IC()
    tool_name: str | None = None  # T="name"
    frame: str = ""  # the frame instruction of the block (TRANS, AROT, ...)
    rpl: tuple[float, int] | None = None  # ROT/AROT RPL=angle: (degrees, column)
    mcall: bool = False  # MCALL: the call that follows is modal (a bare MCALL cancels it)
    mcall_col: int = 0  # the column of MCALL
    call: CycleCall | None = None  # a drilling cycle called in the block


@dataclass(frozen=True)
class CycleCall:
    """A drilling cycle's call, ``CYCLE81(RTP, RFP, SDIS, DP, DPR, ...)``: its name, its
    parameters' values in order (None where left empty) and the column of its name."""

    name: str
    args: tuple[float | None, ...]
    col: int


def code_end(line: str) -> int:
    """Where the block's code ends: the ';' comment (outside a string) or the line ending."""
    quoted = False
    for k, c in enumerate(line):
        if c == '"':
            quoted = not quoted
        elif c == ";" and not quoted:
            return k
        elif c in "\r\n" and not quoted:
            return k
    return len(line)


def _number(code: str, k: int) -> int:
    """The end of the number starting at ``k`` (``k`` itself when there is none)."""
    j = k
    if j < len(code) and code[j] in "+-":
        j += 1
    start = j
    while j < len(code) and (code[j].isdigit() or code[j] == "."):
        j += 1
    return j if j > start and code[start:j] != "." else k


def _skip(code: str, k: int) -> int:
    while k < len(code) and code[k] in " \t":
        k += 1
    return k


def _closing(code: str, k: int) -> int:
    """The index after the ')' that closes the '(' at ``k`` (strings skipped)."""
    depth, quoted = 0, False
    for j in range(k, len(code)):
        c = code[j]
        if c == '"':
            quoted = not quoted
        elif not quoted and c == "(":
            depth += 1
        elif not quoted and c == ")":
            depth -= 1
            if depth == 0:
                return j + 1
    return -1


#: DEF types read (their values are numbers); the others (FRAME, AXIS, STRING, CHAR) are refused
NUMBER_TYPES = frozenset({"REAL", "INT", "BOOL"})
#: functions of expressions (Job planning, "Arithmetic functions"; angles in degrees)
FUNCTIONS: dict[str, Callable[..., float]] = {
    "SIN": lambda a: math.sin(math.radians(a)), "COS": lambda a: math.cos(math.radians(a)),
    "TAN": lambda a: math.tan(math.radians(a)), "ASIN": lambda a: math.degrees(math.asin(a)),
    "ACOS": lambda a: math.degrees(math.acos(a)), "ATAN2": lambda y, x: math.degrees(math.atan2(y, x)),
    "SQRT": math.sqrt, "ABS": abs, "POT": lambda a: a * a, "TRUNC": math.trunc, "ROUND": lambda a: float(round(a)),
    "MINVAL": min, "MAXVAL": max,
}
KEYWORDS_NOT_NAMES = frozenset({"DEF", "DIV", "MOD"})


def number_text(v: float) -> str:
    """A value read from an expression, as the text of a word's number."""
    text = f"{v:.10f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


class BlockReader:
    def __init__(self, line: str, path: str | None, lineno: int, env: dict[str, float] | None = None) -> None:
        self.line = line
        self.code = line[:code_end(line)]
        self.path, self.lineno = path, lineno
        self.block = SinumerikBlock()
        self.env = {} if env is None else env  # R parameters ("R1") and DEF variables, upper case

    def refuse(self, k: int, what: str, hint: str | None = None) -> UnsupportedGcodeError:
        return UnsupportedGcodeError(f"Sinumerik {what}", path=self.path, lineno=self.lineno, col=k + 1, hint=hint)

    def read(self) -> SinumerikBlock:
        code = self.code
        k = _skip(code, 0)
        if k < len(code) and code[k] == "%":
            return self.block  # the %_N_..._MPF header: no geometry
        if k < len(code) and code[k] == "/":
            self.block.block_delete = True
            k += 1
        while True:
            k = _skip(code, k)
            if k >= len(code):
                return self.block
            if not (code[k].isalpha() or code[k] == "_"):
                raise GcodeSyntaxError(f"unexpected character {code[k]!r} in a Sinumerik block", path=self.path,
                                       lineno=self.lineno, col=k + 1)
            k = self.item(k)

    def item(self, k: int) -> int:
        """Read the address, keyword or call at ``k``; the index after it."""
        code = self.code
        j = k
        while j < len(code) and (code[j].isalpha() or code[j] == "_"):
            j += 1
        name = code[k:j].upper()
        digits = j
        while digits < len(code) and code[digits].isdigit():
            digits += 1
        ident = name + code[j:digits]
        after = _skip(code, digits)
        assigns = after < len(code) and code[after] == "=" and code[after + 1:after + 2] != "="
        if assigns and (ident in self.env or (name == "R" and digits > j)):
            return self.set_variable(ident, k, _skip(code, after + 1))  # R1=..., SIDE=...
        if name == "DEF" and digits == j:
            return self.define(k, after)
        if len(name) == 1:
            e = _number(code, _skip(code, j))
            if e > j:
                return self.word(name, _skip(code, j), e, k)
        if assigns and digits == j:
            return self.assignment(name, k, _skip(code, after + 1))
        if after < len(code) and code[after] == "(":
            return self.call(ident, k, after)
        if ident == "MCALL":
            self.block.mcall, self.block.mcall_col = True, k + 1
            return digits
        if ident in END_KEYWORDS:
            self.block.ends = True
            return digits
        if ident in KEPT_KEYWORDS:
            return digits
        if ident in FRAME_KEYWORDS:
            if self.block.frame or any(w.letter != "N" for w in self.block.words):
                raise self.refuse(k, f"{ident} not alone in its block", "write the frame in a block of its own")
            self.block.frame = ident
            return digits
        raise self.refuse(k, f"{ident} (not read by postproc)", "post the program without it")

    def call(self, ident: str, k: int, open_at: int) -> int:
        """``NAME(...)`` at ``k``: a drilling cycle read, a call kept, or refused."""
        end = _closing(self.code, open_at)
        if end < 0:
            raise GcodeSyntaxError(f"'(' of {ident} is not closed on its line", path=self.path,
                                   lineno=self.lineno, col=open_at + 1)
        if ident in DRILL_CYCLES:
            if self.block.call is not None:
                raise self.refuse(k, f"{ident} after another cycle call in its block", "call one cycle per block")
            self.block.call = CycleCall(ident, self.arguments(open_at + 1, end - 1), k + 1)
            return end
        if ident not in KEPT_CALLS:
            raise self.refuse(k, f"{ident}() call", "post the program without it (its moves written out)")
        return end

    def word(self, letter: str, start: int, end: int, letter_pos: int) -> int:
        if letter not in WORD_LETTERS and not (letter == "R" and self.code[letter_pos:letter_pos + 2].upper() == "CR"):
            raise self.refuse(letter_pos, f"address {letter} (not read by postproc)",
                              "post the program without it")
        self.block.words.append(Word(letter, self.code[start:end], start, end, letter_pos))
        return end

    def assignment(self, name: str, k: int, v: int) -> int:
        """``NAME=value``: T="name", CR=r, X=AC(v)/IC(v), X=v."""
        code = self.code
        if name == "T" and v < len(code) and code[v] == '"':
            end = code.find('"', v + 1)
            if end < 0:
                raise GcodeSyntaxError("tool name not closed with '\"'", path=self.path, lineno=self.lineno,
                                       col=v + 1)
            self.block.tool_name = code[v + 1:end]
            return end + 1
        if name == "RPL" and self.block.frame in ("ROT", "AROT"):
            value, e = self.expression(v)
            self.block.rpl = (value, k + 1)
            return e
        if name in KEPT_SETTINGS:
            e = _number(code, v)
            if e == v:
                _value, e = self.expression(v)
            return e
        letter = "R" if name == "CR" else name
        if len(letter) != 1:
            raise self.refuse(k, f"{name}= (not read by postproc)", "post the program without it")
        mode = code[v:v + 2].upper()
        if mode in ("AC", "IC") and _skip(code, v + 2) < len(code) and code[_skip(code, v + 2)] == "(":
            open_at = _skip(code, v + 2)
            s = _skip(code, open_at + 1)
            e = _number(code, s)
            close = _skip(code, e)
            if e == s or close >= len(code) or code[close] != ")":
                raise self.refuse(k, f"{name}={mode}() with an expression", "post the coordinate as a number")
            (self.block.absolute if mode == "AC" else self.block.incremental).append((letter, k + 1))
            self.word(letter, s, e, k)
            return close + 1
        e = _number(code, v)
        if e > v and (e >= len(code) or code[e] in " \t"):
            return self.word(letter, v, e, k)
        value, e = self.expression(v)  # X=R1*2, CR=RADIUS: the word's number is the expression's value
        self.word(letter, v, e, k)
        w = self.block.words[-1]
        self.block.words[-1] = Word(w.letter, number_text(value), w.start, w.end, w.letter_pos)
        return e

    # -- variables: R parameters and DEF (Job planning, "Flexible NC programming") -------------
    def define(self, k: int, v: int) -> int:
        """``DEF REAL NAME[=value][, NAME2[=value]]``: names set to their value or 0."""
        code = self.code
        j = v
        while j < len(code) and code[j].isalpha():
            j += 1
        kind = code[v:j].upper()
        if kind not in NUMBER_TYPES:
            raise self.refuse(k, f"DEF {kind or '?'} (only REAL, INT and BOOL variables are read)",
                              "post the program with numbers in place of such variables")
        j = _skip(code, j)
        while True:
            s = j
            while j < len(code) and (code[j].isalnum() or code[j] == "_"):
                j += 1
            name = code[s:j].upper()
            if not name or not (name[0].isalpha() or name[0] == "_") or name in KEYWORDS_NOT_NAMES:
                raise GcodeSyntaxError("DEF without a variable name", path=self.path, lineno=self.lineno, col=s + 1)
            j = _skip(code, j)
            if j < len(code) and code[j] == "[":
                raise self.refuse(j, "DEF of an array", "post the program with numbers in place of arrays")
            value = 0.0
            if j < len(code) and code[j] == "=":
                value, j = self.expression(_skip(code, j + 1))
                j = _skip(code, j)
            self.env[name] = value
            if j < len(code) and code[j] == ",":
                j = _skip(code, j + 1)
                continue
            if j < len(code):
                raise GcodeSyntaxError(f"unexpected {code[j]!r} in DEF", path=self.path, lineno=self.lineno,
                                       col=j + 1)
            return j

    def arguments(self, k: int, close: int) -> tuple[float | None, ...]:
        """The values of a call's parameters from ``k`` to the ')' at ``close`` (an empty
        parameter, ``CYCLE81(10,0,,-15)``, is None: the cycle's default)."""
        code = self.code
        args: list[float | None] = []
        while True:
            k = _skip(code, k)
            if k >= close or code[k] == ",":
                args.append(None)
            else:
                value, k = self.expression_at(k, True)
                args.append(value)
                k = _skip(code, k)
            if k >= close:
                return tuple(args)
            if code[k] != ",":
                raise GcodeSyntaxError(f"unexpected {code[k]!r} in the call's parameters", path=self.path,
                                       lineno=self.lineno, col=k + 1)
            k += 1

    def set_variable(self, name: str, k: int, v: int) -> int:
        value, e = self.expression(v)
        self.env[name] = value
        return e

    def expression(self, k: int) -> tuple[float, int]:
        """The value of the expression at ``k`` and the index after it (no blanks outside
        parentheses: a blank ends it, as the next word follows)."""
        value, e = self.expression_at(k, False)
        return value, e

    def expression_at(self, k: int, blanks: bool) -> tuple[float, int]:
        value, k = self._product(k, blanks)
        while True:
            j = _skip(self.code, k) if blanks else k
            if j < len(self.code) and self.code[j] in "+-":
                rhs, k = self._product(j + 1, blanks)
                value = value + rhs if self.code[j] == "+" else value - rhs
            else:
                return value, k

    def _product(self, k: int, blanks: bool) -> tuple[float, int]:
        value, k = self._factor(k, blanks)
        while True:
            # "N DIV 2", "A * 2": a blank before DIV, MOD, * or / keeps the expression going
            j = _skip(self.code, k)
            op = self.code[j:j + 1]
            word = self.code[j:j + 3].upper()
            if op in ("*", "/"):
                rhs, k = self._factor(_skip(self.code, j + 1), blanks)
            elif word in ("DIV", "MOD") and not (self.code[j + 3:j + 4].isalnum()):
                op = word
                rhs, k = self._factor(_skip(self.code, j + 3), blanks)
            else:
                return value, k
            if op != "*" and rhs == 0:
                raise GcodeSyntaxError("division by zero", path=self.path, lineno=self.lineno, col=j + 1)
            value = (value * rhs if op == "*" else value / rhs if op == "/" else
                     float(int(value) // int(rhs)) if op == "DIV" else math.fmod(value, rhs))

    def _factor(self, k: int, blanks: bool) -> tuple[float, int]:
        code = self.code
        k = _skip(code, k) if blanks else k
        c = code[k:k + 1]
        if c in ("+", "-"):
            value, e = self._factor(k + 1, blanks)
            return (-value if c == "-" else value), e
        if c == "(":
            value, e = self.expression_at(k + 1, True)
            e = _skip(code, e)
            if code[e:e + 1] != ")":
                raise GcodeSyntaxError("')' missing in the expression", path=self.path, lineno=self.lineno,
                                       col=e + 1)
            return value, e + 1
        e = _number(code, k)
        if e > k and c not in "+-":
            return float(code[k:e]), e
        j = k
        while j < len(code) and (code[j].isalnum() or code[j] == "_"):
            j += 1
        name = code[k:j].upper()
        if not name:
            raise GcodeSyntaxError("expected a number, a variable or '(' in the expression", path=self.path,
                                   lineno=self.lineno, col=k + 1)
        if name in FUNCTIONS and code[j:j + 1] == "(":
            args, e = [], j + 1
            while True:
                a, e = self.expression_at(e, True)
                args.append(a)
                e = _skip(code, e)
                if code[e:e + 1] == ",":
                    e += 1
                    continue
                if code[e:e + 1] != ")":
                    raise GcodeSyntaxError(f"')' missing after the arguments of {name}", path=self.path,
                                           lineno=self.lineno, col=e + 1)
                try:
                    return float(FUNCTIONS[name](*args)), e + 1
                except (ValueError, TypeError):
                    raise GcodeSyntaxError(f"{name} of {args} is not defined", path=self.path, lineno=self.lineno,
                                           col=k + 1) from None
        if name in self.env:
            return self.env[name], j
        if name[0] == "R" and name[1:].isdigit():
            raise self.refuse(k, f"R parameter {name} read before the program sets it (its value is kept by "
                              "the controller)", f"set {name} in the program before it is read")
        raise self.refuse(k, f"{name} in an expression (not a variable the program defines)",
                          "define it with DEF, or post the program with numbers in its place")


def code_of(line: str) -> str:
    """The block without its comment, strings blanked (what the refusals are matched on)."""
    code = line[:code_end(line)]
    out, quoted = [], False
    for c in code:
        if c == '"':
            quoted = not quoted
            out.append(c)
        else:
            out.append(" " if quoted else c)
    return "".join(out)


def read_block(line: str, path: str | None, lineno: int, env: dict[str, float] | None = None) -> SinumerikBlock:
    """The words of one Sinumerik block (``line`` with or without its ending); ``env``
    holds the R parameters and DEF variables set so far, and gets the block's settings."""
    return BlockReader(line, path, lineno, env).read()
