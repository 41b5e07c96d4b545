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
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import partial
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias, cast

import numpy as np

from postproc.constants import SOLVER_ACCEPT_MM
from postproc.errors import (
    AlreadyCorrectedError,
    MissingSetupError,
    PostprocError,
)
from postproc.fileio import Lines
from postproc.gcode import bulk, cutter, emit
from postproc.gcode.emitter import PlanNeeded, Subdivided
from postproc.gcode.engine_use import accept_residual, prepare_engine
from postproc.gcode.interp import Interpreter, Move, NeedsExpansion, start_position
from postproc.gcode.moves import kind_of
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.planner import Planner
from postproc.gcode.reader import ChunkReader
from postproc.gcode.source import Setup, iter_source_lines
from postproc.gcode.table import Table
from postproc.gcode.vplan import (
    ArcHint,
    Plan,
    PlanMove,
)
from postproc.gcode.writer import ChunkWriter, Entry
from postproc.limits import BoundedWriter

# Lines held while an axis is not yet positioned (they are corrected once it is, a few KB
# each: 1.5 million held took 3.7 GB). Real programs position every axis in their first
# lines; one that never does is refused at its end anyway, this refuses it in bounded memory.
UNKNOWN_AXIS_LINES = 200_000
# Lines taken at a time where a later part's process skips lines (a bound on its memory).
SKIP_LINES = 50_000

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

