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

import math
import re
from dataclasses import dataclass, field

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
    moved: list[MovedBlock] = field(default_factory=list)

    def axis_stats(self) -> dict:
        if not self.moved:
            return {a: {"max_mm": 0.0, "mean_mm": 0.0} for a in "XYZ"}
        d = np.abs(np.array([m.delta_mm for m in self.moved]))
        return {a: {"max_mm": float(d[:, k].max()), "mean_mm": float(d[:, k].mean())} for k, a in enumerate("XYZ")}

    def to_dict(self) -> dict:
        return {
            "original": self.original, "corrected": self.corrected, "header": self.header,
            "lines_original": self.lines_original, "lines_corrected": self.lines_corrected,
            "lines_unchanged": self.lines_unchanged, "lines_inserted": self.lines_inserted,
            "moves": self.moves, "moves_unchanged": self.moves_unchanged, "moves_moved": len(self.moved),
            "per_axis": self.axis_stats(),
            "moved": [{"line": m.lineno, "line_corrected": m.lineno_corrected,
                       "delta_mm": [round(x, 7) for x in m.delta_mm], "size_mm": round(m.size_mm, 7)}
                      for m in self.moved],
        }


def _records(source, drop_header: bool, setup: Setup | None):
    path, lines = iter_source_lines(source)
    interp = Interpreter(setup or Setup(), path, lenient_setup=True)
    recs = []
    header = ""
    for lineno, line in enumerate(lines, start=1):
        if drop_header and not header and emit.is_header(line):
            header = line.strip()
            recs.append((lineno, line, None, True))
            continue
        mv = interp.feed_line(lineno, line)
        recs.append((lineno, line, None if mv is None else np.array(mv.q1, dtype=float), False))
    return path, recs, header


def compare_programs(original, corrected, setup: Setup | None = None) -> DiffReport:
    """Pair the blocks of two programs and measure how far each move's end point moved.

    ``setup`` gives work offsets and tool lengths (those not given count as zero);
    they matter only for G53 blocks, whose words are machine coordinates.
    """
    opath, orecs, _ = _records(original, drop_header=False, setup=setup)
    cpath, crecs, header = _records(corrected, drop_header=True, setup=setup)
    crecs = [r for r in crecs if not r[3]]
    rep = DiffReport(str(opath or "<text>"), str(cpath or "<text>"), header=header,
                     lines_original=len(orecs), lines_corrected=len(crecs))
    j = 0
    i = 0
    while i < len(orecs):
        # the next anchor (non-move line) in the original, and where it sits in the corrected
        k = i
        while k < len(orecs) and orecs[k][2] is not None:
            k += 1
        moves = orecs[i:k]
        if k < len(orecs):
            anchor = orecs[k][1]
            jj = j
            while jj < len(crecs) and not (crecs[jj][2] is None and crecs[jj][1] == anchor):
                jj += 1
            if jj == len(crecs):
                raise PostprocError(f"line {orecs[k][0]} of the original is missing from the corrected program",
                                    path=rep.corrected, hint="is this the corrected version of that program?")
        else:
            jj = len(crecs)
        window = crecs[j:jj]
        pos = 0
        for m_idx, (o_lineno, o_line, o_end, _) in enumerate(moves):
            sk = skeleton(o_line)
            best = None
            worse = 0
            stop = len(window) - (len(moves) - 1 - m_idx)
            for w in range(pos, stop):
                c_lineno, c_line, c_end, _h = window[w]
                if c_end is None or (skeleton(c_line) != sk and not _compatible(o_line, c_line)):
                    continue
                dist = float(np.nansum(np.abs(c_end - o_end)))
                if best is None or dist < best[0]:
                    best = (dist, w)
                    worse = 0
                else:
                    # past the nearest line the end points walk away again (the next
                    # move's inserted lines): stop after a few that do not come closer
                    worse += 1
                    if worse >= STOP_AFTER_WORSE:
                        break
            if best is None:
                raise PostprocError(f"move on line {o_lineno} of the original has no counterpart in the corrected program",
                                    path=rep.corrected)
            w = best[1]
            rep.lines_inserted += sum(1 for x in window[pos:w] if x[2] is not None)
            c_lineno, c_line, c_end, _h = window[w]
            rep.moves += 1
            delta = np.nan_to_num(c_end - o_end)
            if c_line == o_line:
                rep.moves_unchanged += 1
                rep.lines_unchanged += 1
            else:
                rep.moved.append(MovedBlock(o_lineno, c_lineno, tuple(float(x) for x in delta)))
            pos = w + 1
        rep.lines_inserted += sum(1 for x in window[pos:] if x[2] is not None)
        if k < len(orecs):
            rep.lines_unchanged += 1
            j = jj + 1
        else:
            j = jj
        i = k + 1
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
