"""Compare an original program with its corrected version, block by block.

Lines that are not moves must be byte-identical in both (they are the anchors).
Between two anchors, each original move is paired with the corrected line of the
same skeleton (the line without its numbers, motion and arc words, N words kept)
whose end point is nearest; the corrected lines left over are the lines inserted by
segmentation. Positions are compared in the machine frame; work offsets and tool lengths not
given count as zero (both versions use the same ones, so they cancel, except in G53
blocks whose words are machine coordinates: give them for programs using G53).
"""

from __future__ import annotations

import dataclasses
import math
import re
from array import array
from collections import deque
from dataclasses import dataclass, field
from itertools import islice

import numpy as np

from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup, iter_source_lines

# Pairing stops after this many candidate lines that are farther than the best one.
STOP_AFTER_WORSE = 8
_SKELETON_DROP = re.compile(r"[XYZIJKRPFxyzijkrpf][ \t]*[+-]?(?:\d+\.?\d*|\.\d+)|[Gg][ \t]*0*[0-3](?![0-9.])|\s+")


def skeleton(line: str) -> str:
    """A line without coordinates, arc words, feeds, motion codes and blanks."""
    body = line.split("(")[0].split(";")[0]
    rest = line[len(body):]
    return _SKELETON_DROP.sub("", body) + rest.strip()


@dataclass
class MovedBlock:
    lineno: int  # in the original
    lineno_corrected: int
    delta_mm: tuple[float, float, float]

    @property
    def size_mm(self) -> float:
        return math.sqrt(sum(d * d for d in self.delta_mm))


@dataclass
class DiffReport:
    original: str
    corrected: str
    header: str = ""
    lines_original: int = 0
    lines_corrected: int = 0
    lines_unchanged: int = 0
    lines_inserted: int = 0
    moves: int = 0
    moves_unchanged: int = 0
    # moved blocks, stored compactly: original line, corrected line, dX, dY, dZ
    _lines: array = field(default_factory=lambda: array("q"))
    _clines: array = field(default_factory=lambda: array("q"))
    _deltas: array = field(default_factory=lambda: array("d"))

    def add_moved(self, lineno: int, clineno: int, delta) -> None:
        self._lines.append(lineno)
        self._clines.append(clineno)
        self._deltas.extend(delta)

    @property
    def n_moved(self) -> int:
        return len(self._lines)

    def _delta_array(self) -> np.ndarray:
        return np.frombuffer(self._deltas, dtype=float).reshape(-1, 3) if self._lines else np.zeros((0, 3))

    @property
    def moved(self) -> list[MovedBlock]:
        d = self._delta_array()
        return [MovedBlock(int(a), int(b), (float(x), float(y), float(z)))
                for a, b, (x, y, z) in zip(self._lines, self._clines, d.tolist(), strict=True)]

    def largest(self, n: int) -> list[MovedBlock]:
        d = self._delta_array()
        order = np.argsort(-np.linalg.norm(d, axis=1), kind="stable")[:n]
        return [MovedBlock(self._lines[i], self._clines[i], tuple(float(x) for x in d[i])) for i in order]

    def axis_stats(self) -> dict:
        d = np.abs(self._delta_array())
        if not len(d):
            return {a: {"max_mm": 0.0, "mean_mm": 0.0} for a in "XYZ"}
        return {a: {"max_mm": float(d[:, k].max()), "mean_mm": float(d[:, k].mean())} for k, a in enumerate("XYZ")}

    def to_dict(self) -> dict:
        return {
            "original": self.original, "corrected": self.corrected, "header": self.header,
            "lines_original": self.lines_original, "lines_corrected": self.lines_corrected,
            "lines_unchanged": self.lines_unchanged, "lines_inserted": self.lines_inserted,
            "moves": self.moves, "moves_unchanged": self.moves_unchanged, "moves_moved": self.n_moved,
            "per_axis": self.axis_stats(),
            "moved": [{"line": m.lineno, "line_corrected": m.lineno_corrected,
                       "delta_mm": [round(x, 7) for x in m.delta_mm], "size_mm": round(m.size_mm, 7)}
                      for m in self.moved],
        }


def _records(source, setup: Setup | None, counter: list, drop_header: bool = False, header: list | None = None):
    """Yield ``(lineno, line, end or None)`` lazily; counts lines in ``counter[0]``."""
    path, lines = iter_source_lines(source)
    interp = Interpreter(setup or Setup(), path, lenient_setup=True)
    for lineno, line in enumerate(lines, start=1):
        counter[0] += 1
        if drop_header and header is not None and lineno <= 3 and emit.is_header(line):
            header.append(line.strip())
            counter[0] -= 1
            continue
        mv = interp.feed_line(lineno, line)
        yield lineno, line, (None if mv is None else mv.q1)


_HEADER_START = re.compile(r"; start ((?:[XYZ][-+0-9.eE]+,?)+)")


