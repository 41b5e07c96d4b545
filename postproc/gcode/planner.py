"""The planner: a chunk's table of moves corrected, and how each move is to be written.

The reader (:mod:`postproc.gcode.pipeline`) gathers a chunk's moves into a
:class:`Table`, one row per move in program order. :meth:`Planner.plan` fills its
columns (nominal starts, approach directions, corrected starts and targets) with one
engine call for the chunk's targets, settles in bulk the moves that stay one line or
one exact arc (:mod:`postproc.gcode.vplan`), and samples the others for the writer's
fits: a plan per move (:class:`postproc.gcode.vplan.Plan`) or a hint per arc
(:class:`postproc.gcode.vplan.ArcHint`).

Order of corrections: the engine inverse first (``q = F^-1(p*, r)``), then each of
``added`` in turn, ``q += added.delta(p*, context)``, every one evaluated at the
nominal point ``p*``. The safety bound ``max_correction_mm`` applies to the total.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

import numpy as np

from postproc.errors import SolverError
from postproc.gcode import bulk, vplan
from postproc.gcode.directions import (
    direction_axes,
)
from postproc.gcode.dirplan import TAKEUP_MIN_MM, plan_directions
from postproc.gcode.emitter import (
    FIT_BUDGET,
    PlanNeeded,
    Subdivided,
    _unit_decimals,
    subdivision_key,
)
from postproc.gcode.engine_use import EngineCalls
from postproc.gcode.geometry import (
    arc_params,
    arc_points,
)
from postproc.gcode.moves import Kind
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.places import file_of, pick
from postproc.gcode.sampling import (
    ARC_CHECK_MIN_SAMPLES,
    ARC_CHECK_STEP_RAD,
    SAMPLE_STEP_MM,
    _RunLine,
    _sample_moves,
    _Sampled,
)
from postproc.gcode.segment import Curve, quadrant_breaks
from postproc.gcode.source import backfill_unknown
from postproc.gcode.state import PLANES
from postproc.gcode.table import Table
from postproc.gcode.vplan import (
    ArcHint,
    ArcMove,
    FloatArray,
    IntArray,
    Piece,
    Plan,
    PlanMove,
    Step,
)

if TYPE_CHECKING:
    from collections.abc import Mapping

    from postproc.engine.base import Engine

# An arc the bulk planner settles with a fit beyond this share of the budget gets its
# general plan with the chunk's (one engine call) in case its hint fails when written:
# on a parametric gencam program 70 % of those hints fail, 2 % of the others.
HINT_PREPLAN_SHARE = 0.7



class Planner(EngineCalls):
    """The plans of a chunk's moves, with the engine calls (and their safety checks) of
    :class:`EngineCalls`; carries the corrected position and directions from one chunk
    to the next."""

    def __init__(self, engine: Engine, options: CorrectOptions, report: CorrectReport, rotary: set[str],
                 context: Mapping[str, float], accept_residual_mm: float, start: Sequence[float],
                 path: str | None = None) -> None:
        super().__init__(engine, options, report, rotary, context, accept_residual_mm, path)
        self.linear_exact = bool(engine.affine) and not options.added
        # moves settled in bulk (vplan) unless the correction depends on the approach
        # direction (take-ups at reversals) or on maps the planner cannot sample in bulk
        self.bulk_plan = options.bulk_plan and not options.added and not engine.direction_dependent
        # where the machine is before the first move: the start position (NaN: unknown);
        # the machine is there uncorrected, so it is also the previous target
        self.prev_nominal = np.array(start, dtype=float)
        self.prev_target = np.array(start, dtype=float)
        self.dirs = np.zeros(3)


    def plan(self, tab: Table) -> tuple[dict[int, Plan], dict[int, ArcHint]]:
        """Fill ``tab``'s columns (nominal starts, approach directions, corrected starts
        and targets) and return the plans of the moves that need one and the hints of the
        arcs the bulk planner settles (:class:`vplan.ArcHint`)."""
        self.approach(tab)
        self._targets(tab)
        T, D = tab.target, tab.dirs
        # starts: the corrected previous target (unrounded)
        tab.start = np.vstack([self.prev_target[None, :], T[:-1]])
        tab.d_in = np.vstack([self.dirs[None, :], D[:-1]])
        start_unknown = cast("list[bool]", np.isnan(tab.start).any(axis=1).tolist())
        # the moves that may have to be split: arcs, and straight ones unless lines stay lines
        split = {Kind.ARC_CW, Kind.ARC_CCW} if self.linear_exact else {Kind.ARC_CW, Kind.ARC_CCW, Kind.FEED}
        kinds = tab.kind.tolist()
        # (a start's coordinates are finite or NaN: unknown; their sum is NaN where one is)
        planned = [(i, m) for i, m in tab.moves
                   if kinds[i] in split and not start_unknown[i] and not math.isnan(m.q0[0] + m.q0[1] + m.q0[2])]
        plans: dict[int, Plan] = {}
        hints: dict[int, ArcHint] = {}
        if direction_axes(self.engine):  # the directions the corrected commands take
            plan_directions(self, planned, tab, plans)
        else:
            hints = self._plan_fits(planned, tab, plans)
        self.prev_nominal = tab.q1[-1].copy()
        self.prev_target = tab.target[-1].copy()
        self.dirs = tab.dirs[-1].copy()
        return plans, hints

    def skip(self, tab: Table) -> None:
        """What a chunk read but not corrected carries to the next: the last nominal
        target and the direction each axis last moved in (the caller asks only where the
        approach directions are the nominal moves' own: no direction-dependent engine or
        added map)."""
        if len(tab):
            self.approach(tab, arc_ends=False)
            self.prev_nominal = tab.q1[-1].copy()
            self.dirs = tab.dirs[-1].copy()

    def _targets(self, tab: Table) -> None:
        """The corrected target of every row, in one engine call: a row that goes to a
        stored position keeps it, a line of a run that moves nothing stays where the line
        before it went."""
        Q1, R, D, rot, linenos = tab.q1, tab.r, tab.dirs, tab.rot, tab.lineno
        M = len(Q1)
        fixed_rows, fixed_q = tab.fixed_rows, tab.fixed_q
        inert = [r.trow + j for r in tab.runs for j in r.inert]
        if fixed_rows or inert:
            live = np.ones(M, dtype=bool)
            live[fixed_rows] = False
            live[inert] = False
            T = np.empty_like(Q1)
            T[live] = self.corrected(Q1[live], R[live], D[live], self.rotary_at(rot, np.flatnonzero(live)),
                                     linenos[live], pick(tab.files, live))
            if fixed_rows:
                T[fixed_rows] = fixed_q
                Q1[fixed_rows] = fixed_q
            if inert:
                # a line of a run that moves nothing stays where the line before it went
                # (a run starts at a line that moves)
                moved = np.ones(M, dtype=bool)
                moved[inert] = False
                T[inert] = T[bulk.last_index(moved)[inert]]
        else:
            T = self.corrected(Q1, R, D, rot, linenos, tab.files)
        tab.target = T

    def _plan_fits(self, planned: list[tuple[int, PlanMove]], tab: Table,
                   plans: dict[int, Plan]) -> dict[int, ArcHint]:
        """Plans and hints where the correction does not depend on the approach
        direction: straight moves of the runs that must be split, then the moves read
        line by line settled in bulk (:func:`vplan.plan_chunk`), then the rest sampled."""
        Q0, Q1, R, D, S, T, rot, linenos = tab.q0, tab.q1, tab.r, tab.dirs, tab.start, tab.target, tab.rot, tab.lineno
        runs = tab.runs
        hints: dict[int, ArcHint] = {}

        def corr(rows: IntArray, nom: FloatArray) -> FloatArray:
            return self.corrected(nom, R[rows], D[rows], self.rotary_at(rot, rows), linenos[rows],
                                  pick(tab.files, rows))

        def curvature(rows: IntArray) -> FloatArray:
            # the commands the inverse finds lie within the largest allowed correction
            return self.engine.line_curvature_bound(Q0[rows], Q1[rows], np.linalg.norm(R[rows], axis=1),
                                                    self.opt.max_correction_mm)

        if runs and not self.linear_exact:
            # straight moves of the runs of plain lines: those that must be split are
            # planned when they are written (their Move is made then)
            rows, owner = tab.run_rows(Kind.FEED)
            ok = vplan.lines_within(rows, vplan.MoveEnds(Q0, Q1, S, T), corr, step_mm=SAMPLE_STEP_MM,
                                    limit=self.opt.tolerance_mm * FIT_BUDGET
                                    - max(self.round_err(r.unit) for r in runs), curvature=curvature)
            run_lines: list[tuple[int, PlanMove | _RunLine]] = []
            for i, o in zip(rows[~ok].tolist(), owner[~ok].tolist(), strict=True):
                runs[o].cut.append(i - runs[o].trow)
                run_lines.append((i, _RunLine(int(linenos[i]))))
            if run_lines:
                self._plan_moves(run_lines, tab, plans)
        if planned and self.bulk_plan:
            _ok_lines, hints, planned = vplan.plan_chunk(
                planned, tab.arc_prm, vplan.MoveEnds(Q0, Q1, S, T), corr, vplan.Sampling(
                    step_mm=SAMPLE_STEP_MM, step_rad=ARC_CHECK_STEP_RAD, min_arc_samples=ARC_CHECK_MIN_SAMPLES,
                    budget=self.opt.tolerance_mm * FIT_BUDGET,
                    rounding=max(self.round_err(m.unit) for _i, m in tab.moves)), curvature=curvature)
            self._hint_plans(hints, tab, plans)
        if planned:
            self._plan_moves(planned, tab, plans)
        return hints

    def approach(self, tab: Table, arc_ends: bool = True) -> None:
        """Fill ``tab``'s nominal targets (the unknown filled), its nominal starts and the
        approach direction of every move on each axis, the rows going to a stored position
        (and their targets as given), the arc_params of the arcs and the quadrant breaks
        of the arcs whose end tangent was taken. ``arc_ends`` False: the arcs' end
        tangents are not taken (chord signs serve where no direction-dependent engine or
        added map reads them)."""
        Q1, linenos, general = tab.q1, tab.lineno, tab.moves
        M = len(Q1)
        fixed_rows: list[int] = np.flatnonzero(tab.kind == Kind.AT).tolist()
        fixed_q = Q1[fixed_rows].copy() if fixed_rows else None
        if fixed_rows:
            # a stored position not given (NaN) stays unknown; the interpreter refuses moves needing it
            for i in fixed_rows:  # unknown axes: taken as not moving (no approach direction)
                before = Q1[i - 1] if i > 0 else self.prev_nominal
                Q1[i] = np.where(np.isnan(Q1[i]), before, Q1[i])
        Q1 = backfill_unknown(Q1, linenos, self.path, tab.files)
        Q0 = np.vstack([self.prev_nominal[None, :], Q1[:-1]])
        Q0 = np.where(np.isnan(Q0), Q1, Q0)
        # approach directions: chord signs (end tangent for arcs), carried where zero
        d = Q1 - Q0
        sign = np.sign(np.where(np.abs(d) > 1e-9, d, 0.0))
        arcs = [(i, m, m.arc) for i, m in general if m.arc is not None] if arc_ends else []
        # a run's arcs have their turn from their reading (plainscan.run_arcs), in the XY plane
        turns = {r.trow + j: arc[2] for r in tab.runs for j, arc in r.arcs.items()} if arcs else {}
        xy = PLANES[170][0]
        arc_prm = {i: (xy, *turns[i]) if i in turns else arc_params(arc, m.q0, m.q1) for i, m, arc in arcs}
        breaks: dict[int, FloatArray] = {}  # of the arcs the general planner cuts (made when needed)
        # the approach directions at arc ends matter only to a correction that reads them
        for i, m, arc in arcs if self.engine.direction_dependent or self.opt.added else ():
            prm = arc_prm[i]
            br = breaks[i] = quadrant_breaks(prm[1], prm[2])
            # the approach direction at the end: the motion over the arc's last piece
            # (between quadrant points every axis moves one way)
            ends = arc_points(arc, m.q0, m.q1, np.array([float(br[-1]) if len(br) else 0.0, 1.0]), prm)
            dd = ends[1] - ends[0]
            sign[i] = np.sign(np.where(np.abs(dd) > 1e-12, dd, 0.0))
        D = np.empty_like(sign)
        for ax in range(3):
            col = sign[:, ax]
            idx = np.where(col != 0, np.arange(M), -1)
            np.maximum.accumulate(idx, out=idx)
            D[:, ax] = np.where(idx >= 0, col[np.maximum(idx, 0)], self.dirs[ax])
        tab.q1, tab.q0, tab.dirs = Q1, Q0, D
        tab.fixed_rows, tab.fixed_q, tab.arc_prm, tab.breaks = fixed_rows, fixed_q, arc_prm, breaks

    def _hint_plans(self, hints: dict[int, ArcHint], tab: Table, plans: dict[int, Plan]) -> None:
        """Make now, in one engine call, the general plans (into ``plans``) of the arcs whose
        hint may well not do when written: those whose fit comes near the budget (rounded
        centre, written ends) and those whose centre words already fail for their
        corrected ends rounded as words are (:meth:`_hints_failing_rounded`). The writer
        asks for any other it needs (:meth:`provide`)."""
        moves = dict(tab.moves)
        budget = self.opt.tolerance_mm * FIT_BUDGET
        near = HINT_PREPLAN_SHARE * budget
        # a hint is only ever made for an arc (a Move or a RunMove: an ArcMove)
        arcs = cast("dict[int, ArcMove]", moves)
        fails = self._hints_failing_rounded([(i, arcs[i], hint) for i, hint in hints.items() if not hint.worst > near],
                                            budget)
        marginal = [(i, moves[i]) for i, hint in hints.items() if hint.worst > near or i in fails]
        if marginal:
            self._plan_moves(marginal, tab, plans)
        for i, hint in hints.items():
            hint.edge = i in plans

    def provide(self, need: PlanNeeded, tab: Table, plans: dict[int, Plan],
                subdivided: Subdivided) -> None:
        """Make what the writer found it needs (:class:`postproc.gcode.emitter.PlanNeeded`):
        the general plan of an arc whose hint did not hold for its ends as written (into
        ``plans``), or the engine's subdivision of a fitted curve (into ``subdivided``)."""
        if need.curve is None:
            mv = next(m for i, m in tab.moves if i == need.row)
            self._plan_moves([(need.row, mv)], tab, plans)
        else:
            self._subdivisions(need, plans, subdivided)

    def _subdivisions(self, need: PlanNeeded, plans: dict[int, Plan], subdivided: Subdivided) -> None:
        """The engine's subdivision of the span the writer asked about and, in the same
        call, of the spans after it in the curve's plan (a fit that needs one often needs
        more): one span at the curve's first request, twice as many at each next, so that
        a curve whose fit needs k spans takes about log2(k) requests. Where the engine
        refuses a call of several spans (a jump, or a solver's scatter beyond the
        tolerance: a refused span can cost thousands of evaluations), the curve's spans
        are subdivided one at a time from then on; a span's refusal is kept for the
        writer, which raises it where a fit needs that span."""
        curve = cast("Curve", need.curve)
        size = subdivided.batch.get(id(curve), 1)
        spans = [cast("FloatArray", need.span)]
        if size > 1:
            ahead = [np.array(ab) for plan in plans.values() if plan.get("curve") is curve
                     for st in plan["seq"] if st[0] == "piece"
                     for ab in zip(st[1][:-1].tolist(), st[1][1:].tolist(), strict=True)
                     if ab[0] > need.key[1] and subdivision_key(curve, np.array(ab)) not in subdivided]
            spans += ahead[:size - 1]
        try:
            got = self.subdivide([curve] * len(spans), spans, need.unit)
        except SolverError as exc:
            if len(spans) == 1:
                subdivided[need.key] = exc
                return
            subdivided.batch[id(curve)] = 0  # one at a time from now on
            self._subdivisions(need, plans, subdivided)
            return
        for sp, g in zip(spans, got, strict=True):
            subdivided[subdivision_key(curve, sp)] = g
        if size:
            subdivided.batch[id(curve)] = 2 * size

    def _hints_failing_rounded(self, arcs: list[tuple[int, ArcMove, ArcHint]], budget: float) -> set[int]:
        """The rows of the arcs whose hint gives no centre words for their corrected ends
        rounded to the output's decimals: the end points as written but for the input's
        own longer decimals and the words added for unnamed axes, so that such a hint most
        likely fails when written too (an arc whose centre no rounded words put on the
        bisector of its ends within half a step, e.g. an end's coordinate one odd step
        beyond the other's across a short chord). A guess for planning only: what is
        written is settled by the hint or the plan either way. The writer, asking with
        the same ends, gets the answer given here (:meth:`ArcHint.words`)."""
        decimals: dict[float, int] = {}
        failing: set[int] = set()
        for i, mv, hint in arcs:
            arc = mv.arc
            if arc is None:
                continue
            unit = mv.unit
            d = decimals.get(unit)
            if d is None:
                d = decimals[unit] = _unit_decimals(self.opt, unit)
            if hint.guess(arc, d, unit, mv.shift, mv.arc_absolute, budget) is None:
                failing.add(i)
        return failing

    def _plan_moves(self, planned: Sequence[tuple[int, PlanMove | _RunLine]], tab: Table,
                    plans: dict[int, Plan]) -> None:
        """Sample the corrected ideal path of every planned move in one engine call.

        A move is cut into pieces along which every axis moves one way (arcs at their
        quadrant points); each piece is evaluated with its own approach directions. Where
        the correction differs across a reversal (backlash), the plan takes up the
        difference there, as a controller's backlash compensation does; elsewhere the
        pieces are joined again."""
        arc_prm, Q0, Q1, R, S, T, d_in = tab.arc_prm, tab.q0, tab.q1, tab.r, tab.start, tab.target, tab.d_in
        rot, linenos = tab.rot, tab.lineno
        smp = _sample_moves(planned, tab)
        owner = np.repeat(np.array(smp.piece_move, dtype=int), smp.counts)
        corr = self.corrected(smp.nom, R[owner], np.repeat(smp.dirs, smp.counts, axis=0),
                              self.rotary_at(rot, owner), linenos[owner], pick(tab.files, owner))
        takeup = _takeups(smp, corr, S, d_in)
        layout = [(i, m, [(smp.s[a:b], smp.nom[a:b], takeup[p], smp.bulge[a - p:b - p - 1])
                          for p, a, b in pieces])
                  for (i, m), pieces in zip(planned, smp.pieces_of, strict=True)]
        off = 0
        for i, m, pieces in layout:
            seq: list[Step] = []
            last: Piece | None = None  # the last step, a piece (pieces are joined to it)
            prev_end = S[i]
            for s, nom, take, bulge in pieces:
                n = len(s)
                Q = corr[off:off + n].copy()
                off += n
                if take:
                    seq.append(("takeup", Q[0].copy()))
                else:
                    Q[0] = prev_end
                    if last is not None:
                        seq.pop()
                        _t, s0, Qa, na, ba = last
                        s, Q, nom, bulge = (np.concatenate([s0, s[1:]]), np.vstack([Qa, Q[1:]]),
                                            np.vstack([na, nom[1:]]), np.vstack([ba, bulge]))
                piece: Piece = ("piece", s, Q, nom, bulge)
                seq.append(piece)
                last = piece
                prev_end = Q[-1]
            Q[-1] = T[i]  # the last piece's end: the move's target
            if m.arc is not None:
                _axes, _t0, sweep, r0, r1 = arc_prm[i]
                plans[i] = {"seq": seq, "whole": len(seq) == 1, "nsweep": sweep, "mismatch": abs(r1 - r0),
                            "curve": Curve(m.q0, m.q1, m.arc, R[i], d_in[i], m.lineno, m.rotary, arc_prm[i],
                                           file_of(tab.files, i, None))}
            else:
                plans[i] = {"seq": seq, "whole": len(seq) == 1,
                            "curve": Curve(tuple(Q0[i]), tuple(Q1[i]), None, R[i], d_in[i], m.lineno, m.rotary,
                                           path=file_of(tab.files, i, None))}





def _takeups(smp: _Sampled, corr: FloatArray, S: FloatArray, d_in: FloatArray) -> list[bool]:
    """For every piece of the sampled moves, whether a take-up goes before it: its approach
    directions differ from the piece's before (a move's first piece: from the move's
    ``d_in``) and its first corrected sample lies more than TAKEUP_MIN_MM (on an axis)
    from where the piece before ended (a move's first piece: from its corrected start S)."""
    first = [k == 0 for pieces in smp.pieces_of for k in range(len(pieces))]
    if not first:
        return []
    rows = np.array(smp.piece_move, dtype=int)
    begin = np.cumsum(smp.counts) - smp.counts  # each piece's first sample
    lead = np.array(first, dtype=bool)
    before = np.maximum(np.arange(len(lead)) - 1, 0)  # the piece before (within the move where not lead)
    prev_dirs = np.where(lead[:, None], d_in[rows], smp.dirs[before])
    prev_end = np.where(lead[:, None], S[rows], corr[np.maximum(begin - 1, 0)])
    differ = (smp.dirs != prev_dirs).any(axis=1)
    jump = np.abs(corr[begin] - prev_end).max(axis=1) > TAKEUP_MIN_MM
    return cast("list[bool]", (differ & jump).tolist())
