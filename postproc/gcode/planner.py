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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast, final

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import (
    CorrectionTooLargeError,
    OutOfVolumeError,
    PostprocError,
    SafetyError,
    SolverError,
)
from postproc.gcode import bulk, vplan
from postproc.gcode.directions import (
    MACHINE_STEP_MM,
    Commanding,
    PieceInputs,
    SettledPoints,
    direction_axes,
    plan_pieces,
    reversals,
    settle,
)
from postproc.gcode.emitter import FIT_BUDGET, _unit_decimals
from postproc.gcode.geometry import (
    ArcColumns,
    arc_length,
    arc_params,
    arc_points,
    arcs_points,
    line_points,
)
from postproc.gcode.moves import Arc
from postproc.gcode.options import CorrectOptions, CorrectReport
from postproc.gcode.path import backfill_unknown
from postproc.gcode.segment import Curve, quadrant_breaks, subdivide
from postproc.gcode.state import LINE, PLANES
from postproc.gcode.vplan import (
    ArcHint,
    ArcMove,
    ArcParams,
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

# Samples of the corrected ideal path that every emitted arc and chord is fitted to and
# checked against: at most this far apart along a move (half verify's run step) ...
SAMPLE_STEP_MM = 0.25
# ... and this far apart in angle along an arc, with at least this many on each piece.
ARC_CHECK_STEP_RAD = math.pi / 32
ARC_CHECK_MIN_SAMPLES = 5
# An arc the bulk planner settles with a fit beyond this share of the budget gets its
# general plan with the chunk's (one engine call) in case its hint fails when written:
# on a parametric gencam program 70 % of those hints fail, 2 % of the others.
HINT_PREPLAN_SHARE = 0.7
# A reversal whose corrections on either side differ by more than this gets a take-up move.
TAKEUP_MIN_MM = 1e-7

_NO_POINTS = np.zeros((0, 3))


@dataclass(eq=False)
class Table:
    """A chunk's moves, a row each in program order, as columns. The reader fills what it
    read (targets, lines, tool vectors, rotary positions, the moves read line by line and
    the runs of plain lines); the planner the rest."""

    q1: FloatArray  # (M, 3) nominal targets (machine mm; unknown axes filled by the planner)
    lineno: IntArray  # (M,) source line of each row
    r: FloatArray  # (M, 3) tool vectors
    rot: list[dict[str, float]]  # rotary axis positions of each row ({} without rotary axes)
    moves: list[tuple[int, PlanMove]]  # (row, move) of the rows read line by line, and the runs' arcs
    runs: Sequence[bulk.Run] = ()  # runs of plain lines (each knows its first row, trow)
    # -- filled by Planner.approach
    q0: FloatArray = field(default_factory=lambda: _NO_POINTS)  # nominal starts
    dirs: FloatArray = field(default_factory=lambda: _NO_POINTS)  # approach direction of each axis (-1, 0, 1)
    arc_prm: dict[int, ArcParams] = field(default_factory=dict)  # arc_params of the arcs, by row
    breaks: dict[int, FloatArray] = field(default_factory=dict)  # quadrant breaks of arcs, by row
    fixed_rows: list[int] = field(default_factory=list)  # rows that go to a stored position, uncorrected
    fixed_q: FloatArray | None = None  # their targets as given
    # -- filled by Planner.plan
    target: FloatArray = field(default_factory=lambda: _NO_POINTS)  # corrected targets (unrounded)
    start: FloatArray = field(default_factory=lambda: _NO_POINTS)  # corrected starts: the target before
    d_in: FloatArray = field(default_factory=lambda: _NO_POINTS)  # directions before each row

    def __len__(self) -> int:
        return len(self.q1)


class Planner:
    """Engine calls with their safety checks, and the plans of a chunk's moves; carries
    the corrected position and directions from one chunk to the next."""

    def __init__(self, engine: Engine, options: CorrectOptions, report: CorrectReport, rotary: set[str],
                 context: Mapping[str, float], accept_residual_mm: float, start: Sequence[float],
                 path: str | None = None) -> None:
        self.engine = engine
        self.opt = options
        self.report = report
        self.path = path
        self.rotary = rotary  # the rotary axes the program names (the interpreter's set, filled as it reads)
        self.setup_context = dict(context)
        self.accept_residual_mm = accept_residual_mm
        self.linear_exact = bool(engine.affine) and not options.added
        # moves settled in bulk (vplan) unless the correction depends on the approach
        # direction (take-ups at reversals) or on maps the planner cannot sample in bulk
        self.bulk_plan = options.bulk_plan and not options.added and not engine.direction_dependent
        # where the machine is before the first move: the start position (NaN: unknown);
        # the machine is there uncorrected, so it is also the previous target
        self.prev_nominal = np.array(start, dtype=float)
        self.prev_target = np.array(start, dtype=float)
        self.dirs = np.zeros(3)
        self.units_checked: set[float] = set()


    def context(self, dirs: FloatArray, rotary: Sequence[dict[str, float]]) -> dict[str, FloatArray]:
        ctx: dict[str, FloatArray] = {"dirx": dirs[:, 0], "diry": dirs[:, 1], "dirz": dirs[:, 2]}
        for a in sorted(self.rotary):
            ctx[a] = np.array([d.get(a, 0.0) for d in rotary])
        for k, v in self.setup_context.items():
            ctx[k] = np.full(len(dirs), float(v))
        return ctx

    def corrected(self, q_nom: FloatArray, r: FloatArray, dirs: FloatArray, rotary: Sequence[dict[str, float]],
                  lineno: IntArray) -> FloatArray:
        """Corrected gauge positions for nominal gauge positions (all safety checks)."""
        eng = self.engine
        p = q_nom + r
        ctx = self.context(dirs, rotary)
        inside = eng.inside(q_nom)
        p_eval = p
        if not inside.all():
            bad = np.flatnonzero(~inside)
            if self.opt.extrapolate == "refuse":
                lines = sorted(set(lineno[bad].tolist()))
                first = q_nom[bad[0]]
                raise OutOfVolumeError(
                    f"target outside the calibrated volume at lines {', '.join(map(str, lines[:8]))}"
                    f"{' ...' if len(lines) > 8 else ''}: commanded ({first[0]:.3f}, {first[1]:.3f}, "
                    f"{first[2]:.3f}) mm, volume {eng.volume_mm[0].tolist()} .. {eng.volume_mm[1].tolist()} mm",
                    path=self.path, lineno=int(lineno[bad[0]]),
                    hint="check --offset/--tool-length, or allow it with --extrapolate clamp|linear")
            self.report.extrapolated_points += len(bad)
            if self.opt.extrapolate == "clamp":
                q_eval = np.clip(q_nom, eng.volume_mm[0], eng.volume_mm[1])
                p_eval = q_eval + r
        try:
            res = eng.correction(p_eval, r, ctx)
        except PostprocError as exc:
            raise exc.at(path=self.path, lineno=int(lineno[0]) if len(lineno) else None) from None
        delta = np.asarray(res.q, dtype=float)
        resid = np.asarray(res.residual_mm, dtype=float)
        bad = ~np.isfinite(delta).all(axis=1) | ~(resid <= self.accept_residual_mm)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            solver = f" {self.report.solver}" if self.report.solver else ""
            raise SolverError(
                f"the {eng.method}{solver} inverse did not converge (residual {resid[i]:.3g} mm, "
                f"accepted up to {self.accept_residual_mm:.3g} mm)",
                path=self.path, lineno=int(lineno[i]),
                hint="the calibration may be unusable here; check it with 'postproc check'")
        if len(resid):
            self.report.max_residual_mm = max(self.report.max_residual_mm, float(resid.max()))
        ctx_added = dict(ctx, lineno=lineno) if self.opt.added else ctx
        for add in self.opt.added:
            try:
                d = np.asarray(add.delta(p, ctx_added), dtype=float)
            except PostprocError as exc:
                # a map names the point it refused (point_index); name its program line
                at = getattr(exc, "point_index", None)
                ln = int(lineno[at]) if at is not None and 0 <= at < len(lineno) else None
                raise exc.at(path=self.path, lineno=ln) from None
            if d.shape != delta.shape or not np.isfinite(d).all():
                raise SolverError(f"correction map {add.name!r} gave no finite correction here",
                                  path=self.path, lineno=int(lineno[0]))
            delta = delta + d
        size = np.linalg.norm(delta, axis=1)
        if len(size):
            i = int(np.argmax(size))
            if size[i] > self.opt.max_correction_mm:
                raise CorrectionTooLargeError(
                    f"correction of {size[i]:.4f} mm exceeds --max-correction {self.opt.max_correction_mm:g} mm",
                    path=self.path, lineno=int(lineno[i]),
                    hint="a correction this large suggests wrong units or a wrong calibration; "
                         "raise --max-correction only if it is real")
            self.report.max_correction_mm = max(self.report.max_correction_mm, float(size[i]))
        return q_nom + delta

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
        planned = [(i, m) for i, m in tab.moves
                   if (m.arc is not None or (not self.linear_exact and m.kind == LINE and not m.planned))
                   and not start_unknown[i] and not any(math.isnan(v) for v in m.q0)]
        plans: dict[int, Plan] = {}
        hints: dict[int, ArcHint] = {}
        if direction_axes(self.engine):  # the directions the corrected commands take
            self._plan_directions(planned, tab, plans)
        else:
            hints = self._plan_fits(planned, tab, plans)
        self.prev_nominal = tab.q1[-1].copy()
        self.prev_target = tab.target[-1].copy()
        self.dirs = tab.dirs[-1].copy()
        return plans, hints

    def skip(self, tab: Table) -> None:
        """What a chunk read but not corrected carries to the next, where the approach
        directions are the nominal moves' own (no direction-dependent engine or added
        map): the last nominal target and the direction each axis last moved in."""
        if not (self.engine.direction_dependent or self.opt.added) and len(tab):
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
            T[live] = self.corrected(Q1[live], R[live], D[live], [rot[i] for i in np.flatnonzero(live)],
                                     linenos[live])
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
            T = self.corrected(Q1, R, D, rot, linenos)
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
            return self.corrected(nom, R[rows], D[rows], [rot[i] for i in rows.tolist()], linenos[rows])

        def curvature(rows: IntArray) -> FloatArray:
            # the commands the inverse finds lie within the largest allowed correction
            return self.engine.line_curvature_bound(Q0[rows], Q1[rows], np.linalg.norm(R[rows], axis=1),
                                                    self.opt.max_correction_mm)

        if runs and not self.linear_exact:
            # straight moves of the runs of plain lines: those that must be split are
            # planned when they are written (their Move is made then)
            rows, owner = bulk.line_rows(runs)
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
            self._hint_plans(hints, tab)
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
        fixed_rows = [i for i, m in general if m.fixed]
        fixed_q = Q1[fixed_rows].copy() if fixed_rows else None
        if fixed_rows:
            # a stored position not given (NaN) stays unknown; the interpreter refuses moves needing it
            for i in fixed_rows:  # unknown axes: taken as not moving (no approach direction)
                before = Q1[i - 1] if i > 0 else self.prev_nominal
                Q1[i] = np.where(np.isnan(Q1[i]), before, Q1[i])
        Q1 = backfill_unknown(Q1, linenos, self.path)
        Q0 = np.vstack([self.prev_nominal[None, :], Q1[:-1]])
        Q0 = np.where(np.isnan(Q0), Q1, Q0)
        # approach directions: chord signs (end tangent for arcs), carried where zero
        d = Q1 - Q0
        sign = np.sign(np.where(np.abs(d) > 1e-9, d, 0.0))
        arcs = [(i, m, m.arc) for i, m in general if m.arc is not None] if arc_ends else []
        arc_prm = {i: arc_params(arc, m.q0, m.q1) for i, m, arc in arcs}
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

    def _hint_plans(self, hints: dict[int, ArcHint], tab: Table) -> None:
        """Give every hint its general plan, for when the hint does not do: made now, in
        one engine call, for the arcs whose fit comes near the budget (their hints often
        fail when written: rounded centre, written ends) and those whose centre words
        already fail for their corrected ends rounded as words are
        (:meth:`_hints_failing_rounded`), else when asked for."""
        moves = dict(tab.moves)
        budget = self.opt.tolerance_mm * FIT_BUDGET
        near = HINT_PREPLAN_SHARE * budget
        made: dict[int, Plan] = {}
        # a hint is only ever made for an arc (a Move or a RunMove: an ArcMove)
        fails = self._hints_failing_rounded([(i, cast("ArcMove", moves[i]), hint) for i, hint in hints.items()
                                             if not hint.worst > near], budget)
        marginal = [(i, moves[i]) for i, hint in hints.items() if hint.worst > near or i in fails]
        if marginal:
            self._plan_moves(marginal, tab, made)
        for i, hint in hints.items():
            plan = made.get(i)
            hint.edge = plan is not None
            hint.lazy = (self._lazy_plan(i, moves[i], tab)
                         if plan is None else _given(plan))

    def _hints_failing_rounded(self, arcs: list[tuple[int, ArcMove, ArcHint]], budget: float) -> set[int]:
        """The rows of the arcs whose hint gives no centre words for their corrected ends
        rounded to the output's decimals: the end points as written but for the input's
        own longer decimals and the words added for unnamed axes, so that such a hint most
        likely fails when written too (an arc whose centre no rounded words put on the
        bisector of its ends within half a step, e.g. an end's coordinate one odd step
        beyond the other's across a short chord). A guess for planning only: what is
        written is settled by the hint or the plan either way. All the arcs are asked at
        once (:func:`vplan.words_many`); the writer, asking with the same ends, gets the
        answers given here."""
        arcs = [(i, mv, hint) for i, mv, hint in arcs if mv.arc is not None]
        if not arcs:
            return set()
        axes = np.array([PLANES[cast("Arc", mv.arc).plane][0] for _i, mv, _h in arcs], dtype=int)
        unit = np.array([mv.unit for _i, mv, _h in arcs], dtype=float)
        d = [_unit_decimals(self.opt, u) for u in unit.tolist()]
        shift = np.array([mv.shift for _i, mv, _h in arcs], dtype=float)
        ends = np.array([hint.ends for _i, _mv, hint in arcs], dtype=float)
        rows = np.arange(len(arcs))[:, None]
        sh = shift[rows, axes]  # each arc's shift in its plane's order, as its ends
        u = unit[:, None]
        # the corrected ends rounded as words are: round((q - shift) / unit, d) * unit + shift
        S, E = np.empty_like(sh), np.empty_like(sh)
        S[rows, axes] = vplan.round_many((ends[:, :3] - sh) / u, d) * u + sh
        E[rows, axes] = vplan.round_many((ends[:, 3:] - sh) / u, d) * u + sh
        absolute = np.array([mv.arc_absolute for _i, mv, _h in arcs], dtype=bool)[:, None]
        base = np.where(absolute, sh[:, :2], S[rows, axes[:, :2]])
        clockwise = [cast("Arc", mv.arc).clockwise for _i, mv, _h in arcs]
        got = vplan.words_many([h for _i, _mv, h in arcs], vplan.WrittenArcs(S, E, axes, clockwise, d, unit, base),
                               budget)
        return {i for (i, _mv, _h), w in zip(arcs, got, strict=True) if w is None}

    def _lazy_plan(self, i: int, mv: PlanMove, tab: Table) -> Callable[[], Plan]:
        """The general plan of move ``i``, made when asked for."""

        def plan() -> Plan:
            out: dict[int, Plan] = {}
            self._plan_moves([(i, mv)], tab, out)
            return out[i]

        return plan

    def _plan_directions(self, planned: list[tuple[int, PlanMove]], tab: Table, plans: dict[int, Plan]) -> None:
        """Targets, directions and plans of a chunk for a direction-dependent correction
        (backlash), settled on the directions the corrected commands take
        (:mod:`postproc.gcode.directions`): the commanded points are every sample of a
        planned move (sampled as :meth:`_plan_moves` does) and the target of any other
        move; a point less than one output unit against its axis's direction is held.
        Fills ``plans``, and the table's targets and directions."""
        arc_prm, breaks, Q0, Q1, R, T, D = tab.arc_prm, tab.breaks, tab.q0, tab.q1, tab.r, tab.target, tab.dirs
        rot, linenos, fixed_rows = tab.rot, tab.lineno, tab.fixed_rows
        M = len(T)
        axes = direction_axes(self.engine)
        counts = np.ones(M, dtype=int)
        # i -> (s (n,), nominal (n, 3), dirs (n, 3), given axes)
        samples: dict[int, tuple[FloatArray, FloatArray, FloatArray, list[int]]] = {}
        planned = [(i, m) for i, m in planned if not m.fixed]  # a stored position is one point
        for i, m in planned:
            arc = m.arc
            if arc is None:
                length = float(np.linalg.norm(Q1[i] - Q0[i]))
                s = np.linspace(0.0, 1.0, max(3, math.ceil(length / SAMPLE_STEP_MM) + 1))[1:]
                samples[i] = (s, line_points(Q0[i], Q1[i], s), D[i], [])
            else:
                prm = arc_prm[i]
                (a1, a2, _an), _t0, sweep, _r0, _r1 = prm
                length = arc_length(arc, m.q0, m.q1, prm)
                cuts = [0.0, *breaks[i].tolist(), 1.0]
                ss = [np.linspace(sa, sb, _arc_piece_samples(sb - sa, length, sweep))[1:]
                      for sa, sb in zip(cuts[:-1], cuts[1:], strict=True)]
                ends = arc_points(arc, m.q0, m.q1, np.array(cuts), prm)
                dd = np.diff(ends, axis=0)
                dr = np.where(np.abs(dd) > 1e-12, np.sign(dd), D[i])  # each quarter's own direction
                s = np.concatenate(ss)
                dirs = np.repeat(dr, [len(x) for x in ss], axis=0)
                samples[i] = (s, arc_points(arc, m.q0, m.q1, s, prm), dirs, [a1, a2])
            counts[i] = len(samples[i][0])
        owner = np.repeat(np.arange(M), counts)
        last = np.cumsum(counts) - 1
        first = last - counts + 1
        nominal, Tx, Dx = Q1[owner], T[owner], D[owner]
        sx = np.ones(len(owner))
        given = np.zeros(nominal.shape, dtype=bool)  # an arc's in-plane axes: the direction of its quarter
        for i, (s, nom, dirs, plane) in samples.items():
            sl = slice(first[i], last[i] + 1)
            sx[sl], nominal[sl], Dx[sl] = s, nom, dirs
            given[sl, plane] = True
        free = np.ones(M, dtype=bool)
        free[fixed_rows] = False
        free = free[owner]
        hold = max(MACHINE_STEP_MM, *(10.0 ** -_unit_decimals(self.opt, u) * u for u in self.units_checked))

        def solve(rows: IntArray, dirs: FloatArray, at: FloatArray | None = None) -> FloatArray:
            own = owner[rows]
            return self.corrected(nominal[rows] if at is None else at, R[own], dirs,
                                  [rot[j] for j in own.tolist()], linenos[own])

        inner = np.flatnonzero(counts[owner] > 1)
        if len(inner):
            Tx[inner] = solve(inner, Dx[inner])
        Ex, Dx = settle(Tx, Dx, Commanding(self.prev_target, self.dirs, hold, axes, free, given, first[owner]), solve,
                        linenos[owner], path=self.path)
        T, D = tab.target, tab.dirs = Ex[last], Dx[last]
        if not planned:
            return
        # take-ups: before a point a direction-dependent axis reverses into, the point
        # before it corrected with the new directions
        rows = np.concatenate([np.arange(first[i], last[i] + 1) for i, _m in planned])
        rows = rows[reversals(Dx, self.dirs, axes, rows)]
        takeups: dict[int, FloatArray] = {}
        if len(rows):
            at = np.array([nominal[j - 1] if j != first[owner[j]] else Q0[owner[j]] for j in rows.tolist()])
            takeups = dict(zip(rows.tolist(), solve(rows, Dx[rows], at), strict=True))
        for i, m in planned:
            j0 = int(first[i])
            start = Ex[j0 - 1] if j0 > 0 else self.prev_target
            start_dirs = Dx[j0 - 1] if j0 > 0 else self.dirs
            arc = m.arc
            bulge: Callable[[FloatArray, FloatArray], FloatArray]
            if arc is not None:
                prm = arc_prm[i]

                def arc_bulge(s: FloatArray, nom: FloatArray, arc: Arc = arc, m: PlanMove = m,
                              prm: ArcParams = prm) -> FloatArray:
                    mid = arc_points(arc, m.q0, m.q1, 0.5 * (s[:-1] + s[1:]), prm)
                    return mid - 0.5 * (nom[:-1] + nom[1:])

                bulge = arc_bulge
            else:
                bulge = _no_bulge
            seq = plan_pieces(PieceInputs(j0, int(last[i]), start, start_dirs, Q0[i], bulge,
                                          self.opt.tolerance_mm - self.round_err(m.unit), m.lineno),
                              SettledPoints(Ex, Dx, sx, nominal, takeups, rows, axes, TAKEUP_MIN_MM), path=self.path)
            if arc is not None:
                (_a1, _a2, an), _t0, sweep, r0, r1 = arc_prm[i]
                carried = np.array(start_dirs, dtype=float)
                carried[an] = D[i][an]
                plans[i] = {"seq": seq, "whole": len(seq) == 1, "nsweep": sweep, "mismatch": abs(r1 - r0),
                            "curve": Curve(m.q0, m.q1, arc, R[i], carried, m.lineno, m.rotary, arc_prm[i])}
            else:  # a line's standing axes: the direction its corrected command takes
                plans[i] = {"seq": seq, "whole": len(seq) == 1,
                            "curve": Curve(tuple(Q0[i]), tuple(Q1[i]), None, R[i], D[i], m.lineno, m.rotary)}

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
                              [rot[i] for i in owner.tolist()], linenos[owner])
        layout = [(i, m, [(smp.s[a:b], smp.nom[a:b], smp.dirs[p], smp.bulge[a - p:b - p - 1])
                          for p, a, b in pieces])
                  for (i, m), pieces in zip(planned, smp.pieces_of, strict=True)]
        off = 0
        for i, m, pieces in layout:
            seq: list[Step] = []
            last: Piece | None = None  # the last step, a piece (pieces are joined to it)
            prev_end = S[i]
            prev_dirs = d_in[i]
            for s, nom, dr, bulge in pieces:
                n = len(s)
                Q = corr[off:off + n].copy()
                off += n
                if (dr != prev_dirs).any() and np.abs(Q[0] - prev_end).max() > TAKEUP_MIN_MM:
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
                prev_dirs = dr
            Q[-1] = T[i]  # the last piece's end: the move's target
            if m.arc is not None:
                _axes, _t0, sweep, r0, r1 = arc_prm[i]
                plans[i] = {"seq": seq, "whole": len(seq) == 1, "nsweep": sweep, "mismatch": abs(r1 - r0),
                            "curve": Curve(m.q0, m.q1, m.arc, R[i], d_in[i], m.lineno, m.rotary, arc_prm[i])}
            else:
                plans[i] = {"seq": seq, "whole": len(seq) == 1,
                            "curve": Curve(tuple(Q0[i]), tuple(Q1[i]), None, R[i], d_in[i], m.lineno, m.rotary)}

    def check_rounding(self, unit: float, lineno: int) -> None:
        """Refuse when rounding the words to their decimals alone exceeds the tolerance."""
        err = self.round_err(unit)
        if err >= self.opt.tolerance_mm:
            d = _unit_decimals(self.opt, unit)
            raise SafetyError(
                f"words written with {d} decimals in {'inch' if unit == MM_PER_INCH else 'mm'} are rounded by up "
                f"to {err:.3g} mm, more than --tolerance {self.opt.tolerance_mm:g} mm",
                path=self.path, lineno=lineno,
                hint=f"give more --decimals or a --tolerance above {err:.3g} mm")
        self.units_checked.add(unit)

    def round_err(self, unit: float) -> float:
        d = _unit_decimals(self.opt, unit)
        return 0.5 * 10.0 ** (-d) * unit * math.sqrt(3.0)

    def subdivide(self, curves: list[Curve], s_init: list[FloatArray], unit: float
                   ) -> list[tuple[FloatArray, FloatArray]]:
        rerr = self.round_err(unit)
        line_ids = np.array([c.arc is None for c in curves])
        Q0 = np.array([c.q0 for c in curves], dtype=float)
        Q1 = np.array([c.q1 for c in curves], dtype=float)
        Rr = np.array([c.r for c in curves], dtype=float)

        def evaluate(cid: np.ndarray, s: np.ndarray) -> np.ndarray:
            nom = np.empty((len(s), 3))
            dirs = np.empty((len(s), 3))
            is_line = line_ids[cid]
            if is_line.any():
                c = cid[is_line]
                nom[is_line] = Q0[c] + (Q1[c] - Q0[c]) * s[is_line, None]
                dd = np.sign(Q1[c] - Q0[c])
                carried = np.array([curves[j].dirs for j in c]).reshape(-1, 3)
                dirs[is_line] = np.where(dd == 0, carried, dd)
            if (~is_line).any():
                for j in np.unique(cid[~is_line]).tolist():
                    sel = cid == j
                    nom[sel] = curves[j].nominal(s[sel])
                    dirs[sel] = curves[j].directions(s[sel])
            rot = [curves[j].rotary for j in cid.tolist()]
            ln = np.array([curves[j].lineno for j in cid.tolist()])
            return self.corrected(nom, Rr[cid], dirs, rot, ln)

        try:
            return subdivide(curves, s_init, evaluate, self.opt.tolerance_mm - rerr)
        except SolverError as exc:
            if self.accept_residual_mm > self.opt.tolerance_mm:
                exc.hint = (f"the {self.report.solver or self.engine.method} solver's answers scatter by up to "
                            f"its residual (largest so far {self.report.max_residual_mm * 1000:.3g} um), more than "
                            f"--tolerance {self.opt.tolerance_mm:g} mm allows: raise --tolerance above that "
                            "residual, or use a calibration with the newton solver")
            raise exc.at(path=self.path) from None


