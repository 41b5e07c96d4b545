"""Syntax of the expansion stage: one source line as a block, files as units.

A block is what rs274ngc (or a Fanuc control) reads from one line: words whose values
may be expressions, parameter settings, an o-word statement (LinuxCNC) or a macro
statement (Fanuc ``IF``/``GOTO``/``WHILE``/``DO``/``END``). Evaluation and control
flow live in :mod:`postproc.gcode.expand`.
"""

from __future__ import annotations

import re
from bisect import bisect_right
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import accumulate

from postproc.errors import PostprocError, UnsupportedGcodeError
from postproc.gcode.expr import ExprParser, Packed, pack

# Fanuc/Haas WHILE..DO loop identifiers.
FANUC_DO_IDS = (1, 2, 3)

_O_LINE = re.compile(r"[ \t]*/?[ \t]*(?:[nN][ \t]*\d+[ \t]*)?[oO:]")
_N_LINE = re.compile(r"[ \t]*/?[ \t]*[nN][ \t]*(\d+)")
# Quick filter for needs_expansion: lines without any of these need nothing.
CANDIDATE = re.compile(r"[#\[oO]|[mM][ \t]*0*9[ \t]*[789]|[gG][ \t]*6[ \t]*[56]|[iI][fF]|[gG][oO][tT][oO]"
                        r"|[wW][hH][iI][lL][eE]|[eE][nN][dD]|[dD][oO]")
# Macro B statements, G65, and a setting with arithmetic outside brackets (#1=#2+3, which
# LinuxCNC refuses): a generic program holding one of these is read as Fanuc macro B.
_FANUC_MARK = re.compile(
    r"(?<![A-Z])(?:IF\s*\[|GOTO\s*[\d#\[]|WHILE\s*\[|DO\s*[123](?!\d)|END\s*[123](?!\d))"
    r"|G\s*65(?!\d)|#\s*\d+\s*=\s*[^\[(;\s][^\[(;]*?[-+*/]",
    re.IGNORECASE)
_LINUXCNC_MARK = re.compile(r"^\s*[oO]\s*(<|\d+\s*(sub|call|if|while|do|repeat)\b)|#\s*<", re.IGNORECASE)

_O_KEYWORDS = ("endrepeat", "endwhile", "endsub", "elseif", "endif", "else", "sub", "call",
               "do", "while", "if", "break", "continue", "return", "repeat")


@dataclass(frozen=True, slots=True)
class SourceLine:
    """One executed line of the flat program."""

    lineno: int  # 1-based line in ``path``
    path: str | None  # file the line comes from (a subroutine file for o<name> call)
    text: str  # the line as executed, with its line ending
    original: bool  # text is byte-identical to the source line


# ---------------------------------------------------------------------------
# Parsed blocks
# ---------------------------------------------------------------------------


@dataclass(slots=True)
class Word:
    letter: str  # upper case
    node: tuple | None  # expression, or None for a plain number
    raw: str  # packed number text when node is None
    span: tuple[int, int]  # source span of the value
    letter_at: int  # source index of the letter
    col: int  # 1-based column of the letter


@dataclass(slots=True)
class Assign:
    target: tuple  # ("par", node, col) or ("name", name, col)
    node: tuple
    span: tuple[int, int]  # source span of the whole setting
    col: int


@dataclass(slots=True)
class OWord:
    name: str  # "100" or "name" (lower case, no blanks)
    kw: str  # keyword, or "" for a bare O number (Fanuc-style label)
    args: list[tuple]
    col: int


@dataclass(slots=True)
class Macro:
    """A Fanuc macro statement: if_goto, if_then, goto, while, do, end."""

    kind: str
    cond: tuple | None = None
    target: tuple | None = None  # GOTO sequence number
    loop: int = 0  # DO/END identifier
    assign: Assign | None = None
    col: int = 0


