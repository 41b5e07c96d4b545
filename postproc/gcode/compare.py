"""Compare an original program with its corrected version, block by block.

Lines that are not moves must be byte-identical in both (they are the anchors).
Between two anchors, each original move is paired with the corrected line of the
same skeleton (the line without its numbers, motion and arc words, N words kept)
whose end point is nearest; the corrected lines left over are the lines inserted by
segmentation. Positions are compared in the machine frame, with the work offsets, tool lengths,
start and tool vector the corrected program's header records (those given by the
caller take their place); they matter for G53 blocks, whose words are machine
coordinates. Offsets and tool lengths neither given nor recorded count as zero.
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


_PROGRAM_START = emit._PROGRAM_START


def _records(source, setup: Setup | None, counter: list, drop_header: bool = False, header: list | None = None):
    """Yield ``(lineno, line, end or None)`` lazily; counts lines in ``counter[0]``.

    With ``drop_header`` the header lines at the start (after a ``%`` line and an ``O``
    number line; several headers in a row for a program corrected more than once) are
    left out and collected in ``header``."""
    path, lines = iter_source_lines(source)
    interp = Interpreter(setup or Setup(), path, lenient_setup=True)
    head_open = drop_header
    for lineno, line in enumerate(lines, start=1):
        counter[0] += 1
        if head_open:
            if emit.is_header(line):
                if header is not None:
                    header.append(line.strip())
                counter[0] -= 1
                continue
            if not _PROGRAM_START.match(line) or lineno > 2:
                head_open = False
        mv = interp.feed_line(lineno, line)
        yield lineno, line, (None if mv is None else mv.q1)


_OLD_START = re.compile(r"; start ((?:[XYZ][-+0-9.eE]+,?)+)")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass
class HeaderSetup:
    """The setup a corrected program's header records (empty where it records none)."""

    offsets: dict = field(default_factory=dict)  # "G54" -> (x, y, z) machine mm
    tool_lengths: dict = field(default_factory=dict)  # H -> mm
    start: dict = field(default_factory=dict)  # axis -> machine mm
    tool_vector: tuple | None = None
    home: dict = field(default_factory=dict)  # "G28"/"G30" -> {axis: machine mm}


def _header_rows(source, limit: int = 200) -> list[str]:
    """The header lines at the start of a program (old one-line form or the new lines)."""
    _path, lines = iter_source_lines(source)
    rows: list[str] = []
    try:
        for k, line in enumerate(islice(lines, limit), start=1):
            if emit.is_header(line):
                rows.append(line.strip())
            elif rows or not (_PROGRAM_START.match(line) and k <= 2):
                break
    finally:
        close = getattr(lines, "close", None)
        if close is not None:
            close()
    return rows


def _axis_values(text: str) -> dict[str, float]:
    return {m.group(1).upper(): float(m.group(2)) for m in re.finditer(rf"([XYZxyz])({_NUMBER})", text)}


def header_setup(source) -> HeaderSetup:
    """Offsets, tool lengths, start and tool vector recorded in a corrected program's header."""
    hs = HeaderSetup()
    for row in _header_rows(source):
        if row.startswith(emit.HEADER_TAG):  # the one-line header of earlier versions
            for part in (p.strip() for p in row.rstrip(")").split(";")[1:]):
                m = re.fullmatch(rf"(G5\S*?)=({_NUMBER}),({_NUMBER}),({_NUMBER})", part)
                if m:
                    hs.offsets[m.group(1).upper()] = tuple(float(m.group(i)) for i in (2, 3, 4))
                elif part.startswith("tools "):
                    for item in part[6:].split(","):
                        h, _, v = item.partition("=")
                        hs.tool_lengths[int(float(h))] = float(v)
                elif part.startswith("tool vector "):
                    hs.tool_vector = tuple(float(v) for v in part[12:].split(","))
                elif re.match(r"G(28|30)=", part):
                    hs.home[part[:3]] = _axis_values(part[4:])
            m = _OLD_START.search(row)
            if m:
                hs.start.update({item[0]: float(item[1:]) for item in m.group(1).split(",") if item})
            continue
        words = row[len(emit.HEADER_PREFIX):].rstrip(")").strip().upper()
        m = re.fullmatch(r"OFFSET (G5\S+) (.*)", words)
        if m:
            v = _axis_values(m.group(2))
            hs.offsets[m.group(1)] = (v.get("X", 0.0), v.get("Y", 0.0), v.get("Z", 0.0))
        elif words.startswith("TOOL LENGTHS "):
            for h, v in re.findall(rf"H(\d+) ({_NUMBER})", words):
                hs.tool_lengths[int(h)] = float(v)
        elif words.startswith("START "):
            hs.start.update(_axis_values(words[6:]))
        elif re.match(r"G(28|30) ", words):
            hs.home[words[:3]] = _axis_values(words[4:])
        elif words.startswith("TOOL VECTOR "):
            v = _axis_values(words[12:])
            hs.tool_vector = (v.get("X", 0.0), v.get("Y", 0.0), v.get("Z", 0.0))
    return hs


def header_start(source) -> dict[str, float]:
    """The ``--start`` a corrected program's header records (``{}`` when none)."""
    return header_setup(source).start


def setup_from_header(corrected, setup: Setup | None) -> Setup:
    """``setup`` with what it leaves out (offsets, tool lengths, start, tool vector, G28/G30
    stored positions) taken
    from the corrected program's header: the setup the program was corrected with."""
    hs = header_setup(corrected)
    setup = setup or Setup()
    changes = {}
    if not setup.offsets and hs.offsets:
        changes["offsets"] = dict(hs.offsets)
    if not setup.tool_lengths and hs.tool_lengths:
        changes["tool_lengths"] = dict(hs.tool_lengths)
    if not setup.start and hs.start:
        changes["start"] = dict(hs.start)
    if setup.tool_vector is None and hs.tool_vector is not None:
        changes["tool_vector"] = hs.tool_vector
    if hs.home and hasattr(setup, "home") and not setup.home:
        changes["home"] = {k: dict(v) for k, v in hs.home.items()}
    return dataclasses.replace(setup, **changes) if changes else setup


def _distance(a, b) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True) if not (math.isnan(x) or math.isnan(y)))


def compare_programs(original, corrected, setup: Setup | None = None) -> DiffReport:
    """Pair the blocks of two programs and measure how far each move's end point moved.

    Streams both programs (memory does not grow with their length, apart from the
    compact list of moved blocks). ``setup`` gives work offsets and tool lengths
    (those not given count as zero); they matter only for G53 blocks, whose words
    are machine coordinates.
    """
    # what the program was corrected with, where the caller gives nothing: the start (axes
    # it never names start there), and the offsets and tool lengths that G53 blocks need
    setup = setup_from_header(corrected, setup)
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
    rep.header = "\n".join(header)
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
