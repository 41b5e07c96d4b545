"""The correction pipeline: G-code lines in, corrected G-code lines out, in chunks.

For each chunk of lines (default 20,000) the interpreter yields the moves; all their
targets go to the engine in one vectorised call (``Engine.correction``), then arcs
and moves needing segmentation get their own batched calls; then the lines are
emitted one by one, splicing new numbers into the original text.

Order of corrections: the engine inverse first (``q = F^-1(p*, r)``), then each of
``added`` in turn, ``q += added.delta(p*, context)``, every one evaluated at the
nominal point ``p*``. The safety bound ``max_correction_mm`` applies to the total.
"""

from __future__ import annotations

import gc
import math
import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

import numpy as np

from postproc.constants import (
    DEFAULT_MAX_CORRECTION_MM,
    DEFAULT_TOLERANCE_MM,
    MM_PER_INCH,
)
from postproc.errors import (
    AlreadyCorrectedError,
    MissingSetupError,
    PostprocError,
    UnsupportedGcodeError,
)
from postproc.gcode import bulk, cutter, emit
from postproc.gcode.emitter import _unit_decimals
from postproc.gcode.engine_use import SOLVER_ACCEPT_MM, accept_residual, prepare_engine
from postproc.gcode.interp import Cycle, Interpreter, Move, NeedsExpansion, start_position
from postproc.gcode.path import Setup, iter_source_lines
from postproc.gcode.planner import Planner, Table
from postproc.gcode.state import CANNED_CYCLES, LINE, RAPID
from postproc.gcode.vplan import (
    ArcHint,
    FloatArray,
    Plan,
    PlanMove,
)
from postproc.gcode.writer import ChunkWriter, Entry, Rebase, Store
from postproc.limits import BoundedWriter, Limits

# Lines held while an axis is not yet positioned (they are corrected once it is, a few KB
# each: 1.5 million held took 3.7 GB). Real programs position every axis in their first
# lines; one that never does is refused at its end anyway, this refuses it in bounded memory.
UNKNOWN_AXIS_LINES = 200_000

if TYPE_CHECKING:
    from postproc.engine.base import Engine

# Lines read before they are corrected and written together. Larger chunks gain nothing
# measurable past a few thousand lines (gencam 1M, static: 20,000, 10,000 and 5,000 lines
# within the machine's noise) and cost memory (peak RSS 116, 94 and 81 MB), which a
# program corrected in two processes pays twice.
DEFAULT_CHUNK_LINES = 5_000
# With segmentation (non-affine engines, maps) every move's midpoints go through the
# engine together: smaller chunks keep the peak memory low at the same speed.
SEGMENTED_CHUNK_LINES = 2_000
# Output growth (lines out / lines in) above which the summary warns.
GROWTH_WARN = 5.0
# --cycles auto keeps a cycle block when its tilt (the correction's change between R
# plane and bottom) is within this share of the tolerance left after rounding: the share
# left covers the approach directions the block is written with, which differ from those
# the choice is made with (the machine's last known ones) on a backlash calibration.
CYCLE_KEEP_SHARE = 0.9

Write: TypeAlias = bulk.Write


@dataclass
class CorrectOptions:
    tolerance_mm: float = DEFAULT_TOLERANCE_MM
    decimals: int | None = None  # default 4 in mm, 5 in inch
    max_correction_mm: float = DEFAULT_MAX_CORRECTION_MM
    extrapolate: str = "refuse"  # refuse | clamp | linear
    force: bool = False
    added: list = field(default_factory=list)
    chunk_lines: int | None = None  # default: DEFAULT_CHUNK_LINES, or SEGMENTED_CHUNK_LINES with segmentation
    dialect: str = "generic"  # the controller the program is for: how it is read and written
    expand: bool = True  # flatten parameters, O-words, subprograms and macros (False: refuse them)
    subroutine_path: tuple = ()  # folders searched for o<name> call and M98 subprogram files
    # keep: a cycle stays a cycle (X/Y at the bottom, R and Z along the tool axis); expand: its
    # moves written out as G0/G1, each corrected; auto: kept where its tilt is within the
    # tolerance, else expanded with the rest of its series (to the next G80 or other motion)
    cycles: str = "auto"
    bulk_lane: bool = True  # runs of plain lines read and written per chunk (same output; off for comparison)
    bulk_plan: bool = True  # moves that stay one line or one exact arc settled in bulk (off: sample by sample)
    processes: int = 1  # more: a large program file is cut into parts corrected in that many (postproc.gcode.split)
    limits: Limits = field(default_factory=Limits)  # iterations, output lines, helix turns (postproc.limits)


