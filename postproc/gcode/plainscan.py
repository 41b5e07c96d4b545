"""The plain moves of a scanned chunk, cut into the pieces the bulk writer rejoins.

A plain move is a line of words (:attr:`postproc.gcode.scanner.Columns.plain`) in the
order ``[N..] [G0|G1|G2|G3] [G43 H<digits>] [X..] [Y..] [Z..] [I..] [J..] [F..]`` (any
case, G00 to G03 too). :func:`pieces` gives, per line, 14 texts that join back to the
line without its ``\\n``: the head (blanks, N, G and G43 H words), the G number, for X,
Y, Z, I and J the text from the piece before up to the number and the number, then the
rest (F word, trailing blanks, ``\\r``) and the F number. Every other line has 14 empty
texts. This reads the scanner's columns: no grammar of its own.

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
_MOTIONS: Final = ("0", "1", "2", "3", "00", "01", "02", "03")


def _leading_blanks(text: str, i: int, n: int) -> int:
    while i < n and (text[i] == " " or text[i] == "\t"):
        i += 1
    return i


def pieces(text: str, cols: Columns) -> list[list[str]]:
    """The 14 columns (a list of texts per piece, a text per line) of the chunk ``text``
    scanned into ``cols``; see the module docstring."""
    out: list[list[str]] = [[] for _ in range(GROUPS)]
    line_start, plain, first_word = cols.line_start, cols.plain, cols.first_word
    letter, start, end = cols.letter, cols.start, cols.end
    empty = ["", "", "", "", "", "", "", "", "", "", "", "", "", ""]
    row = empty[:]
    for li in range(len(plain)):
        s = line_start[li]
        e = line_start[li + 1]
        w = first_word[li]
        we = first_word[li + 1]
        ok = plain[li]
        if ok:
            if e > s and text[e - 1] == "\n":
                e -= 1
            row = empty[:]
            head = _leading_blanks(text, s, e)
            if w < we and letter[w] == "N":
                head = end[w]
                w += 1
            if w < we and letter[w] == "G":
                g = text[start[w]:end[w]]
                if g in _MOTIONS:
                    row[_G] = g
                    head = end[w]
                    w += 1
            if (w + 1 < we and letter[w] == "G" and letter[w + 1] == "H" and text[start[w]:end[w]] == "43"
                    and text[start[w + 1]:end[w + 1]].isdigit()):
                head = end[w + 1]
                w += 2
            row[_HEAD] = text[s:head]
            prev = head
            for k in range(5):
                if w < we and letter[w] == _AXES[k]:
                    row[2 + 2 * k] = text[prev:start[w]]
                    row[3 + 2 * k] = text[start[w]:end[w]]
                    prev = end[w]
                    w += 1
            if w < we and letter[w] == "F":
                row[_F] = text[start[w]:end[w]]
                w += 1
            row[_REST] = text[prev:e]
            ok = w == we
        if ok:
            for k in range(GROUPS):
                out[k].append(row[k])
        else:
            for k in range(GROUPS):
                out[k].append("")
    return out
