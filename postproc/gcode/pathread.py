"""A program read for its path: the lane's reader, and the moves it reads as samples.

:func:`read_program` reads a program (path or text) with a
:class:`postproc.gcode.reader.LineReader` (the interpreter line by line, runs of plain
lines in bulk), as ``correct`` and ``diff`` read it; a program that needs expanding
(parameters, O-words, subprograms, macros) is read again expanded, its lines one by one.

:class:`Sampler` is the reader of :func:`postproc.gcode.path.sample_program`: each move
of a line the interpreter reads is sampled as itself, each run of plain lines from the
run's columns (its targets, tool vector, line numbers and arcs) at once.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from postproc.gcode import bulk
from postproc.gcode.geometry import arc_chord_steps, arc_length, arc_points
from postproc.gcode.interp import Interpreter, Move, NeedsExpansion, plain_moves, start_position
from postproc.gcode.options import CorrectOptions
from postproc.gcode.reader import LineReader
from postproc.gcode.state import RAPID
from postproc.limits import Limits, ResourceLimitError

if TYPE_CHECKING:
    from postproc.gcode.path import ProgramPath, Setup

# Lines read into one block (the scanner's unit, and the sampler's between two takes).
BLOCK_LINES = 5_000

R = TypeVar("R", bound=LineReader)


def _blocks(lines: Iterable, n: int) -> Iterator[list]:
    """``lines`` in lists of ``n``; an error while taking them (a line too long, an
    expansion refused) comes after the list of the lines before it."""
    it = iter(lines)
    while True:
        part: list = []
        error: Exception | None = None
        try:
            for x in it:
                part.append(x)
                if len(part) == n:
                    break
        except Exception as exc:  # noqa: BLE001  (raised after the lines before it are read)
            error = exc
        if part:
            yield part
        if error is not None:
            raise error
        if len(part) < n:
            return


def read_program(source, setup: Setup, reader: Callable[[Interpreter, str | None], R], *, dialect: str = "generic",
                 subroutine_path=(), lenient_setup: bool = False, limits: Limits | None = None) -> R:
    """Read a program (path or text) with the reader ``reader(interp, path)`` makes: its
    lines a block at a time (:meth:`LineReader.block`); when the program needs expanding
    (:class:`postproc.gcode.interp.NeedsExpansion`), a new reader reads the expanded
    program instead, each line numbered (and its file named) as the line it comes from.
    Returns the reader that read it. ``limits``: the bounds on loops and helix turns
    (:class:`postproc.limits.Limits`, default its own)."""
    from postproc.gcode.path import iter_source_lines

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
    rd.expanded(where)
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
    """Moves as columns: start, end, samples, tool vector, line, rapid, rotary positions
    (None: no rotary axis used by any of them)."""

    __slots__ = ("q0", "q1", "n", "r", "lineno", "rapid", "rot")

    def __init__(self, q0: np.ndarray, q1: np.ndarray, n: np.ndarray, r: np.ndarray, lineno: np.ndarray,
                 rapid: np.ndarray, rot: list[dict] | None) -> None:
        self.q0, self.q1, self.n, self.r, self.lineno, self.rapid, self.rot = q0, q1, n, r, lineno, rapid, rot


class Sampler(LineReader[tuple[int, Move]]):
    """Reads a program's moves as samples (see :func:`postproc.gcode.path.sample_program`):
    queues each move of a line the interpreter reads (its block's plain moves, then the
    drilling cycle it runs) and each run of plain lines; after each block, takes what it
    queued in order, counting the samples of each move and refusing the move that
    passes ``max_samples`` (at its line), before any error of a later line."""

    def __init__(self, interp: Interpreter, path: str | None, step_mm: float | None, chord_mm: float | None,
                 max_samples: int) -> None:
        super().__init__(interp, CorrectOptions(), path)
        self.step_mm, self.chord_mm, self.max_samples = step_mm, chord_mm, max_samples
        self.cols: list[_Columns] = []  # the moves taken, in order
        self.arcs: dict[int, np.ndarray] = {}  # an arc's samples by its move's index
        self.moves = 0  # moves taken
        self.total = 0  # samples so far
        self._g0: dict[int, tuple[bulk.Block, np.ndarray]] = {}  # by block: which lines name G0

    def queue(self, line: str, mv: Move | None, lineno: int) -> None:
        if mv is not None:
            self.entries.extend((lineno, m) for m in plain_moves(mv))
        cyc = self.interp.cycle_move
        if cyc is not None:
            self.entries.extend((lineno, m) for m in plain_moves(cyc))

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

    def _refuse(self, lineno: int) -> ResourceLimitError:
        every = f" every {self.step_mm:g} mm" if self.step_mm else ""
        return ResourceLimitError(f"sampling the program{every} makes more than {self.max_samples:,} points",
                                  path=self.path, lineno=lineno, col=1, hint="give postproc verify a larger --max-step")

    def _take(self) -> None:
        """Count and keep the moves queued, in order."""
        entries = self.entries
        if not entries:
            return
        step_mm, chord_mm, max_samples = self.step_mm, self.chord_mm, self.max_samples
        q0s: list = []
        q1s: list = []
        counts: list[int] = []
        rs: list = []
        lns: list[int] = []
        rapid: list[bool] = []
        rot: list[dict] = []

        def flush() -> None:
            if counts:
                self.cols.append(_Columns(np.asarray(q0s, dtype=float), np.asarray(q1s, dtype=float),
                                          np.asarray(counts, dtype=np.int64), np.asarray(rs, dtype=float),
                                          np.asarray(lns, dtype=np.int64), np.asarray(rapid, dtype=bool), list(rot)))
                self.moves += len(counts)
                for acc in (q0s, q1s, counts, rs, lns, rapid, rot):
                    acc.clear()

        blocks: dict[int, bulk.Block] = {}
        try:
            for e in entries:
                if type(e) is bulk.Run:
                    flush()
                    blocks[id(e.block)] = e.block
                    self._take_run(e)
                    continue
                lineno, mv = e
                q0, q1 = mv.q0, mv.q1
                if any(math.isnan(v) for v in q0) or mv.kind == RAPID:
                    n = 1
                    q0 = q1
                elif mv.arc is not None:
                    n = max(1, _steps(arc_length(mv.arc, q0, q1), step_mm) if step_mm else 1,
                            arc_chord_steps(mv.arc, q0, q1, chord_mm) if chord_mm else 1)
                    if self.total + n <= max_samples:  # (else refused below, before the points are made)
                        self.arcs[self.moves + len(counts)] = arc_points(mv.arc, q0, q1, np.arange(1, n + 1) / n)
                else:
                    n = max(1, _steps(math.dist(q0, q1), step_mm)) if step_mm else 1
                self.total += n
                if self.total > max_samples:
                    raise self._refuse(lineno)
                q0s.append(q0)
                q1s.append(q1)
                counts.append(n)
                rs.append(mv.r)
                lns.append(lineno)
                rapid.append(mv.kind == RAPID)
                rot.append(mv.rotary)
            flush()
        finally:
            entries.clear()
            for blk in blocks.values():
                blk.runs = []  # (each run refers to its block: let go of both)
            self._g0.clear()
            self.interp.comp_moves = []  # (those of cutter compensation: the corrector's to bound)

    def _names_g0(self, blk: bulk.Block) -> np.ndarray:
        """Whether each line of ``blk`` names G0 (or G00) as its motion word."""
        got = self._g0.get(id(blk))
        if got is None:
            got = self._g0[id(blk)] = (blk, np.fromiter((g[-1:] == "0" for g in blk.gword), dtype=bool,
                                                        count=len(blk.gword)))
        return got[1]

    def _take_run(self, run: bulk.Run) -> None:
        """Count and keep the moves of a run of plain lines, from its columns."""
        blk, a, b = run.block, run.a, run.b
        js = np.flatnonzero(~blk.neutral[a:b])  # the lines that move (within the run)
        if not len(js):
            return
        q1_all = run.q1
        q1 = q1_all[js]
        q0 = np.vstack([np.asarray(run.q0, dtype=float)[None, :], q1_all[:-1]])[js]
        last_g = np.asarray(blk.last_g[a:b])[js]  # the line whose G word is modal at each
        named = last_g >= a
        rapid = np.where(named, self._names_g0(blk)[np.maximum(last_g, 0)], run.motion0 == RAPID)
        step_mm, chord_mm = self.step_mm, self.chord_mm
        n = np.ones(len(js), dtype=np.int64)
        arc_at: dict[int, int] = {}  # line within the run -> its row among js
        if run.arcs:
            arc_at = {j: k for k, j in enumerate(js.tolist()) if j in run.arcs}
        if step_mm:
            straight = ~rapid
            if arc_at:
                straight[list(arc_at.values())] = False
            sel = np.flatnonzero(straight)
            if len(sel):
                d = np.fromiter(map(math.dist, q0[sel].tolist(), q1[sel].tolist()), dtype=float, count=len(sel))
                n[sel] = _steps_all(d, step_mm)
        arcs: list[tuple[int, bulk.RunMove, int]] = []
        if arc_at:
            for j, mv in bulk.arc_moves(run):
                k = arc_at[j]
                arc = mv.arc
                assert arc is not None
                c = max(1, _steps(arc_length(arc, mv.q0, mv.q1), step_mm) if step_mm else 1,
                        arc_chord_steps(arc, mv.q0, mv.q1, chord_mm) if chord_mm else 1)
                n[k] = c
                arcs.append((k, mv, c))
        cum = self.total + np.cumsum(n)
        over = cum > self.max_samples
        if over.any():
            raise self._refuse(run.lineno + int(js[int(np.argmax(over))]))
        self.total = int(cum[-1])
        for k, am, c in arcs:
            assert am.arc is not None
            self.arcs[self.moves + k] = arc_points(am.arc, am.q0, am.q1, np.arange(1, c + 1) / c)
        q0 = np.where(rapid[:, None], q1, q0)
        self.cols.append(_Columns(q0, q1, n, np.broadcast_to(np.asarray(run.r, dtype=float), q1.shape), run.lineno + js,
                                  rapid, None))
        self.moves += len(js)

    def path_of(self, setup: Setup, rotary: set[str]) -> ProgramPath:
        """The samples of the moves read, with their context."""
        from postproc.gcode.path import ProgramPath, backfill_unknown, motion_signs

        if not self.moves:
            empty = np.zeros((0, 3))
            return ProgramPath(empty, empty.copy(), np.zeros(0, dtype=int), np.zeros(0, dtype=bool),
                               {"dirx": np.zeros(0), "diry": np.zeros(0), "dirz": np.zeros(0)})
        cols = self.cols
        n = np.concatenate([c.n for c in cols])
        move = np.repeat(np.arange(len(n)), n)
        k = np.arange(len(move)) - np.repeat(np.cumsum(n) - n, n) + 1  # 1..n within each move
        a = np.concatenate([c.q0 for c in cols])
        b = np.concatenate([c.q1 for c in cols])
        q = a[move] + (b[move] - a[move]) * (k / n[move])[:, None]  # as line_points does
        if self.arcs:
            first = np.cumsum(n) - n
            for j, pts in self.arcs.items():
                q[first[j]:first[j] + n[j]] = pts
        lineno_arr = np.concatenate([c.lineno for c in cols])[move]
        q = backfill_unknown(q, lineno_arr, self.path)
        r = np.concatenate([c.r for c in cols])[move]
        signs = motion_signs(q, start=np.array(start_position(setup.start), dtype=float))
        context: dict = {"dirx": signs[:, 0], "diry": signs[:, 1], "dirz": signs[:, 2]}
        for ax in sorted(rotary):
            context[ax] = np.concatenate([
                np.zeros(len(c.n)) if c.rot is None else np.asarray([d.get(ax, 0.0) for d in c.rot], dtype=float)
                for c in cols])[move]
        for key, v in (setup.context or {}).items():
            context[key] = np.full(len(q), float(v))
        return ProgramPath(q + r, r, lineno_arr, np.concatenate([c.rapid for c in cols])[move], context)