@dataclass(slots=True)
class Block:
    packed: Packed
    items: list  # Word / Assign in source order
    oword: OWord | None = None
    macro: Macro | None = None
    program_number: int | None = None  # Fanuc "O1234" / ":1234" line
    slash: bool = False
    settings_only: bool = False  # parameter settings and nothing else (set by parse_block)
    plain_found: bool | None = None  # what ``plain`` says, once asked

    @property
    def words(self) -> list[Word]:
        return [it for it in self.items if isinstance(it, Word)]

    @property
    def assigns(self) -> list[Assign]:
        return [it for it in self.items if isinstance(it, Assign)]

    @property
    def plain(self) -> bool:
        """Nothing to evaluate or execute (found once: a block is not changed once parsed)."""
        if self.plain_found is None:
            self.plain_found = (self.oword is None and self.macro is None and self.program_number is None
                                and all(isinstance(it, Word) and it.node is None for it in self.items))
        return self.plain_found


def parse_block(line: str, *, fanuc: bool, path: str | None, lineno: int,
                nested_comments: bool = True) -> Block:
    """Parse one source line (with or without its ending)."""
    packed = pack(line, path=path, lineno=lineno, nested_comments=nested_comments)
    p = ExprParser(packed, fanuc=fanuc, path=path, lineno=lineno)
    s = packed.text
    n = len(s)
    block = Block(packed, [])
    i = 0
    if s.startswith("/"):
        block.slash = True
        i = 1
    if fanuc and i == 0 and (s.startswith("o") or s.startswith(":")) and s[1:].isdigit() and n > 1:
        block.program_number = int(s[1:])
        return block
    while i < n:
        c = s[i]
        if c == "#":
            block.items.append(_read_assign(p, i, fanuc))
            i = _assign_end(block.items[-1], packed)
            if fanuc:
                _expect_end(p, i, "a macro assignment must be alone in its block")
        elif c == "o" and not fanuc:
            block.oword, i = _read_oword(p, i)
        elif fanuc and c == "o" and i + 1 < n and (s[i + 1] == "<" or s[i + 1].isdigit()) and (
                _read_oword(p, i)[0].kw or s[i + 1] == "<"):
            raise p.error(i, "o-word control (o100 sub/call/if/while, o<name>) is LinuxCNC syntax",
                          hint="choose --dialect linuxcnc (or generic) for this program")
        elif fanuc and _macro_start(s, i):
            block.macro, i = _read_macro(p, i)
        elif c.isalpha():
            word, i = _read_word(p, i)
            block.items.append(word)
        elif c in "@^":
            raise _polar(packed, i, path, lineno)
        elif c in "+-*/" and block.items and isinstance(block.items[-1], Assign) and not fanuc:
            raise p.error(i, f"unexpected {c!r} after a parameter setting",
                          hint="LinuxCNC takes one value after '=': write the expression in [ ], "
                          "e.g. #1 = [2 + 3]")
        else:
            raise p.error(i, f"unexpected character {c!r}",
                          hint="a G-code line holds words (letter + value), parameter settings and comments")
    block.settings_only = (bool(block.items) and block.oword is None and block.macro is None
                           and all(isinstance(it, Assign) for it in block.items))
    return block


def _assign_end(a: Assign, packed: Packed) -> int:
    # index in packed text after the assignment
    end_src = a.span[1]
    for k, col in enumerate(packed.cols):
        if col >= end_src:
            return k
    return len(packed.text)


def _expect_end(p: ExprParser, i: int, why: str) -> None:
    if i < len(p.s):
        raise p.error(i, f"unexpected {p.s[i:i + 10]!r} after the statement ({why})")


def _read_assign(p: ExprParser, i: int, fanuc: bool) -> Assign:
    start = i
    target, i = p.param(i)
    if p.peek(i) != "=":
        raise p.error(i, "a parameter at the start of a setting must be followed by '='",
                      hint="set a parameter with #1 = value, or use it inside a word (X#1)")
    i += 1
    if fanuc:
        node, i = p.expression(i, closing="")
    else:
        node, i = p.value(i)
    a, _ = p.p.span(start, i)
    _, b = p.p.span(start, i)
    return Assign(target, node, (a, b), p.p.col(start))


def _polar(packed: Packed, i: int, path: str | None, lineno: int) -> UnsupportedGcodeError:
    return UnsupportedGcodeError(
        f"polar coordinate word '{packed.text[i]}' (LinuxCNC @ distance, ^ angle) is not supported",
        path=path, lineno=lineno, col=packed.col(i), hint="write the point in X/Y coordinates")


