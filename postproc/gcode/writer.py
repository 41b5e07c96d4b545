"""The writer: a chunk's lines written in order, from its planned table.

:meth:`ChunkWriter.write` walks the chunk's entries (:data:`Entry`, and the runs of plain
lines of :mod:`postproc.gcode.bulk`) with the table's corrected targets and the plans
and hints the planner made (:mod:`postproc.gcode.planner`): a line that moves nothing is
passed as it is; a run is written by :func:`postproc.gcode.bulk.emit_run`; every other
move by the emitter (:mod:`postproc.gcode.emitter`: only the words that change, lines
inserted before their line, arcs kept or fitted); kept canned cycles, offsets set from
the position and stored positions here. The writer holds what the controller will
hold: the emitted position ``qe``, its modal motion, the cycle's Z and R words, the
positions it stored.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TypeAlias, final

from postproc.errors import SafetyError
from postproc.gcode import bulk, cutter, emit, numfmt
from postproc.gcode.emitter import EmitterMixin, PlanNeeded, Subdivided, _unit_decimals, round_err
from postproc.gcode.lexer import Word, split_lines
from postproc.gcode.moves import Cycle, Move, Role
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.table import Table
from postproc.gcode.vplan import ArcHint, FloatArray, Plan

Write: TypeAlias = bulk.Write


@final
class Store:
    """A G28.1/G30.1 line: the controller stores the position it is at."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name  # "G28" or "G30"


@final
class Rebase:
    """A line that sets an offset from where the machine is (G92, G10 L20, G10 L10/L11)."""

    __slots__ = ("words", "axes", "nominal", "unit")

    def __init__(self, words: list[Word], axes: list[tuple[int, int]], nominal: Sequence[float],
                 unit: float) -> None:
        self.words = words  # the line's words
        self.axes = axes  # [(word index, axis), ...] of the values taken from the position
        self.nominal = nominal  # the nominal gauge position when the line runs
        self.unit = unit  # mm per program unit then


#: a line queued for its chunk: (its text, "" for a move it makes without a line of its
#: own; its Move, the offset or stored position it sets, or None when it moves nothing;
#: whether it names a motion word; the program's modal motion after it)
Entry: TypeAlias = "tuple[str, Move | Rebase | Store | None, bool, int | None]"


@final
class _Chunk:
    """A chunk being written: its targets, plans and hints, the text written so far, where
    each entry's text starts in it (``marks``: (index, its line, 1: every line is that
    line's, 0: a line passed as it is, the file of that line: None for the program's
    own), or (index, j, 2: a run's lines one by one from its line j, the run)), the next
    row of the table, the lines passed as they are, the runs' prepared emissions, and the
    last saved state (:meth:`ChunkWriter._save`)."""

    __slots__ = ("T", "plans", "hints", "out", "marks", "k", "passed", "prepared", "blocks", "saved")

    def __init__(self, T: FloatArray, plans: dict[int, Plan], hints: dict[int, ArcHint]) -> None:
        self.T = T
        self.plans = plans
        self.hints = hints
        self.out: list[str] = []  # the chunk's text, written at once
        self.marks: list[tuple[int, int, int, bulk.Run | str | None]] = []
        self.k = 0
        self.passed = 0
        self.prepared: dict[int, bulk.Emission] = {}
        self.blocks: list[bulk.Block] = []
        self.saved: tuple = ()


@final
class _RunMarks:
    """The marks of where the text written next comes from while ``run`` (part ``part``
    of entry ``i``) is written (:func:`postproc.gcode.bulk.emit_run`), and the writer's
    saves of its state within the run."""

    __slots__ = ("w", "o", "i", "part", "run")

    def __init__(self, w: ChunkWriter, o: _Chunk, i: int, part: int, run: bulk.Run) -> None:
        self.w, self.o, self.i, self.part, self.run = w, o, i, part, run

    def __call__(self, j: int, whole: bool) -> None:
        o = self.o
        run = self.run
        o.marks.append((len(o.out), run.line(j), 1, run.path(j)) if whole else (len(o.out), j, 2, run))

    def save(self, y: int) -> None:
        self.w._save(self.o, self.i, (self.part, y))