@dataclass
class CorrectReport:
    lines_in: int = 0
    lines_out: int = 0
    moves: int = 0
    words_changed: int = 0
    lines_changed: int = 0
    lines_inserted: int = 0
    arcs_kept: int = 0
    arcs_linearised: int = 0
    extrapolated_points: int = 0
    max_correction_mm: float = 0.0
    g54_assumed_zero: bool = False
    solver: str = ""  # the engine's inverse solver when it names one (parametric: newton | astatic)
    accept_residual_mm: float = SOLVER_ACCEPT_MM  # largest inverse residual accepted
    max_residual_mm: float = 0.0  # largest inverse residual met
    cycles_kept: int = 0
    splines_linearised: int = 0
    expanded: bool = False  # the program was expanded (subprograms, loops, parameters)
    cycles_expanded: int = 0
    arcs_split: int = 0  # arcs emitted as several exact arcs
    takeups: int = 0  # lines inserted to take up a reversal (backlash)
    header_lines: int = 0  # the postproc header's lines (counted in lines_out)
    cutter: cutter.Bound | None = None  # moves under cutter radius compensation and their bound

    @property
    def growth(self) -> float:
        """The program's own lines out / lines in: the header, which carries the setup
        (one line per few tool lengths), is not the program growing."""
        return (self.lines_out - self.header_lines) / self.lines_in if self.lines_in else 1.0


