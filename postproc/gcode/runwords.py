"""The run writer's loops: the words it adds to run lines for an axis they do not name,
and the lines rewritten.

A line that does not name an axis keeps the position the line before reached; where the
corrected position differs from it by half an output step or more, a word is added, and
the position is then the one that word reaches. Whether a word is added depends on the
position reached before it, so the lines are decided in order, one axis at a time
(:meth:`Unnamed.add`); the values of the words that may be added are made for the whole
block beforehand (:func:`postproc.gcode.bulk.prepare_emission`), the text of each only
where it is added. :func:`join_rows` then writes the lines: each line's own text with
the numbers that change and the words added put in at their offsets
(:mod:`postproc.gcode.plainscan`), every other byte as it was; every other line is
written by :func:`edit_line` in the same way, from the edits the general writer makes.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
It imports nothing of the package but :mod:`postproc.gcode.numfmt`, compiled with it.
"""

from __future__ import annotations

from bisect import bisect_left

from postproc.gcode.numfmt import added_text, reached


class Unnamed:
    """One axis of a block (``letter``): its lines that do not name it (inert ones aside),
    each with the corrected target, the value and decimals of the word that would be
    added, and the last line at or before it that names the axis; and by line of the
    block, the number text of the axis's word where it is written anew (``nums``; ""
    where the line keeps its own), the value of the line's own word (``own``), whether
    the line names it (``has``) and the line itself (``lines``)."""

    letter: str
    rows: list[int]  # the lines that do not name the axis, increasing
    target: list[float]  # their corrected targets (machine mm)
    value: list[float]  # the value a word added for each would carry (program units)
    decimals: list[int]  # the decimals it would be written with
    last: list[int]  # the last line at or before each that names the axis (-1: none)
    nums: list[str]
    own: list[float]
    has: list[bool]
    lines: list[str]

    def __init__(self, letter: str, rows: list[int], target: list[float], value: list[float], decimals: list[int],
                 last: list[int], named: tuple[list[str], list[float], list[bool], list[str]]) -> None:
        self.letter, self.rows, self.target, self.value, self.decimals, self.last = (letter, rows, target, value,
                                                                                      decimals, last)
        self.nums, self.own, self.has, self.lines = named

    def written(self, y: int) -> float:
        """The value of line ``y``'s word on the axis as written (program units):
        ``float`` of its new text, or its own value (the scanner's, ``float`` of its
        text: either is the value the controller reads, correctly rounded)."""
        t = self.nums[y]
        return float(t) if t else self.own[y]

    def add(self, span: tuple[int, int, int], scale: tuple[float, float], qk: float,
            add_col: list[str], want: dict[int, list[float]]) -> float:
        """Add the words of lines ``s:b`` (``span``: s, b and the axis's index k) to
        ``add_col`` (an entry per line from s), fill in ``want`` (line -> the written
        position wanted there) on axis k, and return the position on the axis after line
        ``b - 1`` (``qk``: before line s). ``scale``: the run's mm per program unit and its
        shift on the axis."""
        s, b, k = span
        unit, sk = scale[0], scale[1]
        has = self.has
        for y, w in want.items():
            if has[y]:
                w[k] = self.written(y) * unit + sk
        miss = self.rows
        lo, hi = bisect_left(miss, s), bisect_left(miss, b)
        if lo < hi:
            qk = self._decide(lo, hi, s, scale, qk, add_col, want, k)
        return qk

    def _decide(self, lo: int, hi: int, s: int, scale: tuple[float, float], qk: float,
                add_col: list[str], want: dict[int, list[float]], k: int) -> float:
        """Rows ``lo:hi`` of :attr:`rows` in order (see :meth:`add`); the position after them."""
        unit, sk = scale
        miss, ts, vs, decs, lasts, lines = (self.rows, self.target, self.value, self.decimals, self.last,
                                            self.lines)
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
                    qk = self.written(p) * unit + sk
            i = miss[j]
            text = added_text(ts[j], qk, unit, vs[j], decs[j])  # "": none (qk NaN: never positioned)
            if text:
                word = letter + text
                qk = reached(text, vs[j]) * unit + sk  # the position the added word reaches
                line = lines[i]
                sep = " " if (" " in line or "\t" in line) else ""
                add_col[i - s] += sep + (word.lower() if line.islower() else word)
            if check_want:
                wi = want.get(i)
                if wi is not None:
                    wi[k] = qk
        return qk


def added_counts(add_col: list[str], c: int, named: list[int], s: int) -> tuple[int, int]:
    """Of the first ``c`` lines of ``add_col`` (words added per line, from block line
    ``s``): how many have words added, and how many of those change no word they name
    (``named``: by block line, the named words that change)."""
    rows = newly = 0
    for k in range(c):
        if add_col[k]:
            rows += 1
            if named[s + k] == 0:
                newly += 1
    return rows, newly


def join_rows(lines: list[str], span: tuple[int, int], at: list[list[int]], nums: list[list[str]],
              added: list[str], centres: tuple[list[str], list[str]]) -> str:
    """Lines ``s:stop`` (``span``) of ``lines`` as written: each line's own text, line
    ending included, with the number of X, Y and Z replaced where ``nums[k][y]`` is a
    text ("": the line's own stays), the words ``added[y - s]`` put in after Z's place,
    and the number of I and J replaced where ``centres[0 or 1][y - s]`` is a text;
    ``at``: the offsets of :class:`postproc.gcode.plainscan.Pieces`."""
    s, stop = span
    out: list[str] = []
    nx, ny, nz = nums[0], nums[1], nums[2]
    ci, cj = centres
    xs, xe, ys, ye, zs, ze = at[1], at[2], at[3], at[4], at[5], at[6]
    i_s, i_e, js, je = at[7], at[8], at[9], at[10]
    for y in range(s, stop):
        line = lines[y]
        i = y - s
        tx, ty, tz, add, ti, tj = nx[y], ny[y], nz[y], added[i], ci[i], cj[i]
        if not (tx or ty or tz or add or ti or tj):
            out.append(line)
            continue
        p = 0
        if tx:
            p = _put(out, line, p, xs[y], xe[y], tx)
        if ty:
            p = _put(out, line, p, ys[y], ye[y], ty)
        if tz:
            p = _put(out, line, p, zs[y], ze[y], tz)
        if add:
            p = _put(out, line, p, ze[y], ze[y], add)
        if ti:
            p = _put(out, line, p, i_s[y], i_e[y], ti)
        if tj:
            p = _put(out, line, p, js[y], je[y], tj)
        out.append(line[p:])
    return "".join(out)


def edit_line(line: str, edits: list[tuple[int, int, str]]) -> str:
    """``line`` with ``line[start:end]`` replaced by ``text`` for each ``(start, end,
    text)`` of ``edits`` (spans that do not overlap, in any order): the general writer's
    lines, written as :func:`join_rows` writes a run's. A word added after ``X=AC(10)``
    (Sinumerik: an insertion at a ")") goes after it, not in it."""
    if not edits:
        return line
    out: list[str] = []
    p = 0
    for start, end, text in (sorted(edits) if len(edits) > 1 else edits):
        if start == end and line[start:start + 1] == ")":
            start = end = start + 1
        p = _put(out, line, p, start, end, text)
    out.append(line[p:])
    return "".join(out)


def _put(out: list[str], line: str, p: int, a: int, b: int, text: str) -> int:
    """Append ``line[p:a]``, then ``text`` in the place of ``line[a:b]``; returns ``b``."""
    out.append(line[p:a])
    out.append(text)
    return b