Write: TypeAlias = bulk.Write


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
        self.accept_residual_mm = accept_residual(engine)
        self.report.accept_residual_mm = self.accept_residual_mm
        self.report.solver = engine.solver
        # the engine calls and the plans of each chunk's table; carries the corrected
        # position and the approach directions from chunk to chunk
        self.planner = Planner(engine, options, self.report, self.interp.used_rotary, setup.context or {},
                               self.accept_residual_mm, start, path)
        self.cutter = cutter.Bound()  # compensated moves corrected so far and their bound
        self.writer = ChunkWriter(options, self.report, start, self.cutter, path)
        self.reader = ChunkReader(self.interp, self.planner, options, self.report, path)
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
        self.reader.report = report

    @property
    def linear_exact(self) -> bool:
        """An affine engine and no added map: every straight move stays one line."""
        return self.planner.linear_exact

    # -- the run -----------------------------------------------------------------------
    @property
    def chunk_lines(self) -> int:
        """Lines read before the moves read are corrected and written (at least)."""
        return self.opt.chunk_lines or (DEFAULT_CHUNK_LINES if self.linear_exact else SEGMENTED_CHUNK_LINES)

    def run(self, lines: Iterable[str], write: Write, progress: Callable[[int], None] | None = None,
            source: deque[tuple[int, str | None]] | None = None, *, skip_until: int = 0,
            boundary: Callable[[int], bool] | None = None, go_on_from: int = 0) -> CorrectReport:
        """Correct ``lines`` into ``write``. For a program corrected in several processes
        (:mod:`postproc.gcode.split`): the chunks that end at or before line ``skip_until``
        are read but not corrected (the modal state advances, nothing is written); after
        the first chunk, the lines before line ``go_on_from`` are not read at all
        (:mod:`postproc.gcode.skipahead`); and ``boundary(lines read)`` is asked after
        each chunk: True stops the run there (the rest is another process's)."""
        # Millions of small short-lived objects, none of them cyclic: the cyclic
        # garbage collector only costs time here (the chunks bound the memory).
        was_enabled = gc.isenabled()
        gc.disable()
        try:
            report = self._run(lines, write, progress, source, skip_until, boundary, go_on_from)
            if self.cutter.moves and self.cutter_known is None:
                raise cutter.Rerun(self.cutter)  # the header must carry the bound
            report.cutter = self.cutter if self.cutter.moves else None
            return report
        finally:
            if was_enabled:
                gc.enable()

    def _run(self, lines: Iterable[str], write: Write, progress: Callable[[int], None] | None = None,
             source: deque[tuple[int, str | None]] | None = None, skip_until: int = 0,
             boundary: Callable[[int], bool] | None = None, go_on_from: int = 0) -> CorrectReport:
        """``lines``: taken a chunk at a time, as a list (:meth:`postproc.fileio.Lines.take`
        where they are :class:`~postproc.fileio.Lines`, the same lists either way);
        ``source``: for an expanded program, the (line, file) each of ``lines`` comes
        from, in order, given as the lines are (its runs of plain lines are read in bulk
        too, each line numbered by its source)."""
        it = iter(lines)
        take = it.take if isinstance(it, Lines) else partial(_take, it)
        rd = self.reader
        self.interp.may_expand = source is None and self.opt.expand
        if source is not None:
            rd.expanded(source, in_bulk=True)
        head, keep = emit.start_lines(it)
        self._write_start(head, keep, write)
        for line in head[keep:]:
            rd.line(line)
        pending = len(head) - keep  # lines in the chunk read
        chunk = size = self.chunk_lines
        while block := take(size):
            size = chunk
            self._read_block(block)
            pending += len(block)
            if pending > UNKNOWN_AXIS_LINES:  # the lines wait for an axis to be positioned: bounded
                self._unknown_too_long(rd.lineno - 1 if source is None else rd.last, pending)
            if pending >= chunk and not any(math.isnan(v) for v in self.interp.state.pos):
                if rd.lineno - 1 > skip_until:
                    self._chunk(rd.entries, write)
                else:  # read, not corrected
                    self._read_only(rd.entries)
                rd.entries.clear()
                pending = 0
                if progress is not None:
                    progress(rd.lineno - 1)
                if boundary is not None and boundary(rd.lineno - 1):
                    self.report.lines_in = rd.lineno - 1
                    return self.report
                if go_on_from > rd.lineno and source is None:
                    pending = self._skip_to(go_on_from, take)
                    size = chunk - pending  # the chunks after end where they would have
                go_on_from = 0
        self._chunk(rd.entries, write)
        if progress is not None:
            progress(rd.lineno - 1)
        self.report.lines_in = rd.lineno - 1
        self.report.g54_assumed_zero = self.interp.implicit_g54
        return self.report

    def _skip_to(self, line: int, take: Callable[[int], list[str]]) -> int:
        """Go on from line ``line``: the lines before it are taken and not read (a later
        part's process, :mod:`postproc.gcode.skipahead`); returns how many were skipped,
        modulo the chunk size."""
        rd = self.reader
        skipped = 0
        while rd.lineno < line and (got := len(take(min(line - rd.lineno, SKIP_LINES)))):
            rd.lineno += got
            skipped += got
        return skipped % self.chunk_lines

    def _read_block(self, block: list[str]) -> None:
        """Read a block of lines into the chunk; on an error, the lines read before it are
        corrected first, so that an error of an earlier line (found when correcting) is
        the one reported, whatever the chunk size."""
        try:
            self.reader.block(block)
        except NeedsExpansion:
            raise
        except PostprocError as exc:
            if not any(math.isnan(v) for v in self.interp.state.pos):
                self._chunk(self.reader.entries, lambda _text: None)
            raise exc from None

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

    def _write_start(self, head: list[str], keep: int, write: Write) -> None:
        """Write the first ``keep`` lines of ``head`` (they stay before the header), then
        the header. Refuses a program that carries a header already (unless forced)."""
        for k, line in enumerate(head):
            if emit.is_header(line) and not self.opt.force:
                raise AlreadyCorrectedError(
                    "this program already carries a postproc header: it has been corrected before",
                    path=self.path, lineno=k + 1, col=1,
                    hint="correct the original program instead, or use --force to correct it again")
        ending = emit.new_line_ending(head[0]) if head else "\n"
        header_rows = emit.header_lines(self.opt.dialect, (self.cal_name, self.cal_sha), self.opt.tolerance_mm,
                                        self._setup_note(), ending, expanded=self.expanded, setup=self.setup,
                                        cycles_expanded=self.opt.cycles == "expand")
        rd = self.reader
        for line in head[:keep]:
            self.interp.feed_line(rd.where(rd.lineno), line)
            write(line if emit.line_ending(line) else line + ending)
            self.report.lines_out += 1
            rd.lineno += 1
        if head and not keep and head[0].startswith("\ufeff"):
            write("\ufeff")  # the byte-order mark stays the file's first bytes
            head[0] = head[0][1:]
        write("".join(header_rows))
        self.report.lines_out += len(header_rows)
        self.report.header_lines = len(header_rows)

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
                    self.planner.check_rounding(e.unit, e.lineno, e.path(0))
            elif type(mv := e[1]) is Move and mv.unit not in checked:
                self.planner.check_rounding(mv.unit, mv.lineno, mv.path)

    def _gather(self, entries: list[Entry | bulk.Run], arcs: bool = True) -> Table:
        """A chunk's table: its moves in order, runs of plain lines as blocks and other
        moves one by one, with every move's nominal target, line, tool vector and rotary
        positions, the (row, Move) of the moves not read in bulk (with the runs' arcs
        unless ``arcs`` is False) and the runs (each given its first row, ``trow``)."""
        # the chunk's moves in order: runs of plain lines as blocks, other moves one by one
        rot: list[dict[str, float]] = []
        general: list[tuple[int, PlanMove]] = []
        read: list[tuple[int, Move]] = []  # the moves read one at a time
        M = 0
        runs: list[bulk.Run] = []
        for e in entries:
            if type(e) is bulk.Run:
                runs.append(e)
                e.trow = M
                rot.extend([{}] * len(e) if e.rot is None else e.rot)
                if e.arcs and arcs:  # planned as any other arc
                    general.extend((M + j, mv) for j, mv in bulk.arc_moves(e))
                M += len(e)
            elif type(mv := e[1]) is Move:
                rot.append(mv.rotary)
                general.append((M, mv))
                read.append((M, mv))
                M += 1
        # every move's nominal target, line and tool vector: runs by slices, the others at once
        Q1 = np.empty((M, 3))
        lns = np.empty(M, dtype=int)
        Rt = np.empty((M, 3))
        kind = np.empty(M, dtype=np.int8)
        for e in runs:
            sl = slice(e.trow, e.trow + len(e))
            Q1[sl] = e.q1
            lns[sl] = e.linenos()
            Rt[sl] = e.r
            kind[sl] = e.kinds()
        if read:
            at = [i for i, _m in read]
            Q1[at] = [m.q1 for _i, m in read]
            lns[at] = [m.lineno for _i, m in read]
            Rt[at] = [m.r for _i, m in read]
            kind[at] = [kind_of(m.role, m.kind) for _i, m in read]
        files = None
        if self.reader.source is not None:  # an expanded program: the file of each row too
            files = np.full(M, self.path, dtype=object)
            if read:
                files[at] = [m.path or self.path for _i, m in read]
            for e in runs:
                paths = e.paths()
                if paths is not None:
                    files[e.trow:e.trow + len(e)] = paths
        return Table(Q1, lns, Rt, rot, general, kind, runs, files)

    def _read_only(self, entries: list[Entry | bulk.Run]) -> None:
        """What a chunk read but not corrected carries to the next (a process correcting a
        later part of the program reads up to it so, :mod:`postproc.gcode.split`): its
        units checked, the runs' blocks let go of (as :meth:`_chunk` does), and, where the
        approach directions are the nominal moves' own (no direction-dependent engine or
        added map), the last nominal target and the direction each axis last moved in.
        The machine is then taken to be where the program put it, uncorrected, as at the
        program's start: the planner's previous target and the writer's emitted position
        are the last nominal target (the first corrected moves, the warm-up, would
        otherwise start from the program's start position, or from no position on an
        axis the chunks read name no more: a fit from a point far off, or unknown,
        splits every move and asks for the engine's subdivision at every sample)."""
        self._check_units(entries)
        self.interp.comp_moves = []  # another process bounds them
        if not (self.engine.direction_dependent or self.opt.added):
            self.planner.skip(self._gather(entries, arcs=False))
        last = _last_target(entries)
        if last is not None:
            q = np.array(last, dtype=float)
            known = ~np.isnan(q)
            for v in (self.planner.prev_nominal, self.planner.prev_target):
                v[known] = q[known]
            self.writer.qe[:] = np.where(known, q, self.writer.qe).tolist()
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
        subdivided = Subdivided()
        while True:  # every engine call is the planner's, before the chunk is written
            try:
                self.writer.write(entries, tab, plans, hints, subdivided, write_out)
                return
            except PlanNeeded as need:
                self.planner.provide(need, tab, plans, subdivided)


