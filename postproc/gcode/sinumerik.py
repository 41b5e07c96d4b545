"""A Sinumerik 840D block read into the words the interpreter reads.

SINUMERIK 840D sl Programming Manual, Fundamentals: a block holds addresses with a
number (``X10.5``, ``G1``), addresses with ``=`` (``X=10.5``, ``CR=5``, ``T="CUTTER"``,
``X=AC(10)``, ``X=IC(5)``), keywords (``SOFT``, ``BRISK``, ``FFWON``, ``RET``) and calls
(``MSG("...")``, ``CYCLE832(...)``); ``;`` starts the comment. What is read:

- the ISO words the interpreter reads (N, G, M, X Y Z, A B C, I J K, F, S, T, D), with
  the spans of their numbers in the line, so an edited number is written in its place;
- ``CR=r`` as the arc radius R (negative: the arc of more than 180 degrees, as R);
- ``X=AC(v)`` in G90 and ``X=IC(v)`` in G91, which mean what ``Xv`` means there;
- ``T="name"``, ``MSG()``, ``CYCLE832()``, ``SOFT``/``BRISK``/``DRIVE``/``FFWON``/``FFWOF``
  and the like: kept as they are (no geometry);
- ``RET``: the end of the program (as M17 and M30);
- ``TRANS X.. Y.. Z..`` (the programmable frame's translation, replaced) and ``ATRANS``
  (added to it); ``ROT``, ``SCALE``, ``MIRROR`` without values, which delete the
  programmable frame (Fundamentals, "Frames").

Everything else is refused naming the construct in Sinumerik's words (the dialect's
``refused`` list names the cycles, frames, variables and control with what to post instead).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode.lexer import Word

#: addresses read as the interpreter's words (H: an auxiliary function, L/P: subprogram calls)
WORD_LETTERS = frozenset("NGMXYZABCIJKFSTD")
#: keywords that change no geometry: kept as they are
KEPT_KEYWORDS = frozenset({
    "SOFT", "BRISK", "DRIVE", "FFWON", "FFWOF", "CFC", "CFTCP", "CFIN", "STOPRE", "TRAFOOF", "UPATH", "SPATH",
    "ACC", "WAITM", "COMPOF", "G642", "G641", "G643", "G644", "G645",
})
#: calls that change no geometry: kept as they are
KEPT_CALLS = frozenset({"MSG", "CYCLE832", "SETMS", "WORKPIECE", "TOOLGEOMETRY"})
END_KEYWORDS = frozenset({"RET"})
#: frame instructions read: TRANS/ATRANS with X, Y, Z (a translation); ROT, SCALE, MIRROR
#: (and their A forms) only without values, which delete the programmable frame
FRAME_KEYWORDS = frozenset({"TRANS", "ATRANS"})
FRAME_RESETS = frozenset({"ROT", "SCALE", "MIRROR"})
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
    frame: str = ""  # TRANS (replaces the programmable frame), ATRANS (adds to it), RESET (ROT etc. alone)


def _code_end(line: str) -> int:
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


class _Reader:
    def __init__(self, line: str, path: str | None, lineno: int) -> None:
        self.line = line
        self.code = line[:_code_end(line)]
        self.path, self.lineno = path, lineno
        self.block = SinumerikBlock()

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
        if len(name) == 1:
            e = _number(code, _skip(code, j))
            if e > j:
                return self.word(name, _skip(code, j), e, k)
        digits = j
        while digits < len(code) and code[digits].isdigit():
            digits += 1
        ident = name + code[j:digits]
        after = _skip(code, digits)
        if after < len(code) and code[after] == "=" and digits == j:
            return self.assignment(name, k, _skip(code, after + 1))
        if after < len(code) and code[after] == "(":
            end = _closing(code, after)
            if end < 0:
                raise GcodeSyntaxError(f"'(' of {ident} is not closed on its line", path=self.path,
                                       lineno=self.lineno, col=after + 1)
            if ident not in KEPT_CALLS:
                raise self.refuse(k, f"{ident}() call", "post the program without it (its moves written out)")
            return end
        if ident in END_KEYWORDS:
            self.block.ends = True
            return digits
        if ident in KEPT_KEYWORDS:
            return digits
        if ident in FRAME_KEYWORDS or ident in FRAME_RESETS:
            if self.block.frame or any(w.letter != "N" for w in self.block.words):
                raise self.refuse(k, f"{ident} not alone in its block", "write the frame in a block of its own")
            self.block.frame = ident if ident in FRAME_KEYWORDS else "RESET"
            return digits
        raise self.refuse(k, f"{ident} (not read by postproc)", "post the program without it")

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
        if e == v or (_skip(code, e) < len(code) and code[_skip(code, e)] not in " \t" and
                      not code[_skip(code, e)].isalpha()):
            raise self.refuse(k, f"{name}= with an expression (variables or arithmetic)",
                              "post the program with numbers in place of variables")
        return self.word(letter, v, e, k)


def code_of(line: str) -> str:
    """The block without its comment, strings blanked (what the refusals are matched on)."""
    code = line[:_code_end(line)]
    out, quoted = [], False
    for c in code:
        if c == '"':
            quoted = not quoted
            out.append(c)
        else:
            out.append(" " if quoted else c)
    return "".join(out)


def read_block(line: str, path: str | None, lineno: int) -> SinumerikBlock:
    """The words of one Sinumerik block (``line`` with or without its ending)."""
    return _Reader(line, path, lineno).read()