def _read_word(p: ExprParser, i: int) -> tuple[Word, int]:
    s = p.s
    letter = s[i].upper()
    col = p.p.col(i)
    j = i + 1
    if j >= len(s):
        raise p.error(i, f"letter {letter} has no value")
    if s[j] in "@^":
        raise _polar(p.p, j, p.path, p.lineno)
    node, k = p.value(j)
    a, b = p.p.span(j, k)
    if node[0] == "num" and s[j] != "[":  # a number in brackets ([2]) is written as its value
        return Word(letter, None, s[j:k], (a, b), p.p.cols[i], col), k
    return Word(letter, node, "", (a, b), p.p.cols[i], col), k


def _read_oword(p: ExprParser, i: int) -> tuple[OWord, int]:
    s = p.s
    col = p.p.col(i)
    j = i + 1
    if p.peek(j) == "<":
        k = s.find(">", j)
        if k < 0:
            raise p.error(j, "o-word name '<' is not closed with '>'")
        name = s[j + 1:k]
        j = k + 1
    else:
        k = j
        while k < len(s) and s[k].isdigit():
            k += 1
        if k == j:
            raise p.error(j, "an O-word needs a number or a <name>")
        name = str(int(s[j:k]))
        j = k
    for kw in _O_KEYWORDS:
        if s.startswith(kw, j):
            j += len(kw)
            break
    else:
        kw = ""
    args: list[tuple] = []
    while j < len(s):
        if s[j] != "[":
            raise p.error(j, f"unexpected {s[j:j + 10]!r} in an O-word line",
                          hint="O-word arguments and conditions are written in [ ]")
        node, j = p.bracket(j)
        args.append(node)
    if kw in ("if", "elseif", "while", "repeat") and len(args) != 1:
        raise p.error(len(s), f"'o{name} {kw}' needs one [condition]")
    return OWord(name, kw, args, col), j


def _macro_start(s: str, i: int) -> bool:
    return (s.startswith("if[", i) or s.startswith("goto", i) or s.startswith("while[", i)
            or (s.startswith("do", i) and i + 2 < len(s) and s[i + 2].isdigit())
            or (s.startswith("end", i) and i + 3 < len(s) and s[i + 3].isdigit()))


def _read_macro(p: ExprParser, i: int) -> tuple[Macro, int]:
    s = p.s
    col = p.p.col(i)
    if s.startswith("goto", i):
        target, j = p.value(i + 4)
        return Macro("goto", target=target, col=col), j
    if s.startswith("if[", i):
        cond, j = p.bracket(i + 2)
        if s.startswith("goto", j):
            target, j = p.value(j + 4)
            return Macro("if_goto", cond=cond, target=target, col=col), j
        if s.startswith("then", j):
            j += 4
            if p.peek(j) != "#":
                raise p.error(j, "IF [..] THEN must be followed by a variable setting #i = ...")
            a = _read_assign(p, j, True)
            return Macro("if_then", cond=cond, assign=a, col=col), len(s)
        raise p.error(j, "IF [condition] must be followed by GOTO n or THEN #i = ...")
    if s.startswith("while[", i):
        cond, j = p.bracket(i + 5)
        if not s.startswith("do", j):
            raise p.error(j, "WHILE [condition] must be followed by DO m")
        m, j = _loop_id(p, j + 2)
        return Macro("while", cond=cond, loop=m, col=col), j
    if s.startswith("do", i):
        m, j = _loop_id(p, i + 2)
        return Macro("do", loop=m, col=col), j
    m, j = _loop_id(p, i + 3)
    return Macro("end", loop=m, col=col), j


def _loop_id(p: ExprParser, i: int) -> tuple[int, int]:
    j = i
    while j < len(p.s) and p.s[j].isdigit():
        j += 1
    if j == i or int(p.s[i:j]) not in FANUC_DO_IDS:
        raise p.error(i, "a DO/END loop identifier must be 1, 2 or 3")
    return int(p.s[i:j]), j


# ---------------------------------------------------------------------------
# Program units (files) and the cheap scan
# ---------------------------------------------------------------------------


