"""The chunk scanner: the lexer's grammar over a chunk of text, into typed columns.

One pass over the text of any number of lines gives, per line, where it starts and
whether it is *plain* (words and ``[ \\t]`` blanks only, which the interpreter and the
writers read from the columns), and per word its upper-case letter, the span of its
number text in its line and the number's value (``float`` of the text: correctly rounded); the
index of the letter is read back from the span (:func:`letter_pos`). Comments, symbols
and letters without a number make a line not plain; they are skipped here and read,
where needed, by :func:`postproc.gcode.lexer.lex`, which also names the place of
anything that is not G-code.

The grammar is :mod:`postproc.gcode.lexer`'s (``_MASTER``): blanks ``[ \\t\\f\\v]``,
comments ``(...)`` (open to the end of the line) and ``;...``, a word ``letter [ \\t]*
number`` with number ``[+-]?(\\d+\\.?\\d*|\\.\\d+)``, line endings CRLF, LF or a lone CR.
Tests check the two agree token for token.

This module is the hot loop of reading, compiled at install by mypyc (``setup.py``); it
runs unchanged, only slower, where it is not. It imports nothing of the package, so that
it compiles on its own.
"""

from __future__ import annotations

from typing import Final, NamedTuple

# i64: a native 64-bit integer where mypyc compiles the module, a plain int where it does not
from mypy_extensions import i64


class Word(NamedTuple):
    """A word of a line: its upper-case letter, the number's text as written, the span
    ``start:end`` of that text in the line and the index of the letter."""

    letter: str
    number: str
    start: int
    end: int
    letter_pos: int


class Columns:
    """The columns of a scanned chunk (offsets are into the chunk's text)."""

    line_start: list[int]  # where each line starts; one more entry: the end of the text
    plain: list[bool]  # by line: words and [ \t] blanks only
    letter: list[str]  # upper case; where it stands: letter_pos(line, start)
    start: list[int]  # the span of the number text in its line (from the line's start)
    end: list[int]
    value: list[float]
    first_word: list[int]  # by line: its first word's index; one more entry: the word count
    frac: list[int]  # by word: the digits after the number's point (0: none)
    longest: int  # the most digits before the point of any word's number (leading zeros too)

    def __init__(self) -> None:
        self.frac = []
        self.longest = 0
        self.line_start = []
        self.plain = []
        self.letter = []
        self.start = []
        self.end = []
        self.value = []
        self.first_word = []

    def __len__(self) -> int:
        return len(self.plain)


# Exact powers of ten as floats (10**22 is the largest a double holds exactly).
_POW10: Final = [10.0**k for k in range(23)]


def read_number(text: bytes, i: i64, n: i64, cols: Columns | None) -> i64:
    """The end of the number ``[+-]?(\\d+\\.?\\d*|\\.\\d+)`` starting at ``i`` (-1 if
    none), read in one pass. ``cols``: the number is a word's of those columns: its value
    goes to :attr:`Columns.value`, correctly rounded (with at most 15 digits its digits
    are an exact double and so is the power of ten it is divided by, and one IEEE
    division rounds the quotient correctly; longer numbers go through ``float`` of the
    text, correctly rounded too), its digits after the point to :attr:`Columns.frac`, and
    :attr:`Columns.longest` takes its digits before the point where they are more."""
    k: i64 = i
    neg = False
    c: i64
    if k < n:
        c = text[k]
        if c == 43 or c == 45:  # + -
            neg = c == 45
            k += 1
    m: i64 = 0
    digits: i64 = 0
    frac: i64 = -1  # digits after the point; -1: no point yet
    while k < n:
        c = text[k]
        if 48 <= c <= 57:
            if digits < 16:  # (more: the value is float's of the text)
                m = m * 10 + (c - 48)
            digits += 1
            if frac >= 0:
                frac += 1
        elif c == 46 and frac < 0:  # .
            frac = 0
        else:
            break
        k += 1
    if digits == 0:
        return -1
    if cols is not None:
        if digits > 15:
            v = float(text[i:k])
        else:
            v = float(m) / _POW10[frac] if frac > 0 else float(m)
            if neg:
                v = -v
        cols.value.append(v)
        after: i64 = max(frac, 0)
        cols.frac.append(after)
        if digits - after > cols.longest:
            cols.longest = digits - after
    return k


