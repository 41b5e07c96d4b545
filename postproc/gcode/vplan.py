"""Planning a chunk's moves in bulk: which stay one line or one exact arc.

The planner (:meth:`postproc.gcode.pipeline.Corrector._plan`) must know, for every
move of a chunk, whether the corrected ideal path stays within the budget of the one
line or the one exact circle that will be written for it. Nearly every move of a CAM
program does, so that question is answered here for the whole chunk at once, with one
engine call and array arithmetic over all samples:

- a straight move stays one line when every corrected sample lies within
  ``budget - rounding`` of the chord between the corrected (unrounded) end points: the
  written end points differ from those by at most the rounding, so the written line is
  within the budget;
- an arc gets an :class:`ArcHint`: the centre on the bisector of the corrected end
  points that fits the corrected samples best (Gauss-Newton on the signed distance along
  the bisector, for all arcs at once) and the largest distance of the samples from that
  circle. When the line is written, :meth:`ArcHint.spec` moves the centre onto the
  bisector of the end points as written, rounds it, and accepts it when the bound on
  its deviation (the ideal circle's deviation plus how far the rounded circle moved)
  stays within the budget; an arc whose end words do not change keeps its own centre
  words under the same bound (:meth:`ArcHint.keep`).

What this does not settle (moves that must be split, arcs whose bound fails, full
circles, R-form or multi-turn arcs, direction-dependent calibrations) takes the
planner's general path, sample by sample. The samples are those of the general path:
one every ``step_mm`` along the move and, on arcs, every ``step_rad`` of sweep; where
the engine bounds the correction's curvature along a straight move
(:meth:`postproc.engine.base.Engine.line_curvature_bound`), the move is settled with
fewer samples, or none.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Literal,
    NotRequired,
    Protocol,
    TypeAlias,
    TypedDict,
    TypeVar,
)

import numpy as np
import numpy.typing as npt

from postproc.gcode import hintcore
from postproc.gcode.geometry import ArcColumns, arcs_points
from postproc.gcode.geometry import ArcParams as ArcParams  # (the planner's name for them)
from postproc.gcode.hintcore import ArcHint as ArcHint  # (the hints the planner makes)
from postproc.gcode.hintcore import ArcMove as ArcMove
from postproc.gcode.segment import CENTRE_SETTLED_MM
from postproc.gcode.state import PLANES

if TYPE_CHECKING:
    from postproc.gcode.interp import Arc
    from postproc.gcode.moves import Role
    from postproc.gcode.segment import Curve

FloatArray: TypeAlias = npt.NDArray[np.float64]
IntArray: TypeAlias = npt.NDArray[np.intp]
BoolArray: TypeAlias = npt.NDArray[np.bool_]
KindArray: TypeAlias = npt.NDArray[np.int8]  # postproc.gcode.moves.Kind, a row each

TWO_PI = 2.0 * math.pi
# Share of the limit left to the path between the samples of a straight move, where the
# engine bounds the correction's curvature (the samples are then spaced to fit it).
BETWEEN_SAMPLES_SHARE = 0.1
# Gauss-Newton steps of the bisector centre fit (it converges in 3-5 on real arcs; the
# fit only seeds the rounded centre, whose deviation is bounded separately).
CENTRE_ITERATIONS = 8

# -- what the planner hands the emitter ------------------------------------------------
#: A step of a general plan: a take-up to a point (the corrected point before a reversal,
#: (3,)), or a piece of corrected samples: (s (n,), corrected (n, 3), nominal (n, 3),
#: bulge (n - 1, 3): how the nominal path bulges from its chord between samples).
TakeUp: TypeAlias = tuple[Literal["takeup"], FloatArray]
Piece: TypeAlias = tuple[Literal["piece"], FloatArray, FloatArray, FloatArray, FloatArray]
Step: TypeAlias = TakeUp | Piece


class Plan(TypedDict):
    """The general plan of a move (:meth:`postproc.gcode.pipeline.Corrector._plan_moves`):
    its steps, whether it is one piece, the curve the fits refine along and, for an arc,
    its nominal sweep (rad) and end-radius mismatch (mm)."""

    seq: list[Step]
    whole: bool
    curve: Curve
    nsweep: NotRequired[float]
    mismatch: NotRequired[float]


class PlanMove(Protocol):
    """What the planner reads of a move it plans (a :class:`postproc.gcode.interp.Move`,
    or a :class:`postproc.gcode.bulk.RunMove` for an arc of a run of plain lines)."""

    @property
    def arc(self) -> Arc | None: ...
    @property
    def kind(self) -> int: ...
    @property
    def lineno(self) -> int: ...
    @property
    def q0(self) -> tuple[float, float, float]: ...
    @property
    def q1(self) -> tuple[float, float, float]: ...
    @property
    def r(self) -> tuple[float, float, float]: ...
    @property
    def unit(self) -> float: ...
    @property
    def rotary(self) -> dict[str, float]: ...
    @property
    def role(self) -> Role: ...


_M = TypeVar("_M", bound=PlanMove)
#: ``corrected(rows, nominal points (N, 3))``: the engine's corrected points (N, 3)
Corrected: TypeAlias = Callable[[IntArray, FloatArray], FloatArray]
#: ``curvature(rows)``: the engine's bound on the correction's curvature along each move
Curvature: TypeAlias = Callable[[IntArray], FloatArray]
#: an arc's ends in the plane's order: (s1, s2, sn, e1, e2, en)
Ends: TypeAlias = hintcore.Ends


@dataclass(frozen=True, eq=False)
class MoveEnds:
    """A chunk's moves as the bulk planner reads them, one row per move (N, 3): nominal
    starts ``q0`` and ends ``q1``, corrected starts ``start`` and ends ``target``."""

    q0: FloatArray
    q1: FloatArray
    start: FloatArray
    target: FloatArray


@dataclass(frozen=True)
class Sampling:
    """How :func:`plan_chunk` samples and judges the moves: a sample every ``step_mm``
    along a move and, on arcs, every ``step_rad`` of sweep, at least ``min_arc_samples``
    on an arc (its ends included); ``budget`` (mm): how far the written line or arc may
    lie from the corrected samples, ``rounding`` (mm): what rounding the words may add
    to a line's ends (taken from the budget of straight moves)."""

    step_mm: float
    step_rad: float
    min_arc_samples: int
    budget: float
    rounding: float


