"""Compare an original program with its corrected version, block by block.

Lines that are not moves must be byte-identical in both (they are the anchors), and
the k-th anchor of one program pairs with the k-th of the other. Between two anchors,
when both programs have as many moves, each move pairs with the line at the same place,
which must be of the same skeleton (the line without its numbers, motion and arc words,
N words kept; or the same N word, or the same comment). Where the corrected program has
more lines, each original move is paired with the corrected line of the same skeleton
whose end point is nearest its own plus the previous move's correction; the corrected
lines left over are the lines inserted by segmentation. Positions are compared in the
machine frame, with the work offsets, tool lengths, start and tool vector the corrected
program's header records (those given by the caller take their place); they matter for
G53 blocks, whose words are machine coordinates. Offsets and tool lengths neither given
nor recorded count as zero.

Both programs are read in chunks of lines, and memory does not grow with their length
(apart from the compact list of moved blocks, unless only the largest are kept). They are
read by the reader ``correct`` reads with (:class:`postproc.gcode.reader.LineReader`):
runs of plain lines in bulk (:mod:`postproc.gcode.bulk`), every other line through the
interpreter, which carries the modal state from one run to the next; each line is kept
as its text, line number, end point and pairing keys (:class:`_Rows`). A large original
is read by a forked child process of its own while this one reads the corrected program
and pairs (:class:`_ForkedReader`; the same chunks, keys and errors). Pairing takes a chunk at a time: the stretches
with as many moves in both at once; in a stretch with lines inserted, the moves before
and after each insertion at once (the nearest-end-point rule checked for all of them),
the move at the insertion one at a time. The rule looks at the corrected lines up to the
next anchor; the compatible ones are looked up by their keys (skeleton, N word,
comment), so a program with no anchor for long, every move with its own N word, is
paired in windows too. Its corrected version is then held up to that anchor (the whole
program when it has none), as the rule needs. Where the nearest line is not much nearer
than an earlier one (a move shorter than the change of the correction over the move
before it, whose own line the prediction misses by more than its length), the next few
records are aligned with the lines at once, the one where the deltas change least from
move to move taken.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import multiprocessing
import operator
import os
import re
from array import array
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from itertools import chain, islice, repeat
from pathlib import Path
from typing import Any, NamedTuple, TypeAlias

import numpy as np

from postproc.errors import PostprocError
from postproc.fileio import Lines, read_blocks
from postproc.gcode import bulk, emit, forking
from postproc.gcode.interp import Interpreter
from postproc.gcode.lexer import Word
from postproc.gcode.moves import Move
from postproc.gcode.options import CorrectOptions
from postproc.gcode.places import PathArray, file_of, line_place, pick
from postproc.gcode.reader import LineReader
from postproc.gcode.source import Setup, iter_source_lines, open_source
from postproc.limits import Limits

# Pairing stops after this many candidate lines that are farther than the best one,
STOP_AFTER_WORSE = 8
# unless the best is farther than this from the predicted end point (no correction changes
# so much from one move to the next: the move's own line lies further on, e.g. the last
# piece of a full circle cut into many arcs, whose first pieces walk away and back), up
# to FAR_SCAN candidates.
PLAUSIBLE_MM = 1.0
FAR_SCAN = 512
# Lines read at a time from each program.
CHUNK_LINES = 20_000
# Lines the reader scans at a time (a chunk's lines in blocks of this many: the scanner's
# columns of a smaller block stay in the processor's caches).
BLOCK_LINES = 5_000
# Corrected records looked at past the window for the anchor that ends each scan.
SCAN_AHEAD = 256
# After a record that had to be paired one at a time, this many are paired so before
# records are paired at once again, in a window of at least MIN_WINDOW.
SLOW_STRETCH = 4
MIN_WINDOW = 256
# Insertions in one stretch between anchors checked at once (more: paired one at a time).
MAX_LEVELS = 8
# A program file at least this large is read by a child process of its own (where
# processes can be forked): two cores read the two programs while this one pairs them.
FORK_MIN_BYTES = 2_000_000
_COMMENT_SPLIT = re.compile(r"(\([^)]*\)?|;.*)")
# (a spline, G5 or G5.1 with its I J P Q words, is written as straight chords: its last
# chord has the skeleton of the original line)
# (the S, T and before-motion M words of a split move, with their E/L/P/Q parameters, go
# on its first piece: postproc.gcode.interp Move.event_idx; its modal G words and G43 H
# are copied there)
_SKELETON_DROP = re.compile(r"[XYZIJKRPQFSTHELxyzijkrpqfsthel][ \t]*[+-]?(?:\d+\.?\d*|\.\d+)"
                            r"|[Gg][ \t]*0*(?:[0-3]|5(?:\.1)?|1[7-9]|2[01]|9[0-4](?:\.1)?|5[4-9](?:\.\d)?|4[39])"
                            r"(?![0-9.])"
                            r"|[Mm][ \t]*+0*+(?!(?:0|1|2|6|30|60)(?![0-9.]))\d+(?![0-9.])|\s+")


def skeleton(line: str) -> str:
    """A line without coordinates, arc words, feeds, motion codes and blanks (its comments
    kept as they are, also where words follow a comment)."""
    parts = _COMMENT_SPLIT.split(line)
    return "".join(part if k % 2 else _SKELETON_DROP.sub("", part) for k, part in enumerate(parts))


_SKELETON_LETTERS = frozenset("XYZIJKRPQFSTHEL")


def _without_assigned(line: str, words: Sequence[Word]) -> str:
    """``line`` without its words of those letters written ``NAME=value`` (Sinumerik:
    ``X=R1*2``, ``X=AC(10)``, ``CR=5``; ``words``: the interpreter's, with their spans),
    for :func:`skeleton`. ``correct`` writes a number in place of such a word's value (its
    expression, or the number inside AC()), which the skeleton's patterns do not know
    where it ends: it goes whole, in the original and in the corrected line alike."""
    cut = [(w.letter_pos, w.end) for w in words
           if w.letter in _SKELETON_LETTERS and 0 <= w.letter_pos < w.start <= w.end <= len(line)
           and "=" in line[w.letter_pos:w.start]]
    if not cut:
        return line
    parts, last = [], 0
    for a, b in sorted(cut):
        parts.append(line[last:a])
        last = max(last, b)
    parts.append(line[last:])
    return "".join(parts)


@dataclass
class MovedBlock:
    lineno: int  # in the original (in ``file`` where given)
    lineno_corrected: int
    delta_mm: tuple[float, float, float]
    # the file of the original line where it is not the original's own (a subprogram's
    # file, the original read expanded); None: a line of the original
    file: str | None = None

    @property
    def size_mm(self) -> float:
        return math.sqrt(sum(d * d for d in self.delta_mm))

    @property
    def place(self) -> str:
        """The original line as the report names it: its number, or ``file:line`` for a
        line of another file (:func:`postproc.gcode.places.line_place`)."""
        return line_place(self.lineno, self.file, None)


@dataclass
class DiffReport:
    original: str
    corrected: str
    header: str = ""
    lines_original: int = 0  # read: the lines executed when the original is read expanded
    lines_corrected: int = 0
    lines_unchanged: int = 0
    # G92 lines whose axis words correct rewrote (to keep the nominal coordinates)
    lines_rewritten: int = 0
    lines_inserted: int = 0
    moves: int = 0
    moves_unchanged: int = 0
    # Moved blocks kept: all of them (None), or only the ``keep`` largest, so that memory
    # does not grow with the program (the per-axis figures still count every block).
    keep: int | None = None
    # the original was read expanded (subprograms, loops and macros written out), as the
    # corrected program was written
    expanded: bool = False
    # moved blocks, stored compactly: original line, corrected line, dX, dY, dZ
    _lines: array = field(default_factory=lambda: array("q"))
    _clines: array = field(default_factory=lambda: array("q"))
    _deltas: array = field(default_factory=lambda: array("d"))
    # the file of each moved block's original line, as an index into _paths (-1: the
    # original's own); None until a block of another file is stored (an expanded program's)
    _files: array | None = None
    _paths: list = field(default_factory=list)
    # with ``keep``: every moved block's count, largest and summed |delta| per axis
    _n_moved: int = 0
    _abs_max: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    _abs_sum: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    _counted: int = 0  # stored blocks already in _abs_max and _abs_sum

    def add_moved(self, lineno: int, clineno: int, delta, path: str | None = None) -> None:
        """A moved block (``path``: the file of its original line, None: the original's own)."""
        self._add_files(None if path is None else [path], 1)
        self._lines.append(lineno)
        self._clines.append(clineno)
        self._deltas.extend(delta)
        self._n_moved += 1
        if self.keep is not None and len(self._lines) > self._limit():
            self._prune()

    def _add_files(self, paths: list | None, n: int) -> None:
        """The files of ``n`` blocks about to be stored (``paths``, None where all are the
        original's own)."""
        if paths is not None and any(p is not None for p in paths):
            if self._files is None:
                self._files = array("q", [-1]) * len(self._lines)
            known = {p: k for k, p in enumerate(self._paths)}
            for p in paths:
                if p is not None and p not in known:
                    known[p] = len(self._paths)
                    self._paths.append(p)
            self._files.extend(-1 if p is None else known[p] for p in paths)
        elif self._files is not None:
            self._files.extend(array("q", [-1]) * n)

    def add_moved_rows(self, linenos: np.ndarray, clinenos: np.ndarray, deltas: np.ndarray,
                       files: PathArray | None = None) -> None:
        """Many moved blocks at once (arrays of line numbers and an (n, 3) array of deltas;
        ``files``: the file of each original line, :mod:`postproc.gcode.places`)."""
        self._add_files(None if files is None else files.tolist(), len(linenos))
        self._lines.frombytes(np.ascontiguousarray(linenos, dtype=np.int64).tobytes())
        self._clines.frombytes(np.ascontiguousarray(clinenos, dtype=np.int64).tobytes())
        self._deltas.frombytes(np.ascontiguousarray(deltas, dtype=np.float64).tobytes())
        self._n_moved += len(linenos)
        if self.keep is not None and len(self._lines) > self._limit():
            self._prune()

    def _limit(self) -> int:
        assert self.keep is not None
        return max(8 * self.keep, 65_536)

    def _count(self) -> None:
        """With ``keep``: the blocks stored since the last count into the per-axis largest
        and summed |delta| (counted when they are pruned or the figures are asked for)."""
        d = self._delta_array()[self._counted:]
        if len(d):
            a = np.abs(d)
            for k, (mx, sm) in enumerate(zip(a.max(axis=0).tolist(), a.sum(axis=0).tolist(), strict=True)):
                self._abs_sum[k] += sm
                if mx > self._abs_max[k]:
                    self._abs_max[k] = mx
        self._counted = len(self._lines)

    def _prune(self) -> None:
        """With ``keep``: drop all but the ``keep`` largest blocks stored (in the order
        :meth:`largest` gives: size, then the order they came in), once they are counted."""
        keep = self.keep
        assert keep is not None
        self._count()
        order = np.sort(self._largest_order(keep))
        lines = np.frombuffer(self._lines, dtype=np.int64)[order]
        clines = np.frombuffer(self._clines, dtype=np.int64)[order]
        deltas = self._delta_array()[order]
        self._lines, self._clines, self._deltas = array("q"), array("q"), array("d")
        self._lines.frombytes(lines.tobytes())
        self._clines.frombytes(clines.tobytes())
        self._deltas.frombytes(np.ascontiguousarray(deltas).tobytes())
        if self._files is not None:
            self._files = array("q", np.frombuffer(self._files, dtype=np.int64)[order].tobytes())
        self._counted = len(self._lines)

    @property
    def n_moved(self) -> int:
        return self._n_moved

    def _delta_array(self) -> np.ndarray:
        return np.frombuffer(self._deltas, dtype=float).reshape(-1, 3) if self._lines else np.zeros((0, 3))

    def _largest_order(self, n: int) -> np.ndarray:
        """The rows of the ``n`` largest deltas, largest first, equal ones in the order
        they came in (the first ``n`` of a stable sort by size, found without sorting all)."""
        neg = -np.linalg.norm(self._delta_array(), axis=1)
        if 0 < n < len(neg) and np.isfinite(neg).all():
            # every row at or above the n-th largest size, then those sorted stably
            rows = np.flatnonzero(neg <= np.partition(neg, n - 1)[n - 1])
            return rows[np.argsort(neg[rows], kind="stable")][:n]
        return np.argsort(neg, kind="stable")[:n]

    @property
    def moved(self) -> list[MovedBlock]:
        """Every moved block, in the original's order (not with ``keep``: see :meth:`largest`)."""
        if self.keep is not None and len(self._lines) < self._n_moved:
            raise ValueError(f"only the {self.keep} largest moved blocks were kept (DiffReport.keep)")
        d = self._delta_array()
        return [MovedBlock(int(a), int(b), (float(x), float(y), float(z)), self._path(i))
                for i, (a, b, (x, y, z)) in enumerate(zip(self._lines, self._clines, d.tolist(), strict=True))]

    def _path(self, i: int) -> str | None:
        """The file of stored block ``i``'s original line (None: the original's own)."""
        if self._files is None or self._files[i] < 0:
            return None
        return self._paths[self._files[i]]

    def largest(self, n: int) -> list[MovedBlock]:
        """The ``n`` largest moved blocks, largest first (equal ones in the original's order)."""
        if self.keep is not None and n > self.keep:
            raise ValueError(f"only the {self.keep} largest moved blocks were kept (DiffReport.keep)")
        d = self._delta_array()
        order = self._largest_order(n)
        return [MovedBlock(self._lines[i], self._clines[i], (x, y, z), self._path(i))
                for i, (x, y, z) in zip(order.tolist(), d[order].tolist(), strict=True)]

    def axis_stats(self) -> dict:
        if self.keep is not None:
            self._count()
            n = self._n_moved
            return {a: {"max_mm": self._abs_max[k] if n else 0.0, "mean_mm": self._abs_sum[k] / n if n else 0.0}
                    for k, a in enumerate("XYZ")}
        d = np.abs(self._delta_array())
        if not len(d):
            return {a: {"max_mm": 0.0, "mean_mm": 0.0} for a in "XYZ"}
        return {a: {"max_mm": float(d[:, k].max()), "mean_mm": float(d[:, k].mean())} for k, a in enumerate("XYZ")}

    def to_dict(self) -> dict:
        return {
            "original": self.original, "corrected": self.corrected, "header": self.header,
            "expanded": self.expanded,
            "lines_original": self.lines_original, "lines_corrected": self.lines_corrected,
            "lines_unchanged": self.lines_unchanged, "lines_inserted": self.lines_inserted,
            "lines_rewritten": self.lines_rewritten,
            "moves": self.moves, "moves_unchanged": self.moves_unchanged, "moves_moved": self.n_moved,
            "per_axis": self.axis_stats(),
            "moved": [_moved_dict(m) for m in self.moved],
        }


def _moved_dict(m: MovedBlock) -> dict:
    """A moved block in the JSON report: ``file`` only for a line of another file than the
    original (a subprogram's, the original read expanded)."""
    out: dict[str, Any] = {"line": m.lineno}
    if m.file is not None:
        out["file"] = m.file
    out.update({"line_corrected": m.lineno_corrected, "delta_mm": [round(x, 7) for x in m.delta_mm],
                "size_mm": round(m.size_mm, 7)})
    return out


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
    variables: dict = field(default_factory=dict)  # machine-state variables given with --var
    expanded: bool = False  # the program was corrected expanded (subprograms, loops, macros written out)
    cycles_expanded: bool = False  # its canned cycles were written as their moves (--cycles expand)
    # the header says whether the cycles were expanded (its rows of this form say so: a
    # header without the CYCLES EXPANDED row is of a program corrected without it)
    cycles_recorded: bool = False


def _header_rows(source) -> list[str]:
    """The header lines at the start of a program (old one-line form or the new lines)."""
    _path, lines = iter_source_lines(source)
    try:
        _kept, header, _after = emit.header_run(lines)
    finally:
        close = getattr(lines, "close", None)
        if close is not None:
            close()
    return [line.strip() for line in header]


def _axis_values(text: str) -> dict[str, float]:
    return {m.group(1).upper(): float(m.group(2)) for m in re.finditer(rf"([XYZxyz])({_NUMBER})", text)}


def header_setup(source) -> HeaderSetup:
    """Offsets, tool lengths, start and tool vector recorded in a corrected program's header."""
    hs = HeaderSetup()
    for row in _header_rows(source):
        if row.startswith(emit.HEADER_TAG):  # the one-line header of earlier versions
            _old_header_row(hs, row)
            continue
        words = row[len(emit.HEADER_PREFIX):].rstrip(")").strip().upper()
        hs.cycles_recorded = True
        m = re.fullmatch(r"OFFSET (\S+) (.*)", words)
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
        elif words.startswith("VARIABLES "):
            for n, v in re.findall(rf"(\d+) ({_NUMBER})", words[10:]):
                hs.variables[int(n)] = float(v)
        elif words.startswith("EXPANDED"):
            hs.expanded = True
        elif words == "CYCLES EXPANDED":
            hs.cycles_expanded = True
    return hs


def _old_header_row(hs: HeaderSetup, row: str) -> None:
    """Read the one-line header of earlier versions into ``hs``."""
    for part in (p.strip() for p in row.rstrip(")").split(";")[1:]):
        m = re.fullmatch(rf"(G5\S*?)=({_NUMBER}),({_NUMBER}),({_NUMBER})", part)
        if m:
            hs.offsets[m.group(1).upper()] = tuple(float(m.group(i)) for i in (2, 3, 4))
        elif part.startswith("tools "):
            for item in part[6:].split(","):
                h, _, length = item.partition("=")
                hs.tool_lengths[int(float(h))] = float(length)
        elif part.startswith("tool vector "):
            hs.tool_vector = tuple(float(v) for v in part[12:].split(","))
        elif re.match(r"G(28|30)=", part):
            hs.home[part[:3]] = _axis_values(part[4:])
        elif part.lower().startswith("expanded"):
            hs.expanded = True
    m = _OLD_START.search(row)
    if m:
        hs.start.update({item[0]: float(item[1:]) for item in m.group(1).split(",") if item})


def setup_from_header(hs: HeaderSetup, setup: Setup | None) -> Setup:
    """``setup`` with what it leaves out (offsets, tool lengths, start, tool vector, G28/G30
    stored positions) taken from the corrected program's header (``hs``,
    :func:`header_setup`): the setup the program was corrected with."""
    setup = setup or Setup()
    changes: dict[str, Any] = {}  # Setup fields to replace
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
    if hs.variables and not setup.variables:
        changes["variables"] = dict(hs.variables)
    return dataclasses.replace(setup, **changes) if changes else setup


# -- reading ---------------------------------------------------------------------------

_N_WORD = re.compile(r"\s*[Nn]\s*\d+")


def _last_index(present: np.ndarray) -> np.ndarray:
    """For each row, the index of the last present row at or before it (-1: none)."""
    idx = np.where(present, np.arange(len(present)), -1)
    np.maximum.accumulate(idx, out=idx)
    return idx


def _next_index(present: np.ndarray) -> np.ndarray:
    """For each row, the index of the first present row at or after it (len: none)."""
    n = len(present)
    idx = np.where(present, np.arange(n), n)
    return np.minimum.accumulate(idx[::-1])[::-1]


# A plain N word: N and 1 to 15 digits, no leading zero (N0 itself is one).
_PLAIN_N = re.compile(r"N(?:0|[1-9][0-9]{0,14})").fullmatch


class _Keys:
    """Integers standing for the pieces of a line that pairing compares (skeleton, N word,
    comment): 0 for none, n + 1 for the plain N word Nn, negative numbers for the rest."""

    def __init__(self) -> None:
        self.table: dict[str, int] = {}
        self.texts: list[str] | None = None  # when a list: every new text is added to it

    def __call__(self, text: str) -> int:
        if not text:
            return 0
        if _PLAIN_N(text):
            return int(text[1:]) + 1
        key = self.table.get(text)
        if key is None:
            key = self.table[text] = -1 - len(self.table)
            if self.texts is not None:
                self.texts.append(text)
        return key

    def of_line(self, line: str) -> tuple[int, int, int]:
        """Skeleton, N word and comment of any line (see :func:`_compatible_keys`)."""
        n = _N_WORD.match(line)
        c = line.find("(")
        return self(skeleton(line)), self(n.group().strip() if n else ""), self(line[c:] if c >= 0 else "")


def _compatible_keys(o: tuple, c: tuple) -> bool:
    """Whether two lines pair, from their keys: :func:`skeleton` equal, or the same N word
    where both have one, else the same comment (a line whose motion words were
    rewritten: a linearised arc)."""
    if o[0] == c[0]:
        return True
    if o[1] and c[1]:
        return o[1] == c[1]
    return o[2] != 0 and o[2] == c[2]


class _Rows:
    """Consecutive lines of a program: text, line number, whether each makes a move, its
    end point (machine mm, NaN where unknown or no move), its pairing keys and, for a
    program read expanded, the file of its line (:mod:`postproc.gcode.places`)."""

    __slots__ = ("lines", "lineno", "move", "end", "keys", "files", "_index")

    def __init__(self, lines: list[str], lineno, move, end, keys, files: PathArray | None = None) -> None:
        self.lines = lines
        self.lineno = lineno
        self.move = move
        self.end = end
        self.keys = keys  # (n, 3) int64: skeleton, N word, comment
        self.files = files  # the file of each row (None: the program's own), or None for all
        self._index: _Index | None = None

    def index(self) -> _Index:
        """Where each key lies in these rows (built when first asked for, then kept)."""
        if self._index is None:
            self._index = _Index(self)
        return self._index

    @classmethod
    def blank(cls, lines: list[str], lineno0: int) -> _Rows:
        n = len(lines)
        return cls(lines, np.arange(lineno0, lineno0 + n, dtype=np.int64), np.zeros(n, dtype=bool),
                   np.full((n, 3), np.nan), np.zeros((n, 3), dtype=np.int64))

    def __len__(self) -> int:
        return len(self.lines)

    def head(self, n: int) -> _Rows:
        return _Rows(self.lines[:n], self.lineno[:n], self.move[:n], self.end[:n], self.keys[:n],
                     pick(self.files, slice(None, n)))

    @classmethod
    def join(cls, parts: list[_Rows]) -> _Rows:
        if len(parts) == 1:
            return parts[0]
        lines: list[str] = []
        for p in parts:
            lines += p.lines
        files = None
        if any(p.files is not None for p in parts):
            files = np.concatenate([np.full(len(p), None, dtype=object) if p.files is None else p.files
                                    for p in parts])
        return cls(lines, np.concatenate([p.lineno for p in parts]),
                   np.concatenate([p.move for p in parts]), np.concatenate([p.end for p in parts]),
                   np.concatenate([p.keys for p in parts]), files)

    def tail(self, start: int) -> _Rows:
        return _Rows(self.lines[start:], self.lineno[start:], self.move[start:], self.end[start:],
                     self.keys[start:], pick(self.files, slice(start, None)))

    def place(self, i: int, own: str) -> str:
        """Row ``i``'s line as a refusal names it: ``line 5 of the original`` (``own``: the
        program's name), or, for a line of another file (an expanded program's
        subprogram), ``line 5 of sub.ngc (called by the original)``."""
        n = int(self.lineno[i])
        path = file_of(self.files, i, None)
        return f"line {n} of {own}" if path is None else f"line {n} of {path} (called by {own})"


@dataclass(frozen=True)
class _ReadOptions:
    """How :class:`_Reader` reads its program."""

    # the header lines (emit.header_run) left out (the corrected program)
    drop_header: bool = False
    dialect: str = "generic"
    # the program read as executed: subprograms, loops and macros written out, as correct
    # writes them (each line numbered by its source line); its external subprograms
    # looked up on subroutine_path
    expand: bool = False
    subroutine_path: tuple[Path, ...] = ()
    # each canned cycle block is read as the lines correct writes it as when it expands it
    # (both programs so, as correct may keep some cycles and expand others), their G98/G99
    # retracts kept unless correct was given --cycles expand
    cycle_retract: bool = True
    limits: Limits | None = None  # loops and helix turns (postproc.limits)


# what a line read that is not in a run is queued as: its text, line number, end point
# (None: it moves nothing), pairing keys and file (an expanded program's; else None)
_Record: TypeAlias = tuple[str, int, "tuple[float, float, float] | None", tuple[int, int, int], "str | None"]
_NO_KEYS = (0, 0, 0)
# The head of a plain line (bulk.Block: blanks, N, G and G43 H words) that starts with a
# plain N word: the N word and what follows it.
_HEAD_N = r"[ \t]*+(N(?:0|[1-9][0-9]{0,14}))(?![0-9.])(.*+)"
# The N word and the rest of each of heads joined by line feeds (two empty strings for a
# head that does not start with one).
_HEADS_N = re.compile(rf"^{_HEAD_N}$|^.*+$", re.M).findall


class _LineRows(LineReader[_Record]):
    """The lane's reader (:class:`postproc.gcode.reader.LineReader`: the interpreter line
    by line, runs of plain lines in bulk), queueing each line's end point and keys; a
    canned cycle block as the lines ``correct`` writes it as when it expands it."""

    def __init__(self, interp: Interpreter, keys: _Keys, retract: bool, path: str | None) -> None:
        super().__init__(interp, CorrectOptions(), path)
        self.keys = keys
        # only letter-number words (else also NAME=value ones, Sinumerik's: see _without_assigned)
        self.iso_words = interp.d.block_syntax == "iso"
        self.retract = retract
        # the keys of a plain line's head without an N word, as a row of _head_table (0: no head)
        self._head_ids: dict[str, int] = {"": 0}
        self._head_rows: list[tuple[int, int, int]] = [_NO_KEYS]
        self._head_table = np.zeros((1, 3), dtype=np.int64)
        self._rest_skeletons: dict[str, str] = {}  # the skeleton of a head after its N word

    def queue(self, line: str, mv: Move | None, lineno: int) -> None:
        """Queue the line's record; a canned cycle block's (or Sinumerik drilling cycle's)
        as the records of the lines correct writes it as: the lines that move nothing as
        they are, each G0/G1 step a move to its point (of empty keys, numbered by the
        block's line)."""
        it = self.interp
        steps: Sequence[str | emit.CycleStep | None] | None = None
        if mv is not None and mv.cycle is not None:
            steps = emit.cycle_lines(line, mv, mv.cycle, self.retract)
        if it.call_line or it.cycle_move is not None:
            steps = emit.drill_cycle_lines(line, bool(it.call_line), mv, it.cycle_move, it.state.motion)
        path = None if self.source is None else it.path  # (an expanded program's: the line's file)
        if mv is None:
            rec: _Record = (line, lineno, None, _NO_KEYS, path)
        else:
            rec = (line, lineno, mv.q1, self.keys.of_line(line if self.iso_words else _without_assigned(line, mv.words)),
                   path)
        entries = self.entries
        if steps is None:
            entries.append(rec)
            return
        path = rec[4]
        for k, step in enumerate(steps):
            if step is None:  # the block itself (a Sinumerik position block)
                entries.append(rec)
            elif isinstance(step, str):
                entries.append((step, lineno, None, _NO_KEYS, path))
            else:
                # never a written line's text; the same for the same block on both sides (a
                # cycle kept unchanged), and differs from its corrected version
                entries.append((f"\0{line}\0{k}", lineno, step[2], _NO_KEYS, path))

    def rows(self) -> _Rows:
        """The records queued, as rows (then let go of)."""
        entries = self.entries
        n = sum(len(e) if type(e) is bulk.Run else 1 for e in entries)
        lines: list[str] = []
        lineno = np.empty(n, dtype=np.int64)
        move = np.zeros(n, dtype=bool)
        end = np.full((n, 3), np.nan)
        keys = np.zeros((n, 3), dtype=np.int64)
        runs: dict[int, list[tuple[bulk.Run, int]]] = {}  # by block: its runs and the row of each
        at: list[int] = []  # the rows of the records that are not in a run
        at_lineno: list[int] = []
        at_files: list[str | None] = []
        moved: list[int] = []
        ends: list[tuple[float, float, float]] = []
        moved_keys: list[tuple[int, int, int]] = []
        i = 0
        for e in entries:
            if type(e) is bulk.Run:
                lines += e.block.lines[e.a:e.b]
                runs.setdefault(id(e.block), []).append((e, i))
                i += e.b - e.a
                continue
            line, ln, q1, k, path = e
            lines.append(line)
            at.append(i)
            at_lineno.append(ln)
            at_files.append(path)
            if q1 is not None:
                moved.append(i)
                ends.append(q1)
                moved_keys.append(k)
            i += 1
        if at:
            lineno[at] = at_lineno
        if moved:
            move[moved] = True
            end[moved] = ends
            keys[moved] = moved_keys
        for group in runs.values():
            blk = group[0][0].block
            src = np.concatenate([np.arange(r.a, r.b) for r, _i in group])  # the runs' lines in the block
            dst = np.concatenate([np.arange(i, i + r.b - r.a) for r, i in group])  # their rows
            lineno[dst] = np.concatenate([r.linenos() for r, _i in group])
            inert = blk.neutral[src]
            move[dst] = ~inert
            q = np.concatenate([r.q1 for r, _i in group])
            q[inert] = np.nan
            end[dst] = q
            keys[dst] = self._run_keys(blk, [(r.a, r.b) for r, _i in group], src)
        files = None if self.source is None else self._files(n, at, at_files, runs)
        self.let_go()
        return _Rows(lines, lineno, move, end, keys, files)

    def _files(self, n: int, at: list[int], at_files: list[str | None],
               runs: dict[int, list[tuple[bulk.Run, int]]]) -> PathArray | None:
        """The file of each of an expanded program's ``n`` rows (None: the program's own),
        or None when every row is the program's own: ``at_files`` those of the rows
        ``at``, the runs' from their blocks (:meth:`bulk.Run.paths`)."""
        files = np.full(n, None, dtype=object)
        if at:
            files[at] = at_files
        for group in runs.values():
            for r, i in group:
                paths = r.paths()
                if paths is not None:
                    files[i:i + len(paths)] = paths
        own = files == self.path
        if own.all():
            return None
        files[own] = None
        return files

    def _run_keys(self, blk: bulk.Block, spans: list[tuple[int, int]], src: np.ndarray) -> np.ndarray:
        """The keys of the block's run lines (``spans``: each run's lines a:b; ``src``: all
        of them, in order): a plain line's skeleton is its N word (or nothing) and its
        rotary words, its N word its own, no comment; a line that moves nothing has none.
        A head without an N word is looked up among those met before (its keys' row of
        :attr:`_head_table`), the others' keys found line by line."""
        lines, head_end = blk.lines, blk.at[0]
        hs: list[str] = []  # each line's head (N, G and G43 H words); "" where it moves nothing
        for a, b in spans:
            hs += map(str.__getitem__, lines[a:b], map(slice, repeat(0), head_end[a:b]))
        for k in np.flatnonzero(blk.neutral[src]).tolist():
            hs[k] = ""
        ids = self._head_ids
        found = np.fromiter(map(ids.get, hs, repeat(-1)), dtype=np.int64, count=len(hs))
        own: dict[int, tuple[int, int, int]] = {}  # rows whose keys are their line's own
        if blk.rotary is not None:  # a line naming a rotary axis: its whole skeleton
            named = np.zeros(len(lines), dtype=bool)
            for _letter, has, _val in blk.rotary:
                named |= np.array(has, dtype=bool)
            for k in np.flatnonzero(named[src]).tolist():
                own[k] = self.keys.of_line(blk.lines[int(src[k])])
        miss = [k for k in np.flatnonzero(found < 0).tolist() if k not in own]
        if miss:
            self._head_rows_of(blk.lines, src, [hs[k] for k in miss], miss, found, own)
        if len(self._head_table) != len(self._head_rows):
            self._head_table = np.array(self._head_rows, dtype=np.int64)
        out = self._head_table[found]
        if own:
            out[np.fromiter(own, dtype=np.int64, count=len(own))] = np.fromiter(
                chain.from_iterable(own.values()), dtype=np.int64, count=3 * len(own)).reshape(-1, 3)
        return out

    def _head_rows_of(self, lines: list[str], src: np.ndarray, heads: list[str], rows: list[int],
                      found: np.ndarray, own: dict[int, tuple[int, int, int]]) -> None:
        """The keys of the run lines ``rows`` (of the heads ``heads``) whose heads were
        not met before, found line by line (their N words all parsed at once): into ``own``
        those of an N word (and what follows it) or of the line itself; a head without an
        N word added to those looked up by head (:meth:`_run_keys`), its row into ``found``."""
        keys, ids, rests = self.keys, self._head_ids, self._rest_skeletons
        # (a match a head: no head holds a line feed)
        for k, (n_word, rest), h in zip(rows, _HEADS_N("\n".join(heads)), heads, strict=True):
            if n_word:
                skel = rests.get(rest)
                if skel is None:
                    skel = rests[rest] = skeleton(rest)
                nk = int(n_word[1:]) + 1
                own[k] = (keys(n_word + skel) if skel else nk, nk, 0)
                continue
            if "N" in h or "n" in h:
                own[k] = keys.of_line(lines[int(src[k])])
                continue
            got = ids.get(h)
            if got is None:
                got = ids[h] = len(self._head_rows)
                self._head_rows.append(keys.of_line(h))
            found[k] = got


class _Reader:
    """One program read in chunks of :class:`_Rows` by the lane's reader (:class:`_LineRows`);
    an error of a line comes after the rows of the lines before it."""

    def __init__(self, source, setup: Setup, keys: _Keys, options: _ReadOptions = _ReadOptions()) -> None:
        self.path, self._lines = iter_source_lines(source)
        self.interp = Interpreter(setup, self.path, lenient_setup=True, dialect=options.dialect)
        self.limits = options.limits or Limits()
        self.interp.max_arc_turns = self.limits.max_arc_turns
        self.options = options
        self.variables = getattr(setup, "variables", None)  # --var: machine state the program reads
        self.header: list[str] = []
        self.count = 0  # lines read, header lines left out
        self._keys = keys
        self._rd = _LineRows(self.interp, keys, options.cycle_retract, self.path)

    @property
    def keys(self) -> _Keys:
        return self._keys

    @keys.setter
    def keys(self, keys: _Keys) -> None:  # (a reader in a child process: its own keys)
        self._keys = self._rd.keys = keys

    def chunks(self):
        """Yield :class:`_Rows`; an error of a line comes after the rows before it."""
        if self.path is None:
            yield from self._chunks(self._lines)
            return
        self._lines.close()  # (a file's, not started)
        with open_source(self.path) as fh:  # its lines taken from the file, a chunk at a time, each bounded
            yield from self._chunks(Lines(read_blocks(fh, self.path)))

    def _chunks(self, it: Lines):
        """:meth:`chunks` of the lines of ``it``."""
        rd = self._rd
        if self.options.drop_header:
            # the header lines after the lines kept before them (emit.header_run) are left out
            kept, header, after = emit.header_run(it)
            self.header += [line.strip() for line in header]
            head = kept if after is None else [*kept, after]

            def read_head() -> None:
                for k, line in enumerate(head):
                    if k == len(kept):
                        rd.lineno += len(header)  # numbered as in the file, not counted
                        self.count -= len(header)
                    rd.line(line)

            yield from self._read(read_head)
        if self.options.expand:
            yield from self._expanded_chunks(it)
            return
        for lines in iter(partial(it.take, CHUNK_LINES), []):
            yield from self._read(partial(self._blocks, lines))

    def _blocks(self, lines: list[str]) -> None:
        """Read a chunk's lines, :data:`BLOCK_LINES` at a time."""
        for k in range(0, len(lines), BLOCK_LINES):
            self._rd.block(lines[k:k + BLOCK_LINES])

    def _expanded_chunks(self, lines: Iterator[str]):
        """:meth:`chunks` of the program as executed (:func:`postproc.gcode.expand.expand`)."""
        from postproc.gcode.expand import expand

        opt = self.options
        flat = expand(list(lines), path=self.path, dialect=opt.dialect, subroutine_path=opt.subroutine_path,
                      variables=self.variables, max_iterations=self.limits.max_iterations)
        rd = self._rd
        source: deque[tuple[int, str | None]] = deque()
        rd.expanded(source, in_bulk=True)
        for part in iter(lambda: list(islice(flat, CHUNK_LINES)), []):
            source.extend((sl.lineno, sl.path) for sl in part)
            yield from self._read(partial(rd.block, [sl.text for sl in part]))
            source.clear()

    def _read(self, read: Callable[[], None]):
        """Read a chunk (``read``): yield its rows, then raise the error that stopped it, if any."""
        rd = self._rd
        first = rd.lineno
        try:
            read()
            error = None
        except PostprocError as exc:
            error = exc
        self.count += rd.lineno - first
        yield rd.rows()
        if error is not None:
            raise error


class _ForkedReader:
    """A :class:`_Reader` run in a child process (forked): the same chunks, header, count
    and errors, the chunks' keys mapped to this process's :class:`_Keys`. The child reads
    ahead as far as the pipe between them holds (a chunk), so memory stays bounded."""

    def __init__(self, reader: _Reader, keys: _Keys) -> None:
        self._reader = reader
        self.keys = keys
        self.path = reader.path
        self.header: list[str] = []
        self.count = 0

    @staticmethod
    def usable(reader: _Reader) -> bool:
        """Whether ``reader``'s program is a file large enough to be read so, on a system
        that forks, from a process that may have children (not a daemon, as a
        ``multiprocessing.Pool`` worker is)."""
        if not forking.available():
            return False
        path = reader.path
        try:
            return path is not None and os.path.getsize(path) >= FORK_MIN_BYTES
        except OSError:
            return False  # the reader names the file it cannot read

    def chunks(self):
        """Yield :class:`_Rows` as :meth:`_Reader.chunks` does, read by the child."""
        ctx = multiprocessing.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        child = ctx.Process(target=_read_in_child, args=(self._reader, send), daemon=True)
        forking.start(child)
        send.close()
        glob = np.zeros(0, dtype=np.int64)  # the child's key -1 - j is this process's glob[j]
        try:
            while True:
                try:
                    kind, payload, new_keys, self.count, header = recv.recv()
                except EOFError:
                    raise RuntimeError(f"the process reading {self.path} ended without a word") from None
                self.header[:] = header
                if new_keys:
                    glob = np.concatenate([glob, np.array([self.keys(t) for t in new_keys], dtype=np.int64)])
                if kind == "rows":
                    lines, lineno, move, end, keys, files = payload
                    if isinstance(lines, str):  # the lines joined (see _read_in_child)
                        lines = lines.splitlines(keepends=True)
                    neg = keys < 0
                    if neg.any():
                        keys[neg] = glob[-1 - keys[neg]]
                    yield _Rows(lines, lineno, move, end, keys, files)
                elif kind == "end":
                    return
                else:  # "error": the reader's own error (after its rows), or a failure
                    raise payload
        finally:
            recv.close()
            if child.is_alive():
                child.terminate()
            child.join()


# The characters str.splitlines splits at besides "\n", "\r" and "\r\n".
_SPLITS_ELSE = re.compile("[\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")


def _read_in_child(reader: _Reader, conn) -> None:
    """The child's side of :class:`_ForkedReader`: send each chunk's rows, with the key
    texts it added, the lines read and the header, then the end or the error."""
    forking.in_child()
    keys = reader.keys = _Keys()
    texts = keys.texts = []  # the key texts in the order of their keys (-1, -2, ...)
    sent = 0

    def new_keys() -> list[str]:
        nonlocal sent
        new = texts[sent:]
        sent = len(texts)
        return new

    try:
        for rows in reader.chunks():
            # the lines as one text where str.splitlines gives them back as they are (a lone
            # "\r" or another character it splits at inside a line: the list itself)
            text = "".join(rows.lines)
            lines: str | list[str] = text
            if _SPLITS_ELSE.search(text) or ("\r" in text and text.count("\r") != text.count("\r\n")):
                lines = rows.lines
            conn.send(("rows", (lines, rows.lineno, rows.move, rows.end, rows.keys, rows.files), new_keys(),
                       reader.count, reader.header))
        conn.send(("end", None, new_keys(), reader.count, reader.header))
    except BaseException as exc:  # noqa: BLE001 - every failure is the parent's to raise
        try:
            conn.send(("error", exc, new_keys(), reader.count, reader.header))
        except Exception:  # noqa: BLE001 - an exception that does not pickle
            conn.send(("error", RuntimeError(f"reading {reader.path} failed: {exc!r}"), [],
                       reader.count, reader.header))
    finally:
        conn.close()


class _Index:
    """Where the pairing keys lie in a tape's rows: for each column (skeleton, N word,
    comment) the rows in the order of their keys (equal keys in row order) and each row's
    next row of the same key, and the anchors. With it, the rows of one key that follow a
    place are found without looking at the others: a line whose N word is its own is
    paired without reading every line up to the next anchor."""

    __slots__ = ("order", "sorted", "next_same", "anchors")

    def __init__(self, rows: _Rows) -> None:
        n = len(rows)
        self.order, self.sorted, self.next_same = [], [], []
        for col in range(3):
            keys = rows.keys[:, col]
            order = np.argsort(keys, kind="stable").astype(np.int32)
            ordered = keys[order]
            self.order.append(order)
            self.sorted.append(ordered)
            if col < 2:  # (the comments' next rows are not asked for)
                nxt = np.full(n, n, dtype=np.int32)
                same = ordered[1:] == ordered[:-1]
                nxt[order[:-1][same]] = order[1:][same]
                self.next_same.append(nxt)
        self.anchors = np.flatnonzero(~rows.move)

    def next_anchor(self, i: int, n: int) -> int:
        """The first anchor at or after row i (n: none)."""
        k = int(np.searchsorted(self.anchors, i))
        return int(self.anchors[k]) if k < len(self.anchors) else n

    def rows_of(self, col: int, key: int, lo: int, hi: int) -> np.ndarray:
        """The rows in lo:hi whose key in column col is key, in order."""
        ordered = self.sorted[col]
        group = self.order[col][np.searchsorted(ordered, key, "left"):np.searchsorted(ordered, key, "right")]
        return group[np.searchsorted(group, lo):np.searchsorted(group, hi)]


class _Tape:
    """The records of one program not yet paired, read ahead as needed."""

    def __init__(self, chunks) -> None:
        self._chunks = chunks
        self.rows = _Rows.blank([], 1)
        self.pos = 0
        self.done = False  # nothing more to read: the end of the program, or an error
        self.error: PostprocError | None = None

    def avail(self) -> int:
        return len(self.rows) - self.pos

    def fill(self, need: int) -> None:
        """Read on until ``need`` records are available (or nothing more can be read)."""
        if self.avail() >= need or self.done:
            return
        parts = [self.rows.tail(self.pos)]
        have = len(parts[0])
        while have < need:
            try:
                part = next(self._chunks)
            except StopIteration:
                self.done = True
                break
            except PostprocError as exc:
                self.done, self.error = True, exc
                break
            parts.append(part)
            have += len(part)
        self.rows = _Rows.join(parts)
        self.pos = 0

    def reach_anchor(self, i: int) -> None:
        """Read on until a record at or after the i-th ahead is an anchor (or nothing
        more can be read), the whole program at most; more at a time as it goes on."""
        while not self.done and self.rows.move[self.pos + i:].all():
            self.fill(2 * self.avail() + CHUNK_LINES)

    def peek(self, i: int) -> int | None:
        """Row index of the i-th record ahead, None at the end of the program."""
        if self.avail() <= i:
            self.fill(max(i + 1, CHUNK_LINES // 2))
            if self.avail() <= i:
                if self.error is not None:
                    raise self.error
                return None
        return self.pos + i


# -- pairing ---------------------------------------------------------------------------


def _distance(a, b) -> float:
    return sum(abs(x - y) for x, y in zip(a, b, strict=True) if not (math.isnan(x) or math.isnan(y)))


def _l1(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`_distance` row by row (same sums, in the same order)."""
    d = np.abs(a - b)
    s = d[:, 0] + d[:, 1] + d[:, 2]
    nan = np.isnan(s)
    if nan.any():
        s[nan] = np.nansum(d[nan], axis=1)
    return s


def _pair_chunk(orig: _Tape, corr: _Tape, rep: DiffReport, last_delta: tuple,
                limit: int) -> tuple[int, bool, tuple]:
    """Pair up to ``limit`` records of orig with the lines of corr (see the module docstring).

    The k-th anchor of orig goes with the k-th of corr. Between two anchors, when both
    programs have as many moves, each move pairs with the line at the same place (of a
    compatible skeleton). Where corr has more lines (inserted ones), the moves before the
    first insertion pair at the place after the previous anchor, those after it one line
    further, and so on: each checked at once against the nearest-end-point rule of
    :func:`_pair_one`, which pairs the move at each insertion. The rest of the window after
    its last anchor waits for the next window (unless the window has no anchor, or both
    programs end in it). Returns (records paired, whether a check failed at the next
    one, the last move's delta).
    """
    m = min(orig.avail(), limit)
    want = m + m // 2 + SCAN_AHEAD
    if (m and not corr.done and corr.rows.move[corr.pos:corr.pos + want].all()
            and orig.rows.keys[orig.pos:orig.pos + m].any()):
        # no anchor in the window, and moves with N words, skeletons or comments: their
        # scans run to corr's next anchor (or its end), which is read now
        corr.reach_anchor(want)
    span = min(corr.avail(), want)
    if m == 0 or span == 0:
        return 0, True, last_delta
    window = _Window(orig, corr, rep, last_delta, m, span)
    f, held = window.check()
    return window.pair(f, held)


class _Level(NamedTuple):
    """Records of a window each placed at a line of corr: whether the place is checked
    (for a level of :meth:`_Window.check`: by the nearest-end-point rule), whether the
    line is identical to the record's, the place (a line from corr.pos) and the delta."""

    ok: np.ndarray
    same: np.ndarray
    t: np.ndarray
    delta: np.ndarray


class _Window:
    """The records of orig paired at once by :func:`_pair_chunk` (m of them, from orig.pos)
    and the lines of corr they may pair with (span of them from corr.pos; ext, up to
    corr's next anchor past the window when it has none in it), as columns the steps
    share: :meth:`check`, then :meth:`pair`."""

    def __init__(self, orig: _Tape, corr: _Tape, rep: DiffReport, last_delta: tuple, m: int, span: int) -> None:
        self.orig, self.corr, self.rep = orig, corr, rep
        self.last_delta = last_delta  # the delta of the move before the window
        self.m, self.span = m, span
        p, q = self.p, self.q = orig.pos, corr.pos
        ro, rc = self.ro, self.rc = orig.rows, corr.rows
        avail = corr.avail()
        real_end = self.real_end = span == avail and corr.done and corr.error is None
        om = self.om = ro.move[p:p + m]
        cmove = self.cmove = rc.move[q:q + span]
        # the scans of the nearest-end-point rule look at corr up to its next anchor: past
        # the window when there is none in it (ext lines from q)
        ext = span
        if not real_end and cmove.all():
            later = np.flatnonzero(~rc.move[q + span:q + avail])
            ext = span + int(later[0]) + 1 if len(later) else avail
        self.ext = ext
        self.real_end_x = ext == avail and corr.done and corr.error is None
        self._stretches()
        self.oe = ro.end[p:p + m]
        self.cend = np.append(rc.end[q:q + ext], np.zeros((1, 3)), axis=0)
        self.ckeys = rc.keys[q:q + ext]
        cmove_x = self.cmove_x = rc.move[q:q + ext]
        self.stop = np.append(_next_index(~cmove_x), ext)
        self.prev = np.concatenate([[-1], _last_index(om)[:-1]])  # previous move of each record

    def _stretches(self) -> None:
        """The anchors, the k-th of each as long as they are identical, and the stretches
        they end (stretch j ends with the j-th anchor; stretch k: the rest of the window)."""
        ao = np.flatnonzero(~self.om)
        ac = np.flatnonzero(~self.cmove)
        k = min(len(ao), len(ac))
        if k:
            equal = np.fromiter(map(operator.eq, map(self.ro.lines.__getitem__, (ao[:k] + self.p).tolist()),
                                    map(self.rc.lines.__getitem__, (ac[:k] + self.q).tolist())),
                                dtype=bool, count=k)
            k = k if equal.all() else int(np.argmin(equal))
        self.k = k
        ao, ac = self.ao, self.ac = ao[:k], ac[:k]
        start_o = self.start_o = np.concatenate([[0], ao + 1])
        off_start = self.off_start = np.concatenate([[0], ac + 1]) - start_o
        off_end = self.off_end = ac - ao
        more = self.more = off_end - off_start[:-1]
        self.inserted = np.append(more > 0, False)  # stretches with lines inserted
        seg = self.seg = np.searchsorted(ao, np.arange(self.m))
        self.split = self.inserted[seg]

    def place(self, t: np.ndarray, rows: np.ndarray | None = None) -> tuple:
        """Lines of corr at places t (of records rows): in the window, identical, delta."""
        span, ro, p = self.span, self.ro, self.p
        inside = t < span
        tc = np.minimum(t, span - 1)
        olines = ro.lines[p:p + self.m] if rows is None else map(ro.lines.__getitem__, (rows + p).tolist())
        same = np.fromiter(map(operator.eq, olines, map(self.rc.lines.__getitem__, (tc + self.q).tolist())),
                           dtype=bool, count=len(t))
        o = self.oe if rows is None else self.oe[rows]
        ce = self.cend[tc]
        return inside, tc, same, np.where(np.isnan(ce) | np.isnan(o), 0.0, ce - o)

    def nearest(self, rows: np.ndarray, t0: np.ndarray, ld: np.ndarray) -> np.ndarray:
        """Whether the scan of each move (records rows, own line t0, previous delta ld)
        picks its own line: it looks at the lines after it up to the next anchor (or the
        end of the program; not an error not yet reached) and stops after
        STOP_AFTER_WORSE compatible ones that are not nearer than the best."""
        ext, cend, ckeys = self.ext, self.cend, self.ckeys
        end_at = self.stop[t0 + 1]
        real_stop = (end_at < ext) | self.real_end_x
        predicted = self.oe[rows] + ld
        okeys = self.ro.keys[self.p + rows]
        own = ckeys[t0]
        good = np.zeros(len(rows), dtype=bool)
        plain = ~okeys.any(axis=1)
        a = np.flatnonzero(plain)
        if len(a):
            # no N word, skeleton or comment: compatible with the moves of empty skeleton;
            # its own line must be one, and the nearest of the first few after it
            ta, ea, pa = t0[a], end_at[a], predicted[a]
            z = np.flatnonzero(self.cmove_x & (ckeys[:, 0] == 0))
            i = np.searchsorted(z, ta)
            z = np.append(z, [ext] * (STOP_AFTER_WORSE + 1))
            d0 = _l1(cend[ta], pa)
            nearer = np.zeros(len(a), dtype=bool)
            looked = np.zeros(len(a), dtype=np.int64)
            for j in range(1, STOP_AFTER_WORSE + 1):
                c = z[i + j]
                scanned = c < ea
                nearer |= scanned & (_l1(cend[c], pa) < d0)
                looked += scanned
            good[a] = (own[a, 0] == 0) & ~nearer & ((looked == STOP_AFTER_WORSE) | real_stop[a]) & (d0 <= PLAUSIBLE_MM)
        b = np.flatnonzero(~plain)
        if len(b):
            # an N word or another skeleton (and no comment): its own line when the later
            # lines before the anchor with its skeleton or N word (one of each at most, a
            # program that numbers its blocks again) are not nearer
            q = self.q
            tb, eb, ob, cb = t0[b], end_at[b], okeys[b], own[b]
            pb = predicted[b]
            nxt = self.rc.index().next_same
            ok_b = real_stop[b] & (ob[:, 2] == 0) & (ob[:, 0] == cb[:, 0]) & ((ob[:, 1] == 0) | (ob[:, 1] == cb[:, 1]))
            d_own = _l1(cend[tb], pb)
            for col, named in ((0, ok_b), (1, ok_b & (ob[:, 1] != 0))):
                after = nxt[col][q + tb] - q
                r = np.flatnonzero(named & (after < eb))
                if len(r):
                    second = nxt[col][q + after[r]] - q
                    ok_b[r] &= (second >= eb[r]) & (_l1(cend[after[r]], pb[r]) >= d_own[r])
            good[b] = ok_b & (d_own <= PLAUSIBLE_MM)
        return good

    def previous(self, rows: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """The delta of each record's previous move (before the window: its last one)."""
        pr = self.prev[rows]
        return np.where(pr[:, None] >= 0, delta[np.maximum(pr, 0)], np.asarray(self.last_delta, dtype=float))

    def check(self) -> tuple[int, int]:
        """Place every record and check the places: (the first record whose place does
        not hold, m if all do; the records before the rest of the window that waits for
        the next one)."""
        m, k, seg, split, om, cmove, more = self.m, self.k, self.seg, self.split, self.om, self.cmove, self.more
        # the line of corr at each record's place: after the previous anchor, or (in a stretch
        # with inserted lines) before the next one
        t = np.arange(m) + np.where(split, np.append(self.off_end, 0)[seg], self.off_start[seg])
        inside, tc, same, delta = self.place(t)
        tail = seg == k
        # (a stretch with fewer lines in corr: paired one at a time, which reports it)
        ok = np.append(more >= 0, True)[seg] & (~tail | (inside & np.where(om, cmove[tc], ~cmove[tc] & same)))
        # the rest of the window is a stretch too when both programs end in it
        orig = self.orig
        ends = self.real_end and orig.done and orig.error is None and m == orig.avail()
        last = int(self.start_o[k])
        direct = np.append(more == 0, ends and m - last == self.span - last - int(self.off_start[k]))[seg]
        rows = np.flatnonzero(om & ok & direct)
        if len(rows):
            # as many moves in both: each pairs with the line at its place, of the same skeleton
            # (or N word, or comment)
            o3, c3 = self.ro.keys[self.p + rows], self.rc.keys[self.q + t[rows]]
            both_n = (o3[:, 1] != 0) & (c3[:, 1] != 0)
            ok[rows] = ((o3[:, 0] == c3[:, 0]) | (both_n & (o3[:, 1] == c3[:, 1]))
                        | (~both_n & (o3[:, 2] != 0) & (o3[:, 2] == c3[:, 2])))
        held = m
        if k and not ends:
            held = last  # the rest of the window: with the next window, where its anchor is
        else:
            rows = np.flatnonzero(om & ok & ~direct & ~split)
            if len(rows):  # no anchor in the window: the nearest-end-point rule, checked
                ok[rows] = self.nearest(rows, t[rows], self.previous(rows, delta))
        self.placed = _Level(ok, same, t, delta)
        self.levels = self._levels(delta) if split.any() else []
        bad = np.flatnonzero(~(ok | split))
        return min(int(bad[0]) if len(bad) else m, held), held

    def _levels(self, delta: np.ndarray) -> list[_Level]:
        """In a stretch with lines inserted, the moves between the e-th and the next
        insertion pair at the place after the previous anchor plus e: the places of level
        e for every e at once, each checked by the nearest-end-point rule."""
        m, seg, split, om, off_start, prev = self.m, self.seg, self.split, self.om, self.off_start, self.prev
        n_ins = np.append(self.more, 0)
        levels = []
        for e in range(min(int(n_ins.max()), MAX_LEVELS) + 1):
            rows_e = np.flatnonzero(split & om & (n_ins[seg] >= e))
            t_e = rows_e + off_start[seg[rows_e]] + e
            _in, _tc, same_e, d_e = self.place(t_e, rows_e)
            full = np.zeros((m, 3))
            full[rows_e] = d_e
            pr = np.maximum(prev[rows_e], 0)
            within = ((prev[rows_e] >= 0) & (seg[pr] == seg[rows_e]))[:, None]
            ok_e = np.zeros(m, dtype=bool)
            ok_e[rows_e] = self.nearest(rows_e, t_e, np.where(within, full[pr], self.previous(rows_e, delta)))
            same_full = np.zeros(m, dtype=bool)
            same_full[rows_e] = same_e
            levels.append(_Level(ok_e, same_full, np.arange(m) + np.append(off_start[:-1], 0)[seg] + e, full))
        return levels

    def take(self, r0: int, r1: int, last_delta: tuple, at: _Level) -> tuple:
        """Count the records r0:r1, each paired with the line at its place ``at``; returns
        the last move's delta."""
        rep = self.rep
        moves = self.om[r0:r1]
        n_moves = int(np.count_nonzero(moves))
        unchanged = int(np.count_nonzero(moves & at.same[r0:r1]))
        rep.moves += n_moves
        rep.moves_unchanged += unchanged
        rep.lines_unchanged += r1 - r0 - n_moves + unchanged
        moved = np.flatnonzero(moves & ~at.same[r0:r1]) + r0
        if len(moved):
            rep.add_moved_rows(self.ro.lineno[self.p + moved], self.rc.lineno[self.q + at.t[moved]], at.delta[moved],
                               pick(self.ro.files, self.p + moved))
        if n_moves:
            last_delta = tuple(at.delta[r0 + int(np.flatnonzero(moves)[-1])].tolist())
        return last_delta

    def pair(self, f: int, held: int) -> tuple[int, bool, tuple]:
        """Pair the records checked (:meth:`check`: the first f, in a stretch with lines
        inserted the moves at each insertion one at a time, by :func:`_pair_one`) and move
        both tapes past them: (records paired, whether a check failed at the next one, the
        last move's delta)."""
        orig, corr, p, q, m = self.orig, self.corr, self.p, self.q, self.m
        placed, levels = self.placed, self.levels
        last_delta = self.last_delta
        done = 0
        for j in np.flatnonzero(self.inserted).tolist():
            s0, a0 = int(self.start_o[j]), int(self.ao[j])
            if s0 >= f:
                break
            last_delta = self.take(done, s0, last_delta, placed)
            r, e = s0, 0
            while True:
                at = levels[e]
                # the next insertion: at the first move not paired at this place
                x = r + int(np.argmin(at.ok[r:a0])) if not at.ok[r:a0].all() else a0
                last_delta = self.take(r, x, last_delta, at)
                orig.pos, corr.pos = p + x, q + int(at.t[x])
                last_delta = _pair_one(orig, corr, self.rep, last_delta)
                done = x + 1
                if not (orig.rows is self.ro and corr.rows is self.rc):
                    return done, False, last_delta
                if x == a0:
                    break
                e = corr.pos - q - 1 - x - int(self.off_start[j])
                if not (0 <= e < len(levels) and last_delta == tuple(levels[e].delta[x].tolist())):
                    return done, False, last_delta  # paired otherwise than assumed: look again from here
                r = x + 1
            if corr.pos != q + self.ac[j] + 1 or (a0 > s0 and last_delta != tuple(placed.delta[a0 - 1].tolist())):
                return done, False, last_delta  # the next stretch was checked with another delta
        f = max(f, done)
        last_delta = self.take(done, f, last_delta, placed)
        orig.pos = p + f
        corr.pos = q + (int(placed.t[f]) if f < m else m + int(self.off_start[self.k]))
        return f, f < held, last_delta


# Lines of corr the pairing of one record looks at one by one before it looks up the
# compatible lines by their keys.
SCAN_NEAR = 64
# When the nearest line is a later one than the move's own place and less than this
# many times nearer than it, the next records are aligned to choose (_align_ahead).
AMBIGUOUS = 16.0
# End points nearer each other than this (the output's rounding, a few times over) are
# not told apart by their distances alone.
RESOLUTION_MM = 1e-3
# Records aligned at once, and lines of corr beyond those they need at the least.
ALIGN_RECORDS = 8
ALIGN_SLACK = 16


def _pick(dists) -> tuple[tuple | None, tuple | None, int | None]:
    """The nearest-end-point rule over the distances of the compatible moves in order (an
    iterable, consumed only as far as the rule looks): the nearest and the nearest before
    it (the one it displaced; None when it is the first), each as (distance, index), and
    the index where the rule stopped (None: it ran to the end of ``dists``). Past the
    nearest line the end points walk away again (the next move's inserted lines): it
    stops after STOP_AFTER_WORSE that do not come closer."""
    best = runner = None
    worse = 0
    for j, dist in enumerate(dists):
        if best is None or dist < best[0]:
            runner, best = best, (dist, j)
            worse = 0
        else:
            worse += 1
            if worse >= STOP_AFTER_WORSE and (best[0] <= PLAUSIBLE_MM or j >= FAR_SCAN):
                return best, runner, j
    return best, runner, None


def _scan_near(corr: _Tape, o_keys: tuple, predicted: tuple, skip: int) -> tuple[bool, tuple | None, tuple | None]:
    """The scan of :func:`_pair_one` over the lines of corr read, from ``skip`` lines
    after corr.pos, SCAN_NEAR of them at most: whether these lines settle it, the nearest
    compatible move and the nearest before it (:func:`_pick`), each as (distance, offset
    from corr.pos), or None (none before the next anchor)."""
    rc = corr.rows
    c0 = corr.pos
    n = min(len(rc), c0 + skip + SCAN_NEAR)
    move, keys, end = rc.move, rc.keys, rc.end
    offsets: list[int] = []
    anchor = [False]

    def dists():
        for c in range(c0 + skip, n):
            if not move[c]:
                anchor[0] = True  # the next anchor: the pair lies before it
                return
            if _compatible_keys(o_keys, tuple(keys[c].tolist())):
                offsets.append(c - c0)
                yield _distance(end[c].tolist(), predicted)

    best, runner, stopped = _pick(dists())
    if stopped is None and not anchor[0]:
        return False, None, None

    def at(found: tuple | None) -> tuple | None:
        return None if found is None else (found[0], offsets[found[1]])

    return True, at(best), at(runner)


def _scan(corr: _Tape, o_keys: tuple, predicted: tuple, skip: int) -> tuple[tuple | None, tuple | None]:
    """:func:`_scan_near` over every line of corr up to its next anchor (or its end): the
    compatible moves are looked up by their keys (:class:`_Index`), more of them at a time
    until the rule stops among those known, and corr is read on only as far as that needs.
    Returns the nearest compatible move and the nearest before it (or None, None); raises
    the error that ended corr's reading when the scan reaches it."""
    o0, o1, o2 = o_keys
    take = 4 * (STOP_AFTER_WORSE + 1)
    while True:
        rc, c0 = corr.rows, corr.pos
        n = len(rc)
        idx = rc.index()
        a = idx.next_anchor(c0 + skip, n)
        lists = [idx.rows_of(0, o0, c0 + skip, a)]
        if o1:
            lists.append(idx.rows_of(1, o1, c0 + skip, a))
        if o2:
            lists.append(idx.rows_of(2, o2, c0 + skip, a))
        while True:
            # the first `take` rows of each key; every compatible row up to `known` is among them
            known = min((int(rows[take - 1]) for rows in lists if len(rows) > take), default=a)
            cand = np.unique(np.concatenate([rows[:take] for rows in lists]))
            keys = rc.keys[cand]
            both_n = (o1 != 0) & (keys[:, 1] != 0)
            cand = cand[(keys[:, 0] == o0) | np.where(both_n, keys[:, 1] == o1, (o2 != 0) & (keys[:, 2] == o2))]
            best, runner, stop_j = _pick(_l1(rc.end[cand], np.array(predicted)).tolist())
            stopped = None if stop_j is None else int(cand[stop_j])
            if stopped is not None and stopped <= known:
                break
            if known == a:
                if a == n and not corr.done:
                    best = None  # the scan runs past the lines read: read on, look again
                break
            take *= 4
        if stopped is not None or a < n or corr.done:
            if stopped is None and a == n and corr.error is not None:
                raise corr.error
            if best is None:
                return None, None
            return (best[0], int(cand[best[1]]) - c0), None if runner is None else (runner[0], int(cand[runner[1]]) - c0)
        corr.fill(2 * corr.avail() + CHUNK_LINES)


def _nearest(corr: _Tape, o_keys: tuple, predicted: tuple, skip: int = 0) -> tuple[tuple | None, tuple | None]:
    """The compatible move of corr nearest ``predicted`` from ``skip`` lines after corr.pos
    up to the next anchor, and the nearest one before it: (distance, offset from corr.pos)
    each, or None."""
    settled, best, runner = _scan_near(corr, o_keys, predicted, skip)
    if not settled:
        best, runner = _scan(corr, o_keys, predicted, skip)
    return best, runner


def _align_ahead(orig: _Tape, corr: _Tape, o_end: list, o_keys: tuple, last_delta: tuple, best: tuple) -> tuple:
    """The line to pair the current move with when the nearest one is not much nearer
    than the nearest before it: the first line of the alignment of the next records (up to
    ALIGN_RECORDS, none past an anchor) with the lines of corr (the current ones, up to
    the next anchor) in which the delta changes least from one move to the next, lines
    left out being inserted ones. A run of moves shorter than the change of the correction
    over one long move would otherwise each be paired with the next one's line."""
    orig.fill(ALIGN_RECORDS)
    ro, pos = orig.rows, orig.pos
    ends, keys = [o_end], [o_keys]
    for r in range(pos, min(len(ro), pos + ALIGN_RECORDS - 1)):
        if not ro.move[r]:
            break
        ends.append(ro.end[r].tolist())
        keys.append(tuple(ro.keys[r].tolist()))
    width = best[1] + 1 + len(ends) + ALIGN_SLACK
    corr.fill(width)
    rc, c0 = corr.rows, corr.pos
    a = rc.index().next_anchor(c0, len(rc))
    width = min(width, a - c0)
    c_end = rc.end[c0:c0 + width]
    c_keys = rc.keys[c0:c0 + width]
    cost = None
    choice = []
    prev_delta = np.asarray(last_delta, dtype=float)[None, :]
    for end, key in zip(ends, keys, strict=True):
        ok = np.fromiter((_compatible_keys(key, tuple(k)) for k in c_keys.tolist()), dtype=bool, count=width)
        e = np.asarray(end, dtype=float)
        delta = np.where(np.isnan(c_end) | np.isnan(e), 0.0, c_end - e)
        step = np.abs(delta[:, None, :] - prev_delta[None, :, :]).sum(axis=2)  # (line, previous line)
        if cost is None:
            new = step[:, 0]
            came = np.zeros(width, dtype=np.int64)
        else:
            # the previous record on an earlier line
            total = cost[None, :] + step
            total[np.triu_indices(width)] = np.inf
            came = np.argmin(total, axis=1)
            new = total[np.arange(width), came]
        new = np.where(ok, new, np.inf)
        if not np.isfinite(new).any():
            break
        cost = new
        choice.append(came)
        prev_delta = delta
    assert cost is not None  # (the nearest line itself is a path)
    j = int(np.argmin(cost))
    for came in choice[:0:-1]:
        j = int(came[j])
    return (best[0], j)


def _pair_one(orig: _Tape, corr: _Tape, rep: DiffReport, last_delta: tuple) -> tuple:
    """Pair the next record of orig: an anchor with the next anchor of corr (the moves before it
    were inserted); a move with the compatible move of corr, before corr's next anchor, whose end
    point is nearest its own plus the previous move's delta. Returns the last move's delta."""
    ro = orig.rows
    o = orig.pos
    orig.pos += 1
    o_lineno = int(ro.lineno[o])
    rc = corr.rows
    if not ro.move[o]:
        # an anchor: every corrected move before it was inserted
        while True:
            c = corr.peek(0)
            if c is None:
                raise PostprocError(f"{ro.place(o, 'the original')} is missing from the corrected program",
                                    path=rep.corrected, hint="is this the corrected version of that program?")
            rc = corr.rows
            corr.pos += 1
            if not rc.move[c]:
                if rc.lines[c] != ro.lines[o]:
                    if _rewritten_g92(ro.lines[o], rc.lines[c]):
                        rep.lines_rewritten += 1
                        return last_delta
                    c_lineno = int(rc.lineno[c])
                    raise PostprocError(
                        f"line {c_lineno} of the corrected program differs from {ro.place(o, 'the original')}",
                        path=rep.corrected, lineno=c_lineno,
                        hint="lines that are not moves must be identical: is this its corrected version?")
                rep.lines_unchanged += 1
                return last_delta
            rep.lines_inserted += 1
    o_end = ro.end[o].tolist()
    o_keys = tuple(ro.keys[o].tolist())
    o_line = ro.lines[o]
    predicted = tuple(e + d for e, d in zip(o_end, last_delta, strict=True))
    best, runner = _nearest(corr, o_keys, predicted)
    if best is not None and runner is not None and runner[0] <= AMBIGUOUS * best[0] + RESOLUTION_MM:
        # lines skipped as inserted, the nearest one not much nearer than an earlier one
        best = _align_ahead(orig, corr, o_end, o_keys, last_delta, best)
    if best is None:
        raise PostprocError(f"move on {ro.place(o, 'the original')} has no counterpart in the corrected program",
                            path=rep.corrected)
    rc = corr.rows
    rep.lines_inserted += best[1]
    c = corr.pos + best[1]
    corr.pos = c + 1
    c_end = rc.end[c].tolist()
    rep.moves += 1
    delta = tuple(0.0 if (math.isnan(x) or math.isnan(y)) else x - y for x, y in zip(c_end, o_end, strict=True))
    if rc.lines[c] == o_line:
        rep.moves_unchanged += 1
        rep.lines_unchanged += 1
    else:
        rep.add_moved(o_lineno, int(rc.lineno[c]), delta, file_of(ro.files, o, None))
    return delta


def compare_programs(original, corrected, setup: Setup | None = None, progress=None,
                     keep: int | None = None, options: CorrectOptions | None = None) -> DiffReport:
    """Pair the blocks of two programs and measure how far each move's end point moved.

    Streams both programs (memory does not grow with their length, apart from the
    compact list of moved blocks, 40 bytes each, 48 once one comes from a subprogram's
    file; with ``keep``, only the ``keep`` largest are kept and memory is bounded).
    ``setup`` gives work offsets and tool lengths
    (those not given count as zero); they matter only for G53 blocks, whose words
    are machine coordinates. ``progress(n)``, if given, is called with the number of
    lines of the original read so far, after each chunk. ``options`` are those
    ``correct`` was given, of which the ones that say how a program is read count: the
    dialect both are read in (G53 in G91, comments, ...), the subroutine path, the limits
    and the canned cycles' mode.

    When the corrected program's header says it was corrected expanded (subprograms,
    loops, macros written out), the original is read expanded the same way (its external
    subroutines looked up on the subroutine path); its blocks are then numbered by their
    source lines, a subprogram's line once per call, and a block whose line comes from
    another file than the original's (a subprogram's) is named with that file
    (:attr:`MovedBlock.file`). Each canned cycle block of both programs is read as the
    moves ``correct`` writes for it when it expands it (whatever
    ``--cycles`` was: with ``auto`` it keeps some and expands others), their G98/G99
    retracts kept unless the program was corrected with ``--cycles expand``: as its
    header records (``CYCLES EXPANDED``), or, when it has no header saying so (left out,
    or of the one-line form of earlier versions), as ``options.cycles`` says.
    """
    opt = options or CorrectOptions()
    reading = _ReadOptions(dialect=opt.dialect, subroutine_path=tuple(Path(p) for p in opt.subroutine_path),
                           limits=opt.limits, cycle_retract=opt.cycles != "expand")
    # Many small short-lived objects, none of them cyclic: the cyclic garbage collector
    # only costs time here (the chunks bound the memory).
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        return _compare(original, corrected, setup, progress, keep, reading)
    finally:
        if was_enabled:
            gc.enable()


def _compare(original, corrected, setup: Setup | None, progress, keep: int | None,
             reading: _ReadOptions) -> DiffReport:
    # what the program was corrected with, where the caller gives nothing: the start (axes
    # it never names start there), and the offsets and tool lengths that G53 blocks need
    hs = header_setup(corrected)
    setup = setup_from_header(hs, setup)
    keys = _Keys()
    if hs.cycles_recorded:
        reading = dataclasses.replace(reading, cycle_retract=not hs.cycles_expanded)
    readers = (_Reader(original, setup, keys, dataclasses.replace(reading, expand=hs.expanded)),
               _Reader(corrected, setup, keys, dataclasses.replace(reading, drop_header=True, subroutine_path=())))
    # a large original is read by a child process while this one reads the corrected program
    # and pairs; a second child for the corrected program gains no time on two cores and
    # costs a process's memory (their summed peak passed 150 MB on a 1M-line pair)
    o_reader = _ForkedReader(readers[0], keys) if _ForkedReader.usable(readers[0]) else readers[0]
    c_reader = readers[1]
    o_chunks, c_chunks = o_reader.chunks(), c_reader.chunks()
    try:
        orig, corr = _Tape(o_chunks), _Tape(c_chunks)
        rep = DiffReport(str(o_reader.path or "<text>"), str(c_reader.path or "<text>"), keep=keep,
                         expanded=hs.expanded)
        _pair_all(orig, corr, rep, o_reader, progress)
        _count_the_rest(corr, rep)
        if progress is not None:
            progress(o_reader.count)
    finally:  # a child reading the corrected program stops here, whatever happened
        o_chunks.close()
        c_chunks.close()
    rep.header = "\n".join(c_reader.header)
    rep.lines_original = o_reader.count
    rep.lines_corrected = c_reader.count
    return rep


def _pair_all(orig: _Tape, corr: _Tape, rep: DiffReport, o_reader: _Reader | _ForkedReader, progress) -> None:
    """Pair every record of orig: windows at once (:func:`_pair_chunk`), a few records
    one at a time (:func:`_pair_one`) after a window that stopped short."""
    last_delta = (0.0, 0.0, 0.0)
    slow = 0
    window = CHUNK_LINES
    shown = 0
    while True:
        orig.fill(1 if slow else CHUNK_LINES // 2)
        if not orig.avail():
            if orig.error is not None:
                raise orig.error
            break
        if progress is not None and o_reader.count >= shown + CHUNK_LINES:
            shown = o_reader.count
            progress(shown)
        if not slow:
            w = min(orig.avail(), window)
            corr.fill(w + w // 2 + SCAN_AHEAD + 1)
            n, failed, last_delta = _pair_chunk(orig, corr, rep, last_delta, window)
            if n and not failed:
                # a longer window next; about twice what was paired when that stopped short
                # of the window (more insertions in a stretch than MAX_LEVELS), so that the
                # levels are not checked over a long window for a few records each time
                window = min(CHUNK_LINES, 2 * window, max(MIN_WINDOW, 4 * n))
                continue
            # a record the rule pairs otherwise (a line inserted here): one at a time for a
            # while, then a window about as long as the stretch that was paired at once
            window = max(MIN_WINDOW, 2 * n)
            slow = SLOW_STRETCH
        last_delta = _pair_one(orig, corr, rep, last_delta)
        slow -= 1


def _count_the_rest(corr: _Tape, rep: DiffReport) -> None:
    """The lines of corr after the last record of orig: inserted moves (an anchor there
    has no counterpart)."""
    while True:
        c = corr.peek(0)
        if c is None:
            break
        corr.pos += 1
        if not corr.rows.move[c]:
            lineno = int(corr.rows.lineno[c])
            raise PostprocError(f"line {lineno} of the corrected program has no counterpart in the original",
                                path=rep.corrected, lineno=lineno)
        rep.lines_inserted += 1


_G92 = re.compile(r"[Gg][ \t]*0*92(?![.0-9])")


# axis words and blanks: what correct rewrites on a G92 line
_AXIS_WORDS = re.compile(r"[XYZABCxyzabc][ \t]*[+-]?(?:\d+\.?\d*|\.\d+)|\s+")


def _rewritten_g92(o_line: str, c_line: str) -> bool:
    """A G92 line whose axis words ``correct`` rewrote: it sets the current position, which
    the correction has moved, so that the program's coordinates after it stay nominal."""
    return bool(_G92.search(o_line.split("(")[0].split(";")[0])) and (
        _AXIS_WORDS.sub("", o_line) == _AXIS_WORDS.sub("", c_line))