def header_start(source) -> dict[str, float]:
    """The ``--start`` a corrected program's header records (``{}`` when none)."""
    _path, lines = iter_source_lines(source)
    try:
        for line in islice(lines, 3):
            m = _HEADER_START.search(line) if emit.is_header(line) else None
            if m:
                items = (item for item in m.group(1).split(",") if item)
                return {item[0]: float(item[1:]) for item in items}
    finally:
        close = getattr(lines, "close", None)
        if close is not None:
            close()
    return {}


def _distance(a, b) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True) if not (math.isnan(x) or math.isnan(y)))


def compare_programs(original, corrected, setup: Setup | None = None) -> DiffReport:
    """Pair the blocks of two programs and measure how far each move's end point moved.

    Streams both programs (memory does not grow with their length, apart from the
    compact list of moved blocks). ``setup`` gives work offsets and tool lengths
    (those not given count as zero); they matter only for G53 blocks, whose words
    are machine coordinates.
    """
    if not (setup and setup.start):
        # the start the program was corrected with: axes it never names start there
        start = header_start(corrected)
        if start:
            setup = dataclasses.replace(setup or Setup(), start=start)
    ocount, ccount, header = [0], [0], []
    opath, _ = iter_source_lines(original)
    cpath, _ = iter_source_lines(corrected)
    orecs = _records(original, setup, ocount)
    crecs = _records(corrected, setup, ccount, drop_header=True, header=header)
    rep = DiffReport(str(opath or "<text>"), str(cpath or "<text>"))
    buf: deque = deque()  # corrected records read ahead, not yet paired

    def peek(i: int):
        while len(buf) <= i:
            nxt = next(crecs, None)
            if nxt is None:
                return None
            buf.append(nxt)
        return buf[i]

    last_delta = (0.0, 0.0, 0.0)
    for o_lineno, o_line, o_end in orecs:
        if o_end is None:
            # an anchor: every corrected move before it was inserted
            while True:
                rec = peek(0)
                if rec is None:
                    raise PostprocError(f"line {o_lineno} of the original is missing from the corrected program",
                                        path=rep.corrected, hint="is this the corrected version of that program?")
                buf.popleft()
                if rec[2] is None:
                    if rec[1] != o_line:
                        raise PostprocError(
                            f"line {rec[0]} of the corrected program differs from line {o_lineno} of the original",
                            path=rep.corrected, lineno=rec[0],
                            hint="lines that are not moves must be identical: is this its corrected version?")
                    rep.lines_unchanged += 1
                    break
                rep.lines_inserted += 1
            continue
        sk = skeleton(o_line)
        predicted = tuple(e + d for e, d in zip(o_end, last_delta, strict=True))
        best = None
        worse = 0
        i = 0
        while True:
            rec = peek(i)
            if rec is None or rec[2] is None:
                break  # the end, or the next anchor: the pair lies before it
            if skeleton(rec[1]) == sk or _compatible(o_line, rec[1]):
                dist = _distance(rec[2], predicted)
                if best is None or dist < best[0]:
                    best = (dist, i)
                    worse = 0
                else:
                    # past the nearest line the end points walk away again (the next
                    # move's inserted lines): stop after a few that do not come closer
                    worse += 1
                    if worse >= STOP_AFTER_WORSE:
                        break
            i += 1
        if best is None:
            raise PostprocError(f"move on line {o_lineno} of the original has no counterpart in the corrected program",
                                path=rep.corrected)
        for _ in range(best[1]):
            buf.popleft()
            rep.lines_inserted += 1
        c_lineno, c_line, c_end = buf.popleft()
        rep.moves += 1
        delta = tuple(0.0 if (math.isnan(c) or math.isnan(o)) else c - o for c, o in zip(c_end, o_end, strict=True))
        last_delta = delta
        if c_line == o_line:
            rep.moves_unchanged += 1
            rep.lines_unchanged += 1
        else:
            rep.add_moved(o_lineno, c_lineno, delta)
    while True:
        rec = peek(0)
        if rec is None:
            break
        buf.popleft()
        if rec[2] is None:
            raise PostprocError(f"line {rec[0]} of the corrected program has no counterpart in the original",
                                path=rep.corrected, lineno=rec[0])
        rep.lines_inserted += 1
    rep.header = header[-1] if header else ""
    rep.lines_original = ocount[0]
    rep.lines_corrected = ccount[0]
    return rep


def _compatible(o_line: str, c_line: str) -> bool:
    """Same N word and comment: a line whose motion words were rewritten (a linearised arc)."""
    n_o = re.match(r"\s*[Nn]\s*\d+", o_line)
    n_c = re.match(r"\s*[Nn]\s*\d+", c_line)
    if n_o and n_c:
        return n_o.group().strip() == n_c.group().strip()
    co = o_line[o_line.find("("):] if "(" in o_line else ""
    cc = c_line[c_line.find("("):] if "(" in c_line else ""
    return bool(co) and co == cc