def _take(it: Iterator[str], n: int) -> list[str]:
    """The next ``n`` lines of ``it`` (fewer at its end)."""
    return list(islice(it, n))


def _last_target(entries: list[Entry | bulk.Run]) -> Sequence[float] | None:
    """The nominal target of the last move of a chunk's entries (None: it has none)."""
    for e in reversed(entries):
        if type(e) is bulk.Run:
            if len(e):
                return cast("Sequence[float]", e.q1[-1].tolist())
        elif type(mv := e[1]) is Move:
            return mv.q1
    return None


# -- entry points ---------------------------------------------------------------------
def correct_text(text: str, engine: Engine, setup: Setup | None = None, options: CorrectOptions | None = None, *,
                 path: str | None = None, calibration_name: str = "",
                 calibration_sha256: str = "") -> tuple[str, CorrectReport]:
    """Correct G-code ``text``; returns ``(corrected_text, CorrectReport)``."""
    from postproc.gcode.lexer import split_lines

    out: list[str] = []
    lines = split_lines(text)
    job = _Job(engine, setup or Setup(), options or CorrectOptions(), path, calibration_name, calibration_sha256)
    report = _correct_lines(_Program(lambda: Lines([lines]), None, len(lines), len(text)), out.append, out.clear,
                            job)
    return "".join(out), report


