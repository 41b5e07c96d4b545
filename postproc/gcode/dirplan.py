"""Plans for a correction that depends on the approach direction (backlash).

The targets and directions of a chunk are settled on the directions the corrected
commands take (:mod:`postproc.gcode.directions`): the commanded points are every sample
of a planned move and the target of any other move; a point less than one output unit
against its axis's direction is held. Where an axis reverses, the point before the
reversal, corrected with the new directions, becomes a take-up move.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Protocol, final

import numpy as np

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
from postproc.gcode.emitter import _unit_decimals
from postproc.gcode.geometry import arc_length, arc_points, line_points
from postproc.gcode.moves import Arc
from postproc.gcode.options import CorrectOptions
from postproc.gcode.places import PathArray, file_of, pick
from postproc.gcode.sampling import SAMPLE_STEP_MM, _arc_piece_samples, _no_bulge
from postproc.gcode.segment import Curve
from postproc.gcode.table import Table
from postproc.gcode.vplan import ArcParams, FloatArray, IntArray, Plan, PlanMove

if TYPE_CHECKING:
    from postproc.engine.base import Engine

# A reversal whose corrections on either side differ by more than this gets a take-up move.
TAKEUP_MIN_MM = 1e-7


class _Planner(Protocol):
    """What these plans use of :class:`postproc.gcode.planner.Planner`."""

    @property
    def engine(self) -> Engine: ...

    opt: CorrectOptions
    path: str | None
    prev_target: FloatArray
    dirs: FloatArray
    units_checked: set[float]

    def corrected(self, q_nom: FloatArray, r: FloatArray, dirs: FloatArray, rotary: Sequence[dict[str, float]],
                  lineno: IntArray, files: PathArray | None = None) -> FloatArray: ...

    def rotary_at(self, rot: Sequence[dict[str, float]], rows: IntArray) -> list[dict[str, float]]: ...
    def round_err(self, unit: float) -> float: ...


@final
class _Settled:
    """A chunk's commanded points once settled: each row's samples (``owner``: the row of
    each point, ``first``/``last``: each row's points), their parameters, nominal
    points, commanded points and directions, and the engine call for some of them."""

    __slots__ = ("owner", "first", "last", "sx", "nominal", "Ex", "Dx", "solve")

    def __init__(self, owner: IntArray, first: IntArray, last: IntArray, sx: FloatArray, nominal: FloatArray,
                 Ex: FloatArray, Dx: FloatArray, solve: Callable[..., FloatArray]) -> None:
        self.owner, self.first, self.last, self.sx, self.nominal = owner, first, last, sx, nominal
        self.Ex, self.Dx, self.solve = Ex, Dx, solve


def plan_directions(pl: _Planner, planned: list[tuple[int, PlanMove]], tab: Table, plans: dict[int, Plan]) -> None:
    """Targets, directions and plans of a chunk for a direction-dependent correction (see
    the module docstring): fills ``plans``, and the table's targets and directions."""
    st = _settle(pl, planned, tab)
    if planned:
        _plan_pieces(pl, planned, tab, st, plans)


def _samples(planned: list[tuple[int, PlanMove]], tab: Table, counts: IntArray
             ) -> dict[int, tuple[FloatArray, FloatArray, FloatArray, list[int]]]:
    """The samples of each planned move (sampled as the planner's general path does):
    row -> (parameters, nominal points, directions, the axes whose direction is given);
    ``counts`` set to each row's number of points."""
    arc_prm, breaks, Q0, Q1, D = tab.arc_prm, tab.breaks, tab.q0, tab.q1, tab.dirs
    # i -> (s (n,), nominal (n, 3), dirs (n, 3), given axes)
    samples: dict[int, tuple[FloatArray, FloatArray, FloatArray, list[int]]] = {}
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
    return samples


def _settle(pl: _Planner, planned: list[tuple[int, PlanMove]], tab: Table) -> _Settled:
    """Every commanded point of the chunk settled with its direction; the table's targets
    and directions set to its rows' last points."""
    Q1, R, T, D = tab.q1, tab.r, tab.target, tab.dirs
    rot, linenos, fixed_rows = tab.rot, tab.lineno, tab.fixed_rows
    M = len(T)
    axes = direction_axes(pl.engine)
    counts = np.ones(M, dtype=int)
    samples = _samples(planned, tab, counts)
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
    hold = max(MACHINE_STEP_MM, *(10.0 ** -_unit_decimals(pl.opt, u) * u for u in pl.units_checked))

    def solve(rows: IntArray, dirs: FloatArray, at: FloatArray | None = None) -> FloatArray:
        own = owner[rows]
        return pl.corrected(nominal[rows] if at is None else at, R[own], dirs,
                            pl.rotary_at(rot, own), linenos[own], pick(tab.files, own))

    inner = np.flatnonzero(counts[owner] > 1)
    if len(inner):
        Tx[inner] = solve(inner, Dx[inner])
    Ex, Dx = settle(Tx, Dx, Commanding(pl.prev_target, pl.dirs, hold, axes, free, given, first[owner]), solve,
                    linenos[owner], path=pl.path, files=pick(tab.files, owner))
    tab.target, tab.dirs = Ex[last], Dx[last]
    return _Settled(owner, first, last, sx, nominal, Ex, Dx, solve)


def _plan_pieces(pl: _Planner, planned: list[tuple[int, PlanMove]], tab: Table, st: _Settled,
                 plans: dict[int, Plan]) -> None:
    """The plan of each planned move from its settled points: its pieces, with a take-up
    before a point an axis reverses into."""
    arc_prm, Q0, Q1, R, D = tab.arc_prm, tab.q0, tab.q1, tab.r, tab.dirs
    owner, first, last, sx, nominal, Ex, Dx, solve = st.owner, st.first, st.last, st.sx, st.nominal, st.Ex, st.Dx, \
        st.solve
    axes = direction_axes(pl.engine)
    # take-ups: before a point a direction-dependent axis reverses into, the point
    # before it corrected with the new directions
    rows = np.concatenate([np.arange(first[i], last[i] + 1) for i, _m in planned])
    rows = rows[reversals(Dx, pl.dirs, axes, rows)]
    takeups: dict[int, FloatArray] = {}
    if len(rows):
        at = np.array([nominal[j - 1] if j != first[owner[j]] else Q0[owner[j]] for j in rows.tolist()])
        takeups = dict(zip(rows.tolist(), solve(rows, Dx[rows], at), strict=True))
    for i, m in planned:
        j0 = int(first[i])
        start = Ex[j0 - 1] if j0 > 0 else pl.prev_target
        start_dirs = Dx[j0 - 1] if j0 > 0 else pl.dirs
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
                                      pl.opt.tolerance_mm - pl.round_err(m.unit), m.lineno,
                                      file_of(tab.files, i, None)),
                          SettledPoints(Ex, Dx, sx, nominal, takeups, rows, axes, TAKEUP_MIN_MM), path=pl.path)
        if arc is not None:
            (_a1, _a2, an), _t0, sweep, r0, r1 = arc_prm[i]
            carried = np.array(start_dirs, dtype=float)
            carried[an] = D[i][an]
            plans[i] = {"seq": seq, "whole": len(seq) == 1, "nsweep": sweep, "mismatch": abs(r1 - r0),
                        "curve": Curve(m.q0, m.q1, arc, R[i], carried, m.lineno, m.rotary, arc_prm[i],
                                       file_of(tab.files, i, None))}
        else:  # a line's standing axes: the direction its corrected command takes
            plans[i] = {"seq": seq, "whole": len(seq) == 1,
                        "curve": Curve(tuple(Q0[i]), tuple(Q1[i]), None, R[i], D[i], m.lineno, m.rotary,
                                       path=file_of(tab.files, i, None))}
