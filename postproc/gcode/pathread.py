"""A program read for its path: the lane's reader, and the moves it reads as samples.

:func:`read_program` reads a program (path or text) with a
:class:`postproc.gcode.reader.LineReader` (the interpreter line by line, runs of plain
lines in bulk), as ``correct`` and ``diff`` read it; a program that needs expanding
(parameters, O-words, subprograms, macros) is read again expanded, its runs in bulk too.

:class:`Sampler` is the reader of :func:`postproc.gcode.path.sample_program`: each move
of a line the interpreter reads is sampled as itself, each run of plain lines from the
run's columns (its targets, tool vector, line numbers and arcs) at once.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias, TypeVar

import numpy as np

from postproc.fileio import Lines
from postproc.gcode import bulk
from postproc.gcode.geometry import (
    ArcColumns,
    ArcParams,
    arc_chord_steps,
    arc_length,
    arc_params,
    arcs_points,
)
from postproc.gcode.interp import Interpreter, Move, NeedsExpansion, plain_moves, start_position
from postproc.gcode.moves import Arc
from postproc.gcode.options import CorrectOptions
from postproc.gcode.places import PathArray, file_of
from postproc.gcode.reader import LineReader
from postproc.gcode.state import PLANES, RAPID
from postproc.limits import Limits, ResourceLimitError

if TYPE_CHECKING:
    from postproc.gcode.source import ProgramPath, Setup

# Lines read into one block (the scanner's unit, and the sampler's between two takes).
BLOCK_LINES = 5_000

R = TypeVar("R", bound=LineReader)
Point: TypeAlias = tuple[float, float, float]


def _blocks(lines: Iterable, n: int) -> Iterator[list]:
    """``lines`` in lists of ``n``; an error while taking them (a line too long, an
    expansion refused) comes after the list of the lines before it."""
    if isinstance(lines, Lines):  # a program's lines, a block at a time
        return lines.lists(n)
    return _guarded_blocks(lines, n)


def _guarded_blocks(lines: Iterable, n: int) -> Iterator[list]:
    """:func:`_blocks` of lines taken one at a time (the expanded program's)."""
    failed: list[Exception] = []

    def guarded() -> Iterator:
        try:
            yield from lines
        except Exception as exc:  # noqa: BLE001  (raised after the lines before it are read)
            failed.append(exc)

    it = guarded()
    while part := list(islice(it, n)):
        yield part
    if failed:
        raise failed[0]


def read_program(source, setup: Setup, reader: Callable[[Interpreter, str | None], R], *, dialect: str = "generic",
                 subroutine_path=(), lenient_setup: bool = False, limits: Limits | None = None) -> R:
    """Read a program (path or text) with the reader ``reader(interp, path)`` makes: its
    lines a block at a time (:meth:`LineReader.block`); when the program needs expanding
    (:class:`postproc.gcode.interp.NeedsExpansion`), a new reader reads the expanded
    program instead, each line numbered (and its file named) as the line it comes from.
    Returns the reader that read it. ``limits``: the bounds on loops and helix turns
    (:class:`postproc.limits.Limits`, default its own)."""
    from postproc.gcode.source import iter_source_lines

    limits = limits or Limits()

    def interpreter() -> Interpreter:
        interp = Interpreter(setup, path, dialect=dialect, lenient_setup=lenient_setup)
        interp.max_arc_turns = limits.max_arc_turns
        return interp

    path, lines = iter_source_lines(source)
    interp = interpreter()
    interp.may_expand = True
    rd = reader(interp, path)
    try:
        for part in _blocks(lines, BLOCK_LINES):
            rd.block(part)
        return rd
    except NeedsExpansion:
        pass
    from postproc.gcode.expand import expand

    _path, lines = iter_source_lines(source)
    rd = reader(interpreter(), path)
    where: deque[tuple[int, str | None]] = deque()
    rd.expanded(where, in_bulk=True)
    flat = expand(list(lines), path=path, dialect=dialect, subroutine_path=[Path(p) for p in subroutine_path],
                  variables=getattr(setup, "variables", None), max_iterations=limits.max_iterations)
    for part in _blocks(flat, BLOCK_LINES):
        where.extend((sl.lineno, sl.path) for sl in part)
        rd.block([sl.text for sl in part])
        where.clear()
    return rd


def _steps(length_mm: float, step_mm: float) -> int:
    """Pieces of ``step_mm`` in ``length_mm`` (rounded up; huge for a step of 1e-320 mm,
    never an overflow)."""
    pieces = length_mm / step_mm
    return math.ceil(pieces) if pieces < 1e18 else 10**18


def _steps_all(length_mm: np.ndarray, step_mm: float) -> np.ndarray:
    """:func:`_steps` of each length, at least 1 (int64)."""
    with np.errstate(over="ignore"):  # (a step of 1e-320 mm: inf pieces, 10**18 samples)
        pieces = length_mm / step_mm
    n = np.where(pieces < 1e18, np.ceil(np.where(pieces < 1e18, pieces, 0.0)), 1e18).astype(np.int64)
    return np.maximum(n, 1)


class _Columns:
    """Moves as columns: start, end, samples, tool vector, line, whether rapid, and the
    file of the line (an expanded program's: :mod:`postproc.gcode.places`; None where all
    are the program's own)."""

    __slots__ = ("q0", "q1", "n", "r", "lineno", "rapid", "files")

    def __init__(self, q0: np.ndarray, q1: np.ndarray, n: np.ndarray, r: np.ndarray, lineno: np.ndarray,
                 rapid: np.ndarray, files: PathArray | None = None) -> None:
        self.q0, self.q1, self.n, self.r, self.lineno, self.rapid = q0, q1, n, r, lineno, rapid
        self.files = files

    def __len__(self) -> int:
        return len(self.n)

    def __getitem__(self, k: slice) -> _Columns:
        return _Columns(self.q0[k], self.q1[k], self.n[k], self.r[k], self.lineno[k], self.rapid[k],
                        None if self.files is None else self.files[k])

    @staticmethod
    def join(parts: list[_Columns]) -> _Columns:
        if len(parts) == 1:
            return parts[0]
        files = None
        if any(c.files is not None for c in parts):
            files = np.concatenate([np.full(len(c), None, dtype=object) if c.files is None else c.files
                                    for c in parts])
        q0, q1, n, r, lineno, rapid = (np.concatenate([getattr(c, f) for c in parts]) for f in _Columns.__slots__[:-1])
        return _Columns(q0, q1, n, r, lineno, rapid, files)


# an arc to sample: its row among the moves taken with it, the arc, its start and end,
# its samples and its arc_params
_ArcToSample: TypeAlias = tuple[int, Arc, Point, Point, int, tuple]


class Sampler(LineReader[tuple[int, Move, "str | None"]]):
    """Reads a program's moves as samples (see :func:`postproc.gcode.path.sample_program`):
    queues each move of a line the interpreter reads (its block's plain moves, then the
    drilling cycle it runs) and each run of plain lines; after each block, takes what it
    queued in order, counting the samples of each move and refusing the move that
    passes ``max_samples`` (at its line), before any error of a later line. A run's
    moves are taken from its columns, all the block's runs at once. An expanded
    program's moves keep the file of their line too (a subprogram's), for the samples
    (:attr:`postproc.gcode.source.ProgramPath.files`) and the refusals."""

    def __init__(self, interp: Interpreter, path: str | None, step_mm: float | None, chord_mm: float | None,
                 max_samples: int) -> None:
        super().__init__(interp, CorrectOptions(), path)
        self.step_mm, self.chord_mm, self.max_samples = step_mm, chord_mm, max_samples
        self.cols: list[_Columns] = []  # the moves taken, a block at a time
        self.moves = 0  # moves taken
        self.total = 0  # samples so far
        # the arcs' samples: (their moves' indices, their counts, the points)
        self.arcs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.rot: list[tuple[int, dict]] = []  # a move's rotary positions by its index (where it has any)

    def queue(self, line: str, mv: Move | None, lineno: int) -> None:
        path = None if self.source is None else self.interp.path  # (an expanded program's: the line's file)
        if mv is not None:
            self.entries.extend((lineno, m, path) for m in plain_moves(mv))
        cyc = self.interp.cycle_move
        if cyc is not None:
            self.entries.extend((lineno, m, path) for m in plain_moves(cyc))

    def block(self, lines: list[str]) -> None:
        """Read a block of lines, then take its moves (an error of a line comes after
        the moves of the lines before it, and after the refusal of too many samples)."""
        error: Exception | None = None
        try:
            super().block(lines)
        except Exception as exc:  # noqa: BLE001  (raised after the moves before it are taken)
            error = exc
        self._take()
        if error is not None:
            raise error

    def _refuse(self, cols: _Columns, row: int) -> ResourceLimitError:
        """The refusal of the move ``row`` of ``cols``, the one whose samples pass the bound."""
        every = f" every {self.step_mm:g} mm" if self.step_mm else ""
        return ResourceLimitError(f"sampling the program{every} makes more than {self.max_samples:,} points",
                                  path=file_of(cols.files, row, self.path), lineno=int(cols.lineno[row]), col=1,
                                  hint="give postproc verify a larger --max-step")

    def _own(self, files: list[str | None]) -> PathArray | None:
        """An expanded program's files of its moves (None for its own lines), or None when
        every one is the program's own or the program is read as written."""
        if self.source is None:
            return None
        arr = np.array(files + [None], dtype=object)[:-1]  # (a 1-d array of str, whatever their lengths)
        own = arr == self.path
        arr[own] = None
        return None if own.all() else arr

    def _arc_samples(self, arc: Arc, q0: Point, q1: Point, params: ArcParams | None = None) -> tuple[int, tuple]:
        """An arc's samples (every ``step_mm`` of its length and, with ``chord_mm``, every
        chord within it: the finer) and its arc_params (``params``: when known)."""
        params = params or arc_params(arc, q0, q1)
        step_mm, chord_mm = self.step_mm, self.chord_mm
        n = max(1, _steps(arc_length(arc, q0, q1, params), step_mm) if step_mm else 1,
                arc_chord_steps(arc, q0, q1, chord_mm, params) if chord_mm else 1)
        return n, params

    def _take(self) -> None:
        """Count and keep the moves queued, in order."""
        if not self.entries:
            return
        try:
            self._take_entries(self.entries)
        finally:
            self.let_go()

    def _take_entries(self, entries: list) -> None:
        step_mm = self.step_mm
        q0s: list = []
        q1s: list = []
        counts: list[int] = []
        rs: list = []
        lns: list[int] = []
        rapid: list[bool] = []
        fs: list[str | None] = []
        parts: list[_Columns] = []
        arcs: list[_ArcToSample] = []
        at = 0  # moves of the parts so far

        def flush() -> None:
            nonlocal at
            if counts:
                parts.append(_Columns(np.asarray(q0s, dtype=float), np.asarray(q1s, dtype=float),
                                      np.asarray(counts, dtype=np.int64), np.asarray(rs, dtype=float),
                                      np.asarray(lns, dtype=np.int64), np.asarray(rapid, dtype=bool), self._own(fs)))
                at += len(counts)
                for acc in (q0s, q1s, counts, rs, lns, rapid, fs):
                    acc.clear()

        runs = self._runs([e for e in entries if type(e) is bulk.Run])
        k = 0
        for e in entries:
            if type(e) is bulk.Run:
                flush()
                cols, run_arcs = runs[k]
                k += 1
                arcs += [(at + row, *rest) for row, *rest in run_arcs]  # type: ignore[misc]
                if e.rot is not None:  # the rotary positions of its lines that move (its rows)
                    moving = np.flatnonzero(~e.block.neutral[e.a:e.b]).tolist()
                    self.rot.extend((self.moves + at + m, e.rot[j]) for m, j in enumerate(moving) if e.rot[j])
                parts.append(cols)
                at += len(cols)
                continue
            lineno, mv, path = e
            q0, q1 = mv.q0, mv.q1
            if any(math.isnan(v) for v in q0) or mv.kind == RAPID:
                n = 1
                q0 = q1
            elif mv.arc is not None:
                n, params = self._arc_samples(mv.arc, q0, q1)
                arcs.append((at + len(counts), mv.arc, q0, q1, n, params))
            else:
                n = max(1, _steps(math.dist(q0, q1), step_mm)) if step_mm else 1
            if mv.rotary:
                self.rot.append((self.moves + at + len(counts), mv.rotary))
            q0s.append(q0)
            q1s.append(q1)
            counts.append(n)
            rs.append(mv.r)
            lns.append(lineno)
            rapid.append(mv.kind == RAPID)
            fs.append(path)
        flush()
        if not parts:
            return
        cols = _Columns.join(parts)
        cum = self.total + np.cumsum(cols.n)
        over = cum > self.max_samples
        if over.any():
            raise self._refuse(cols, int(np.argmax(over)))
        self.total = int(cum[-1])
        if arcs:
            self._sample_arcs(arcs)
        self.cols.append(cols)
        self.moves += len(cols)

    def _sample_arcs(self, arcs: list[_ArcToSample]) -> None:
        """The samples of the arcs taken, all at once (each point the one
        :func:`postproc.gcode.geometry.arc_points` gives)."""
        rows = np.array([a[0] for a in arcs], dtype=np.int64)
        n = np.array([a[4] for a in arcs], dtype=np.int64)
        params = [a[5] for a in arcs]
        owner = np.repeat(np.arange(len(arcs)), n)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each arc
        cols = ArcColumns(np.array([p[0] for p in params], dtype=np.int64),
                          np.array([p[1] for p in params], dtype=float), np.array([p[2] for p in params], dtype=float),
                          np.array([p[3] for p in params], dtype=float), np.array([p[4] for p in params], dtype=float),
                          np.array([a[1].center for a in arcs], dtype=float),
                          np.array([a[2] for a in arcs], dtype=float), np.array([a[3] for a in arcs], dtype=float))
        self.arcs.append((self.moves + rows, n, arcs_points(owner, k / n[owner], cols)))

    def _runs(self, runs: list[bulk.Run]) -> list[tuple[_Columns, list[_ArcToSample]]]:
        """The moves of each run (its lines that move) and its arcs (rows within the run),
        from the columns of the runs of each block at once."""
        out: list[tuple[_Columns, list[_ArcToSample]]] = []
        i = 0
        while i < len(runs):
            blk = runs[i].block
            j = i + 1
            while j < len(runs) and runs[j].block is blk:
                j += 1
            out += self._block_runs(blk, runs[i:j])
            i = j
        return out

    def _block_runs(self, blk: bulk.Block, runs: list[bulk.Run]) -> list[tuple[_Columns, list[_ArcToSample]]]:
        """:meth:`_runs` of runs of one block: their lines as rows (each line's start the
        end of the line before, the run's start for its first), the lines that move
        nothing left out; an arc (G17, one turn, its centre from the run) as
        :func:`postproc.gcode.bulk.arc_moves` gives it."""
        lengths = [r.b - r.a for r in runs]
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        idx = np.concatenate([np.arange(r.a, r.b) for r in runs])  # the runs' lines in the block
        q1 = np.concatenate([r.q1 for r in runs])
        q0 = np.empty_like(q1)  # each line's start: the line before's end, the run's start for its first
        q0[1:] = q1[:-1]
        q0[starts] = np.array([r.q0 for r in runs], dtype=float)
        moving = ~blk.neutral[idx]
        # the motion of each line: the G word of the last line naming one in the run, else the run's
        last_g = np.asarray(blk.last_g)[idx]
        named = last_g >= np.repeat([r.a for r in runs], lengths)
        rapid = np.repeat([r.motion0 == RAPID for r in runs], lengths)
        if named.any():
            rapid[named] = blk.motion[last_g[named]] == 0  # G0, G00
        lineno = np.concatenate([r.linenos() for r in runs])  # (an expanded program's: their source lines)
        tool = np.repeat(np.array([r.r for r in runs], dtype=float), lengths, axis=0)
        n = np.ones(len(idx), dtype=np.int64)
        arc_rows = [int(s) + j for r, s in zip(runs, starts.tolist(), strict=True) for j in r.arcs]
        if self.step_mm:
            straight = moving & ~rapid
            straight[arc_rows] = False
            sel = np.flatnonzero(straight)
            if len(sel):
                d = np.fromiter(map(math.dist, q0[sel].tolist(), q1[sel].tolist()), dtype=float, count=len(sel))
                n[sel] = _steps_all(d, self.step_mm)
        arcs: list[_ArcToSample] = []
        if arc_rows:
            a0, a1 = q0[arc_rows].tolist(), q1[arc_rows].tolist()
            xy = PLANES[170][0]
            read = [r.arcs[j] for r in runs for j in r.arcs]  # (centre, clockwise, turn), in the order of arc_rows
            for row, (centre, clockwise, turn), p0, p1 in zip(arc_rows, read, a0, a1, strict=True):
                arc = Arc(centre, 170, clockwise, 1, (-1, -1), -1)
                p0t, p1t = (p0[0], p0[1], p0[2]), (p1[0], p1[1], p1[2])
                c, params = self._arc_samples(arc, p0t, p1t, (xy, *turn))
                n[row] = c
                arcs.append((row, arc, p0t, p1t, c, params))
        q0 = np.where(rapid[:, None], q1, q0)
        # the moving lines only: a run's rows and an arc's row among them
        cm = np.concatenate([[0], np.cumsum(moving)])
        sel = np.flatnonzero(moving)
        files = None  # (an expanded program's: the file of each line)
        if self.source is not None:
            files = self._own([p for r in runs for p in (r.paths() or [None] * len(r))])
        every = _Columns(q0[sel], q1[sel], n[sel], tool[sel], lineno[sel], rapid[sel],
                         None if files is None else files[sel])
        bounds = cm[starts].tolist() + [int(cm[-1])]
        out: list[tuple[_Columns, list[_ArcToSample]]] = []
        ai = 0
        for k in range(len(runs)):
            lo, hi = bounds[k], bounds[k + 1]
            mine: list[_ArcToSample] = []
            while ai < len(arcs) and arcs[ai][0] < int(starts[k]) + lengths[k]:
                row, *rest = arcs[ai]
                mine.append((int(cm[row]) - lo, *rest))
                ai += 1
            out.append((every[lo:hi], mine))
        return out

    def path_of(self, setup: Setup, rotary: set[str]) -> ProgramPath:
        """The samples of the moves read, with their context."""
        from postproc.gcode.source import ProgramPath, backfill_unknown, motion_signs

        if not self.moves:
            empty = np.zeros((0, 3))
            return ProgramPath(empty, empty.copy(), np.zeros(0, dtype=int), np.zeros(0, dtype=bool),
                               {"dirx": np.zeros(0), "diry": np.zeros(0), "dirz": np.zeros(0)})
        cols = _Columns.join(self.cols)
        n = cols.n
        move = np.repeat(np.arange(len(n)), n)
        k = np.arange(len(move)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each move
        a, b = cols.q0, cols.q1
        q = a[move] + (b[move] - a[move]) * (k / n[move])[:, None]  # as line_points does
        if self.arcs:
            first = np.cumsum(n) - n
            for moves, counts, pts in self.arcs:
                at = np.repeat(first[moves] - (np.cumsum(counts) - counts), counts) + np.arange(len(pts))
                q[at] = pts
        lineno_arr = cols.lineno[move]
        files = None if cols.files is None else cols.files[move]
        q = backfill_unknown(q, lineno_arr, self.path, files)
        r = cols.r[move]
        signs = motion_signs(q, start=np.array(start_position(setup.start), dtype=float))
        context: dict = {"dirx": signs[:, 0], "diry": signs[:, 1], "dirz": signs[:, 2]}
        for ax in sorted(rotary):
            pos = np.zeros(len(n))
            if self.rot:
                pos[[i for i, _d in self.rot]] = [d.get(ax, 0.0) for _i, d in self.rot]
            context[ax] = pos[move]
        for key, v in (setup.context or {}).items():
            context[key] = np.full(len(q), float(v))
        return ProgramPath(q + r, r, lineno_arr, cols.rapid[move], context, files)