@final
class _RunLine:
    """What the planner needs of a straight move read in a run of plain lines."""

    __slots__ = ("lineno",)
    arc: None = None
    rotary: dict[str, float] = {}

    def __init__(self, lineno: int) -> None:
        self.lineno = lineno


@final
class _Sampled:
    """The nominal samples of a chunk's planned moves, cut into pieces along which every
    axis moves one way (see :func:`_sample_moves`)."""

    __slots__ = ("s", "nom", "bulge", "dirs", "counts", "piece_move", "pieces_of")

    def __init__(self, s: FloatArray, nom: FloatArray, bulge: FloatArray, dirs: FloatArray, counts: IntArray,
                 piece_move: list[int], pieces_of: list[list[tuple[int, int, int]]]) -> None:
        self.s = s  # parameters of every sample, piece after piece
        self.nom = nom  # their nominal points
        self.bulge = bulge  # how the nominal path bulges from the chord of each sample interval
        self.dirs = dirs  # (pieces, 3) each piece's approach directions
        self.counts = counts  # samples per piece
        self.piece_move = piece_move  # the row of each piece's move
        self.pieces_of = pieces_of  # per move: (piece, first sample, end) of its pieces


@final
class _Layout:
    """How the planned moves are cut into pieces and sampled (see :func:`_sample_moves`):
    per piece its parameter span (``sa``, ``sb``), its number of samples, its move's row
    and its arc (an index into ``arc_rows``, or -1 for a line); per move its pieces
    (piece, first sample, end); ``total`` samples in all."""

    __slots__ = ("sa", "sb", "n", "piece_move", "arc_piece", "arc_rows", "pieces_of", "total")

    def __init__(self, planned: Sequence[tuple[int, PlanMove | _RunLine]], tab: Table) -> None:
        arc_prm, breaks, Q0, Q1 = tab.arc_prm, tab.breaks, tab.q0, tab.q1
        sa_l: list[float] = []
        sb_l: list[float] = []
        n_l: list[int] = []
        piece_move: list[int] = []
        arc_piece: list[int] = []  # per piece: its arc's index in arc_rows, or -1 for a line
        arc_rows: list[tuple[ArcParams, Sequence[float], Sequence[float], Sequence[float]]] = []  # prm, q0, q1, centre
        pieces_of: list[list[tuple[int, int, int]]] = []
        total = 0
        for i, m in planned:
            own: list[tuple[int, int, int]] = []
            if m.arc is not None:
                prm = arc_prm[i]
                _axes, t0, sweep, _r0, _r1 = prm
                length = arc_length(m.arc, m.q0, m.q1, prm)
                br = breaks.get(i)
                if br is None:
                    br = breaks[i] = quadrant_breaks(t0, sweep)
                cuts = [0.0, *br.tolist(), 1.0]
                k = len(arc_rows)
                arc_rows.append((prm, m.q0, m.q1, m.arc.center))
                for sa, sb in zip(cuts[:-1], cuts[1:], strict=True):
                    n = _arc_piece_samples(sb - sa, length, sweep)
                    own.append((len(n_l), total, total + n))
                    sa_l.append(sa)
                    sb_l.append(sb)
                    n_l.append(n)
                    piece_move.append(i)
                    arc_piece.append(k)
                    total += n
            else:
                length = float(np.linalg.norm(Q1[i] - Q0[i]))
                n = max(3, math.ceil(length / SAMPLE_STEP_MM) + 1)
                own.append((len(n_l), total, total + n))
                sa_l.append(0.0)
                sb_l.append(1.0)
                n_l.append(n)
                piece_move.append(i)
                arc_piece.append(-1)
                total += n
            pieces_of.append(own)
        self.sa, self.sb, self.n, self.piece_move, self.arc_piece = sa_l, sb_l, n_l, piece_move, arc_piece
        self.arc_rows, self.pieces_of, self.total = arc_rows, pieces_of, total


