"""The words the bulk writer adds to run lines for an axis they do not name.

A line that does not name an axis keeps the position the line before reached; where the
corrected position differs from it by half an output step or more, a word is added, and
the position is then the one that word reaches. Whether a word is added depends on the
position reached before it, so the lines are decided in order, one axis at a time
(:meth:`Unnamed.add`); the values of the words that may be added are made for the whole
block beforehand (:func:`postproc.gcode.bulk.prepare_emission`), the text of each only
where it is added.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
It imports nothing of the package but :mod:`postproc.gcode.numfmt`, compiled with it.
"""

from __future__ import annotations

import math
from bisect import bisect_left

from postproc.gcode.numfmt import fmt


class Unnamed:
    """One axis of a block (``letter``): its lines that do not name it (inert ones aside),
    each with the corrected target, the value and decimals of the word that would be
    added, and the last line at or before it that names the axis; and by line of the
    block, the number text of the axis's word as written (``nums``), whether the line
    names it (``has``) and the line itself (``lines``)."""

    letter: str
    rows: list[int]  # the lines that do not name the axis, increasing
    target: list[float]  # their corrected targets (machine mm)
    value: list[float]  # the value a word added for each would carry (program units)
    decimals: list[int]  # the decimals it would be written with
    last: list[int]  # the last line at or before each that names the axis (-1: none)
    nums: list[str]
    has: list[bool]
    lines: list[str]

    def __init__(self, letter: str, rows: list[int], target: list[float], value: list[float], decimals: list[int],
                 last: list[int], named: tuple[list[str], list[bool], list[str]]) -> None:
        self.letter, self.rows, self.target, self.value, self.decimals, self.last = (letter, rows, target, value,
                                                                                      decimals, last)
        self.nums, self.has, self.lines = named

    def add(self, span: tuple[int, int, int], scale: tuple[float, float, float], qk: float,
            add_col: list[str], want: dict[int, list[float]]) -> float:
        """Add the words of lines ``s:b`` (``span``: s, b and the axis's index k) to
        ``add_col`` (an entry per line from s), fill in ``want`` (line -> the written
        position wanted there) on axis k, and return the position on the axis after line
        ``b - 1`` (``qk``: before line s). ``scale``: the run's mm per program unit, its
        shift on the axis and half an output step."""
        s, b, k = span
        unit, sk = scale[0], scale[1]
        nums, has = self.nums, self.has
        for y, w in want.items():
            if has[y]:
                w[k] = float(nums[y]) * unit + sk
        miss = self.rows
        lo, hi = bisect_left(miss, s), bisect_left(miss, b)
        if lo < hi:
            qk = self._decide(lo, hi, s, scale, qk, add_col, want, k)
        return qk

    def _decide(self, lo: int, hi: int, s: int, scale: tuple[float, float, float], qk: float,
                add_col: list[str], want: dict[int, list[float]], k: int) -> float:
        """Rows ``lo:hi`` of :attr:`rows` in order (see :meth:`add`); the position after them."""
        unit, sk, hd = scale
        miss, ts, vs, decs, lasts, nums, lines = (self.rows, self.target, self.value, self.decimals, self.last,
                                                  self.nums, self.lines)
        letter = self.letter
        check_want = len(want) > 0
        named = -2  # the last line that names the axis, of the row before (none yet)
        for j in range(lo, hi):
            p = lasts[j]
            if p != named:
                named = p
                if p >= s:
                    # the position the line's own word reached (float(text) == the value
                    # it was written from, correctly rounded)
                    qk = float(nums[p]) * unit + sk
            if qk != qk:
                continue  # never positioned: nothing to compare with, no word
            i = miss[j]
            if abs(ts[j] - qk) / unit >= hd:
                word = letter + fmt(vs[j], decs[j])
                # the position the added word reaches: its value as written, round(v, d) (the
                # formatter's digits are round's), a zero with v's sign as round keeps it
                reached = float(word[1:])
                if reached == 0.0:
                    reached = math.copysign(0.0, vs[j])
                qk = reached * unit + sk
                line = lines[i]
                sep = " " if (" " in line or "\t" in line) else ""
                add_col[i - s] += sep + (word.lower() if line.islower() else word)
            if check_want:
                wi = want.get(i)
                if wi is not None:
                    wi[k] = qk
        return qk