class Corrector:
    """One correction run: the reader, with the planner and the writer it hands each
    chunk to (see the module docstring)."""

    def __init__(self, engine: Engine, setup: Setup, options: CorrectOptions, *, path: str | None = None,
                 calibration_name: str = "", calibration_sha256: str = "") -> None:
        if options.extrapolate not in ("refuse", "clamp", "linear"):
            raise PostprocError(f"--extrapolate must be refuse, clamp or linear, got {options.extrapolate!r}")
        engine = prepare_engine(engine, options.extrapolate, (setup.context or {}).keys(), path)
        self.engine: Engine = engine
        self.setup = setup
        self.opt = options
        self.path = path
        self.cal_name = calibration_name
        self.cal_sha = calibration_sha256
        self.interp = Interpreter(setup, path, dialect=options.dialect)
        self.interp.max_arc_turns = options.limits.max_arc_turns
        self.interp.require_g54 = bool(setup.start)
        self._report = CorrectReport()
        # where the machine is before the first move: the start position (NaN: unknown);
        # the machine is there uncorrected, so it is also the emitted and the previous target
        start = start_position(setup.start)
        self.expanded = False  # correcting the expanded program (recorded in the header)
        self._series_expanded = False  # --cycles auto: a block of the cycles the controller runs was expanded
        self._spline_kept = False  # a G5 without I/J continues the previous G5 only if it was kept
        self.accept_residual_mm = accept_residual(engine)
        self.report.accept_residual_mm = self.accept_residual_mm
        self.report.solver = engine.solver
        # the engine calls and the plans of each chunk's table; carries the corrected
        # position and the approach directions from chunk to chunk
        self.planner = Planner(engine, options, self.report, self.interp.used_rotary, setup.context or {},
                               self.accept_residual_mm, start, path)
        self.linear_exact = self.planner.linear_exact
        self.bulk_plan = self.planner.bulk_plan
        self.cutter = cutter.Bound()  # compensated moves corrected so far and their bound
        self.writer = ChunkWriter(options, self.report, self.planner, start, path)
        self.writer.cutter = self.cutter  # a take-up is refused on a compensated move's line
        self.cutter_known: cutter.Bound | None = None  # the whole program's, for the header (a second run)

    @property
    def report(self) -> CorrectReport:
        """The run's figures (a process correcting a part of the program starts its own:
        the planner and the writer count into the same)."""
        return self._report

    @report.setter
    def report(self, report: CorrectReport) -> None:
        self._report = report
        self.planner.report = report
        self.writer.report = report

    # -- the run -----------------------------------------------------------------------
    @property
    def chunk_lines(self) -> int:
        """Lines read before the moves read are corrected and written (at least)."""
        return self.opt.chunk_lines or (DEFAULT_CHUNK_LINES if self.linear_exact else SEGMENTED_CHUNK_LINES)

    def run(self, lines: Iterable[str], write: Write, progress: Callable[[int], None] | None = None,
            source: deque[tuple[int, str | None]] | None = None, *, skip_until: int = 0,
            boundary: Callable[[int], bool] | None = None) -> CorrectReport:
        """Correct ``lines`` into ``write``. For a program corrected in several processes
        (:mod:`postproc.gcode.split`): the chunks that end at or before line ``skip_until``
        are read but not corrected (the modal state advances, nothing is written), and
        ``boundary(lines read)`` is asked after each chunk: True stops the run there (the
        rest is another process's)."""
        # Millions of small short-lived objects, none of them cyclic: the cyclic
        # garbage collector only costs time here (the chunks bound the memory).
        was_enabled = gc.isenabled()
        gc.disable()
        try:
            report = self._run(lines, write, progress, source, skip_until, boundary)
            if self.cutter.moves and self.cutter_known is None:
                raise cutter.Rerun(self.cutter)  # the header must carry the bound
            report.cutter = self.cutter if self.cutter.moves else None
            return report
        finally:
            if was_enabled:
                gc.enable()

    # C901: the reading loop; its closures (a line, a block of lines) share the loop's
    # state (line number, whether a run may start) and run for every line read
    def _run(self, lines: Iterable[str], write: Write,  # noqa: C901
             progress: Callable[[int], None] | None = None,
             source: deque[tuple[int, str | None]] | None = None, skip_until: int = 0,
             boundary: Callable[[int], bool] | None = None) -> CorrectReport:
        """``source``: for an expanded program, the (line, file) each of ``lines`` comes
        from, in order (the lines are then read one by one, never in bulk)."""
        it = iter(lines)
        interp = self.interp
        interp.may_expand = source is None and self.opt.expand

        last = [0]  # the source line where() gave last (an expanded program's)

        def where(seq: int) -> int:
            """The line number the interpreter reports for the ``seq``-th line read."""
            if source is None:
                return seq
            ln, p = source.popleft()
            interp.path = p or self.path
            last[0] = ln
            return ln

        head, keep = emit.start_lines(it)
        entries: list[Entry | bulk.Run] = []
        lineno = self._write_start(head, keep, write, where)
        head = head[keep:]

        # runs of plain lines: for every engine whose moves the planner settles in bulk
        use_bulk = (self.linear_exact or self.bulk_plan) and self.opt.bulk_lane and source is None
        run_ok = False  # the modal state lets a run of plain lines start here
        dec_mm = _unit_decimals(self.opt, 1.0)
        dec_in = _unit_decimals(self.opt, MM_PER_INCH)
        pending = 0  # lines in entries

        def feed(line: str) -> None:
            nonlocal lineno, run_ok
            here = where(lineno)
            mv = interp.feed_line(here, line)
            if interp.call_line or interp.cycle_move is not None:
                self._feed_drill_cycle(entries, line, mv, interp, here)
            elif interp.stored_here is not None:
                # G28.1/G30.1: the controller stores where it is, the corrected position
                entries.append((line, Store(interp.stored_here), False, interp.state.motion))
            elif interp.rebase is not None:
                # an offset set from where the machine is: its words follow the correction there
                words, axes, nominal = interp.rebase
                entries.append((line, Rebase(words, axes, nominal, MM_PER_INCH if interp.state.inch else 1.0), False,
                                interp.state.motion))
            elif mv is not None and mv.cycle is not None:
                self._feed_cycle(entries, line, mv, mv.cycle, interp.state.motion)
            elif mv is not None and mv.spline is not None:
                self._feed_spline(entries, line, mv, mv.spline)
            elif mv is not None and mv.fixed:
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
            lineno += 1
            run_ok = use_bulk and bulk.state_allows(interp)

        def feed_block(lines: list[str]) -> None:
            nonlocal lineno, run_ok
            block = bulk.scan(lines) if use_bulk else None
            if block is None:
                for line in lines:
                    feed(line)
                return
            try:
                tlo = block.tlo  # a straight move that sets the tool length (G43 H..) starts a run
                edges = np.diff(np.concatenate([[0], block.plain.view(np.int8), [0]]))
                i, n = 0, len(lines)
                gword, neutral = block.gword, block.neutral
                for a, b in zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(), strict=True):
                    while i < a:
                        feed(lines[i])
                        i += 1
                    while i < b:
                        if tlo and i in tlo and not interp.ended:
                            # the tool length first (again when the interpreter reads the line)
                            interp.set_tool_length(tlo[i], lineno, bulk.tlo_col(lines[i]))
                            run_ok = False
                        # a line naming its own motion word may start a run whatever the modal motion
                        # (a run starts at a line that moves: one that moves nothing is the interpreter's)
                        if not neutral[i] and (run_ok or (not interp.ended and bulk.prime_shift(interp)
                                                          and bulk.state_allows(interp, bool(gword[i])))):
                            dec = dec_in if interp.state.inch else dec_mm
                            run = bulk.read_run(interp, block, i, b, lineno, dec)
                            if run is not None:
                                entries.append(run)
                                self._series_expanded = False  # moves: no cycle series goes on
                                lineno += run.b - i
                                i = run.b
                                run_ok = bulk.state_allows(interp)
                                continue
                        # the modal state does not allow a run here, or an arc the run does
                        # not take (the interpreter reads it, and reports it if it must)
                        feed(lines[i])
                        i += 1
                while i < n:
                    feed(lines[i])
                    i += 1
            finally:
                bulk.finish_block(block)  # the runs read so far stay usable after an error

        for line in head:
            feed(line)
            pending += 1
        chunk = self.chunk_lines
        for block in iter(lambda: list(islice(it, chunk)), []):
            try:
                feed_block(block)
            except NeedsExpansion:
                raise
            except PostprocError as exc:
                # the lines read before this one are corrected first, so that an error of
                # an earlier line (found when correcting) is the one reported, whatever
                # the chunk size
                if not any(math.isnan(v) for v in self.interp.state.pos):
                    self._chunk(entries, lambda _text: None)
                raise exc from None
            pending += len(block)
            if pending > UNKNOWN_AXIS_LINES:  # the lines wait for an axis to be positioned: bounded
                self._unknown_too_long(lineno - 1 if source is None else last[0], pending)
            if pending >= chunk and not any(math.isnan(v) for v in self.interp.state.pos):
                if lineno - 1 > skip_until:
                    self._chunk(entries, write)
                else:  # read, not corrected
                    self._read_only(entries)
                entries.clear()
                pending = 0
                if progress is not None:
                    progress(lineno - 1)
                if boundary is not None and boundary(lineno - 1):
                    self.report.lines_in = lineno - 1
                    return self.report
        self._chunk(entries, write)
        if progress is not None:
            progress(lineno - 1)
        self.report.lines_in = lineno - 1
        self.report.g54_assumed_zero = self.interp.implicit_g54
        return self.report

    def _unknown_too_long(self, lineno: int, waiting: int) -> None:
        """Refuse a program that leaves an axis unknown for more than
        :data:`UNKNOWN_AXIS_LINES` lines (``waiting`` lines read since the last written,
        up to line ``lineno``): they are held until it is known, a few KB each."""
        axis = next((a for a, v in zip("XYZ", self.interp.state.pos, strict=True) if math.isnan(v)), "X")
        raise MissingSetupError(
            f"axis {axis} is still not positioned after {waiting:,} lines, so the correction cannot be evaluated",
            path=self.interp.path or self.path, lineno=lineno, col=1,
            hint=f"give the machine position of {axis} at program start with --start {axis}.. (mm, machine "
                 f"coordinates), or add an absolute move on {axis} near the start")

    def _write_start(self, head: list[str], keep: int, write: Write, where: Callable[[int], int]) -> int:
        """Write the first ``keep`` lines of ``head`` (they stay before the header), then
        the header; returns the number of the next line. Refuses a program that carries a
        header already (unless forced)."""
        for k, line in enumerate(head):
            if emit.is_header(line) and not self.opt.force:
                raise AlreadyCorrectedError(
                    "this program already carries a postproc header: it has been corrected before",
                    path=self.path, lineno=k + 1, col=1,
                    hint="correct the original program instead, or use --force to correct it again")
        ending = emit.new_line_ending(head[0]) if head else "\n"
        header_rows = emit.header_lines(self.opt.dialect, self.cal_name, self.cal_sha, self.opt.tolerance_mm,
                                        self._setup_note(), ending, expanded=self.expanded, setup=self.setup,
                                        cycles_expanded=self.opt.cycles == "expand")
        lineno = 1
        for line in head[:keep]:
            self.interp.feed_line(where(lineno), line)
            write(line if emit.line_ending(line) else line + ending)
            self.report.lines_out += 1
            lineno += 1
        if head and not keep and head[0].startswith("\ufeff"):
            write("\ufeff")  # the byte-order mark stays the file's first bytes
            head[0] = head[0][1:]
        write("".join(header_rows))
        self.report.lines_out += len(header_rows)
        self.report.header_lines = len(header_rows)
        return lineno

    def _setup_note(self) -> str:
        parts = []
        if self.expanded:
            parts.append("expanded: subprograms, loops and parameters written out")
        offs = self.setup.offsets or {}
        if "G54" not in offs:
            parts.append("G54 taken as zero unless named")
        for k in sorted(offs):
            v = offs[k]
            if isinstance(v, dict):
                v = (v.get("X", 0.0), v.get("Y", 0.0), v.get("Z", 0.0))
            parts.append(f"{k}={','.join(f'{x:g}' for x in v)}")
        if self.setup.tool_lengths:
            parts.append("tools " + ",".join(f"{k}={v:g}" for k, v in sorted(self.setup.tool_lengths.items())))
        start = start_position(self.setup.start)
        if self.setup.start:
            parts.append("start " + ",".join(f"{a}{v:.10g}" for a, v in zip("XYZ", start, strict=True) if v == v))
        for name, v in sorted((getattr(self.setup, "home", None) or {}).items()):
            v = v if isinstance(v, dict) else dict(zip("XYZ", v, strict=True))
            parts.append(f"{name}=" + ",".join(f"{a}{float(x):g}" for a, x in sorted(v.items())))
        if self.setup.tool_vector is not None:
            parts.append("tool vector " + ",".join(f"{x:g}" for x in self.setup.tool_vector))
        for a in self.opt.added:
            parts.append(f"map {a.name}")
        if self.cutter_known is not None:
            parts.append(self.cutter_known.note())
        if self.accept_residual_mm > SOLVER_ACCEPT_MM:
            parts.append(f"{self.engine.method} solver {self.report.solver or '?'} "
                         f"accepting residuals up to {self.accept_residual_mm:g} mm")
        return "; ".join(parts)

    # -- one chunk ---------------------------------------------------------------------
    def _check_units(self, entries: list[Entry | bulk.Run]) -> None:
        """Check the output rounding of each unit (mm, inch) the first time a move in it
        comes (:meth:`_check_rounding`)."""
        checked = self.planner.units_checked
        for e in entries:
            if type(e) is bulk.Run:
                if e.unit not in checked:
                    self.planner.check_rounding(e.unit, e.lineno)
            elif type(mv := e[1]) is Move and mv.unit not in checked:
                self.planner.check_rounding(mv.unit, mv.lineno)

    def _gather(self, entries: list[Entry | bulk.Run], arcs: bool = True) -> Table:
        """A chunk's table: its moves in order, runs of plain lines as blocks and other
        moves one by one, with every move's nominal target, line, tool vector and rotary
        positions, the (row, Move) of the moves not read in bulk (with the runs' arcs
        unless ``arcs`` is False) and the runs (each given its first row, ``trow``)."""
        # the chunk's moves in order: runs of plain lines as blocks, other moves one by one
        rot: list[dict[str, float]] = []
        general: list[tuple[int, PlanMove]] = []
        M = 0
        runs: list[bulk.Run] = []
        for e in entries:
            if type(e) is bulk.Run:
                runs.append(e)
                e.trow = M
                rot.extend([{}] * len(e))
                if e.arcs and arcs:  # planned as any other arc
                    general.extend((M + j, mv) for j, mv in bulk.arc_moves(e))
                M += len(e)
            elif type(mv := e[1]) is Move:
                rot.append(mv.rotary)
                general.append((M, mv))
                M += 1
        # every move's nominal target, line and tool vector: runs by slices, the others at once
        Q1 = np.empty((M, 3))
        lns = np.empty(M, dtype=int)
        Rt = np.empty((M, 3))
        for e in runs:
            sl = slice(e.trow, e.trow + len(e))
            Q1[sl] = e.q1
            lns[sl] = np.arange(e.lineno, e.lineno + len(e))
            Rt[sl] = e.r
        if general:
            at = [i for i, _m in general]
            Q1[at] = [m.q1 for _i, m in general]
            lns[at] = [m.lineno for _i, m in general]
            Rt[at] = [m.r for _i, m in general]
        return Table(Q1, lns, Rt, rot, general, runs)

    def _read_only(self, entries: list[Entry | bulk.Run]) -> None:
        """What a chunk read but not corrected carries to the next (a process correcting a
        later part of the program reads up to it so, :mod:`postproc.gcode.split`): its
        units checked, the runs' blocks let go of (as :meth:`_chunk` does), and, where the
        approach directions are the nominal moves' own (no direction-dependent engine or
        added map), the last nominal target and the direction each axis last moved in."""
        self._check_units(entries)
        self.interp.comp_moves = []  # another process bounds them
        if not (self.engine.direction_dependent or self.opt.added):
            self.planner.skip(self._gather(entries, arcs=False))
        for e in entries:
            if type(e) is bulk.Run:
                e.block.runs = []

    def _chunk(self, entries: list[Entry | bulk.Run], write_out: Write) -> None:
        """Plan the chunk read (``entries``) as one table, then write it."""
        self._check_units(entries)
        cutter.check_chunk(self)
        tab = self._gather(entries)
        plans: dict[int, Plan] = {}
        hints: dict[int, ArcHint] = {}
        if len(tab):
            plans, hints = self.planner.plan(tab)
        for run in tab.runs:
            # arcs the bulk planner did not settle: written one by one by the general emitter
            run.cut.extend(j for j in run.arcs if run.trow + j not in hints)
        self.writer.write(entries, tab, plans, hints, write_out)

    # -- moves written out for a cycle or a spline -------------------------------------
    @staticmethod
    def _generated_move(mv: Move, kind: int, prev: tuple[float, float, float], q: tuple[float, float, float],
                        axes: Iterable[int], with_feed: bool, decimals: int, sep: str, lower: bool, ending: str,
                        planned: bool = False) -> Entry:
        """The entry of a G0/G1 line written in place of ``mv`` (a cycle step, a spline
        chord): its nominal words on ``axes`` in the program's distance mode, the F word
        of ``mv`` when ``with_feed``, and the Move the corrector rewrites."""
        from postproc.gcode.lexer import scan_words

        unit = mv.unit
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
                    mv.feed, mv.rotary, motion_idx=0, planned=planned, frame=mv.frame)
        return (text.lower() if lower else text), step, True, kind

    # -- splines -------------------------------------------------------------------------
    def _feed_spline(self, entries: list[Entry | bulk.Run], line: str, mv: Move,
                     spline: list[tuple[float, float]]) -> None:
        """Queue a G5/G5.1 spline as the fewest G1 chords whose corrected path stays within
        --tolerance of the corrected spline (checked at samples 1/10 of the tolerance apart
        in chord error)."""
        from postproc.gcode.interp import spline_points, spline_samples

        tol = self.opt.tolerance_mm - self.planner.round_err(mv.unit)
        has_ij = any(w.letter == "I" for w in mv.words)
        kept = self.linear_exact and (has_ij or self._spline_kept) and self._spline_unmoved(mv, spline)
        self._spline_kept = kept
        if kept:
            # an affine correction maps the spline onto itself: the line stays as it is
            entries.append((line, None, True, LINE))
            entries.append(("", replace(mv, q0=mv.q1, fixed=True, spline=None, words=[],
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
                              [mv.rotary] * len(s), lineno)
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
        unit = mv.unit
        dec = _unit_decimals(self.opt, unit)
        if mv.prefix_words:
            text = sep.join(mv.prefix_words)
            entries.append(((text.lower() if lower else text) + ending, None, False, None))
        prev = mv.q0
        for n, k in enumerate(keep[1:]):
            q = tuple(nom[k].tolist()) if k < len(s) - 1 else mv.q1
            entries.append(self._generated_move(mv, LINE, prev, q, (0, 1), n == 0, dec, sep, lower, ending,
                                                planned=True))
            prev = q
        self.report.splines_linearised += 1

    def _spline_unmoved(self, mv: Move, spline: list[tuple[float, float]]) -> bool:
        """Whether the correction at the spline's control points rounds to nothing (for an
        affine correction the corrected spline is then the spline itself)."""
        pts = np.array([(x, y, mv.q1[2]) for x, y in spline], dtype=float)
        n = len(pts)
        t = self.planner.corrected(pts, np.broadcast_to(np.asarray(mv.r, dtype=float), pts.shape),
                           np.broadcast_to(self.planner.dirs, pts.shape), [mv.rotary] * n, np.full(n, mv.lineno))
        d = _unit_decimals(self.opt, mv.unit)
        return bool(np.abs(t - pts).max() / mv.unit < emit.HALF_UNIT[d])

    # -- canned cycles -------------------------------------------------------------------
    def _feed_cycle(self, entries: list[Entry | bulk.Run], line: str, mv: Move, c: Cycle, motion: int | None) -> None:
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
                entries.append((line, mv, True, motion))
                bottom, rpoint = c.holes[0]
                entries.append(("", replace(mv, q1=rpoint, cycle=None, probe=1), False, motion))
                return
            # several holes from one line, or increments: one word cannot carry each hole's
            # correction; kept only where nothing is corrected
            for bottom, rpoint in c.holes:
                for q in (bottom, rpoint):
                    entries.append(("", replace(mv, q1=q, cycle=None, probe=2), False, motion))
            entries.append((line, None, True, None))
            end = c.steps[-1][1] if c.steps else mv.q0
            entries.append(("", replace(mv, q0=end, q1=end, cycle=None, fixed=True, words=[],
                                          axis_idx=(-1, -1, -1)), False, None))
            return
        ending = emit.new_line_ending(line)
        sep, lower = emit.style_of(line)
        sep = sep or " "
        d = _unit_decimals(self.opt, mv.unit)
        for step in emit.cycle_lines(line, mv, c, retract=self.opt.cycles != "expand"):
            if isinstance(step, str):
                entries.append((step, None, False, None))
            else:
                kind, prev, q, moved, first_feed = step
                entries.append(self._generated_move(mv, kind, prev, q, moved, first_feed, d, sep, lower, ending))
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
                           [mv.rotary] * n, np.full(n, mv.lineno))
        if c.repeats == 1 and not mv.incremental:
            drift = math.hypot(t[1, 0] - t[0, 0], t[1, 1] - t[0, 1])
            return drift <= CYCLE_KEEP_SHARE * (self.opt.tolerance_mm - self.planner.round_err(mv.unit))
        d = _unit_decimals(self.opt, mv.unit)
        return bool(np.abs(t - pts).max() / mv.unit < emit.HALF_UNIT[d])

    def _feed_drill_cycle(self, entries: list[Entry | bulk.Run], line: str, mv: Move | None,
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
                f"Sinumerik {call} (drilling cycle call): read only when written as its moves", path=self.path, lineno=lineno, col=1,
                hint="give --cycles expand or auto to write each hole as its G0/G1 moves, each corrected")
        d = _unit_decimals(self.opt, cyc.unit if cyc is not None else 1.0)
        ending = emit.new_line_ending(line)
        sep, lower = emit.style_of(line)
        for step in emit.drill_cycle_lines(line, bool(interp.call_line), mv, cyc, interp.state.motion):
            if step is None:
                entries.append((line, mv, interp.motion_word, interp.state.motion))
            elif isinstance(step, str):
                entries.append((step, None, False, None))
            elif cyc is not None:  # (a step is made only of a cycle)
                kind, prev, q, moved, _first = step
                entries.append(self._generated_move(cyc, kind, prev, q, moved, False, d, sep or " ", lower, ending))
        if cyc is None:
            return
        self.report.cycles_expanded += 1

    # -- emission ----------------------------------------------------------------------


def _chord_fits(points: FloatArray, budget: float) -> bool:
    """Whether every point lies within ``budget`` of the chord from the first to the last."""
    a, b = points[0], points[-1]
    ab = b - a
    L2 = float(ab @ ab)
    if L2 == 0.0:
        return bool(np.all(np.linalg.norm(points - a, axis=1) <= budget))
    t = np.clip((points - a) @ ab / L2, 0.0, 1.0)
    return bool(np.all(np.linalg.norm(points - (a + t[:, None] * ab), axis=1) <= budget))


# -- entry points ---------------------------------------------------------------------
def correct_text(text: str, engine: Engine, setup: Setup | None = None, options: CorrectOptions | None = None, *,
                 path: str | None = None, calibration_name: str = "",
                 calibration_sha256: str = "") -> tuple[str, CorrectReport]:
    """Correct G-code ``text``; returns ``(corrected_text, CorrectReport)``."""
    from postproc.gcode.lexer import split_lines

    out: list[str] = []
    lines = split_lines(text)
    report = _correct_lines(lambda: lines, out.append, out.clear, engine, setup, options, path,
                            calibration_name, calibration_sha256, input_lines=len(lines), input_chars=len(text))
    return "".join(out), report


def _correct_lines(get_lines: Callable[[], Iterable[str]], write: Write, restart: Callable[[], None], engine: Engine,
                   setup: Setup | None, options: CorrectOptions | None, path: str | None, calibration_name: str,
                   calibration_sha256: str, progress: Callable[[int], None] | None = None,
                   count: int | None = None, input_lines: int = 0, input_chars: int = 0) -> CorrectReport:
    """Correct the lines ``get_lines()`` gives; when the program turns out to need
    expansion, ``restart()`` drops what was written and the expanded program is corrected.
    ``count``: the number of lines, when the program may be cut into parts corrected in
    several processes (:mod:`postproc.gcode.split`); ``input_lines``, ``input_chars``: the
    program's size, for the bounds on the output's (``options.limits``)."""
    from postproc.gcode.interp import NeedsExpansion

    setup = setup or Setup()
    options = options or CorrectOptions()
    known: list[cutter.Bound] = []  # the cutter compensation bound, once a first run found it
    read = 0  # lines read (of the program as written, or as expanded: at[0])
    at: list[tuple[int, str | None]] = [(0, path)]  # the expanded line read last and its file

    def counted(lines: Iterable[str]) -> Iterator[str]:
        nonlocal read
        for read, line in enumerate(lines, start=1):  # noqa: B007 - read is the count so far
            yield line

    bounded = BoundedWriter(write, options.limits.output_lines(input_lines),
                            lambda: (at[-1][1], at[-1][0]) if at[-1][0] else (path, read or None),
                            options.limits.output_chars(input_chars))
    write = bounded

    def dropped() -> None:
        restart()
        bounded.restart()

    def corrector() -> Corrector:
        c = Corrector(engine, setup, options, path=path, calibration_name=calibration_name,
                      calibration_sha256=calibration_sha256)
        c.cutter_known = known[0] if known else None
        return c

    def once() -> CorrectReport:
        """One run: the program as written, else (it needs expansion) expanded."""
        try:
            if count is not None:
                from postproc.gcode import split

                try:
                    return split.run(corrector, get_lines, write, progress, count, options.processes, path)
                except split.Failed:
                    dropped()  # a process for a part failed (not the program): once more, in one
            return corrector().run(counted(get_lines()), write, progress=progress)
        except NeedsExpansion:
            if not options.expand:
                raise
        from postproc.gcode.expand import expand

        dropped()
        lines = list(get_lines())
        source: deque[tuple[int, str | None]] = deque()
        c = corrector()

        def texts() -> Iterator[str]:
            for sl in expand(lines, path=path, dialect=options.dialect,
                             subroutine_path=[Path(p) for p in options.subroutine_path], variables=c.setup.variables,
                             max_iterations=options.limits.max_iterations):
                source.append((sl.lineno, sl.path))
                at[-1] = (sl.lineno, sl.path or path)
                yield sl.text

        c.expanded = True
        report = c.run(texts(), write, progress=progress, source=source)
        report.expanded = True
        return report

    try:
        return once()
    except cutter.Rerun as again:
        dropped()
        known.append(again.bound)
        return once()


def correct_file(source: str | os.PathLike[str], output: str | os.PathLike[str], engine: Engine,
                 setup: Setup | None = None, options: CorrectOptions | None = None, *, calibration_name: str = "",
                 calibration_sha256: str = "", progress: Callable[[int], None] | None = None) -> CorrectReport:
    """Correct the program at ``source`` into ``output`` safely (``postproc.fileio.output_path``).

    On any error nothing is left at ``output`` (an existing file there is untouched); a
    symbolic link is written through, a device or pipe written directly.
    """
    from postproc.errors import DiskFullError, OutputError
    from postproc.fileio import output_path

    # an empty program (no bytes, or blanks and line ends only) is refused: nothing to
    # correct, and most often a file that was not written completely
    try:
        with open(source, "rb") as fh:
            empty = not fh.read(65536).strip() and not fh.read(1)
    except OSError:
        empty = False  # the reader names the problem
    if empty:
        raise PostprocError("the program is empty: nothing to correct", path=str(source),
                            hint="check that this is the program you meant (was it written completely?)")
    from postproc.gcode import forking, split

    path, _lines = iter_source_lines(Path(source))
    try:
        lines_in = split.count_lines(str(source))
        size = os.path.getsize(source)
    except OSError:
        lines_in = size = 0  # the reader names the problem
    count = lines_in if lines_in and options is not None and options.processes > 1 and forking.available() else None
    # staged: a device or pipe gets the whole program at the end (the run may start over)
    try:
        with output_path(output, stage_special=True) as tmp, \
                open(tmp, "w", encoding="utf-8", errors="surrogateescape", newline="") as out:
            def restart() -> None:
                out.seek(0)
                out.truncate()

            report = _correct_lines(lambda: iter_source_lines(Path(source))[1], out.write, restart, engine, setup,
                                    options, path, calibration_name, calibration_sha256, progress, count,
                                    input_lines=lines_in, input_chars=size)
    except DiskFullError:  # disk full keeps its own exit code
        raise
    except OutputError as exc:  # an output that cannot be written stays an input error for correct (exit 3)
        raise PostprocError(exc.message, path=exc.path, hint=exc.hint) from None
    return report