class Unit:
    """The lines of one file, parsed on demand."""

    def __init__(self, lines: list[str], path: str | None, fanuc: bool, nested_comments: bool = True):
        self.lines = lines
        self.path = path
        self.fanuc = fanuc
        self.nested_comments = nested_comments
        self._blocks: dict[int, Block] = {}
        # what each line is to the expander's main loop, found the first time it runs
        self.kinds: list[str | None] = [None] * len(lines)
        self._sources: dict[int, SourceLine] = {}
        self._numbers: dict[int, list[int]] | None = None
        self._programs: dict[int, int] | None = None

    def block(self, idx: int) -> Block:
        b = self._blocks.get(idx)
        if b is None:
            b = parse_block(self.lines[idx], fanuc=self.fanuc, path=self.path, lineno=idx + 1,
                            nested_comments=self.nested_comments)
            self._blocks[idx] = b
        return b

    def source_line(self, idx: int) -> SourceLine:
        """Line ``idx`` as the flat program holds it when it runs unchanged (one object for
        all the times a loop runs it)."""
        sl = self._sources.get(idx)
        if sl is None:
            sl = self._sources[idx] = SourceLine(idx + 1, self.path, self.lines[idx], True)
        return sl

    def maybe_oword(self, idx: int) -> bool:
        return _O_LINE.match(self.lines[idx]) is not None

    def sequence_numbers(self) -> dict[int, list[int]]:
        if self._numbers is None:
            self._numbers = {}
            for k, line in enumerate(self.lines):
                m = _N_LINE.match(line)
                if m:
                    self._numbers.setdefault(int(m.group(1)), []).append(k)
        return self._numbers

    def programs(self) -> dict[int, int]:
        """Program numbers (``O1000`` lines) -> line index (the first of each)."""
        if self._programs is None:
            self._programs = {}
            for k, line in enumerate(self.lines):
                if not _O_LINE.match(line):
                    continue
                b = self.block(k)
                number = b.program_number
                if number is None and b.oword is not None and b.oword.kw == "" and b.oword.name.isdigit():
                    number = int(b.oword.name)
                if number is not None:
                    self._programs.setdefault(number, k)
        return self._programs


def candidate_lines(lines: Sequence[str]) -> list[int]:
    """Indices of the lines that may hold a construct (one regex pass over the text)."""
    text = "".join(lines)
    hits = [m.start() for m in CANDIDATE.finditer(text)]
    if not hits:
        return []
    ends = list(accumulate(map(len, lines)))
    return sorted({bisect_right(ends, h) for h in hits})


def is_fanuc(lines: Sequence[str], dialect: str, candidates: list[int] | None = None) -> bool:
    """Are the program's parameters and control Fanuc macro B (else LinuxCNC o-words)?
    The dialect's ``macro_syntax`` says, or, for ``detect``, the program's own marks."""
    from postproc.gcode.dialect import get

    syntax = get(dialect).macro_syntax
    if syntax != "detect":
        return syntax == "macro-b"
    fanuc = False
    for k in candidate_lines(lines) if candidates is None else candidates:
        code = strip_comments(lines[k])
        if _LINUXCNC_MARK.search(code):
            return False
        if not fanuc and _FANUC_MARK.search(code):
            fanuc = True
    return fanuc


def strip_comments(line: str) -> str:
    out = re.sub(r"\([^)\r\n]*\)?", "", line)
    k = out.find(";")
    return out if k < 0 else out[:k]


def first_code_line(lines: Sequence[str]) -> int:
    for k, line in enumerate(lines):
        try:
            code = pack(line, path=None, lineno=k + 1).text
        except PostprocError:
            return k
        if code and not code.startswith("%"):
            return k
    return -1


def holds_no_code(lines: Iterable[str]) -> bool:
    """True when ``lines`` hold text but not one word or statement: only comments, ``%``
    lines and blanks. Read up to the first line of code (at once for any real program);
    False for no text at all (the empty program has its own refusal) and for a line that
    does not read (its reader names it)."""
    text = False
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        text = True
        try:
            code = pack(line, path=None, lineno=k + 1).text
        except PostprocError:
            return False
        if code and not code.startswith("%"):
            return False
    return text


def plain_value(w: Word) -> float | None:
    if w.node is not None:
        return None
    try:
        return float(w.raw)
    except ValueError:
        return None