def _ragged(n: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """For counts n (k,): the owner of each of sum(n) slots, its index within its owner,
    and the first slot of each owner."""
    n = np.asarray(n, dtype=int)
    owner = np.repeat(np.arange(len(n)), n)
    starts = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(int) if len(n) else np.zeros(0, dtype=int)
    pos = np.arange(int(n.sum())) - np.repeat(starts, n)
    return owner, pos, starts


def _group_max(values: FloatArray, starts: IntArray) -> FloatArray:
    """Largest value of each group of a ragged array (every group non-empty; ``starts``:
    the first slot of each)."""
    return np.maximum.reduceat(values, starts) if len(values) else np.zeros(len(starts))


def _line_samples(rows: IntArray, ends: MoveEnds, step_mm: float, curvature: Curvature | None, limit: float
                  ) -> tuple[IntArray, FloatArray, Callable[[FloatArray], BoolArray]]:
    """Interior samples of the straight moves ``rows`` (every ``step_mm``, at least one):
    ``(owner rows, nominal points, check)``; ``check(corrected points)`` tells for each
    move whether every corrected sample lies within ``limit`` of the chord S-T (a move
    whose start is unknown passes: it is written as it is read).

    ``curvature(rows)``: the engine's bound K on the correction's second derivative
    along each move (:meth:`postproc.engine.base.Engine.line_curvature_bound`). A move
    whose chord the bound holds within ``limit`` (K L^2 / 8) passes unsampled; the others
    are sampled at most ``step_mm`` apart, or farther where K allows (between samples h
    apart the path leaves the polyline of its samples by K h^2 / 8 at most, kept to a
    tenth of the limit), and their samples are held to the limit less that."""
    Q0, Q1, S, T = ends.q0, ends.q1, ends.start, ends.target
    length = np.linalg.norm(Q1[rows] - Q0[rows], axis=1) if len(rows) else np.zeros(0)
    n = np.maximum(3, np.ceil(length / step_mm).astype(int) + 1) if len(rows) else np.zeros(0, dtype=int)
    settled = np.zeros(len(rows), dtype=bool)
    between = np.zeros(len(rows))  # how far the path may leave its samples' polyline
    if curvature is not None and len(rows):
        K = curvature(rows)
        # K L^2 / 8 within the limit; an unbounded K settles nothing, a move of no length
        # included (its inf * 0 is not evaluated)
        settled = np.zeros(len(rows), dtype=bool)
        finite = np.isfinite(K)
        settled[finite] = K[finite] * length[finite] ** 2 / 8.0 <= limit
        bounded = np.isfinite(K) & (K > 0)
        K_b = np.where(bounded, K, 1.0)
        h = np.where(bounded, np.sqrt(BETWEEN_SAMPLES_SHARE * 8.0 * limit / K_b), step_mm)
        n = np.where(bounded, np.maximum(3, np.ceil(length / np.maximum(h, step_mm)).astype(int) + 1), n)
        between = np.where(bounded, K_b * (length / (n - 1)) ** 2 / 8.0, 0.0)
        n = np.where(settled, 2, n)  # no interior sample
    own, pos, start = _ragged(n - 2)
    s = (pos + 1) / (n[own] - 1)
    r = rows[own]
    nom = Q0[r] + (Q1[r] - Q0[r]) * s[:, None]

    def check(P: FloatArray) -> BoolArray:
        A, B = S[r], T[r]
        ab = B - A
        den = np.einsum("ij,ij->i", ab, ab)
        tt = np.clip(np.einsum("ij,ij->i", P - A, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0)
        dist = np.linalg.norm(P - A - tt[:, None] * ab, axis=1)
        worst = np.zeros(len(rows))
        some = n > 2
        if some.any():
            worst[some] = _group_max(dist, start[some])
        return settled | (worst <= limit - between) | ~np.isfinite(S[rows]).all(axis=1)

    return r, nom, check


def lines_within(rows: IntArray, ends: MoveEnds, corrected: Corrected, *, step_mm: float, limit: float,
                 curvature: Curvature | None = None) -> BoolArray:
    """Which straight moves ``rows`` stay within ``limit`` of their corrected chord (see
    :func:`_line_samples`; ``corrected`` as in :func:`plan_chunk`)."""
    r, nom, check = _line_samples(rows, ends, step_mm, curvature, limit)
    return check(corrected(r, nom) if len(r) else np.zeros((0, 3)))


def plan_chunk(planned: list[tuple[int, _M]], arc_prm: dict[int, ArcParams], ends: MoveEnds,
               corrected: Corrected, sampling: Sampling, curvature: Curvature | None = None
               ) -> tuple[list[int], dict[int, ArcHint], list[tuple[int, _M]]]:
    """Settle in bulk the planned moves of a chunk that stay one line or one exact arc.

    ``planned``: (row, Move) pairs; ``arc_prm``: row -> arc_params of the arcs;
    ``ends``: nominal and corrected starts and ends (per row); ``corrected(rows, nominal
    points)``: the engine's corrected points (N, 3) for nominal points on those rows'
    moves; ``curvature``: as :func:`_line_samples`. Returns ``(lines, hints, rest)``: the
    rows of straight moves that stay one line, ``{row: ArcHint}``, and the (row, Move) pairs left to the general path.
    """
    lines_i, arcs_i, rest = _sort_moves(planned, arc_prm)
    li = np.array(lines_i, dtype=int)
    arcs = _arc_samples(arcs_i, arc_prm, ends, sampling)
    lrows, nom_l, lcheck = _line_samples(li, ends, sampling.step_mm, curvature, sampling.budget - sampling.rounding)
    rows_all = np.concatenate([lrows, arcs.rows[arcs.own]])
    corr = corrected(rows_all, np.vstack([nom_l, arcs.nom])) if len(rows_all) else np.zeros((0, 3))
    P_l, P_a = corr[:len(nom_l)], corr[len(nom_l):]
    # -- straight moves: every sample within budget - rounding of the chord ---------------
    ok_lines: list[int] = []
    if len(li):
        good = lcheck(P_l)
        ok_lines = li[good].tolist()
        bad = set(li[~good].tolist())
        rest.extend((i, m) for i, m in planned if m.arc is None and i in bad)
    hints: dict[int, ArcHint] = {}
    if not len(arcs.rows):
        return ok_lines, hints, rest
    pts = _plane_points(arcs, ends, P_a)
    circles = _fit_centres(pts)
    worst, turning = _worst_deviations(pts, circles, arcs)
    usable = circles.usable & turning & np.isfinite(worst) & np.isfinite(circles.rho) & (worst <= sampling.budget)
    # the hints made from the arrays' rows as Python floats (tolist), all at once
    sel = np.flatnonzero(usable)
    c1, c2, rho, sweep, r0, r1 = circles.c1, circles.c2, circles.rho, arcs.cols.sweep, arcs.cols.r0, arcs.cols.r1
    rows = zip(*(x[sel].tolist() for x in (c1, c2, rho, worst, sweep, pts.S1, pts.S2, pts.Sn, pts.E1, pts.E2,
                                           pts.En, np.abs(r1 - r0))), strict=True)
    for (i, _m, _arc), (h1, h2, hr, hw, hs, u1, u2, un, w1, w2, wn, mm) in zip([arcs_i[x] for x in sel.tolist()],
                                                                               rows, strict=True):
        hints[i] = ArcHint(h1, h2, hr, hw, hs, (u1, u2, un, w1, w2, wn), i, mm)
    if len(sel) < len(arcs.rows):
        rest.extend((i, m) for (i, m, _arc), u in zip(arcs_i, usable.tolist(), strict=True) if not u)
    return ok_lines, hints, rest


def _sort_moves(planned: list[tuple[int, _M]], arc_prm: dict[int, ArcParams]
                ) -> tuple[list[int], list[tuple[int, _M, Arc]], list[tuple[int, _M]]]:
    """The rows of the straight moves, the arcs :func:`plan_chunk` may settle (one turn of
    I/J/K form in a known plane, not a full circle) and the moves left to the general path."""
    lines_i: list[int] = []
    arcs_i: list[tuple[int, _M, Arc]] = []
    rest: list[tuple[int, _M]] = []
    for i, m in planned:
        arc = m.arc
        if arc is None:
            lines_i.append(i)
        elif (arc.r_idx < 0 and arc.turns == 1 and arc.plane in PLANES
              and abs(arc_prm[i][2]) < TWO_PI - 1e-9):
            arcs_i.append((i, m, arc))
        else:
            rest.append((i, m))
    return lines_i, arcs_i, rest


@dataclass(frozen=True, eq=False)
class _ArcSamples:
    """The arcs :func:`plan_chunk` fits (k): their ``rows``, geometry ``cols``, sense
    ``clockwise`` and sample counts ``n`` (ends included); the interior samples (owner
    ``own``, parameter ``s``, nominal points ``nom``) and the middles of all the sample
    intervals (owner ``mid_own``, interval ``mid_pos``, parameter ``mid_s``; ``mid_start``:
    each arc's first)."""

    rows: IntArray
    cols: ArcColumns
    clockwise: BoolArray
    n: IntArray
    own: IntArray
    s: FloatArray
    nom: FloatArray
    mid_own: IntArray
    mid_pos: IntArray
    mid_s: FloatArray
    mid_start: IntArray


def _arc_samples(arcs_i: Sequence[tuple[int, PlanMove, Arc]], arc_prm: dict[int, ArcParams], ends: MoveEnds,
                 sampling: Sampling) -> _ArcSamples:
    """The samples of the arcs ``arcs_i``: every ``step_mm`` along and ``step_rad`` of sweep,
    at least ``min_arc_samples``."""
    Q0, Q1 = ends.q0, ends.q1
    step_mm, step_rad = sampling.step_mm, sampling.step_rad
    rows = [i for i, _m, _a in arcs_i]
    ai = np.array(rows, dtype=int)
    # the arcs' parameters by column: planes, start angles, sweeps, start and end radii
    prm = list(zip(*[arc_prm[i] for i in rows], strict=True)) or [(), (), (), (), ()]
    axes = np.array(prm[0], dtype=int).reshape(-1, 3)
    t0, sweep, r0, r1 = (np.array(c, dtype=float) for c in prm[1:5])
    dn = Q1[ai, axes[:, 2]] - Q0[ai, axes[:, 2]] if len(ai) else np.zeros(0)
    length = np.hypot(np.abs(sweep) * 0.5 * (r0 + r1), dn)
    na = np.maximum.reduce([np.full(len(ai), sampling.min_arc_samples), np.ceil(length / step_mm).astype(int) + 1,
                            np.ceil(np.abs(sweep) / step_rad).astype(int) + 1]) if len(ai) else np.zeros(0, int)
    # interior samples only: the ends are S and T
    ao, ap, _astart = _ragged(na - 2)
    s_a = (ap + 1) / (na[ao] - 1)
    # and the middles of the sample intervals (all of them), for the nominal bulge
    mo, mp, mstart = _ragged(na - 1)
    s_m = (mp + 0.5) / (na[mo] - 1)
    centre = np.array([arc.center for _i, _m, arc in arcs_i], dtype=float).reshape(-1, 3)
    cols = ArcColumns(axes, t0, sweep, r0, r1, centre, Q0[ai], Q1[ai])
    cw = np.array([arc.clockwise for _i, _m, arc in arcs_i])
    return _ArcSamples(ai, cols, cw, na, ao, s_a, arcs_points(ao, s_a, cols), mo, mp, s_m, mstart)


@dataclass(frozen=True, eq=False)
class _PlanePoints:
    """The points each arc is fitted to, in its plane: every sample with its ends and the
    bulged middle of every interval (``P1``, ``P2`` in the plane, ``Pn`` along the normal;
    ``owner``: the arc, ``frac``: the point's parameter; the samples arc by arc, then the
    middles arc by arc, ``full_start``: each arc's first sample), the corrected ends of
    each arc (``S1`` .. ``En``) and the first guess of its centre (``c01``, ``c02``)."""

    P1: FloatArray
    P2: FloatArray
    Pn: FloatArray
    owner: IntArray
    frac: FloatArray
    S1: FloatArray
    S2: FloatArray
    Sn: FloatArray
    E1: FloatArray
    E2: FloatArray
    En: FloatArray
    c01: FloatArray
    c02: FloatArray
    full_start: IntArray


def _plane_points(arcs: _ArcSamples, ends: MoveEnds, P_a: FloatArray) -> _PlanePoints:
    """The arcs' corrected samples ``P_a`` (the interior ones) with their ends and bulged
    interval middles, in the plane of each arc, and the first guess of each centre."""
    ai, na, cols = arcs.rows, arcs.n, arcs.cols
    mo, mp, s_m = arcs.mid_own, arcs.mid_pos, arcs.mid_s
    S, T = ends.start, ends.target
    # every sample with its ends: [S, interior..., T] per arc
    full_o, full_p, full_start = _ragged(na)
    Pf = np.empty((len(full_o), 3))
    first = full_p == 0
    last = full_p == na[full_o] - 1
    inner = ~(first | last)
    Pf[first] = S[ai]
    Pf[last] = T[ai]
    Pf[inner] = P_a
    nom_m = arcs_points(mo, s_m, cols)
    nom_f = np.empty_like(Pf)
    nom_f[first] = ends.q0[ai]
    nom_f[last] = ends.q1[ai]
    nom_f[inner] = arcs.nom
    # interval k of arc j lies between full slots full_start[j] + k and + k + 1; its
    # bulge nom_m - (its ends' mean) and middle (its corrected ends' mean) + bulge, in
    # place (the same operations, in order)
    a_idx = full_start[mo] + mp
    bulge = nom_f[a_idx]
    bulge += nom_f[a_idx + 1]
    bulge *= 0.5
    np.subtract(nom_m, bulge, out=bulge)
    mid = Pf[a_idx]
    mid += Pf[a_idx + 1]
    mid *= 0.5
    mid += bulge
    owner = np.concatenate([full_o, mo])
    frac = np.concatenate([full_p / (na[full_o] - 1), s_m])
    k = len(ai)
    j = np.arange(k)
    axes = cols.axes
    ax1, ax2, axn = axes[:, 0], axes[:, 1], axes[:, 2]
    S1, S2, Sn = S[ai, ax1], S[ai, ax2], S[ai, axn]
    E1, E2, En = T[ai, ax1], T[ai, ax2], T[ai, axn]
    if (axes == axes[0]).all():  # every arc in one plane (as CAM programs are): by columns
        P1, P2, Pn = (np.concatenate([Pf[:, b], mid[:, b]]) for b in axes[0].tolist())
    else:
        pts = np.vstack([Pf, mid])
        at = np.arange(len(pts))
        P1, P2, Pn = pts[at, ax1[owner]], pts[at, ax2[owner]], pts[at, axn[owner]]
    # first guess: the nominal centre moved by the mean correction
    off = np.zeros((k, 3))
    cnt = np.bincount(full_o, minlength=k)
    for c in range(3):
        off[:, c] = np.bincount(full_o, Pf[:, c] - nom_f[:, c], minlength=k) / cnt
    c01 = cols.centre[j, ax1] + off[j, ax1]
    c02 = cols.centre[j, ax2] + off[j, ax2]
    return _PlanePoints(P1, P2, Pn, owner, frac, S1, S2, Sn, E1, E2, En, c01, c02, full_start)


@dataclass(frozen=True, eq=False)
class _Circles:
    """The fitted circle of each arc: centre (``c1``, ``c2``) on the bisector of its
    corrected ends, radius ``rho``; ``usable``: a chord of finite, nonzero length."""

    c1: FloatArray
    c2: FloatArray
    rho: FloatArray
    usable: BoolArray


def _fit_centres(p: _PlanePoints) -> _Circles:
    """The centre on the bisector of each arc's corrected ends whose circle fits its points
    best: Gauss-Newton on the signed distance along the bisector, for all arcs at once."""
    S1, S2, E1, E2, P1, P2, owner = p.S1, p.S2, p.E1, p.E2, p.P1, p.P2, p.owner
    k = len(S1)
    M1, M2 = 0.5 * (S1 + E1), 0.5 * (S2 + E2)
    D1, D2 = E1 - S1, E2 - S2
    L = np.hypot(D1, D2)
    usable = (L > 0) & np.isfinite(L)
    Ls = np.where(usable, L, 1.0)
    n1, n2 = -D2 / Ls, D1 / Ls
    h = 0.5 * L
    t = (p.c01 - M1) * n1 + (p.c02 - M2) * n2
    # each arc's fit stops once its step is below CENTRE_SETTLED_MM (the steps after are
    # rounding noise), as segment.bisector_centre's does: what an arc gets does not
    # depend on the arcs fitted with it
    active = np.ones(k, dtype=bool)
    n1o, n2o = n1[owner], n2[owner]  # each point's arc's bisector direction
    for _ in range(CENTRE_ITERATIONS):
        c1, c2 = M1 + t * n1, M2 + t * n2
        v1, v2 = P1 - c1[owner], P2 - c2[owner]
        dist = np.hypot(v1, v2)
        dist = np.where(dist > 0, dist, 1e-300)
        rho = np.hypot(h, t)
        res = dist - rho[owner]
        # J = -(v1 n1 + v2 n2) / dist - t / rho, in place (the same operations, in order)
        J = np.multiply(v1, n1o, out=v1)
        J += np.multiply(v2, n2o, out=v2)
        np.negative(J, out=J)
        J /= dist
        J -= (t / rho)[owner]
        den = np.bincount(owner, np.multiply(J, J, out=v2), minlength=k)
        num = np.bincount(owner, np.multiply(J, res, out=v2), minlength=k)
        dt = np.where(den > 0, -num / np.where(den > 0, den, 1.0), 0.0)
        flip = ((t + dt) * t < 0) & (t != 0)
        step = np.where(flip, -0.5 * t, dt)
        t = np.where(active, t + step, t)
        active &= ~(np.abs(step) <= CENTRE_SETTLED_MM)
        if not active.any():
            break
    c1, c2 = M1 + t * n1, M2 + t * n2
    rho = np.hypot(h, t)
    return _Circles(c1, c2, rho, usable)


def _worst_deviations(p: _PlanePoints, circles: _Circles, arcs: _ArcSamples) -> tuple[FloatArray, BoolArray]:
    """The largest deviation of each arc's points from its fitted circle (a helix along
    the normal axis, turning as the arc does), and whether the circle turns as the
    nominal arc does (within a quarter turn; not at all: False)."""
    c1, c2, rho, owner = circles.c1, circles.c2, circles.rho, p.owner
    S1, S2, Sn, E1, E2, En = p.S1, p.S2, p.Sn, p.E1, p.E2, p.En
    th0 = np.arctan2(S2 - c2, S1 - c1)
    th1 = np.arctan2(E2 - c2, E1 - c1)
    cw = arcs.clockwise
    base = np.where(cw, -np.mod(th0 - th1, TWO_PI), np.mod(th1 - th0, TWO_PI))
    sgn = np.where(cw, -1.0, 1.0)
    asw = np.abs(base)
    turning = (asw > 0) & (np.abs(base - arcs.cols.sweep) <= math.pi / 2)
    asw = np.where(asw > 0, asw, 1.0)
    v1, v2 = p.P1 - c1[owner], p.P2 - c2[owner]
    phi = np.arctan2(v2, v1)
    phi -= th0[owner]
    phi *= sgn[owner]
    alpha = np.mod(phi, TWO_PI, out=phi)
    asw_o = asw[owner]
    # alpha + 2 pi round((frac asw - alpha) / 2 pi), in place (the same operations, in order)
    turns = np.multiply(p.frac, asw_o)
    turns -= alpha
    turns /= TWO_PI
    np.round(turns, out=turns)
    turns *= TWO_PI
    alpha += turns
    alpha /= asw_o  # the share of the turn
    nrm = (En - Sn)[owner]
    nrm *= alpha
    nrm += Sn[owner]
    dev = np.hypot(v1, v2)
    dev -= rho[owner]
    dev = np.hypot(dev, np.subtract(p.Pn, nrm, out=nrm), out=dev)
    # the points are every arc's samples (arc by arc), then every arc's interval middles:
    # each arc's largest of both
    n_full = len(owner) - len(arcs.mid_own)
    worst = np.maximum(_group_max(dev[:n_full], p.full_start), _group_max(dev[n_full:], arcs.mid_start))
    return worst, turning
