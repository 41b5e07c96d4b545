"""The plain moves of a scanned chunk: where their words stand, and what they say.

A plain move is a line of words (:attr:`postproc.gcode.scanner.Columns.plain`) in the
order ``[N..] [G0|G1|G2|G3] [G43 H<digits>] [X..] [Y..] [Z..] [A..] [B..] [C..] [I..]
[J..] [R..] [F..]`` (any case, G00 to G03 too; the F word also before the axis words,
in the head), or with X and Y after the last axis word (before the rotary words) where
they are not before it: a line ``correct`` added them to (:attr:`Pieces.late`; the bulk
writer never rewrites such a line, the general emitter writes it).

:func:`pieces` gives, per line, no text but offsets from the line's start (small
integers, no object each): where its head ends (blanks, N, G and G43 H words, an F word
before the axes) and where the number of each of X, Y, Z, I and J starts and ends (a
word the line does not name: both at the end of what comes before its place); the G
number (-1: none) and the H number of a G43 H in the head (-1: none); and for X, Y, Z,
I, J, R, A, B, C and F whether the line names it, its value (the scanner's) and its
digits after the point. The text is cut only where a line is written
(:func:`postproc.gcode.runwords.join_rows`). Every other line names nothing. This reads
the scanner's columns: no grammar of its own. :func:`run_arcs` then finds, from those
columns, the centre of each arc a run of them takes, as a controller does.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final

from postproc.gcode.fitcore import arc_sweep, r_center
from postproc.gcode.scanner import Columns

SPANS: Final = 11  # head end, then the start and end of X, Y, Z, I and J's numbers
_AXES: Final = "XYZIJ"
_R: Final = 5  # R's index among the named words (after X, Y, Z, I, J)
_ROTARY: Final = "ABC"  # named words 6 to 8
F: Final = 9  # the F word's index among the named words
NAMED: Final = 10
_MOTIONS: Final = ("0", "1", "2", "3", "00", "01", "02", "03")


def _leading_blanks(text: str, i: int, n: int) -> int:
    while i < n and (text[i] == " " or text[i] == "\t"):
        i += 1
    return i


class Pieces:
    """Where the words of a chunk's plain moves stand and what they say: a list per
    offset or word, an entry per line."""

    at: list[list[int]]  # the SPANS offsets from each line's start (0 where not plain)
    motion: list[int]  # the G word's number, 0 to 3 (-1: none)
    tlo: list[int]  # the H number of a G43 H.. in the head (-1: none)
    late: list[bool]  # X or Y named after Z (as correct adds them)
    has: list[list[bool]]  # X, Y, Z, I, J, R, A, B, C, F: named on the line
    value: list[list[float]]  # their values (0.0 where not named)
    frac: list[list[int]]  # their digits after the point (0 where not named)

    def __init__(self, n: int) -> None:
        self.at = [[0] * n for _ in range(SPANS)]
        self.motion = [-1] * n
        self.tlo = [-1] * n
        self.late = [False] * n
        self.has = [[False] * n for _ in range(NAMED)]
        self.value = [[0.0] * n for _ in range(NAMED)]
        self.frac = [[0] * n for _ in range(NAMED)]

    def clear(self, i: int) -> None:
        """Line ``i`` is not a plain move: no offset, no word named."""
        for k in range(SPANS):
            self.at[k][i] = 0
        self.motion[i] = -1
        self.tlo[i] = -1
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


def _after_z(cols: Columns, res: Pieces, li: int, w: int, we: int) -> int:
    """The words of line ``li`` from word ``w`` (``we``: its end) that may stand after Z:
    X and Y where the line named neither before (where ``correct`` adds them, before the
    rotary words), then the rotary words; the word after them."""
    letter = cols.letter
    for a in range(2):
        if w < we and letter[w] == _AXES[a] and not res.has[a][li]:
            _name(cols, res, a, li, w)
            res.late[li] = True
            w += 1
    for r in range(3):
        if w < we and letter[w] == _ROTARY[r]:
            _name(cols, res, 6 + r, li, w)
            w += 1
    return w


def _digits(text: str, a: int, b: int) -> int:
    """The number of the digits ``text[a:b]`` (-1: not digits only)."""
    n = 0
    if a >= b:
        return -1
    for i in range(a, b):
        c = ord(text[i]) - 48
        if c < 0 or c > 9:
            return -1
        n = n * 10 + c
    return n


def pieces(text: str, cols: Columns) -> Pieces:
    """The pieces of the chunk ``text`` scanned into ``cols``; see the module docstring."""
    line_start, plain, first_word = cols.line_start, cols.plain, cols.first_word
    letter, start, end, val, wfrac = cols.letter, cols.start, cols.end, cols.value, cols.frac
    res = Pieces(len(plain))
    at = res.at
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
        head = _leading_blanks(text, s, e) - s  # (offsets from the line's start, as the spans are)
        if w < we and letter[w] == "N":
            head = end[w]
            w += 1
        if w < we and letter[w] == "G":
            g = text[s + start[w]:s + end[w]]
            if g in _MOTIONS:
                res.motion[li] = ord(g[-1]) - 48
                head = end[w]
                w += 1
        if w + 1 < we and letter[w] == "G" and letter[w + 1] == "H" and text[s + start[w]:s + end[w]] == "43":
            h = _digits(text, s + start[w + 1], s + end[w + 1])
            if h >= 0:
                res.tlo[li] = h
                head = end[w + 1]
                w += 2
        f_first = w + 1 < we and letter[w] == "F" and letter[w + 1] in "XYZ"
        if f_first:  # a feed before the axis words (G1 F300 X..): in the head
            _name(cols, res, F, li, w)
            head = end[w]
            w += 1
        prev = head
        at[0][li] = prev
        for k in range(5):
            if k == 3:
                w = _after_z(cols, res, li, w, we)
            if w < we and letter[w] == _AXES[k]:
                a = start[w]
                b = end[w]
                at[1 + 2 * k][li] = a
                at[2 + 2 * k][li] = b
                has[k][li] = True
                value[k][li] = val[w]
                frac[k][li] = wfrac[w]
                prev = b
                w += 1
            else:
                at[1 + 2 * k][li] = prev
                at[2 + 2 * k][li] = prev
        if w < we and letter[w] == "R":
            _name(cols, res, _R, li, w)
            w += 1
        if w < we and letter[w] == "F" and not f_first:
            _name(cols, res, F, li, w)
            w += 1
        if w != we:
            res.clear(li)
    return res


Point = tuple[float, float, float]
#: a run's arc: its centre (machine mm), whether clockwise, and its turn
#: (:func:`postproc.gcode.fitcore.arc_sweep`: start angle, sweep, start and end radii)
RunArc = tuple[Point, bool, tuple[float, float, float, float]]
#: per line of a block: the last line at or before it naming X, Y, Z, and their values
Axes = tuple[list[int], list[int], list[int], list[float], list[float], list[float]]
#: per line: the I and J values, whether it names I, J and R, and R's value
Centres = tuple[list[float], list[float], list[bool], list[bool], list[bool], list[float]]


def run_arcs(rows: list[int], axes: Axes, centres: Centres, motion: tuple[list[int], list[int], bool],
             frame: tuple[int, float, Point, Point, bool], limits: tuple[float, float, float, float],
             radius_ok: Callable[[float, float, float], bool]) -> tuple[int, dict[int, RunArc]]:
    """The XY arcs on the block lines ``rows`` of a run starting at block line ``a``:
    ``(the first of them the run cannot take, or -1; {line within the run: (centre,
    clockwise, turn)})`` for those before it (:data:`RunArc`). ``motion``: each line's G number, the last line
    at or before it naming one, and whether the run starts under G2; ``frame``: ``a``,
    mm per program unit, the shift of absolute words (machine mm), the position before
    the run and whether centre words are absolute (G90.1); ``limits``: the least radius,
    the end-radius difference every controller rule accepts, and the R form's tolerances
    (:func:`postproc.gcode.fitcore.r_center`); ``radius_ok(rs, re, unit)``: the
    controller rule's own answer beyond that difference. The run cannot take an arc of
    zero radius, one whose end radius the rule refuses, or an R arc whose ends coincide
    or whose radius is short of half its chord (the interpreter reports those)."""
    lx, ly, lz, vx, vy, vz = axes
    vi, vj, has_i, has_j, has_r, vr = centres
    gnum, last_g, cw0 = motion
    a, unit, shift, q0, absolute = frame
    min_radius, sure, abs_tol, rel_tol = limits
    sx, sy, sz = shift
    hyp = math.hypot
    arcs: dict[int, RunArc] = {}
    for y in rows:
        # the start: where the line before left each axis (the run's start before its first word)
        p = lx[y - 1] if y > a else -1
        x0 = vx[p] * unit + sx if p >= a else q0[0]
        p = ly[y - 1] if y > a else -1
        y0 = vy[p] * unit + sy if p >= a else q0[1]
        p = lz[y - 1] if y > a else -1
        z0 = vz[p] * unit + sz if p >= a else q0[2]
        p = lx[y]
        x1 = vx[p] * unit + sx if p >= a else q0[0]
        p = ly[y]
        y1 = vy[p] * unit + sy if p >= a else q0[1]
        g = last_g[y]  # (a line without a motion word: the modal arc's)
        clockwise = gnum[g] == 2 if g >= a else cw0
        if has_r[y]:  # the centre the controller finds for R (the interpreter's arc rule)
            c = None if hyp(x1 - x0, y1 - y0) < min_radius else r_center(x0, y0, x1, y1, vr[y] * unit, clockwise,
                                                                            abs_tol, rel_tol)
            if c is None:
                return y, arcs
            arcs[y - a] = ((c[0], c[1], z0), clockwise, arc_sweep(c, (x0, y0), (x1, y1), clockwise, 1))
            continue
        if absolute:
            c1 = vi[y] * unit + sx if has_i[y] else x0
            c2 = vj[y] * unit + sy if has_j[y] else y0
        else:
            c1, c2 = x0 + vi[y] * unit, y0 + vj[y] * unit
        turn = arc_sweep((c1, c2), (x0, y0), (x1, y1), clockwise, 1)
        rs, re = turn[2], turn[3]
        if not (rs >= min_radius and (abs(rs - re) <= sure or radius_ok(rs, re, unit))):
            return y, arcs
        arcs[y - a] = ((c1, c2, z0), clockwise, turn)
    return -1, arcs