class ChunkWriter(EmitterMixin):
    """Writes a chunk's lines (see the module docstring); carries what the controller
    holds from one chunk to the next."""

    def __init__(self, options: CorrectOptions, report: CorrectReport, start: Sequence[float],
                 compensated: cutter.Bound, path: str | None = None) -> None:
        self.opt = options
        self.report = report
        self.path = path
        # the machine is at the start position uncorrected (NaN: unknown)
        self.qe = list(start)  # emitted gauge position (what the controller will hold)
        self.emitted_motion: int | None = None  # the motion the controller holds (None: none yet)
        self._cycle_z: float | None = None  # Z and R words of the cycle the controller holds
        self._cycle_rz: float | None = None
        self._cycle_nominal: tuple | None = None  # nominal (Z, R) of the last kept cycle block
        self._stored: dict[str, list[float]] = {}  # G28.1/G30.1: what the controller stored
        self._long_line = emit.limit_pattern(options.dialect)  # finds a line that may pass the dialect's limits
        self._decimals: dict[float, int] = {}
        self.cutter = compensated  # the compensated moves read (a take-up is refused on their lines)
        self._plans: dict[int, Plan] = {}
        self._subdivided = Subdivided()
        self._resume: _Chunk | None = None  # the chunk to write on from its saved state

    def write(self, entries: list[Entry | bulk.Run], tab: Table, plans: dict[int, Plan],
              hints: dict[int, ArcHint], subdivided: Subdivided,
              write_out: Write) -> None:
        """Write the chunk's ``entries``, planned in ``tab`` (``plans``, ``hints``,
        ``subdivided``: the planner's), as one text to ``write_out``.

        The writer makes no engine call. Where it needs a plan or a subdivision the
        planner has not made (an arc whose hint does not hold for its ends as written, a
        fit that follows the corrected curve more finely than its samples), it raises
        :class:`postproc.gcode.emitter.PlanNeeded`, its state back where it saved it, just
        before that move (before an entry whose move has a hint or a plan; in a run,
        before the line it hands to the general emitter); the caller has the planner make
        it and calls again with the same arguments, and the writer goes on from there."""
        o, self._resume = self._resume, None
        at: tuple[int, int] | None = None  # where in its first entry a resumed chunk goes on
        if o is None:
            o = _Chunk(tab.target, plans, hints)
            first = 0
            self._save(o, 0)
        else:
            first, at = o.saved[0], o.saved[-1]
        self._plans, self._subdivided = plans, subdivided
        try:
            for i in range(first, len(entries)):
                e = entries[i]
                if type(e) is bulk.Run:
                    self._write_run(e, o, i, at)
                    at = None
                    continue
                if o.k in o.hints or o.k in o.plans:  # a move that may need a plan or a subdivision
                    self._save(o, i)
                self._write_entry(e, o)
        except PlanNeeded:
            self._restore(o)
            self._resume = o
            raise
        self._plans, self._subdivided = {}, Subdivided()  # the chunk's own
        for blk in o.blocks:
            blk.runs = []  # runs point back to their block: no cycle left for the (disabled) collector
        self.report.lines_out += o.passed
        text = "".join(o.out)
        # some line may pass the limits only if the longest does (searched alone, not the text)
        if self._long_line.search(max(text.split("\n"), key=len)):
            text = self._fit_lines(o.out, o.marks)
        write_out(text)

    def _save(self, o: _Chunk, i: int, at: tuple[int, int] | None = None) -> None:
        """Save the writer's state before entry ``i`` of chunk ``o`` (``at``: within it, a
        run, from its part and block line; see :meth:`_write_run`): what the controller
        holds, the report's figures and how much of the chunk is written."""
        o.saved = (i, list(self.qe), self.emitted_motion, self._cycle_z, self._cycle_rz, self._cycle_nominal,
                   dict(self._stored), vars(self.report).copy(), len(o.out), len(o.marks), o.k, o.passed, at)

    def _restore(self, o: _Chunk) -> None:
        """Put the writer's state back as :meth:`_save` saved it last."""
        (_i, qe, self.emitted_motion, self._cycle_z, self._cycle_rz, self._cycle_nominal, stored, report,
         n_out, n_marks, o.k, o.passed, _at) = o.saved
        self.qe[:] = qe
        self._stored = dict(stored)
        vars(self.report).update(report)
        del o.out[n_out:], o.marks[n_marks:]

    def _write_run(self, e: bulk.Run, o: _Chunk, i: int, at: tuple[int, int] | None) -> None:
        """Write a run of plain lines (entry ``i``): in bulk, but for the arcs and lines that
        must be split, which the general emitter writes. ``at``: go on from where the
        writer's state was saved within it, (its part, the block line to write on from, or
        -1: the part's start); the parts are the run itself, or the pieces
        :func:`bulk.split_run` cuts it into."""
        out, T, k = o.out, o.T, o.k
        part0, y0 = (0, -1) if at is None else at
        if at is None:
            o.marks.append((len(out), 0, 2, e))
        em = o.prepared.get(id(e.block))
        if em is None:
            em = o.prepared[id(e.block)] = bulk.prepare_emission(e.block, T)
            o.blocks.append(e.block)
        if not e.cut:
            bulk.emit_run(self, e, em, T, out.append, o.hints, _RunMarks(self, o, i, 0, e), y0)
        else:  # arcs and lines that must be split: written by the general emitter
            for p, part in enumerate(bulk.split_run(e, sorted(set(e.cut)))):
                if p < part0:
                    continue
                y = y0 if p == part0 else -1
                if type(part) is bulk.Run:
                    if y < 0:
                        o.marks.append((len(out), 0, 2, part))
                    bulk.emit_run(self, part, em, T, out.append, o.hints, _RunMarks(self, o, i, p, part), y)
                    continue
                j, fm = part
                line = e.block.lines[e.a + j]
                hint = o.hints.get(k + j)
                self._save(o, i, (p, -1))  # its plan or a fit's subdivision may have to be made first
                o.marks.append((len(out), e.line(j), 1, e.path(j)))
                if hint is not None:
                    self.emit_hinted_arc(line, fm.to_move(line), T[k + j].tolist(), hint, out.append)
                else:
                    self.emit_move(line, fm.to_move(line), T[k + j].tolist(), o.plans.get(k + j), out.append)
        o.k += len(e)

    def _write_entry(self, e: Entry, o: _Chunk) -> None:
        """Write a line read by the interpreter: passed as it is where it moves nothing,
        else its move (row ``o.k`` of the table) corrected."""
        out, T, k = o.out, o.T, o.k
        write = out.append
        line, mv, motion_word, prog_motion = e
        o.marks.append((len(out), getattr(mv, "lineno", 0), 0 if mv is None or type(mv) is Store else 1,
                        getattr(mv, "path", None)))
        if type(mv) is Rebase:
            self._emit_rebase(line, mv, write)
            return
        if type(mv) is Store:
            self._stored[mv.name] = list(self.qe)
            write(line)
            o.passed += 1
            return
        if mv is None:
            write(line)
            o.passed += 1
            if motion_word:
                self.emitted_motion = prog_motion
            return
        o.k += 1
        role = mv.role
        if role is Role.R_POINT:  # used by the cycle block before it
            pass
        elif role is Role.HOLE:  # of a cycle block kept as it is: checked here
            self._check_unmoved(mv, T[k])
        elif mv.cycle is not None:
            self._emit_cycle(line, mv, mv.cycle, T[k].tolist(), T[k + 1].tolist(), write)
        elif role is Role.AT:  # the machine is at a stored position, uncorrected
            self.qe = list(mv.q1)
            if mv.stored is not None and mv.stored[0] in self._stored:
                # a position the program stored: the controller stored its corrected one
                for ax in mv.stored[1]:
                    self.qe[ax] = self._stored[mv.stored[0]][ax]
        elif mv.then is not None:  # G28/G30: only the intermediate point's own words change
            self._emit_words_only(line, mv, T[k].tolist(), write)
        else:
            hint = o.hints.get(k)
            if hint is not None:
                self.emit_hinted_arc(line, mv, T[k].tolist(), hint, write)
            else:
                self.emit_move(line, mv, T[k].tolist(), o.plans.get(k), write)

    def _fit_lines(self, out: list[str], marks: list[tuple[int, int, int, bulk.Run | str | None]]) -> str:
        """A chunk's text (``out``, its entries' ``marks``) with every line it writes
        within the dialect's limits: a line that passes them gets its comments on a line
        of their own before it (:func:`emit.fit_line`), or is refused naming its line and
        column. Lines passed as they are stay (the input has them so), in a run too."""
        pieces: list[str] = []
        ends = [m[0] for m in marks[1:]] + [len(out)]
        pieces.extend(out[:marks[0][0]] if marks else out)
        for (a, at, kind, src), b in zip(marks, ends, strict=True):
            run, path = (src, None) if type(src) is bulk.Run else (None, src)
            text = "".join(out[a:b])
            if kind == 0 or not self._long_line.search(text):
                pieces.append(text)
                continue
            # the lines as the reader numbers them: a form feed or vertical tab is a blank
            # inside a line, where str.splitlines would end the line there
            for n, line in enumerate(split_lines(text)):
                if run is not None and run.inert_at(at + n):  # a run's line that moves nothing: as it is
                    pieces.append(line)
                    continue
                fitted, over = emit.fit_line(self.opt.dialect, line)
                if over is not None:
                    col, what = over
                    raise SafetyError(
                        f"{what}, once corrected",
                        path=(run.path(at + n) if run is not None else path) or self.path,
                        lineno=run.text_line(at + n) if run is not None else at,
                        col=col, hint="shorten the line (a comment moved onto a line of its own would not "
                                      "do) or give the --dialect it is for")
                if len(fitted) > 1:
                    self.report.lines_out += 1
                    self.report.lines_inserted += 1
                pieces.extend(fitted)
        return "".join(pieces)

    def _emit_rebase(self, line: str, rb: Rebase, write: Write) -> None:
        """Write a G92 / G10 L20 / G10 L10-L11 line so that the offset the controller sets
        from where it is (the corrected position) is the nominal one: each value it
        subtracts moves by the correction there."""
        unit = rb.unit
        d = _unit_decimals(self.opt, unit)
        edits = []
        for idx, k in rb.axes:
            delta = (self.qe[k] - rb.nominal[k]) / unit
            if not math.isfinite(delta):
                continue
            _l, num, start, end, _p = rb.words[idx]
            own = float(num)
            text = numfmt.word_text(own + delta, own, emit.decimals_of(num), d)
            if text:  # else within half an output step: kept as written
                edits.append((start, end, text))
        self._write_line(line, edits, write)

    def _check_unmoved(self, mv: Move, target: FloatArray) -> None:
        """A cycle block that stays as it is, with several holes or increments: refuse it
        when a hole's correction does not round to nothing."""
        d = _unit_decimals(self.opt, mv.unit)
        moved = max(abs(t - q) for t, q in zip(target, mv.q1, strict=True)) / mv.unit
        if moved >= numfmt.half_unit(d):
            how = "in G91 (incremental)" if mv.incremental else "with L/K repeats"
            raise SafetyError(
                f"canned cycle G{mv.kind / 10:g} {how}: one line drills several holes or moves by increments, "
                f"so its words cannot carry each hole's correction ({moved * mv.unit * 1000:.3g} um here)",
                path=mv.path or self.path, lineno=mv.lineno,
                hint="give --cycles expand to write the cycle as G0/G1 moves, each corrected")

    def _emit_cycle(self, line: str, mv: Move, c: Cycle, t_bottom: list[float], t_r: list[float],
                    write: Write) -> None:
        """Write a kept cycle block (``mv``, its cycle ``c``): X/Y at the corrected bottom, Z
        and R along the tool axis."""
        unit, shift = mv.unit, mv.shift
        d = _unit_decimals(self.opt, unit)
        rerr = round_err(self.opt, unit)
        drift = math.hypot(t_r[0] - t_bottom[0], t_r[1] - t_bottom[1])
        if drift > self.opt.tolerance_mm - rerr:
            raise SafetyError(
                f"canned cycle G{c.code / 10:g}: the correction moves the hole's axis by {drift * 1000:.3g} um "
                f"between its R plane and its bottom, more than --tolerance {self.opt.tolerance_mm:g} mm",
                path=mv.path or self.path, lineno=mv.lineno,
                hint="give --cycles expand to write the cycle as G0/G1 moves, each corrected")
        self.report.moves += 1
        self.report.cycles_kept += 1
        qe = self.qe
        z_before = qe[2]
        flat = replace(mv, axis_idx=(mv.axis_idx[0], mv.axis_idx[1], -1))
        edits, added = self.axis_words(flat, (t_bottom[0], t_bottom[1], qe[2]), qe, d)
        sep, lower = emit.style_of(line)
        same_group = self._cycle_nominal == (c.z_mm, c.r_mm)
        self._cycle_nominal = (c.z_mm, c.r_mm)
        held = [self._cycle_z, self._cycle_rz]  # the Z and R words the controller holds
        written: list[float] = []  # ... and holds after this block
        for n, (letter, idx, t, nominal) in enumerate((("Z", mv.axis_idx[2], t_bottom[2], c.z_mm),
                                                       ("R", c.r_idx, t_r[2], c.r_mm))):
            v = (t - shift[2]) / unit
            if idx < 0 and not same_group:
                # the controller holds the program's own value (given earlier, or R taken as
                # the initial level)
                held[n] = (nominal - shift[2]) / unit
            if idx >= 0:
                _l, num, start, end, _p = mv.words[idx]
                val = float(num)
                text = numfmt.word_text(v, val, emit.decimals_of(num), d)
                if text:  # else within half an output step: kept as written
                    edits.append((start, end, text))
                    val = float(text)
            else:
                h = held[n]
                # a word where the controller holds none, or one half an output step or more away
                text = emit.fmt(v, d) if h is None else numfmt.added_text(v, h, 1.0, v, d)
                if text:
                    added.append(letter + text)
                    val = float(text)
                elif h is not None:  # within half an output step of the word it holds
                    val = h
            written.append(val)
        self._cycle_z, self._cycle_rz = written
        if added:
            pos = self._insert_pos(mv)
            text = "".join(sep + w for w in added)
            edits.append((pos, pos, text.lower() if lower else text))
        r_machine = written[1] * unit + shift[2]
        qe[2] = r_machine if c.retract_r else max(z_before, r_machine)
        self.emitted_motion = c.code
        self._write_line(line, edits, write)

    def _emit_words_only(self, line: str, mv: Move, target: list[float], write: Write) -> None:
        """Rewrite the axis words a line names, adding none and keeping the modal motion
        (G28/G30 intermediate points)."""
        self.report.moves += 1
        d = _unit_decimals(self.opt, mv.unit)
        edits, _added = self.axis_words(mv, target, self.qe, d, present_only=True)
        self._write_line(line, edits, write)