def _sample_moves(planned: Sequence[tuple[int, PlanMove | _RunLine]], tab: Table) -> _Sampled:
    """Samples of the planned moves, every one at once: an arc cut at its quadrant points
    (``breaks`` filled where missing), each piece sampled at least every
    SAMPLE_STEP_MM and ARC_CHECK_STEP_RAD (ARC_CHECK_MIN_SAMPLES at least), a line every
    SAMPLE_STEP_MM (3 samples at least). The parameters are np.linspace's and the
    points :func:`~postproc.gcode.geometry.arc_points`' and
    :func:`~postproc.gcode.geometry.line_points`', element by element the same
    operations. An arc piece's directions are the signs of its chord, carried from the
    piece before (from ``d_in``) where an axis stands; a line's are ``D``."""
    Q0, Q1, D, d_in = tab.q0, tab.q1, tab.dirs, tab.d_in
    lay = _Layout(planned, tab)
    sa_l, sb_l, n_l, piece_move, arc_piece = lay.sa, lay.sb, lay.n, lay.piece_move, lay.arc_piece
    arc_rows, pieces_of, total = lay.arc_rows, lay.pieces_of, lay.total
    counts = np.array(n_l, dtype=int)
    P = len(counts)
    first = np.cumsum(counts) - counts
    sa, sb = np.array(sa_l), np.array(sb_l)
    # np.linspace(sa, sb, n): arange(n) * ((sb - sa) / (n - 1)) + sa, its last value sb
    k_in = (np.arange(total) - np.repeat(first, counts)).astype(float)
    s = k_in * np.repeat((sb - sa) / (counts - 1), counts) + np.repeat(sa, counts)
    s[first + counts - 1] = sb
    owner_piece = np.repeat(np.arange(P), counts)
    rows = np.array(piece_move, dtype=int)
    ap = np.array(arc_piece, dtype=int)
    nom = np.empty((total, 3))
    # lines: q0 + (q1 - q0) * s
    line_smp = np.flatnonzero(ap[owner_piece] < 0)
    if len(line_smp):
        r = rows[owner_piece[line_smp]]
        nom[line_smp] = Q0[r] + (Q1[r] - Q0[r]) * s[line_smp, None]
    # the middle of every sample interval within a piece
    inner = np.ones(total, dtype=bool)
    inner[first + counts - 1] = False
    j = np.flatnonzero(inner)
    s_mid = 0.5 * (s[j] + s[j + 1])
    owner_mid = owner_piece[j]
    bulge = np.zeros((len(j), 3))
    arc_smp = np.flatnonzero(ap[owner_piece] >= 0)
    if len(arc_smp):
        axes = np.array([prm[0] for prm, _q0, _q1, _c in arc_rows], dtype=int)
        t0s, sweeps, r0s, r1s = (np.array([prm[f] for prm, _q0, _q1, _c in arc_rows]) for f in (1, 2, 3, 4))
        q0s, q1s, centres = (np.array([row[f] for row in arc_rows], dtype=float) for f in (1, 2, 3))

        def arc_nominal(which: IntArray, at: FloatArray) -> FloatArray:
            return arcs_points(which, at, ArcColumns(axes, t0s, sweeps, r0s, r1s, centres, q0s, q1s))

        arc_mid = np.flatnonzero(ap[owner_mid] >= 0)
        mid = arc_nominal(ap[owner_mid[arc_mid]], s_mid[arc_mid])
        nom[arc_smp] = arc_nominal(ap[owner_piece[arc_smp]], s[arc_smp])
        jm = j[arc_mid]
        bulge[arc_mid] = mid - 0.5 * (nom[jm] + nom[jm + 1])
    # directions: an arc piece's chord signs, an axis that stands carried from the piece
    # before (the first from d_in); a line's own
    last = first + counts - 1
    dd = nom[last] - nom[first]
    sign = np.sign(np.where(np.abs(dd) > 1e-12, dd, 0.0))
    dirs = np.empty((P, 3))
    carried = np.zeros(3)
    for p in range(P):
        i = piece_move[p]
        if arc_piece[p] < 0:
            dirs[p] = D[i]
            continue
        if p == 0 or arc_piece[p - 1] != arc_piece[p]:  # an arc's first piece
            carried = d_in[i]
        dirs[p] = carried = np.where(sign[p] == 0, carried, sign[p])
    return _Sampled(s, nom, bulge, dirs, counts, piece_move, pieces_of)


def _arc_piece_samples(span: float, length: float, sweep: float) -> int:
    """Samples of an arc piece spanning ``span`` of the arc's parameter (``length``,
    ``sweep``: the whole arc's): at least every SAMPLE_STEP_MM and ARC_CHECK_STEP_RAD,
    and ARC_CHECK_MIN_SAMPLES at least."""
    return max(ARC_CHECK_MIN_SAMPLES, math.ceil(span * length / SAMPLE_STEP_MM) + 1,
               math.ceil(span * abs(sweep) / ARC_CHECK_STEP_RAD) + 1)


def _given(plan: Plan) -> Callable[[], Plan]:
    """A plan already made, as a hint's lazy plan."""
    return lambda: plan


def _no_bulge(s: FloatArray, nom: FloatArray) -> FloatArray:
    """A straight move's nominal path does not bulge from its chords."""
    return np.zeros((len(s) - 1, 3))
