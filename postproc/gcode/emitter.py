"""Emitting corrected lines: splicing numbers, inserted lines, kept and linearised arcs.

A mixin of :class:`postproc.gcode.writer.ChunkWriter`: it uses the writer's emitted
position ``qe``, options and report, and the plans and subdivisions the planner made
for the chunk. It makes no engine call: where it needs a plan or a subdivision the
planner has not made yet, it raises :class:`PlanNeeded` (see the writer).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import PostprocError, SolverError
from postproc.gcode import emit, numfmt
from postproc.gcode.arcfit import Edit, MoveFit, _free_move, _Piece
from postproc.gcode.cutter import take_up as cutter_take_up
from postproc.gcode.framed import FrameView
from postproc.gcode.geometry import r_center
from postproc.gcode.interp import Arc, Move
from postproc.gcode.lexer import Word
from postproc.gcode.moves import Role
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.segment import ArcSpec, Curve, Point
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE, PLANES, RAPID
from postproc.gcode.vplan import ArcHint, ArcMove, Plan

Write = Callable[[str], object]  # writes one output line


class Subdivided(dict[tuple[int, float, float], "tuple[np.ndarray, np.ndarray] | SolverError"]):
    """The engine's subdivisions the planner made for a chunk's arc fits, by
    :func:`subdivision_key`: (the samples' parameters, the corrected points), or the
    engine's refusal of that span; and by curve (its id), how many of its spans the
    planner subdivides when next asked about it (``batch``)."""

    def __init__(self) -> None:
        super().__init__()
        self.batch: dict[int, int] = {}


def _arc_of(mv: ArcMove) -> Arc:
    """The arc of an arc move (the callers' moves are arcs)."""
    arc = mv.arc
    if arc is None:
        raise TypeError("not an arc move")
    return arc


MOTION_TEXT = {RAPID: "0", LINE: "1", ARC_CW: "2", ARC_CCW: "3"}
# Share of --tolerance that a fitted arc or chord may use at the samples of the corrected
# ideal path; the rest covers the path between samples.
FIT_BUDGET = 0.95
# Smallest share of a move's time given to an inserted line in inverse-time mode (G93).
MIN_FEED_FRACTION = 1e-3


def _unit_decimals(options: CorrectOptions, unit: float) -> int:
    if options.decimals is not None:
        return options.decimals
    return 5 if unit == MM_PER_INCH else 4


def _centre_absolute_once(line: str, mv: Move) -> bool:
    """Whether the block's centre words are Sinumerik's ``I=AC(v)``: absolute for this
    block only (the interpreter reads every centre word of such a block so). The centre
    words written for it, on its own line or on the lines inserted before it, must then
    be so too: a plain ``I`` is relative to the arc's start there."""
    arc = mv.arc
    if arc is None or not mv.arc_absolute:
        return False
    idx = [i for i in arc.offset_idx if i >= 0]
    return bool(idx) and "(" in line[mv.words[idx[0]].letter_pos:mv.words[idx[0]].start]


def _word_span(line: str, w: Word) -> tuple[int, int]:
    """Where word ``w`` stands on its line, from its letter to its number's end, or to the
    closing parenthesis of a Sinumerik ``I=AC(v)``."""
    if "(" in line[w.letter_pos:w.start]:
        close = line.find(")", w.end)
        if close >= 0:
            return w.letter_pos, close + 1
    return w.letter_pos, w.end


def _radius_word(dialect: str) -> str:
    """How ``dialect`` writes an arc's radius: ``R`` (``CR=`` for Sinumerik)."""
    from postproc.gcode.dialect import get

    return get(dialect).radius_word


def round_err(options: CorrectOptions, unit: float) -> float:
    """The largest distance (mm) a point moves when its words are rounded to the output's
    decimals in ``unit`` (mm per program unit): half a step on each of three axes."""
    return 0.5 * 10.0 ** (-_unit_decimals(options, unit)) * unit * math.sqrt(3.0)


class PlanNeeded(Exception):
    """What the writer needs of the planner before it can write on: the general plan of
    table row ``row`` (an arc whose hint does not hold for its ends as written), or the
    engine's subdivision of ``curve`` over ``span`` (an arc fit that follows the curve
    more finely than its samples). The planner makes it, and the writer is asked again."""

    def __init__(self, row: int = -1, curve: Curve | None = None, span: np.ndarray | None = None,
                 unit: float = 1.0) -> None:
        super().__init__(row if curve is None else "subdivision")
        self.row, self.curve, self.span, self.unit = row, curve, span, unit

    @property
    def key(self) -> tuple[int, float, float]:
        """The subdivision's key: its curve and span."""
        return subdivision_key(self.curve, self.span)


def subdivision_key(curve: object, span: np.ndarray | None) -> tuple[int, float, float]:
    """Where a subdivision is kept for the writer: its curve (alive while its chunk is
    written) and its span."""
    if span is None:
        raise TypeError("a subdivision without its span")
    return id(curve), float(span[0]), float(span[-1])


class EmitterMixin:
    """Line emission for the writer (see the module docstring)."""

    # the writer's state that the emitter reads and updates
    opt: CorrectOptions
    report: CorrectReport
    path: str | None
    qe: list[float]  # emitted gauge position (what the controller will hold)
    emitted_motion: int | None
    _decimals: dict[float, int]
    _plans: dict[int, Plan]  # the chunk's plans, by row (the general plans of hints too)
    _subdivided: Subdivided

    def subdivision(self, curves: list[Curve], s_init: list[np.ndarray],
                   unit: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """The engine's adaptive subdivision of one curve over one span, as the planner made
        it (:class:`PlanNeeded` when it has not yet)."""
        (curve,), (span,) = curves, s_init
        got = self._subdivided.get(subdivision_key(curve, span))
        if got is None:
            raise PlanNeeded(curve=curve, span=span, unit=unit)
        if isinstance(got, SolverError):
            raise got  # the engine refused this span (see the planner's subdivisions)
        return [got]

    def _general_plan(self, hint: ArcHint, view: FrameView | None = None) -> Plan | None:
        """The general plan of the arc a hint does not settle (in ``view``'s coordinates
        when given), as the planner made it (:class:`PlanNeeded` when it has not yet)."""
        plan = self._plans.get(hint.row)
        if plan is None:
            raise PlanNeeded(row=hint.row)
        return plan if view is None else view.plan(plan)

    def axis_words(self, mv: Move, target: Point, qe: list[float], d: int,
                    present_only: bool = False) -> tuple[list[Edit], list[str]]:
        """Edits for the axis words of ``mv``'s line and the words to add; updates qe. Under a
        rotating, scaling or mirroring frame the words are those of the frame's coordinates."""
        if mv.frame is not None:
            from postproc.gcode import frames

            qp = list(frames.program_from_machine(mv.frame, mv.shift, qe))
            out = self.axis_words(replace(mv, frame=None), frames.program_from_machine(mv.frame, mv.shift, list(target)),
                                   qp, d, present_only)
            qe[:] = frames.machine_from_program(mv.frame, mv.shift, qp)
            return out
        edits: list[Edit] = []
        added: list[str] = []
        unit, shift, inc = mv.unit, mv.shift, mv.incremental
        for k in range(3):
            t = target[k]
            idx = mv.axis_idx[k]
            if idx >= 0:
                _letter, num, start, end, _lpos = mv.words[idx]
                ov = float(num)
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                text = numfmt.word_text(v, ov, emit.decimals_of(num), d)
                if text:
                    edits.append((start, end, text))
                    val = float(text)  # what the controller reads
                else:  # within half an output step: the word keeps its text
                    val = ov
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
            elif not present_only:
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                text = numfmt.added_text(t, qe[k], unit, v, d)
                if not text:
                    continue
                added.append("XYZ"[k] + text)
                val = numfmt.reached(text, v)
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
        return edits, added

    def _decimals_for(self, unit: float) -> int:
        """Decimals of the words written in ``unit`` (mm per program unit), found once."""
        d = self._decimals.get(unit)
        if d is None:
            d = self._decimals[unit] = _unit_decimals(self.opt, unit)
        return d

    def emit_move(self, line: str, mv: Move, target: Point, plan: Plan | None, write: Write) -> None:
        self.report.moves += 1
        d = self._decimals_for(mv.unit)
        if plan is None and mv.arc is None:
            # the common case: a move that is not split; only its words change
            edits, added = self.axis_words(mv, target, self.qe, d)
            if added or (mv.motion_idx < 0 and self.emitted_motion != mv.kind):
                sep, lower = emit.style_of(line)
                self._motion_edit(mv, edits, sep, lower)
                if added:
                    pos = self._insert_pos(mv)
                    text = "".join(sep + w for w in added)
                    edits.append((pos, pos, text.lower() if lower else text))
            self.emitted_motion = mv.kind
            self._write_line(line, edits, write)
            return
        if mv.frame is not None and mv.arc is not None:
            view = FrameView.of(mv)
            with self._in_view(view):
                self._emit_planned_or_not(line, view.move(mv), view.point(target), view.plan(plan), d, write, view)
            return
        self._emit_planned_or_not(line, mv, target, plan, d, write)

    def _emit_planned_or_not(self, line: str, mv: Move, target: Point, plan: Plan | None, d: int, write: Write,
                             view: FrameView | None = None) -> None:
        """An arc or a split line (``view``: the frame a framed arc is written in, whose
        coordinates ``mv``, ``target`` and ``plan`` are in)."""
        if plan is None or "seq" not in plan:
            self._emit_unplanned_arc(line, mv, target, d, write)
            return
        self._emit_planned(line, mv, target, plan, d, write, view)

    @contextmanager
    def _in_view(self, view: FrameView) -> Iterator[None]:
        """The emitted position in ``view``'s coordinates while a framed arc is written
        there, then back in the machine's."""
        self.qe[:] = view.point(self.qe)
        try:
            yield
        finally:
            self.qe[:] = view.machine(self.qe)

    def axis_words_free(self, mv: Move, q: Point, qe: list[float], d: int) -> tuple[list[Edit], list[str]]:
        """Words for an inserted line (no original words): every axis that moves."""
        return self.axis_words(_free_move(mv), q, qe, d)

    def _insert_pos(self, mv: Move) -> int:
        idx = [i for i in mv.axis_idx if i >= 0]
        if idx:
            return mv.words[max(idx)][3]
        if mv.motion_idx >= 0:
            return mv.words[mv.motion_idx].end
        return mv.words[-1].end

    def _motion_edit(self, mv: Move, edits: list[Edit], sep: str, lower: bool) -> None:
        """Add the move's motion word to a line that has none when the controller's modal
        motion differs (after a linearised arc, or a line written in G1)."""
        if mv.motion_idx < 0 and self.emitted_motion != mv.kind:
            text = "G" + MOTION_TEXT[mv.kind]
            edits.append(self._insert_motion(mv, (text.lower() if lower else text) + sep))

    def _insert_motion(self, mv: Move, text: str) -> Edit:
        first = next((w for w in mv.words if w.letter != "N"), mv.words[0])
        return (first[4], first[4], text)

    def _write_line(self, line: str, edits: list[Edit], write: Write) -> None:
        self.report.words_changed += len(edits)
        self.report.lines_changed += bool(edits)
        write(emit.edit_line(line, edits))
        self.report.lines_out += 1

    # -- planned moves: pieces of corrected samples fitted by exact arcs and lines ----------
    def _emit_planned(self, line: str, mv: Move, target: Point, plan: Plan, d: int, write: Write,
                      view: FrameView | None = None) -> None:
        """Emit a move from its plan: take-ups and pieces of corrected samples, each piece
        fitted by the fewest exact arcs (arc moves) or chords that stay within the budget;
        the last segment is written on the move's own line. ``view``: a framed arc's frame,
        whose coordinates the move and its plan are in (its share of the budget, and the
        map of the engine's subdivision into them)."""
        budget = self.opt.tolerance_mm * FIT_BUDGET * (1.0 if view is None else view.budget_share)
        fit = MoveFit(self, mv, plan, d, budget, None if view is None else view.points)
        qe = list(self.qe)
        segs: list[_Piece] = []
        seq = plan["seq"]
        for k, st in enumerate(seq):
            if st[0] == "takeup":
                qn = list(qe)
                _e, added = self.axis_words_free(mv, st[1], qn, d)
                if added:
                    cutter_take_up(self, mv)
                    segs.append(_Piece("line", qn, [], added, 0.0, takeup=True))
                    qe = qn
                continue
            _tag, s, Q, nom, bulge = st
            final = k == len(seq) - 1
            segs.extend(fit.piece(s, Q, nom, bulge, qe, final))
            qe = segs[-1].qe
        last = segs[-1]
        inserted = segs[:-1]
        if inserted and mv.role is Role.WHOLE:
            raise PostprocError(
                "this move must be split to stay within tolerance, but its line also changes the tool "
                "or uses G53, or it is the entry or exit move of cutter radius compensation (which the "
                "controller draws from where the tool is to the offset point)",
                path=mv.path or self.path, lineno=mv.lineno,
                hint="put the tool change or G53 on a line of its own; make a lead-in or lead-out move shorter, "
                     "or raise --tolerance")
        sep, lower = emit.style_of(line)
        self._write_inserted(line, mv, inserted, write)
        arc = mv.arc
        if arc is not None:
            kinds = [sg.kind for sg in segs if not sg.takeup]
            if all(kd == "arc" for kd in kinds):
                if len(kinds) == 1:
                    self.report.arcs_kept += 1
                else:
                    self.report.arcs_split += 1
            else:
                self.report.arcs_linearised += 1
        edits, added = last.edits, last.added
        if inserted:
            edits = edits + self._event_removals(line, mv)
        if last.kind == "line" and arc is not None:
            g1 = "g1" if lower else "G1"
            if mv.motion_idx >= 0:
                _l, num, start, end, _p = mv.words[mv.motion_idx]
                edits.append((start, end, ("0" if num.startswith("0") else "") + "1"))
            else:
                edits.append(self._insert_motion(mv, g1 + sep))
            spans = [_word_span(line, mv.words[ai]) for ai in mv.aux_idx]
            edits.extend((a, b, "") for a, b in emit.removal_spans(line, spans))
            self.emitted_motion = LINE
        else:
            self._motion_edit(mv, edits, sep, lower)
            self.emitted_motion = mv.kind
        if mv.inverse_time and inserted and mv.feed_idx >= 0:
            _l, num, start, end, _p = mv.words[mv.feed_idx]
            edits.append((start, end, emit.fmt(mv.feed / max(last.ds, MIN_FEED_FRACTION),
                                               max(4, emit.decimals_of(num)))))
        self._finish_line(line, mv, edits, added, last.spec if last.kind == "arc" else None, last.qe, write)

    def _write_inserted(self, line: str, mv: Move, inserted: list[_Piece], write: Write) -> None:
        """Write the lines inserted before the move's own line, one per segment but its
        last, in the line's style (the first with the block's S, T and M words)."""
        sep, lower = emit.style_of(line)
        ending = emit.new_line_ending(line)
        arc = mv.arc
        for j, sg in enumerate(inserted):
            words = list(mv.prefix_words) if j == 0 else []
            if sg.kind == "arc" and sg.spec is not None and arc is not None:
                words.append("G2" if arc.clockwise else "G3")
                words.extend(sg.added)
                words.extend(self._arc_words(sg.spec, _centre_absolute_once(line, mv)))
            else:
                words.append("G1")
                words.extend(sg.added)
            if mv.inverse_time:
                words.append("F" + emit.fmt(mv.feed / max(sg.ds, MIN_FEED_FRACTION), 4))
            elif j == 0 and mv.feed_idx >= 0:
                words.append("F" + mv.words[mv.feed_idx].number)
            text = sep.join(words)
            write((text.lower() if lower else text) + ending)
            self.report.lines_inserted += 1
            self.report.lines_out += 1
            if sg.takeup:
                self.report.takeups += 1
            self.emitted_motion = mv.kind if sg.kind == "arc" else LINE

    @staticmethod
    def _event_removals(line: str, mv: Move) -> list[Edit]:
        """Edits deleting the block's S, T and before-motion M words (with their parameters)
        from its own line, once they are written on the first line of a split: the
        controller then acts on each once, before the first piece, as it did before the
        split. A parameter word the motion also reads (an arc's P turns) stays."""
        keep = set(mv.aux_idx)
        spans = [(mv.words[i].letter_pos, mv.words[i].end) for i in mv.event_idx if i not in keep]
        return [(a, b, "") for a, b in emit.removal_spans(line, spans)]

    def _finish_line(self, line: str, mv: Move, edits: list[Edit], added: list[str], spec: ArcSpec | None,
                     qe: Sequence[float], write: Write) -> None:
        """Write the move's own line: its word edits, the arc words of ``spec`` (None:
        not an arc) and the added words; the controller is then at ``qe``."""
        sep, lower = emit.style_of(line)
        arc_added: list[str] = []
        replace = False
        if spec is not None:
            arc_edits, arc_added = self._arc_edits(line, mv, spec)
            edits = edits + arc_edits
            replace = spec.get("replace", False)  # set by _arc_edits
        if added or arc_added:
            if arc_added:
                arc = _arc_of(mv)
                aux = [i for i in (arc.offset_idx + (arc.r_idx,)) if i >= 0 and not replace]
                pos = mv.words[max(aux)][3] if aux else self._insert_pos(mv)
                words_added = added + arc_added
            else:
                pos = self._insert_pos(mv)
                words_added = added
            text = "".join(sep + w for w in words_added) if pos > 0 else "".join(w + sep for w in words_added)
            edits.append((pos, pos, text.lower() if lower else text))
        self.qe[:] = qe
        self._write_line(line, edits, write)

    def emit_hinted_arc(self, line: str, mv: Move, target: Point, hint: ArcHint, write: Write) -> None:
        """An arc the bulk planner settled (:class:`postproc.gcode.vplan.ArcHint`): written
        as one exact arc when the hint's rounded centre passes for the end points as
        written, else planned and fitted as any other arc. A framed arc is written in its
        frame's coordinates (:class:`FrameView`)."""
        d = self._decimals_for(mv.unit)
        if mv.frame is None or mv.arc is None:
            self._write_hinted_arc(line, mv, target, hint, d, write)
            return
        view = FrameView.of(mv)
        vhint = view.hint(hint, mv.arc.plane)
        with self._in_view(view):
            vmv, vtarget = view.move(mv), view.point(target)
            if vhint is None:  # the view does not keep lengths along the normal: the general plan
                self.report.moves += 1
                self._emit_planned_or_not(line, vmv, vtarget, self._general_plan(hint, view), d, write, view)
            else:
                self._write_hinted_arc(line, vmv, vtarget, vhint, d, write, view)

    def _write_hinted_arc(self, line: str, mv: Move, target: Point, hint: ArcHint, d: int, write: Write,
                          view: FrameView | None = None) -> None:
        """:meth:`emit_hinted_arc` of a move without a frame, or of a framed arc in its
        ``view`` (``mv``, ``target``, ``hint`` and the emitted position in its coordinates)."""
        qn = list(self.qe)
        edits, added = self.axis_words(mv, target, qn, d)
        budget = self.opt.tolerance_mm * FIT_BUDGET * (1.0 if view is None else view.budget_share)
        if edits:
            spec = hint.spec(mv, self.qe, qn, d, budget)
        else:  # unchanged end words: the input's own arc words stay if they still pass
            centre = self.input_centre(mv, self.qe, qn)
            spec = None if centre is None else hint.keep(mv, self.qe, qn, centre, budget)
        self.report.moves += 1
        if spec is None:
            self._emit_planned_or_not(line, mv, target, self._general_plan(hint, view), d, write, view)
            return
        sep, lower = emit.style_of(line)
        self._motion_edit(mv, edits, sep, lower)
        self.emitted_motion = mv.kind
        self.report.arcs_kept += 1
        self._finish_line(line, mv, edits, added, spec, qn, write)

    def input_centre(self, mv: Move, S: Point, E: Point) -> np.ndarray | None:
        """Centre (2,) a controller finds from the input line's own arc words, with the
        emitted start and end."""
        arc = _arc_of(mv)
        (a1, a2, _an), _ = PLANES[arc.plane]
        unit = mv.unit
        if arc.r_idx >= 0:
            c = r_center(S[a1], S[a2], E[a1], E[a2], float(mv.words[arc.r_idx].number) * unit, arc.clockwise)
            return None if c is None else np.array(c)
        out = []
        for axis, idx in ((a1, arc.offset_idx[0]), (a2, arc.offset_idx[1])):
            base = mv.shift[axis] if mv.arc_absolute else S[axis]
            val = float(mv.words[idx].number) if idx >= 0 else 0.0
            out.append(base + val * unit)
        return np.array(out)

    def _arc_words(self, spec: ArcSpec, absolute_once: bool = False) -> list[str]:
        """The words of the arc ``spec``; ``absolute_once``: its centre words as Sinumerik's
        ``I=AC(v)`` (:func:`_centre_absolute_once`)."""
        radius = _radius_word(self.opt.dialect)
        words = [radius + text if letter == "R" else f"{letter}=AC({text})" if absolute_once else letter + text
                 for letter, text in spec["vals"]]
        if spec["turns"] > 1:
            words.append(f"P{spec['turns']}")
        return words

    def _arc_edits(self, line: str, mv: Move, spec: ArcSpec) -> tuple[list[Edit], list[str]]:
        """Edits of the move's own arc words for the arc ``spec`` and the words to add."""
        arc = _arc_of(mv)
        if spec["form"] == "keep":
            return [], []
        p_idx = [i for i in mv.aux_idx if mv.words[i].letter == "P"]
        same_form = (spec["form"] == "r") == (arc.r_idx >= 0)
        if not same_form or spec["turns"] != arc.turns:
            # a different form or number of turns: the old words go, the new ones are added
            spans = [_word_span(line, mv.words[ai]) for ai in mv.aux_idx]
            spec["replace"] = True
            edits = [(a, b, "") for a, b in emit.removal_spans(line, spans)]
            return edits, self._arc_words(spec, _centre_absolute_once(line, mv))
        edits, added = [], []
        idxs: tuple[int, ...]
        if spec["form"] == "r":
            idxs = (arc.r_idx,)
        else:
            idxs = arc.offset_idx
        for (letter, text), idx in zip(spec["vals"], idxs, strict=True):
            if idx >= 0:
                _l, num, start, end, _p = mv.words[idx]
                if float(num) != float(text):
                    edits.append((start, end, text))
            elif float(text) != 0.0 or mv.arc_absolute:
                added.extend(self._arc_words({"form": spec["form"], "vals": ((letter, text),), "turns": 1},
                                             _centre_absolute_once(line, mv)))
        del p_idx
        return edits, added

    def _emit_unplanned_arc(self, line: str, mv: Move, target: Point, d: int, write: Write) -> None:
        """An arc whose start is not known (the program's first move): its end words follow
        the target and its centre words keep their offset from the start."""
        edits, added = self.axis_words(mv, target, self.qe, d)
        sep, lower = emit.style_of(line)
        self._motion_edit(mv, edits, sep, lower)
        self.emitted_motion = mv.kind
        if added:
            pos = self._insert_pos(mv)
            text = "".join(sep + w for w in added)
            edits.append((pos, pos, text.lower() if lower else text))
        self.report.arcs_kept += 1
        self._write_line(line, edits, write)