@dataclass
class _Job:
    """What a correction run is given: the engine, the setup and options, and the names the
    header records; and the cutter compensation bound, once a first run found it."""

    engine: Engine
    setup: Setup
    options: CorrectOptions
    path: str | None
    calibration_name: str
    calibration_sha256: str
    known: list[cutter.Bound] = field(default_factory=list)

    def corrector(self) -> Corrector:
        c = Corrector(self.engine, self.setup, self.options, path=self.path, calibration_name=self.calibration_name,
                      calibration_sha256=self.calibration_sha256)
        c.cutter_known = self.known[0] if self.known else None
        return c


@dataclass
class _Program:
    """The program a run reads: ``get_lines()`` gives its lines (again on each call);
    ``count``: their number when it may be cut into parts corrected in several processes
    (:mod:`postproc.gcode.split`); ``lines``, ``chars``: its size, for the bounds on the
    output's (``options.limits``); :attr:`read`: the lines read so far; ``at``: the
    expanded line read last and its file."""

    get_lines: Callable[[], Lines]
    count: int | None = None
    lines: int = 0
    chars: int = 0
    at: tuple[int, str | None] = (0, None)
    _counted: Lines | None = field(default=None, repr=False)  # the lines counted() gave last

    @property
    def read(self) -> int:
        """The lines read so far of those :meth:`counted` gave last."""
        return 0 if self._counted is None else self._counted.taken

    def counted(self) -> Lines:
        """The lines, counted as they are read (:attr:`read`)."""
        self._counted = self.get_lines()
        return self._counted


def _correct_lines(prog: _Program, write: Write, restart: Callable[[], None], job: _Job,
                   progress: Callable[[int], None] | None = None) -> CorrectReport:
    """Correct the program's lines; when the program turns out to need expansion,
    ``restart()`` drops what was written and the expanded program is corrected; when it
    is under cutter compensation, it is corrected again with the bound in its header."""
    options = job.options
    bounded = BoundedWriter(write, options.limits.output_lines(prog.lines),
                            lambda: (prog.at[1], prog.at[0]) if prog.at[0] else (job.path, prog.read or None),
                            options.limits.output_chars(prog.chars))

    def dropped() -> None:
        restart()
        bounded.restart()

    try:
        return _once(prog, job, bounded, dropped, progress)
    except cutter.Rerun as again:
        dropped()
        job.known.append(again.bound)
        return _once(prog, job, bounded, dropped, progress)


def _once(prog: _Program, job: _Job, write: Write, dropped: Callable[[], None],
          progress: Callable[[int], None] | None) -> CorrectReport:
    """One run: the program as written (in parts, where it may be cut), else (it needs
    expansion) expanded."""
    options = job.options
    try:
        if prog.count is not None:
            from postproc.gcode import split

            try:
                return split.run(job.corrector, prog.get_lines, write, progress, prog.count, options.processes,
                                 job.path)
            except split.Failed:
                dropped()  # a process for a part failed (not the program): once more, in one
        return job.corrector().run(prog.counted(), write, progress=progress)
    except NeedsExpansion:
        if not options.expand:
            raise
    dropped()
    return _expanded(prog, job, write, progress)


def _expanded(prog: _Program, job: _Job, write: Write, progress: Callable[[int], None] | None) -> CorrectReport:
    """Correct the program expanded (:func:`postproc.gcode.expand.expand`): subprograms,
    loops and parameters written out, each line read with its source line and file."""
    from postproc.gcode.expand import expand

    options = job.options
    lines = list(prog.get_lines())
    source: deque[tuple[int, str | None]] = deque()
    c = job.corrector()

    def texts() -> Iterator[str]:
        # max_lines_out: the expansion is run dry first, and a flat program beyond the output
        # bound refused before any line is corrected
        for sl in expand(lines, path=job.path, dialect=options.dialect,
                         subroutine_path=[Path(p) for p in options.subroutine_path], variables=c.setup.variables,
                         max_iterations=options.limits.max_iterations,
                         max_lines_out=options.limits.output_lines(prog.lines)):
            source.append((sl.lineno, sl.path))
            prog.at = (sl.lineno, sl.path or job.path)
            yield sl.text

    c.expanded = True
    report = c.run(texts(), write, progress=progress, source=source)
    report.expanded = True
    return report


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

            job = _Job(engine, setup or Setup(), options or CorrectOptions(), path, calibration_name,
                       calibration_sha256)
            prog = _Program(lambda: iter_source_lines(Path(source))[1], count, lines_in, size)
            report = _correct_lines(prog, out.write, restart, job, progress)
    except DiskFullError:  # disk full keeps its own exit code
        raise
    except OutputError as exc:  # an output that cannot be written stays an input error for correct (exit 3)
        raise PostprocError(exc.message, path=exc.path, hint=exc.hint) from None
    return report
