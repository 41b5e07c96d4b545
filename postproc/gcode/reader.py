"""The reader: a program's lines read into a chunk's entries.

:class:`ChunkReader` feeds each line to the interpreter (:mod:`postproc.gcode.interp`)
and queues what it makes (:data:`postproc.gcode.writer.Entry`): a move, a line that moves
nothing, an offset or stored position set from where the machine is. Runs of plain lines
are read in bulk (:mod:`postproc.gcode.bulk`), from the columns the scanner makes of the
whole block; those of an expanded program too, each line numbered by the source line
it comes from (:meth:`LineReader.expanded`). A canned cycle written as its moves, or a
spline as its chords, is queued as the G0/G1 lines written in its place. The corrector
then plans the chunk as one table and writes it.

The reading itself (the interpreter line by line, runs in bulk) is :class:`LineReader`'s;
``postproc diff`` reads both programs with it too, queueing each line's end point
(:mod:`postproc.gcode.compare`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import replace
from itertools import islice
from typing import Generic, TypeVar

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import UnsupportedGcodeError
from postproc.gcode import bulk, emit, numfmt
from postproc.gcode.emitter import _unit_decimals
from postproc.gcode.interp import Interpreter
from postproc.gcode.moves import Cycle, Move, Role
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.places import repeated
from postproc.gcode.planner import Planner
from postproc.gcode.state import CANNED_CYCLES, LINE, RAPID
from postproc.gcode.vplan import FloatArray
from postproc.gcode.writer import Entry, Rebase, Store

# --cycles auto keeps a cycle block when its tilt (the correction's change between R
# plane and bottom) is within this share of the tolerance left after rounding: the share
# left covers the approach directions it is written with, which differ from those
# the choice is made with (the machine's last known ones) on a backlash calibration.
CYCLE_KEEP_SHARE = 0.9

E = TypeVar("E")  # what a line read is queued as


class LineReader(Generic[E]):
    """Reads lines through the interpreter, runs of plain lines in bulk (:meth:`block`);
    queues into :attr:`entries` each run read (a :class:`postproc.gcode.bulk.Run`) and,
    through :meth:`queue`, what each other line makes (:class:`ChunkReader`: the
    corrector's entries). Carries the reading state (line number, whether a run of plain
    lines may start) from one chunk to the next."""

    def __init__(self, interp: Interpreter, options: CorrectOptions, path: str | None = None,
                 use_bulk: bool = True) -> None:
        self.interp = interp
        self.opt = options
        self.path = path
        self.entries: list[E | bulk.Run] = []
        self.lineno = 1  # the number of the next line read (of the program as read)
        self.last = 0  # the source line that where() gave last (an expanded program's)
        self.source: deque[tuple[int, str | None]] | None = None
        self.use_bulk = use_bulk and options.bulk_lane
        self.run_ok = False  # the modal state lets a run of plain lines start here
        self.dec_mm = _unit_decimals(options, 1.0)
        self.dec_in = _unit_decimals(options, MM_PER_INCH)

    def expanded(self, source: deque[tuple[int, str | None]], in_bulk: bool = False) -> None:
        """Read an expanded program: ``source`` gives the (line, file) each line read comes
        from, in order, at least as far as the block being read (:meth:`where` takes each
        line's). With ``in_bulk`` its runs of plain lines are read in bulk too, each of
        their lines numbered by its source line (:meth:`bulk.Block.set_source`); else
        every line is read by the interpreter."""
        self.source = source
        self.use_bulk = self.use_bulk and in_bulk

    def where(self, seq: int) -> int:
        """The line number the interpreter reports for the ``seq``-th line read."""
        if self.source is None:
            return seq
        ln, p = self.source.popleft()
        self.interp.path = p or self.path
        self.last = ln
        return ln

    def _taken(self, n: int) -> None:
        """The next ``n`` lines of an expanded program read (as a run): their sources
        taken, the interpreter's file and :attr:`last` those of the last, as :meth:`where`
        leaves them."""
        source = self.source
        if source is None:
            return
        pop = source.popleft
        for _ in range(n - 1):
            pop()
        ln, p = pop()
        self.interp.path = p or self.path
        self.last = ln

    def line(self, line: str) -> None:
        """Read one line through the interpreter and queue what it makes."""
        here = self.where(self.lineno)
        mv = self.interp.feed_line(here, line)
        if self.source is not None:  # an expanded program's: each move names its file
            self._name_file(mv)
        self.queue(line, mv, here)
        self.lineno += 1
        self.run_ok = self.use_bulk and bulk.state_allows(self.interp)

    def _name_file(self, mv: Move | None) -> None:
        """Give the moves the line just read made the file it comes from (the
        interpreter's, as :meth:`where` set it)."""
        path = self.interp.path
        for m in (mv, mv.then if mv is not None else None, self.interp.cycle_move):
            if m is not None:
                m.path = path

    def queue(self, line: str, mv: Move | None, lineno: int) -> None:
        """Queue what line ``lineno`` (``line``, read by the interpreter: ``mv``) makes."""
        raise NotImplementedError

    def queue_run(self, run: bulk.Run) -> None:
        """Queue a run of plain lines read in bulk."""
        self.entries.append(run)

    def let_go(self) -> None:
        """Clear the entries taken (by a reader that keeps what it needs of them): each
        run's block lets go of its runs (a run refers to its block, a cycle the disabled
        collector would not free), and the interpreter of the cutter compensation moves it
        kept for the corrector's bound."""
        for e in self.entries:
            if type(e) is bulk.Run:
                e.block.runs = []
        self.entries.clear()
        self.interp.comp_moves = []

    def block(self, lines: list[str]) -> None:
        """Read a block of lines: its runs of plain lines in bulk where the modal state
        allows, every other line through the interpreter."""
        block = bulk.scan(lines) if self.use_bulk else None
        if block is None:
            for line in lines:
                self.line(line)
            return
        if self.source is not None:
            # the source line of each line of the block (where() takes them as they are read)
            given = list(islice(self.source, len(lines)))
            if len(given) < len(lines):  # (the sources of the block's lines not all given yet)
                for line in lines:
                    self.line(line)
                return
            block.set_source([ln for ln, _p in given], [p or self.path for _ln, p in given])
        try:
            edges = np.diff(np.concatenate([[0], block.plain.view(np.int8), [0]]))
            i, n = 0, len(lines)
            for a, b in zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True):
                while i < a:
                    self.line(lines[i])
                    i += 1
                while i < b:
                    i = self._plain(block, lines, i, b)
            while i < n:
                self.line(lines[i])
                i += 1
        finally:
            bulk.finish_block(block)  # the runs read so far stay usable after an error

    def _plain(self, block: bulk.Block, lines: list[str], i: int, b: int) -> int:
        """Read from line ``i`` of a stretch of plain lines (ending at ``b``): a run in bulk
        where the modal state allows one, else the line alone; the next line to read."""
        interp = self.interp
        src = block.src
        here = self.lineno if src is None else src[i]  # the line of line i (a run's first)
        tlo = block.tlo  # a straight move that sets the tool length (G43 H..) starts a run
        if tlo and i in tlo and not interp.ended:
            # the tool length first (again when the interpreter reads the line)
            if self.source is not None:
                interp.path = self.source[0][1] or self.path  # (line i's file: where() takes it next)
            interp.set_tool_length(tlo[i], here, bulk.tlo_col(lines[i]))
            self.run_ok = False
        # a line naming its own motion word may start a run whatever the modal motion
        # (a run starts at a line that moves: one that moves nothing is the interpreter's)
        if not block.neutral[i] and (self.run_ok or (not interp.ended and bulk.prime_shift(interp)
                                                     and bulk.state_allows(interp, block.motion_l[i] >= 0))):
            dec = self.dec_in if interp.state.inch else self.dec_mm
            run = bulk.read_run(interp, block, i, b, here, dec)
            if run is not None:
                self.queue_run(run)
                n = run.b - i
                self.lineno += n
                self._taken(n)  # (an expanded program's: the run's sources)
                self.run_ok = bulk.state_allows(interp)
                return run.b
        # the modal state does not allow a run here, or an arc the run does not take (the
        # interpreter reads it, and reports it if it must)
        self.line(lines[i])
        return i + 1


class ChunkReader(LineReader[Entry]):
    """Reads lines into :attr:`entries`, the chunk the corrector plans and writes next
    (:data:`postproc.gcode.writer.Entry` and runs); carries the cycle series and spline
    being read from one chunk to the next."""

    def __init__(self, interp: Interpreter, planner: Planner, options: CorrectOptions, report: CorrectReport,
                 path: str | None = None) -> None:
        # runs of plain lines: for every engine whose moves the planner settles in bulk
        super().__init__(interp, options, path, planner.linear_exact or planner.bulk_plan)
        self.planner = planner
        self.report = report
        self._series_expanded = False  # --cycles auto: a block of the cycles the controller runs was expanded
        self._spline_kept = False  # a G5 without I/J continues the previous G5 only if it was kept

    def queue(self, line: str, mv: Move | None, lineno: int) -> None:
        """Queue what the line makes: a move, a line that moves nothing, a stored position
        or an offset set from where the machine is, a cycle or spline as its lines."""
        interp = self.interp
        entries = self.entries
        if interp.call_line or interp.cycle_move is not None:
            self._feed_drill_cycle(line, mv, interp, lineno)
        elif interp.stored_here is not None:
            # G28.1/G30.1: the controller stores where it is, the corrected position
            entries.append((line, Store(interp.stored_here), False, interp.state.motion))
        elif interp.rebase is not None:
            # an offset set from where the machine is: its words follow the correction there
            words, axes, nominal = interp.rebase
            entries.append((line, Rebase(words, axes, nominal, MM_PER_INCH if interp.state.inch else 1.0), False,
                            interp.state.motion))
        elif mv is not None and mv.cycle is not None:
            self._feed_cycle(line, mv, mv.cycle, interp.state.motion)
        elif mv is not None and mv.spline is not None:
            self._feed_spline(line, mv, mv.spline)
        elif mv is not None and mv.role is Role.AT:
            # the line only sends the machine to a stored position: written as it is
            entries.append((line, None, False, interp.state.motion))
            entries.append(("", mv, False, interp.state.motion))
        elif mv is not None and mv.then is not None:
            entries.append((line, mv, False, interp.state.motion))
            entries.append(("", mv.then, False, interp.state.motion))
        else:
            entries.append((line, mv, interp.motion_word, interp.state.motion))
        if self._series_expanded and interp.state.motion not in CANNED_CYCLES:
            self._series_expanded = False  # G80 or another motion: the series has ended

    def queue_run(self, run: bulk.Run) -> None:
        self.entries.append(run)
        self._series_expanded = False  # moves: no cycle series goes on

    def _feed_spline(self, line: str, mv: Move,
                     spline: list[tuple[float, float]]) -> None:
        """Queue a G5/G5.1 spline as the fewest G1 chords whose corrected path stays within
        --tolerance of the corrected spline (checked at samples 1/10 of the tolerance apart
        in chord error)."""
        from postproc.gcode.interp import spline_points, spline_samples

        tol = self.opt.tolerance_mm - self.planner.round_err(mv.unit)
        has_ij = any(w.letter == "I" for w in mv.words)
        kept = self.planner.linear_exact and (has_ij or self._spline_kept) and self._spline_unmoved(mv, spline)
        self._spline_kept = kept
        if kept:
            # an affine correction maps the spline onto itself: the line stays as it is
            self.entries.append((line, None, True, LINE))
            self.entries.append(("", replace(mv, q0=mv.q1, role=Role.AT, spline=None, words=[],
                                          axis_idx=(-1, -1, -1)), False, None))
            return
        s = spline_samples(spline, tol / 10.0)
        xy = spline_points(spline, s)
        nom = np.column_stack([xy, np.full(len(s), mv.q1[2])])
        d = np.diff(np.vstack([np.asarray(mv.q0)[None, :], nom]), axis=0)
        sign = np.sign(np.where(np.abs(d) > 1e-9, d, 0.0))
        for k in range(1, len(sign)):
            sign[k] = np.where(sign[k] == 0, sign[k - 1], sign[k])
        sign = np.where(sign == 0, self.planner.dirs, sign)
        lineno = np.full(len(s), mv.lineno)
        corr = self.planner.corrected(nom, np.broadcast_to(np.asarray(mv.r, dtype=float), nom.shape), sign,
                              [mv.rotary] * len(s), lineno, repeated(mv.path, len(s)))
        keep = [0]
        i = 0
        budget = 0.9 * tol
        while i < len(s) - 1:
            j = i + 1
            while j + 1 < len(s) and _chord_fits(corr[i:j + 2], budget):
                j += 1
            keep.append(j)
            i = j
        ending = emit.new_line_ending(line)
        sep, lower = emit.style_of(line)
        sep = sep or " "
        if mv.prefix_words:
            text = sep.join(mv.prefix_words)
            self.entries.append(((text.lower() if lower else text) + ending, None, False, None))
        prev = mv.q0
        for n, k in enumerate(keep[1:]):
            q = tuple(nom[k].tolist()) if k < len(s) - 1 else mv.q1
            self.entries.append(self._generated_move(mv, LINE, prev, q, (0, 1), n == 0, line, role=Role.CHORD))
            prev = q
        self.report.splines_linearised += 1

    def _spline_unmoved(self, mv: Move, spline: list[tuple[float, float]]) -> bool:
        """Whether the correction at the spline's control points rounds to nothing (for an
        affine correction the corrected spline is then the spline itself)."""
        pts = np.array([(x, y, mv.q1[2]) for x, y in spline], dtype=float)
        n = len(pts)
        t = self.planner.corrected(pts, np.broadcast_to(np.asarray(mv.r, dtype=float), pts.shape),
                           np.broadcast_to(self.planner.dirs, pts.shape), [mv.rotary] * n, np.full(n, mv.lineno),
                           repeated(mv.path, n))
        d = _unit_decimals(self.opt, mv.unit)
        return bool(np.abs(t - pts).max() / mv.unit < numfmt.half_unit(d))

    def _feed_cycle(self, line: str, mv: Move, c: Cycle, motion: int | None) -> None:
        """Queue the cycle block ``c`` of ``mv``: kept (its bottom and R point corrected) or
        expanded into the controller's own G0/G1 moves, each corrected like any other move.
        With ``--cycles auto`` a block is kept when :meth:`_cycle_keeps` says so and no block
        of its series was expanded (a kept block needs the cycle, R and Z the controller
        holds, and an expansion leaves it in G0/G1)."""
        mode = self.opt.cycles
        if mode == "auto":
            mode = "keep" if not self._series_expanded and self._cycle_keeps(mv, c) else "expand"
            self._series_expanded = mode == "expand"
        if mode != "expand":
            if c.repeats == 1 and not mv.incremental:
                self.entries.append((line, mv, True, motion))
                bottom, rpoint = c.holes[0]
                self.entries.append(("", replace(mv, q1=rpoint, cycle=None, role=Role.R_POINT), False, motion))
                return
            # several holes from one line, or increments: one word cannot carry each hole's
            # correction; kept only where nothing is corrected
            for bottom, rpoint in c.holes:
                for q in (bottom, rpoint):
                    self.entries.append(("", replace(mv, q1=q, cycle=None, role=Role.HOLE), False, motion))
            self.entries.append((line, None, True, None))
            end = c.steps[-1][1] if c.steps else mv.q0
            self.entries.append(("", replace(mv, q0=end, q1=end, cycle=None, role=Role.AT, words=[],
                                          axis_idx=(-1, -1, -1)), False, None))
            return
        for step in emit.cycle_lines(line, mv, c, retract=self.opt.cycles != "expand"):
            if isinstance(step, str):
                self.entries.append((step, None, False, None))
            else:
                kind, prev, q, moved, first_feed = step
                self.entries.append(self._generated_move(mv, kind, prev, q, moved, first_feed, line))
        self.report.cycles_expanded += 1

    def _cycle_keeps(self, mv: Move, c: Cycle) -> bool:
        """Whether a cycle block can stay a cycle: one hole whose correction's tilt between
        its R plane and its bottom is within :data:`CYCLE_KEEP_SHARE` of the tolerance, or
        several holes (or increments) whose corrections all round to nothing."""
        if not c.holes:
            return True
        pts = np.array([q for hole in c.holes for q in hole], dtype=float)
        n = len(pts)
        dirs = np.broadcast_to(self.planner.dirs, pts.shape)
        t = self.planner.corrected(pts, np.broadcast_to(np.asarray(mv.r, dtype=float), pts.shape), dirs,
                           [mv.rotary] * n, np.full(n, mv.lineno), repeated(mv.path, n))
        if c.repeats == 1 and not mv.incremental:
            drift = math.hypot(t[1, 0] - t[0, 0], t[1, 1] - t[0, 1])
            return drift <= CYCLE_KEEP_SHARE * (self.opt.tolerance_mm - self.planner.round_err(mv.unit))
        d = _unit_decimals(self.opt, mv.unit)
        return bool(np.abs(t - pts).max() / mv.unit < numfmt.half_unit(d))

    def _feed_drill_cycle(self, line: str, mv: Move | None,
                          interp: Interpreter, lineno: int) -> None:
        """Queue a Sinumerik block that calls a drilling cycle or runs the modal one: the
        call written as a comment, a position block as any move, then the cycle's G0/G1
        moves (each corrected) and G4 F dwells; the motion mode is restored after them, as
        the cycle (a subprogram with SAVE) restores it. Only with ``--cycles expand``: a
        CYCLE81 call cannot carry each hole's correction in its parameters."""
        cyc = interp.cycle_move
        if self.opt.cycles == "keep":
            call = interp.call_line or f"MCALL {interp.modal_call.name if interp.modal_call else ''}"
            raise UnsupportedGcodeError(
                f"Sinumerik {call} (drilling cycle call): read only when written as its moves",
                path=self.interp.path or self.path, lineno=lineno, col=interp.call_col or 1,
                hint="give --cycles expand or auto to write each hole as its G0/G1 moves, each corrected")
        for step in emit.drill_cycle_lines(line, bool(interp.call_line), mv, cyc, interp.state.motion):
            if step is None:
                self.entries.append((line, mv, interp.motion_word, interp.state.motion))
            elif isinstance(step, str):
                self.entries.append((step, None, False, None))
            elif cyc is not None:  # (a step is made only of a cycle)
                kind, prev, q, moved, _first = step
                self.entries.append(self._generated_move(cyc, kind, prev, q, moved, False, line))
        if cyc is None:
            return
        self.report.cycles_expanded += 1

    def _generated_move(self, mv: Move, kind: int, prev: tuple[float, float, float], q: tuple[float, float, float],
                        axes: Iterable[int], with_feed: bool, line: str, role: Role = Role.MOVE) -> Entry:
        """The entry of a G0/G1 line written in place of ``mv`` (a cycle step, a spline
        chord) in the style of its ``line``: its nominal words on ``axes`` in the
        program's distance mode, the F word of ``mv`` when ``with_feed``, and the Move the
        writer rewrites."""
        from postproc.gcode.lexer import scan_words

        unit = mv.unit
        decimals = _unit_decimals(self.opt, unit)
        sep, lower = emit.style_of(line)
        sep = sep or " "
        ending = emit.new_line_ending(line)
        words = ["G0" if kind == RAPID else "G1"]
        if mv.frame is not None:  # words in the frame's coordinates (Sinumerik ROT/SCALE/MIRROR)
            from postproc.gcode import frames

            q_m, prev_m = q, prev
            prev, q = (frames.program_from_machine(mv.frame, mv.shift, p) for p in (prev, q))
            axes = tuple(k for k in range(3) if emit.fmt(q[k] / unit, decimals) != emit.fmt(prev[k] / unit, decimals))
        for k in axes:
            v = (q[k] - prev[k]) / unit if mv.incremental else (q[k] - mv.shift[k]) / unit
            words.append("XYZ"[k] + emit.fmt(v, decimals))
        if with_feed and mv.feed_idx >= 0:
            words.append("F" + mv.words[mv.feed_idx].number)
        text = sep.join(words) + ending
        ws = scan_words(text)
        if ws is None:  # words and blanks only
            raise AssertionError(f"a generated line that is not plain: {text!r}")
        ix, iy, iz = (next((i for i, w in enumerate(ws) if w.letter == a), -1) for a in "XYZ")
        if mv.frame is not None:
            prev, q = prev_m, q_m
        step = Move(mv.lineno, kind, prev, q, mv.r, mv.shift, unit, mv.incremental,
                    mv.arc_absolute, ws, (ix, iy, iz), next((i for i, w in enumerate(ws) if w.letter == "F"), -1), False,
                    mv.feed, mv.rotary, motion_idx=0, role=role, frame=mv.frame, path=mv.path)
        return (text.lower() if lower else text), step, True, kind


def _chord_fits(points: FloatArray, budget: float) -> bool:
    """Whether every point lies within ``budget`` of the chord from the first to the last."""
    a, b = points[0], points[-1]
    ab = b - a
    L2 = float(ab @ ab)
    if L2 == 0.0:
        return bool(np.all(np.linalg.norm(points - a, axis=1) <= budget))
    t = np.clip((points - a) @ ab / L2, 0.0, 1.0)
    return bool(np.all(np.linalg.norm(points - (a + t[:, None] * ab), axis=1) <= budget))