def number_end(text: bytes, i: i64, n: i64) -> i64:
    """The end of the number starting at ``i`` (:func:`read_number`); -1 if none."""
    return read_number(text, i, n, None)


def number_value(text: bytes, i: i64, e: i64) -> float:
    """The value of the number ``text[i:e]`` as :func:`read_number` reads it."""
    cols = Columns()
    read_number(text, i, e, cols)
    return cols.value[0]


def scan_into(text: bytes, cols: Columns) -> None:
    """Scan ``text`` (whole lines; the last may lack its ending) into ``cols`` (new)."""
    n: i64 = len(text)
    i: i64 = 0
    line_start = cols.line_start
    plain_col = cols.plain
    letter_col = cols.letter
    start_col = cols.start
    end_col = cols.end
    first_word = cols.first_word
    line_start.append(0)
    first_word.append(len(letter_col))
    plain = True
    c: i64
    j: i64
    e: i64
    ls: i64 = 0  # where the line starts (a word's span is kept from there: small numbers)
    while i < n:
        c = text[i]
        if c == 32 or c == 9:  # blank
            i += 1
        elif c == 10 or c == 13:  # line ending (CRLF, LF, CR)
            i += 1
            if c == 13 and i < n and text[i] == 10:
                i += 1
            plain_col.append(plain)
            plain = True
            if i < n:
                ls = i
                line_start.append(i)
                first_word.append(len(letter_col))
        elif (65 <= c <= 90) or (97 <= c <= 122):  # a letter: a word, or a letter alone
            j = i + 1
            while j < n and (text[j] == 32 or text[j] == 9):
                j += 1
            e = read_number(text, j, n, cols)  # (its value and digits on cols)
            if e < 0:
                plain = False
                i += 1
            else:
                letter_col.append(chr(c - 32) if c >= 97 else chr(c))
                start_col.append(j - ls)
                end_col.append(e - ls)
                i = e
        elif c == 40:  # ( comment ), or open to the end of the line
            plain = False
            i += 1
            while i < n:
                c = text[i]
                if c == 41:
                    i += 1
                    break
                if c == 10 or c == 13:
                    break
                i += 1
        elif c == 59:  # ; comment to the end of the line
            plain = False
            while i < n and text[i] != 10 and text[i] != 13:
                i += 1
        else:  # a number alone, a symbol, other blanks, or not G-code (lex names it)
            plain = False
            e = number_end(text, i, n)
            i = e if e > i else i + 1
    if n == 0:  # no text, no line
        line_start.pop()
        first_word.pop()
    elif text[n - 1] != 10 and text[n - 1] != 13:
        plain_col.append(plain)  # a last line without its ending
    line_start.append(n)
    first_word.append(len(letter_col))


def chars(text: str) -> bytes:
    """``text`` one byte per character, for the scanner: characters beyond latin-1 (legal
    only inside comments, where the scanner does not look) become ``?``, so that offsets
    stay those of the text."""
    return text.encode("latin-1", "replace")


def scan(text: str) -> Columns:
    """The columns of ``text``."""
    cols = Columns()
    scan_into(chars(text), cols)
    return cols


def letter_pos(text: str, start: int) -> int:
    """The index of the letter of the word whose number starts at ``start`` in ``text``:
    the grammar's ``letter [ \\t]* number``, read back over the blanks."""
    k = start - 1
    while text[k] == " " or text[k] == "\t":
        k -= 1
    return k


def scan_line(line: str) -> list[Word] | None:
    """The words of one line, or None when it is not plain (comments, symbols, a letter
    without a number, anything else: :func:`postproc.gcode.lexer.lex` reads it)."""
    cols = Columns()
    scan_into(chars(line), cols)
    if len(cols.plain) != 1:
        return [] if not line else None
    if not cols.plain[0]:
        return None
    out: list[Word] = []
    letter, start, end = cols.letter, cols.start, cols.end
    for k in range(len(letter)):
        s = start[k]
        e = end[k]
        out.append(Word(letter[k], line[s:e], s, e, letter_pos(line, s)))
    return out
