"""Emitting corrected lines: splicing numbers, inserted lines, kept and linearised arcs.

A mixin of :class:`postproc.gcode.pipeline.Corrector`: it uses the corrector's
emitted position ``qe``, options, report and engine-call helpers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Generic, Protocol, TypeVar

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import PostprocError, UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.cutter import take_up as cutter_take_up
from postproc.gcode.geometry import TWO_PI
from postproc.gcode.interp import Arc, Move
from postproc.gcode.segment import (
    CENTRE_LATTICE,
    ArcSpec,
    Axes,
    Curve,
    Point,
    arc_candidates,
    bisector_centre,
    bisector_point,
    chord_deviation,
    chord_exceeds,
    circle_fit,
    limited_candidates,
    r_center,
)
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE, PLANES, RAPID
from postproc.gcode.vplan import ArcHint, ArcMove, Plan

Edit = tuple[int, int, str]  # replace line[start:end] by the text
Write = Callable[[str], object]  # writes one output line


class _Options(Protocol):
    """What the emitter reads of the corrector's options
    (:class:`postproc.gcode.pipeline.CorrectOptions`, whose module imports this one)."""

    @property
    def tolerance_mm(self) -> float: ...
    @property
    def decimals(self) -> int | None: ...
    @property
    def dialect(self) -> str: ...


class _Report(Protocol):
    """The counts of the corrector's report (:class:`postproc.gcode.pipeline.CorrectReport`)
    that the emitter keeps."""

    moves: int
    words_changed: int
    lines_changed: int
    lines_out: int
    lines_inserted: int
    takeups: int
    arcs_kept: int
    arcs_split: int
    arcs_linearised: int


_O = TypeVar("_O", bound=_Options)
_R = TypeVar("_R", bound=_Report)


def _arc_of(mv: ArcMove) -> Arc:
    """The arc of an arc move (the callers' moves are arcs)."""
    arc = mv.arc
    if arc is None:
        raise TypeError("not an arc move")
    return arc


MOTION_TEXT = {RAPID: "0", LINE: "1", ARC_CW: "2", ARC_CCW: "3"}
HALF_UNIT = emit.HALF_UNIT
# Share of --tolerance that a fitted arc or chord may use at the samples of the corrected
# ideal path; the rest covers the path between samples.
FIT_BUDGET = 0.95
# Smallest share of a move's time given to an inserted line in inverse-time mode (G93).
MIN_FEED_FRACTION = 1e-3
# A piece that one segment cannot follow is first tried in 2 .. EQUAL_SHARES equal shares
# (each one try) to bracket the farthest sample one segment reaches, before the search
# from the next sample outwards. Where the first half fits, the second is tried at once:
# two segments are then the fewest, with no search.
EQUAL_SHARES = 4


def _unit_decimals(options: _Options, unit: float) -> int:
    if options.decimals is not None:
        return options.decimals
    return 5 if unit == MM_PER_INCH else 4


# exact powers of ten (10.0 ** k is exact up to 1e22), as numpy's round takes them
_POW10 = [10.0 ** k for k in range(23)]
# at and beyond 2**52 every double is a whole number
_WHOLE = 2.0 ** 52


def _np_round(v: float, d: int) -> float:
    """numpy's round of v to d decimals (0 <= d), as a Python float: the product by 10**d
    rounded half to even (as Python's round of a float) and divided by 10**d, a zero
    keeping the product's sign."""
    if d < len(_POW10):
        x = v * _POW10[d]
        if -_WHOLE < x < _WHOLE:
            return (float(round(x)) or math.copysign(0.0, x)) / _POW10[d]
    return float(np.round(v, d))


class _Piece:
    """One written segment of a planned move: an exact arc (``spec``) or a line to ``qe``
    (the emitted position after it), the word edits of the move's own line or the words
    of an inserted line, and ``ds``, its share of the move's parameter."""

    __slots__ = ("kind", "qe", "edits", "added", "ds", "spec", "takeup")

    def __init__(self, kind: str, qe: list[float], edits: list[Edit], added: list[str], ds: float,
                 spec: ArcSpec | None = None, takeup: bool = False) -> None:
        self.kind = kind  # "arc" | "line"
        self.qe = qe
        self.edits = edits
        self.added = added
        self.ds = ds
        self.spec = spec
        self.takeup = takeup


class _Samples:
    """A piece's corrected samples prepared once for all the tries of its fit: the samples
    and the middles of their intervals interleaved (``Qs`` (2n - 1, 3), the chord's middle
    moved by the nominal path's bulge there; ``ss`` their parameters), their plane
    coordinates (``P2``) and the corrections (``dq``: corrected minus nominal)."""

    __slots__ = ("s", "Q", "Qs", "ss", "P2", "dq", "free")

    def __init__(self, mv: Move, s: np.ndarray, Q: np.ndarray, nom: np.ndarray, bulge: np.ndarray) -> None:
        n = len(Q)
        self.s = s
        self.Q = Q
        Qs = np.empty((2 * n - 1, 3))
        Qs[0::2] = Q
        Qs[1::2] = 0.5 * (Q[:-1] + Q[1:]) + bulge[:n - 1]
        ss = np.empty(2 * n - 1)
        ss[0::2] = s
        ss[1::2] = 0.5 * (s[:-1] + s[1:])
        self.Qs = Qs
        self.ss = ss
        self.dq = Q - nom
        self.P2: np.ndarray | None = None
        if mv.arc is not None:
            (a1, a2, _an), _ = PLANES[mv.arc.plane]
            self.P2 = Qs[:, [a1, a2]]
        self.free = _free_move(mv)

    def offset(self, a: int, b: int) -> np.ndarray:
        """The mean correction over samples a..b: corrected minus nominal."""
        # as ndarray.mean: the sum divided by the count
        mean: np.ndarray = np.add.reduce(self.dq[a:b + 1], axis=0) / (b + 1 - a)
        return mean


def _free_move(mv: Move) -> Move:
    """``mv`` without its words: the move an inserted line writes."""
    return Move(mv.lineno, LINE, mv.q0, mv.q1, mv.r, mv.shift, mv.unit, mv.incremental, mv.arc_absolute,
                [], (-1, -1, -1), -1, mv.inverse_time, mv.feed, mv.rotary, frame=mv.frame)


# Offsets of the rounded centre candidates tried around the ideal one, per number of decimals.
_LATTICES: dict[int, np.ndarray] = {}


def _lattice(d: int) -> np.ndarray:
    grid = _LATTICES.get(d)
    if grid is None:
        ks = np.arange(-CENTRE_LATTICE, CENTRE_LATTICE + 1) * 10.0 ** (-d)
        grid = _LATTICES[d] = np.stack(np.meshgrid(ks, ks, indexing="ij"), axis=-1).reshape(-1, 2)
    return grid


class EmitterMixin(Generic[_O, _R]):
    """Line emission for the corrector (see the module docstring); generic in the
    corrector's options and report."""

    # the corrector's state that the emitter reads and updates
    opt: _O
    report: _R
    path: str | None
    qe: list[float]  # emitted gauge position (what the controller will hold)
    emitted_motion: int | None
    _decimals: dict[float, int]

    def _subdivide(self, curves: list[Curve], s_init: list[np.ndarray],
                   unit: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Adaptive subdivision of the curves with the engine (the corrector's)."""
        raise NotImplementedError

    def _axis_words(self, mv: Move, target: Point, qe: list[float], d: int,
                    present_only: bool = False) -> tuple[list[Edit], list[str]]:
        """Edits for the axis words of ``mv``'s line and the words to add; updates qe. Under a
        rotating, scaling or mirroring frame the words are those of the frame's coordinates."""
        if mv.frame is not None:
            from postproc.gcode import frames

            qp = list(frames.program_from_machine(mv.frame, mv.shift, qe))
            out = self._axis_words(replace(mv, frame=None), frames.program_from_machine(mv.frame, mv.shift, list(target)),
                                   qp, d, present_only)
            qe[:] = frames.machine_from_program(mv.frame, mv.shift, qp)
            return out
        edits: list[Edit] = []
        added: list[str] = []
        unit, shift, inc = mv.unit, mv.shift, mv.incremental
        half = HALF_UNIT[d]
        fmt = emit.fmt
        for k in range(3):
            t = target[k]
            idx = mv.axis_idx[k]
            if idx >= 0:
                _letter, num, start, end, _lpos = mv.words[idx]
                ov = float(num)
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                if abs(v - ov) < half:  # within half an output step: the word keeps its text
                    val = ov
                else:
                    dot = num.find(".")  # written with the output's decimals, or the word's own if more
                    dout = d if dot < 0 or len(num) - dot - 1 <= d else len(num) - dot - 1
                    text = fmt(v, dout)
                    edits.append((start, end, text))
                    val = float(text)  # what the controller reads (numpy's round of a numpy float can be a step off)
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
            elif not present_only:
                if math.isnan(qe[k]) or abs(t - qe[k]) / unit < half:
                    continue
                v = (t - qe[k]) / unit if inc else (t - shift[k]) / unit
                text = fmt(v, d)
                added.append("XYZ"[k] + text)
                val = float(text)
                qe[k] = qe[k] + val * unit if inc else val * unit + shift[k]
        return edits, added

    def _decimals_for(self, unit: float) -> int:
        """Decimals of the words written in ``unit`` (mm per program unit), found once."""
        d = self._decimals.get(unit)
        if d is None:
            d = self._decimals[unit] = _unit_decimals(self.opt, unit)
        return d

    def _emit_move(self, line: str, mv: Move, target: Point, plan: Plan | None, write: Write) -> None:
        self.report.moves += 1
        if mv.frame is not None and mv.arc is not None:
            d = self._decimals_for(mv.unit)
            if plan is None and max(abs(t - q) for t, q in zip(target, mv.q1, strict=True)) / mv.unit < HALF_UNIT[d]:
                # the correction rounds to nothing at the arc's end: the line stays as it is
                self.qe[:] = list(mv.q1)
                self.emitted_motion = mv.kind
                self._write_line(line, [], write)
                return
            raise UnsupportedGcodeError(
                "Sinumerik arc under ROT/SCALE/MIRROR: read, but its corrected centre and end words are not "
                "written yet in the frame's coordinates", path=self.path, lineno=mv.lineno, col=1,
                hint="post the arc with the frame deleted (ROT/MIRROR alone), or as its moves")
        d = self._decimals_for(mv.unit)
        if plan is None and mv.arc is None:
            # the common case: a move that is not split; only its words change
            edits, added = self._axis_words(mv, target, self.qe, d)
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
        if plan is None or "seq" not in plan:
            self._emit_unplanned_arc(line, mv, target, d, write)
            return
        self._emit_planned(line, mv, target, plan, d, write)

    def _axis_words_free(self, mv: Move, q: Point, qe: list[float], d: int) -> tuple[list[Edit], list[str]]:
        """Words for an inserted line (no original words): every axis that moves."""
        return self._axis_words(_free_move(mv), q, qe, d)

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
    def _emit_planned(self, line: str, mv: Move, target: Point, plan: Plan, d: int, write: Write) -> None:
        """Emit a move from its plan: take-ups and pieces of corrected samples, each piece
        fitted by the fewest exact arcs (arc moves) or chords that stay within the budget;
        the last segment is written on the move's own line."""
        budget = self.opt.tolerance_mm * FIT_BUDGET
        qe = list(self.qe)
        segs: list[_Piece] = []
        seq = plan["seq"]
        for k, st in enumerate(seq):
            if st[0] == "takeup":
                qn = list(qe)
                _e, added = self._axis_words_free(mv, st[1], qn, d)
                if added:
                    cutter_take_up(self, mv)
                    segs.append(_Piece("line", qn, [], added, 0.0, takeup=True))
                    qe = qn
                continue
            _tag, s, Q, nom, bulge = st
            final = k == len(seq) - 1
            segs.extend(self._fit_piece(mv, plan, s, Q, nom, bulge, qe, final, d, budget))
            qe = segs[-1].qe
        last = segs[-1]
        inserted = segs[:-1]
        if inserted and mv.stays:
            raise PostprocError(
                "this move must be split to stay within tolerance, but its line also changes the tool "
                "or uses G53, or it is the entry or exit move of cutter radius compensation (which the "
                "controller draws from where the tool is to the offset point)", path=self.path, lineno=mv.lineno,
                hint="put the tool change or G53 on a line of its own; make a lead-in or lead-out move shorter, "
                     "or raise --tolerance")
        sep, lower = emit.style_of(line)
        ending = emit.new_line_ending(line)
        arc = mv.arc
        for j, sg in enumerate(inserted):
            words = list(mv.prefix_words) if j == 0 else []
            if sg.kind == "arc" and sg.spec is not None and arc is not None:
                words.append("G2" if arc.clockwise else "G3")
                words.extend(sg.added)
                words.extend(self._arc_words(sg.spec))
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
            spans = [(mv.words[ai].letter_pos, mv.words[ai].end) for ai in mv.aux_idx]
            edits.extend((a, b, "") for a, b in emit.removal_spans(line, spans))
            self.emitted_motion = LINE
        else:
            self._motion_edit(mv, edits, sep, lower)
            self.emitted_motion = mv.kind
        if mv.inverse_time and inserted and mv.feed_idx >= 0:
            _l, num, start, end, _p = mv.words[mv.feed_idx]
            edits.append((start, end, emit.fmt(mv.feed / max(last.ds, MIN_FEED_FRACTION),
                                               max(4, emit.decimals_of(num)))))
        self._finish_line(line, mv, edits, added, last.spec if last.kind == "arc" else None, sep, lower,
                          last.qe, write)

    @staticmethod
    def _event_removals(line: str, mv: Move) -> list[Edit]:
        """Edits deleting the block's S, T and before-motion M words (with their parameters)
        from its own line, once they are written on the first line of a split: the
        controller then acts on each once, before the first piece, as it did before the
        split. A parameter word the motion also reads (an arc's P turns) stays."""
        keep = set(mv.aux_idx)
        spans = [(mv.words[i].letter_pos, mv.words[i].end) for i in mv.event_idx if i not in keep]
        return [(a, b, "") for a, b in emit.removal_spans(line, spans)]

    def _finish_line(self, line: str, mv: Move, edits: list[Edit], added: list[str], spec: ArcSpec | None, sep: str,
                     lower: bool, qe: Sequence[float], write: Write) -> None:
        """Write the move's own line: its word edits, the arc words of ``spec`` (None:
        not an arc) and the added words; the controller is then at ``qe``."""
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

    def _emit_hinted_arc(self, line: str, mv: Move, target: Point, hint: ArcHint, write: Write) -> None:
        """An arc the bulk planner settled (:class:`postproc.gcode.vplan.ArcHint`): written
        as one exact arc when the hint's rounded centre passes for the end points as
        written, else planned and fitted as any other arc."""
        d = self._decimals_for(mv.unit)
        qn = list(self.qe)
        edits, added = self._axis_words(mv, target, qn, d)
        budget = self.opt.tolerance_mm * FIT_BUDGET
        if edits:
            spec = hint.spec(mv, self.qe, qn, d, budget)
        else:  # unchanged end words: the input's own arc words stay if they still pass
            centre = self._input_centre(mv, self.qe, qn)
            spec = None if centre is None else hint.keep(mv, self.qe, qn, centre, budget)
        if spec is None:
            lazy = hint.lazy
            if lazy is None:  # the corrector gives every hint it hands here its general plan
                raise TypeError("an arc hint without its general plan")
            self._emit_move(line, mv, target, lazy(), write)
            return
        self.report.moves += 1
        sep, lower = emit.style_of(line)
        self._motion_edit(mv, edits, sep, lower)
        self.emitted_motion = mv.kind
        self.report.arcs_kept += 1
        self._finish_line(line, mv, edits, added, spec, sep, lower, qn, write)

    def _fit_piece(self, mv: Move, plan: Plan, s: np.ndarray, Q: np.ndarray, nom: np.ndarray, bulge: np.ndarray,
                   qe: list[float], final: bool, d: int, budget: float) -> list[_Piece]:
        """Greedy fit of one piece's samples: from each start, the farthest sample that one
        exact arc (or, failing that, one chord) reaches within the budget, or the two
        halves of what is left when each fits in one segment."""
        n = len(Q)
        a = 0
        cur = list(qe)
        out: list[_Piece] = []
        smp = _Samples(mv, s, Q, nom, bulge)

        def attempt_from(a0: int, b: int, cur0: list[float]) -> _Piece | None:
            return self._try_segment(mv, plan, smp, a0, b, cur0, final, d, budget)

        def attempt(b: int) -> _Piece | None:
            return attempt_from(a, b, cur)

        while a < n - 1:
            seg = attempt(n - 1)
            if seg is not None:
                out.append(seg)
                break
            # equal shares of what is left (a move cut in two or three is the common case):
            # the longest share one segment reaches brackets the farthest sample it
            # reaches, which a bisection between that share and the next longer finds
            hi = n - 1
            b = a
            for k in range(2, EQUAL_SHARES + 1):
                b = a + math.ceil((n - 1 - a) / k)
                if b <= a + 1:
                    break
                seg = attempt(b)
                if seg is not None:
                    break
                hi = b
            if seg is not None:
                if k == 2:
                    # one segment did not reach the end, so two are the fewest: when the
                    # second half fits too, the piece is cut in the middle (the search
                    # for the farthest sample would give two as well)
                    rest = attempt_from(b, n - 1, seg.qe)
                    if rest is not None:
                        out += [seg, rest]
                        break
                lo, seg = self._farthest(attempt, b, hi, seg)
                out.append(seg)
                cur = seg.qe
                a = lo
                continue
            lo_seg = attempt(a + 1)
            if lo_seg is None:
                # the samples are too sparse here: follow the curve by subdivision
                segs = self._refine(mv, plan, s[a], s[a + 1], Q[a + 1], cur, final and a + 1 == n - 1, d)
                out.extend(segs)
                cur = segs[-1].qe
                a += 1
                continue
            lo, hi = a + 1, n - 1
            step = 2
            while a + step < hi:
                sg = attempt(a + step)
                if sg is None:
                    hi = a + step
                    break
                lo, lo_seg = a + step, sg
                step *= 2
            lo, lo_seg = self._farthest(attempt, lo, hi, lo_seg)
            if lo == a + 1:
                # only the next sample is reached: check the path between them with the
                # engine itself (a jump or a solver's scatter there is refused)
                segs = self._refine(mv, plan, s[a], s[a + 1], Q[a + 1], cur, final and a + 1 == n - 1, d)
                if len(segs) > 1 or lo_seg.kind == "line":
                    out.extend(segs)
                    cur = segs[-1].qe
                    a += 1
                    continue
            out.append(lo_seg)
            cur = lo_seg.qe
            a = lo
        return out

    @staticmethod
    def _farthest(attempt: Callable[[int], _Piece | None], lo: int, hi: int, lo_seg: _Piece) -> tuple[int, _Piece]:
        """Bisection for the farthest sample one segment (``attempt(sample)``, None where
        it fails) reaches, between ``lo`` (reached, by ``lo_seg``) and ``hi`` (not
        reached): ``(sample, its segment)``."""
        while hi - lo > 1:
            mid = (lo + hi) // 2
            sg = attempt(mid)
            if sg is None:
                hi = mid
            else:
                lo, lo_seg = mid, sg
        return lo, lo_seg

    def _try_segment(self, mv: Move, plan: Plan, smp: _Samples, a: int, b: int, cur: list[float], final: bool,
                     d: int, budget: float) -> _Piece | None:
        """One segment from sample ``a`` (the controller at ``cur``) to sample ``b``: an
        exact arc (arc moves) or a chord within ``budget`` of the samples and the middles
        of their intervals, or None."""
        last = final and b == len(smp.Q) - 1
        qn = list(cur)
        if last:
            edits, added = self._axis_words(mv, smp.Q[b], qn, d)
        else:
            edits, added = self._axis_words(smp.free, smp.Q[b], qn, d)
        ds = float(smp.s[b] - smp.s[a])
        Qs = smp.Qs[2 * a:2 * b + 1]
        # the chord's deviation is measured only where needed: the middle sample alone
        # often shows it above the limit it is compared with
        mid = Qs[len(Qs) // 2].tolist()
        chord: float | None = None
        if mv.arc is not None and smp.P2 is not None:
            step_mm = 10.0 ** (-d) * mv.unit
            if chord_exceeds(cur, qn, mid, step_mm):
                flat = False
            else:
                chord = chord_deviation(cur, qn, Qs)
                flat = chord <= step_mm
            spec = self._exact_arc(mv, mv.arc, plan, cur, qn, Qs, smp.P2[2 * a:2 * b + 1], smp.offset(a, b),
                                   smp.ss[2 * a:2 * b + 1], flat, last and not edits, d, budget)
            if spec is not None:
                return _Piece("arc", qn, edits, added, ds, spec)
        if chord is None:
            if chord_exceeds(cur, qn, mid, budget):
                return None
            chord = chord_deviation(cur, qn, Qs)
        if chord <= budget:
            return _Piece("line", qn, edits, added, ds)
        return None

    def _refine(self, mv: Move, plan: Plan, sa: float, sb: float, qb: np.ndarray, cur: list[float], last: bool,
                d: int) -> list[_Piece]:
        (ss, qq), = self._subdivide([plan["curve"]], [np.array([sa, sb])], mv.unit)
        qq = np.array(qq, dtype=float)
        qq[-1] = qb
        out = []
        for j in range(1, len(ss)):
            qn = list(cur)
            if last and j == len(ss) - 1:
                edits, added = self._axis_words(mv, qq[j], qn, d)
            else:
                edits, added = self._axis_words_free(mv, qq[j], qn, d)
            out.append(_Piece("line", qn, edits, added, float(ss[j] - ss[j - 1])))
            cur = qn
        return out

    def _exact_arc(self, mv: Move, arc: Arc, plan: Plan, S_: Sequence[float], E_: Sequence[float], Qp: np.ndarray,
                   P2: np.ndarray, offset: np.ndarray, sp: np.ndarray, flat: bool, may_keep: bool, d: int,
                   budget: float) -> ArcSpec | None:
        """The arc from S to E (both as written) that stays within ``budget`` of the
        corrected samples ``Qp`` (``P2``: their plane coordinates; ``offset``: their mean
        correction, which moves the nominal centre to the first guess; ``flat``: their
        largest distance from the chord S-E is at most one output step): its centre on the
        bisector of S and E, the written centre (I/J/K, or R where the input used R)
        chosen among rounded candidates so that the start and end radii agree to half the
        output resolution. None if none passes.

        ``may_keep``: the piece is the whole move and its end words are unchanged: the
        input's own centre words are kept when their arc still passes (identity keeps
        every input arc as it is)."""
        (a1, a2, an), _letters = PLANES[arc.plane]
        S = np.asarray(S_, dtype=float)
        E = np.asarray(E_, dtype=float)
        span = float(sp[-1] - sp[0])
        if span <= 0.0:
            return None
        nsw = span * plan["nsweep"]
        frac = (sp - sp[0]) / span
        if may_keep and span >= 1.0 and plan.get("whole"):
            ctrl = self._input_centre(mv, S, E)
            if ctrl is not None:
                worst, mism, turns = arc_candidates(S, E, ctrl[None, :], (a1, a2, an), arc.clockwise, nsw, Qp, frac)
                # the input's own reading: the spiral its controller draws (no penalty for
                # the input's own radius mismatch)
                if mism[0] <= plan["mismatch"] + 1e-9 and worst[0] - mism[0] <= budget and turns[0] == arc.turns:
                    return {"form": "keep", "turns": int(turns[0])}
        S2, E2 = (float(S[a1]), float(S[a2])), (float(E[a1]), float(E[a2]))
        cx, cy = arc.center[a1] + offset[a1], arc.center[a2] + offset[a2]
        centres = []
        if math.hypot(E2[0] - S2[0], E2[1] - S2[1]) > 0.0:
            if flat:
                # the path bows from the line S-E by less than one output step: a circle
                # fitted to it is set by the rounding of S and E, not by the path (a centre
                # kilometres off, or a circle a few steps wide, where the chord is a few
                # steps long). The nominal circle, moved with the correction and its centre
                # brought onto the bisector, is tried first.
                centres.append(bisector_point(np.array(S2), np.array(E2), np.array([cx, cy])))
            centres.append(bisector_centre(S2, E2, P2, (cx, cy)))
        else:
            centre = circle_fit(P2)
            centres.append(np.array([cx, cy]) if centre is None or not np.isfinite(centre).all() else centre)
        for centre in centres:
            spec = self._arc_about(mv, arc, S, E, centre, nsw, Qp, frac, d, budget)
            if spec is not None:
                return spec
        return None

    def _arc_about(self, mv: Move, arc: Arc, S: np.ndarray, E: np.ndarray, centre: np.ndarray, nsw: float,
                   Qp: np.ndarray, frac: np.ndarray, d: int, budget: float) -> ArcSpec | None:
        """The written arc from S to E whose centre is the rounded candidate nearest
        ``centre`` (2,) that passes (see :meth:`_exact_arc`), or None."""
        (a1, a2, an), (l1, l2) = PLANES[arc.plane]
        axes = (a1, a2, an)
        unit = mv.unit
        step = 10.0 ** (-d)
        agree = 0.5 * step * unit
        if arc.r_idx >= 0 and abs(nsw) < TWO_PI - 1e-6:
            spec = self._r_candidates(S, E, centre, axes, arc.clockwise, nsw, Qp, frac, d, unit, budget)
            if spec is not None:
                return spec
        b1, b2 = (float(mv.shift[a1]), float(mv.shift[a2])) if mv.arc_absolute else (float(S[a1]), float(S[a2]))
        base = np.array([b1, b2])
        # ((centre - base) / unit).round(d), element by element as numpy computes it
        v0 = np.array([_np_round((float(centre[0]) - b1) / unit, d), _np_round((float(centre[1]) - b2) / unit, d)])
        V = (v0 + _lattice(d)).round(d)  # ndarray.round: np.round without its wrapper
        C = base[None, :] + V * unit
        # candidates whose radii disagree are refused unmeasured (their worst is inf)
        meas = limited_candidates(S, E, C, axes, arc.clockwise, nsw, Qp, frac, agree, controller_limits=True)
        if budget < math.inf:
            # the measured candidates within the budget (those within the mismatch limit,
            # not refused); the first of the order below is the best of them when no other
            # ties with it, and is taken when its written centre is the one measured
            worst_l = meas.worst.tolist()
            passing = [w for w in worst_l if w <= budget]
            if not passing:
                return None
            best = min(passing)
            if passing.count(best) == 1:
                k = worst_l.index(best)
                j = int(meas.idx[k])
                texts = (emit.fmt(float(V[j, 0]), d), emit.fmt(float(V[j, 1]), d))
                if float(texts[0]) == V[j, 0] and float(texts[1]) == V[j, 1]:
                    return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(meas.turns[k]),
                            "dev": best, "mismatch": float(meas.mism[k])}
        worst, mism, turns = meas.full()
        ok = (mism <= agree) & (worst <= budget)
        if not ok.any():
            return None
        order = np.argsort(np.where(ok, worst, np.inf))
        # the three best candidates that pass (never one that fails: its radii disagree or
        # it leaves the budget)
        for j in order[:min(3, int(ok.sum()))].tolist():
            texts = (emit.fmt(float(V[j, 0]), d), emit.fmt(float(V[j, 1]), d))
            if float(texts[0]) == V[j, 0] and float(texts[1]) == V[j, 1]:
                # the written centre is the candidate measured (numpy's rounding agreed)
                return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(turns[j]),
                        "dev": float(worst[j]), "mismatch": float(mism[j])}
            ctrl = base + np.array([float(texts[0]), float(texts[1])]) * unit
            w, m, t = arc_candidates(S, E, ctrl[None, :], axes, arc.clockwise, nsw, Qp, frac,
                                     controller_limits=True)
            if m[0] <= agree and w[0] <= budget:
                return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(t[0]),
                        "dev": float(w[0]), "mismatch": float(m[0])}
        return None

    def _r_candidates(self, S: np.ndarray, E: np.ndarray, centre: np.ndarray, axes: Axes, clockwise: bool,
                      nsw: float, Qp: np.ndarray, frac: np.ndarray, d: int, unit: float,
                      budget: float) -> ArcSpec | None:
        a1, a2, an = axes
        step = 10.0 ** (-d)
        half = 0.5 * math.hypot(E[a1] - S[a1], E[a2] - S[a2])
        if half == 0.0:
            return None
        rho = 0.5 * (math.hypot(S[a1] - centre[0], S[a2] - centre[1])
                     + math.hypot(E[a1] - centre[0], E[a2] - centre[1]))
        sign = -1.0 if abs(nsw) > math.pi else 1.0
        r0 = round(rho / unit, d)
        vals = {round(r0 + k * step, d) for k in range(-CENTRE_LATTICE, CENTRE_LATTICE + 1)}
        vals |= {round(math.ceil(half / unit / step) * step + k * step, d) for k in (0, 1, 2)}
        texts, centres = [], []
        for val in sorted(vals):
            text = emit.fmt(sign * val, d)
            R = float(text) * unit
            if abs(R) <= half:
                continue  # every controller must find a centre without its own tolerance
            c = r_center(S[a1], S[a2], E[a1], E[a2], R, clockwise)
            if c is not None:
                texts.append(text)
                centres.append(c)
        if not centres:
            return None
        # every radius's arc measured at once (each row as on its own), the best in the
        # order of the radii: the first of the smallest deviations among one-turn arcs
        w, m, t = arc_candidates(S, E, np.array(centres), axes, clockwise, nsw, Qp, frac, controller_limits=True)
        best = -1
        for j, (wj, tj) in enumerate(zip(w.tolist(), t.tolist(), strict=True)):
            if tj == 1 and (best < 0 or wj < w[best]):
                best = j
        if best < 0 or not w[best] <= budget:
            return None
        return {"form": "r", "vals": (("R", texts[best]),), "turns": 1, "dev": float(w[best]),
                "mismatch": float(m[best])}

    def _input_centre(self, mv: Move, S: Point, E: Point) -> np.ndarray | None:
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

    def _arc_words(self, spec: ArcSpec) -> list[str]:
        radius = self._radius_word()
        words = [(radius if letter == "R" else letter) + text for letter, text in spec["vals"]]
        if spec["turns"] > 1:
            words.append(f"P{spec['turns']}")
        return words

    def _radius_word(self) -> str:
        """How the dialect writes an arc's radius: ``R`` (``CR=`` for Sinumerik)."""
        from postproc.gcode.dialect import get

        return get(self.opt.dialect).radius_word

    def _arc_edits(self, line: str, mv: Move, spec: ArcSpec) -> tuple[list[Edit], list[str]]:
        """Edits of the move's own arc words for the arc ``spec`` and the words to add."""
        arc = _arc_of(mv)
        if spec["form"] == "keep":
            return [], []
        p_idx = [i for i in mv.aux_idx if mv.words[i].letter == "P"]
        same_form = (spec["form"] == "r") == (arc.r_idx >= 0)
        if not same_form or spec["turns"] != arc.turns:
            # a different form or number of turns: the old words go, the new ones are added
            spans = [(mv.words[ai].letter_pos, mv.words[ai].end) for ai in mv.aux_idx]
            spec["replace"] = True
            edits = [(a, b, "") for a, b in emit.removal_spans(line, spans)]
            return edits, self._arc_words(spec)
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
                added.append((self._radius_word() if letter == "R" else letter) + text)
        del p_idx
        return edits, added

    def _emit_unplanned_arc(self, line: str, mv: Move, target: Point, d: int, write: Write) -> None:
        """An arc whose start is not known (the program's first move): its end words follow
        the target and its centre words keep their offset from the start."""
        edits, added = self._axis_words(mv, target, self.qe, d)
        sep, lower = emit.style_of(line)
        self._motion_edit(mv, edits, sep, lower)
        self.emitted_motion = mv.kind
        if added:
            pos = self._insert_pos(mv)
            text = "".join(sep + w for w in added)
            edits.append((pos, pos, text.lower() if lower else text))
        self.report.arcs_kept += 1
        self._write_line(line, edits, write)
