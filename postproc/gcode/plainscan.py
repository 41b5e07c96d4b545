"""The plain moves of a scanned chunk, cut into the pieces the bulk writer rejoins.

A plain move is a line of words (:attr:`postproc.gcode.scanner.Columns.plain`) in the
order ``[N..] [G0|G1|G2|G3] [G43 H<digits>] [X..] [Y..] [Z..] [A..] [B..] [C..] [I..]
[J..] [R..] [F..]`` (any case, G00 to G03 too; the F word also before the axis words,
in the head), or with X and Y after the last axis word
(before the rotary words) where they are not before it: a line ``correct`` added them
to (:attr:`Pieces.late`: its X and Y numbers are given, their text stays in the next
piece; the bulk writer never rejoins such a line, the general emitter writes it).
:func:`pieces` gives, per line, 14 texts that join back to the line without its
``\\n``: the head (blanks, N, G and G43 H words, an F word before the axes), the G number, for X, Y, Z, I and J the
text from the piece before up to the number and the number (the rotary words are in the
piece before I), then the rest (R and F words, trailing blanks, ``\\r``) and the F
number; and for X, Y, Z, I, J, R, A, B and C whether the line names it, its value (the
scanner's) and its digits after the point.
Every other line has 14 empty texts and names nothing. This reads the scanner's columns:
no grammar of its own.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
"""

from __future__ import annotations

from typing import Final

from postproc.gcode.scanner import Columns

GROUPS: Final = 14
_HEAD: Final = 0
_G: Final = 1
_REST: Final = 12
_F: Final = 13
_AXES: Final = "XYZIJ"
_R: Final = 5  # R's index among the named words (after X, Y, Z, I, J; its text is in the rest)
_ROTARY: Final = "ABC"  # named words 6 to 8 (their text in the piece that follows)
NAMED: Final = 9
_MOTIONS: Final = ("0", "1", "2", "3", "00", "01", "02", "03")


def _leading_blanks(text: str, i: int, n: int) -> int:
    while i < n and (text[i] == " " or text[i] == "\t"):
        i += 1
    return i


class Pieces:
    """The pieces of a chunk's lines, a list per piece or axis and an entry per line."""

    text: list[list[str]]  # the 14 pieces
    late: list[bool]  # X or Y named after Z (as correct adds them): their text is in the next piece
    has: list[list[bool]]  # X, Y, Z, I, J, R, A, B, C: named on the line
    value: list[list[float]]  # their values (0.0 where not named)
    frac: list[list[int]]  # their digits after the point (0 where not named)

    def __init__(self, n: int) -> None:
        self.text = [[""] * n for _ in range(GROUPS)]
        self.late = [False] * n
        self.has = [[False] * n for _ in range(NAMED)]
        self.value = [[0.0] * n for _ in range(NAMED)]
        self.frac = [[0] * n for _ in range(NAMED)]

    def clear(self, i: int) -> None:
        """Line ``i`` is not a plain move: every piece empty, no word named."""
        for k in range(GROUPS):
            self.text[k][i] = ""
        self.late[i] = False
        for k in range(NAMED):
            self.has[k][i] = False
            self.value[k][i] = 0.0
            self.frac[k][i] = 0


def _name(cols: Columns, res: Pieces, k: int, li: int, w: int) -> None:
    """Line ``li`` names word ``k`` of :attr:`Pieces.has`: the scanner's word ``w``."""
    res.has[k][li] = True
    res.value[k][li] = cols.value[w]
    res.frac[k][li] = cols.frac[w]


def _after_z(text: str, cols: Columns, res: Pieces, li: int, w: int, we: int) -> int:
    """The words of line ``li`` from word ``w`` (``we``: its end) that may stand after Z:
    X and Y where the line named neither before (their text left in the next piece; where
    ``correct`` adds them, before the rotary words), then the rotary words; the word after
    them."""
    letter = cols.letter
    for a in range(2):
        if w < we and letter[w] == _AXES[a] and not res.has[a][li]:
            res.text[3 + 2 * a][li] = text[cols.start[w]:cols.end[w]]  # its number (the line is never rejoined)
            _name(cols, res, a, li, w)
            res.late[li] = True
            w += 1
    for r in range(3):
        if w < we and letter[w] == _ROTARY[r]:
            _name(cols, res, 6 + r, li, w)
            w += 1
    return w


def pieces(text: str, cols: Columns) -> Pieces:
    """The pieces of the chunk ``text`` scanned into ``cols``; see the module docstring."""
    line_start, plain, first_word = cols.line_start, cols.plain, cols.first_word
    letter, start, end, val, wfrac = cols.letter, cols.start, cols.end, cols.value, cols.frac
    res = Pieces(len(plain))
    out = res.text
    has, value, frac = res.has, res.value, res.frac
    for li in range(len(plain)):
        if not plain[li]:
            continue
        s = line_start[li]
        e = line_start[li + 1]
        w = first_word[li]
        we = first_word[li + 1]
        if e > s and text[e - 1] == "\n":
            e -= 1
        head = _leading_blanks(text, s, e)
        if w < we and letter[w] == "N":
            head = end[w]
            w += 1
        if w < we and letter[w] == "G":
            g = text[start[w]:end[w]]
            if g in _MOTIONS:
                out[_G][li] = g
                head = end[w]
                w += 1
        if (w + 1 < we and letter[w] == "G" and letter[w + 1] == "H" and text[start[w]:end[w]] == "43"
                and text[start[w + 1]:end[w + 1]].isdigit()):
            head = end[w + 1]
            w += 2
        f_first = w + 1 < we and letter[w] == "F" and letter[w + 1] in "XYZ"
        if f_first:  # a feed before the axis words (G1 F300 X..): its text stays in the head
            out[_F][li] = text[start[w]:end[w]]
            head = end[w]
            w += 1
        out[_HEAD][li] = text[s:head]
        prev = head
        for k in range(5):
            if k == 3:
                w = _after_z(text, cols, res, li, w, we)
            if w < we and letter[w] == _AXES[k]:
                a = start[w]
                b = end[w]
                out[2 + 2 * k][li] = text[prev:a]
                out[3 + 2 * k][li] = text[a:b]
                has[k][li] = True
                value[k][li] = val[w]
                frac[k][li] = wfrac[w]
                prev = b
                w += 1
        if w < we and letter[w] == "R":  # its text stays in the rest
            _name(cols, res, _R, li, w)
            w += 1
        if w < we and letter[w] == "F" and not f_first:
            out[_F][li] = text[start[w]:end[w]]
            w += 1
        out[_REST][li] = text[prev:e]
        if w != we:
            res.clear(li)
    return res
