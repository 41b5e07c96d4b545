"""Approach directions as the machine sees them: those of the corrected commands.

A controller reverses an axis, and its lost motion (or its own backlash compensation)
acts, when the *commanded* position of that axis changes direction, by any amount it
resolves. The corrected program commands other positions than the nominal one: a Z
plunge whose correction moves X by a few micrometres is an X move on the machine, and
it may reverse X. A correction that depends on the approach direction (``backlash``)
must therefore be evaluated with the directions of the corrected commands themselves.
They are found as a fixed point (:func:`settle`):

1. directions from the nominal program (chord signs, carried where an axis stands);
2. corrected targets with those directions;
3. the directions those targets command (:func:`commanded`); the moves whose
   direction changed are corrected again with it, and so on until nothing changes.

What the controller is commanded, per direction-dependent axis, from the previous
commanded target to the next:

- a motion along the current direction, or none: no reversal;
- a motion against it by more than one output unit: a reversal. Rounding both words
  to the output resolution keeps at least one unit of it, so the controller reverses;
- a motion against it by one output unit or less is *held*: the target keeps the
  previous target's value exactly, so the written word does not change and the
  controller does not move the axis (it would, by one unit or none, depending on where
  the rounding falls). The point stays within one output unit of the corrected ideal.

Rounding is monotone, so targets that move along their direction or stand still are
written as words that do too: the directions the correction assumed are the ones the
controller executes.

For a lagging axis (lost motion, ``b < 0``) the directions settle: a reversal moves
the corrected target further in the new direction, by the lost motion. For an axis that
runs ahead (``b > 0``, an over-compensated backlash) a small correction against the
direction has no consistent answer (reversing moves the target back by ``b``); the
correction refuses it after :data:`MAX_ITERATIONS` rounds, naming the line. Its
reversals into moves along it settle, and are not taken up (:func:`plan_pieces`).

The points are every sample of a move that is fitted by arcs or split (the samples
the fits follow), with an arc's quadrant points among them, and the target of any
other move. Where a direction-dependent axis reverses inside such a move, the plan
takes the reversal up there (:func:`reversals`, :func:`plan_pieces`), as a
controller's backlash compensation does: between take-ups every direction-dependent
axis of the emitted path moves one way. A reversal after points of the same move that
held the axis is taken up where they start (at the start of the block, for a line).

Not covered: a word the input writes with more decimals than the output keeps them,
and rounds on a finer grid than its neighbours; the points a fit adds between samples
(adaptive subdivision) take the directions of their move, not their own.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from postproc.effects.base import AXES, DIR_COLUMNS
from postproc.errors import SafetyError
from postproc.gcode.places import PathArray, file_of

#: Rounds of re-solving before the directions are declared unsettled.
MAX_ITERATIONS = 16

#: The finest commanded motion a machine resolves (mm): below the command unit of any
#: controller (0.1 um for the finest common increment systems), above the rounding
#: noise of a sampled path. A target closer than this (or than one output unit) to the
#: previous one against the direction is held; the virtual machine of ``verify`` does
#: not reverse an axis for less (:func:`postproc.simulate.verify.machine_directions`).
MACHINE_STEP_MM = 1e-6


def direction_axes(engine) -> tuple[int, ...]:
    """Axes whose approach direction the engine's correction depends on (its effects
    need ``dirx`` / ``diry`` / ``dirz``); empty for engines without such effects."""
    needs = set(engine.needs)
    return tuple(k for k, c in enumerate(DIR_COLUMNS) if c in needs)


@dataclass(frozen=True, eq=False)
class Commanding:
    """How a sequence of M corrected points is commanded (:func:`commanded`, :func:`settle`).

    ``start`` (3,): the point before the first (NaN: unknown, no motion into the first);
    ``dirs0`` (3,): directions before it; ``hold_mm``: one output unit (at least
    :data:`MACHINE_STEP_MM`); ``axes``: the direction-dependent axes (the others'
    directions are 0); ``free`` (M,) bool: points that may be held (False: a stored
    position the machine goes to as it is; None: all may); ``given`` (M, 3) bool:
    directions that are the motion's own, not found (an arc's in-plane axes: the
    direction of their quarter); ``move_first`` (M,) int: the first point of each
    point's move (the samples of one move; None: each point is its own move)."""

    start: Sequence[float] | np.ndarray
    dirs0: Sequence[float] | np.ndarray
    hold_mm: float
    axes: Sequence[int]
    free: np.ndarray | None = None
    given: np.ndarray | None = None
    move_first: np.ndarray | None = None


def commanded(T: np.ndarray, how: Commanding, assumed=None) -> tuple[np.ndarray, np.ndarray]:
    """Targets as commanded and the direction of each axis into each of them.

    ``T`` (M, 3): corrected points in order, commanded as ``how`` says; ``assumed``
    (M, 3): the directions of the points whose directions ``how.given`` marks.

    Where an axis reverses after points of the same move that held it, the reversal is
    put at the first of them: the axis did not move before it in this move, and the
    take-up goes where the motion starts, as a controller takes it up at the start of
    the block that reverses (``D`` of those points is the new direction; corrected with
    it they move, and the next round confirms it).

    Returns ``(E, D)``: ``E`` is ``T`` with the held values, ``D`` (M, 3) the sign of
    each axis's commanded motion into each point, carried where it does not move.
    """
    start, dirs0, hold_mm, given = how.start, how.dirs0, how.hold_mm, how.given
    E = np.array(T, dtype=float, copy=True)
    D = np.zeros_like(E)
    M = len(E)
    may_hold = [True] * M if how.free is None else np.asarray(how.free, dtype=bool).tolist()
    firsts = list(range(M)) if how.move_first is None else np.asarray(how.move_first, dtype=int).tolist()
    for k in how.axes:
        t = E[:, k].tolist()
        fixed = {} if given is None else {int(i): float(assumed[i, k]) for i in np.flatnonzero(given[:, k])}
        e = float(start[k])
        d = float(dirs0[k])
        moved = -1  # the last point the axis moved into (or was reversed at)
        out_d = [0.0] * M
        for i, v in enumerate(t):
            if fixed and i in fixed:
                e = v
                d = fixed[i]
                moved = i
            elif e != e or v != v:  # unknown position: no motion known into this point
                e = v
                moved = i
            else:
                delta = v - e
                if delta == 0.0:
                    pass
                elif d != 0.0 and (delta > 0.0) == (d > 0.0):
                    e = v
                    moved = i
                elif may_hold[i] and abs(delta) <= hold_mm:
                    t[i] = e  # held: the word stays, the axis does not move
                else:
                    e = v
                    d = 1.0 if delta > 0.0 else -1.0
                    for j in range(max(moved + 1, firsts[i]), i):
                        out_d[j] = d  # reversed at the start of the held stretch
                    moved = i
            out_d[i] = d
        E[:, k] = t
        D[:, k] = out_d
    return E, D


def settle(T: np.ndarray, D: np.ndarray, how: Commanding, solve, lineno, *,
           path: str | None = None, files: PathArray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The fixed point of corrected targets and commanded directions (see the module).

    ``T``: targets corrected with the assumed directions ``D`` (both (M, 3)), commanded
    as ``how`` says (:func:`commanded`); ``solve(rows, D_rows)``: the targets of ``rows``
    corrected with directions ``D_rows``; ``lineno`` (M,): program lines, and ``files``
    (M,) their files where not all are ``path``'s, for the refusal. Returns ``(E, D)``,
    the targets as commanded (holds applied) and their directions.
    """
    axes = tuple(how.axes)
    if not axes or not len(T):
        return T, D
    T = np.array(T, dtype=float, copy=True)
    D = np.array(D, dtype=float, copy=True)
    free_mask = np.ones(len(T), dtype=bool) if how.free is None else np.asarray(how.free, dtype=bool)
    cols = list(axes)
    for _round in range(MAX_ITERATIONS):
        E, Dm = commanded(T, how, D)
        diff = Dm[:, cols] != D[:, cols]
        changed = np.flatnonzero(diff.any(axis=1))
        if not len(changed):
            return E, D
        block = np.ix_(changed, np.asarray(cols, dtype=np.intp))
        D[block] = Dm[block]
        redo = changed[free_mask[changed]]
        if len(redo):
            T[redo] = solve(redo, D[redo])
    i = int(changed[0])
    ax = AXES[cols[int(np.flatnonzero(diff[i])[0])]]
    raise SafetyError(
        f"the approach direction of {ax} does not settle here: the correction commanded with one direction "
        f"moves {ax} the other way, and the other way back (a reversal value that makes {ax} run ahead, "
        f"backlash b > 0, cannot be taken up by a small move)",
        path=file_of(files, i, path), lineno=int(lineno[i]),
        hint=f"check the calibration's backlash:{ax}: lost motion has b < 0 (ISO 230-2 B = x_up - x_down); "
             "b > 0 is an axis that runs ahead, as one does whose controller compensates more backlash than there "
             "is: lower that compensation and measure again")


def reversals(D: np.ndarray, dirs0, axes, rows: np.ndarray) -> np.ndarray:
    """Which of the points ``rows`` (indices into the sequence) a direction-dependent
    axis reverses into: its direction differs from the point's before (``dirs0``
    before the first)."""
    cols = list(axes)
    before = np.vstack([np.asarray(dirs0, dtype=float)[None, :], D[:-1]])
    return (D[rows][:, cols] != before[rows][:, cols]).any(axis=1)


def _distance_to_polyline(x: np.ndarray, pts: np.ndarray) -> float:
    """The distance from the point ``x`` (3,) to the polyline through ``pts`` (N, 3)."""
    if len(pts) == 1:
        return float(np.linalg.norm(x - pts[0]))
    a, b = pts[:-1], pts[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", x - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    return float(np.linalg.norm(a + t[:, None] * ab - x, axis=1).min())


#: ``bulge(s, nominal)`` of a move: how its nominal path bulges from the chords between samples
Bulge: TypeAlias = Callable[[npt.NDArray[np.float64], npt.NDArray[np.float64]], npt.NDArray[np.float64]]


@dataclass(frozen=True, eq=False)
class SettledPoints:
    """A chunk's commanded points once settled (:func:`settle`), as :func:`plan_pieces`
    reads them: ``E`` (M, 3) commanded, ``D`` (M, 3) directions, ``s`` (M,) move
    parameter, ``nominal`` (M, 3); ``takeups``: point index -> the point before it
    corrected with the new directions, ``keys``: its indices, increasing; ``axes``: the
    direction-dependent axes; ``takeup_min_mm``: a take-up that moves no axis by more
    is left out."""

    E: np.ndarray
    D: np.ndarray
    s: np.ndarray
    nominal: np.ndarray
    takeups: dict
    keys: np.ndarray
    axes: Sequence[int]
    takeup_min_mm: float


@dataclass(frozen=True, eq=False)
class PieceInputs:
    """One move for :func:`plan_pieces`: its points ``first`` .. ``last`` of the
    sequence; ``start``, ``start_dirs``, ``start_nominal``: the commanded point,
    directions and nominal point it starts from; ``bulge``: how its nominal path bulges
    from its chords between samples; ``jump_budget_mm``: how far a reversal's jump may
    leave the path; ``lineno``: its line, for a refusal, and ``path`` its file where it
    is not the program's own."""

    first: int
    last: int
    start: Sequence[float] | np.ndarray
    start_dirs: Sequence[float] | np.ndarray
    start_nominal: Sequence[float] | np.ndarray
    bulge: Bulge
    jump_budget_mm: float = np.inf
    lineno: int | None = None
    path: str | None = None


def plan_pieces(move: PieceInputs, pts: SettledPoints, path: str | None = None) -> list:
    """The plan sequence of one move, whose points are ``move.first .. move.last`` of the
    settled sequence ``pts``: pieces of samples, and a take-up before each point a
    direction-dependent axis reverses into (:func:`_takeup`). Returns
    ``[("takeup", point) | ("piece", s, Q, nominal, bulge), ...]``.

    A take-up moves a lagging axis (lost motion) in its new direction, through the
    gap, while the table stands. An axis that runs ahead (``b > 0``) would have to be
    taken up in its old direction, where the machine does not reverse but overshoots
    by ``b``; it is not taken up: the first motion in the new direction reverses it and
    the table jumps back by ``b`` at once (the commanded point stays where the old
    direction left it, the next points are corrected with the new one). That jump is
    harmless where it runs along the path that follows (a slot cut back along the axis)
    and is refused (:class:`SafetyError` naming ``move.lineno`` of ``path``) where it
    leaves that path by more than ``move.jump_budget_mm`` (a reversal at an arc's
    quadrant point, or inside a move across the axis).
    """
    E, s, nominal, keys = pts.E, pts.s, pts.nominal, pts.keys
    first, last = move.first, move.last
    seq: list = []
    p_s, p_q, p_n = 0.0, np.asarray(move.start, dtype=float), np.asarray(move.start_nominal, dtype=float)
    a = first

    def close(b: int) -> None:
        if b > a:  # the piece's start and points a .. b-1
            ss = np.concatenate(([p_s], s[a:b]))
            nn = np.vstack([p_n[None, :], nominal[a:b]])
            seq.append(("piece", ss, np.vstack([p_q[None, :], E[a:b]]), nn, move.bulge(ss, nn)))

    for j in keys[np.searchsorted(keys, first):np.searchsorted(keys, last, side="right")].tolist():
        tk, prev_end = _takeup(j, move, pts, path)
        if np.abs(tk - prev_end).max() <= pts.takeup_min_mm:
            continue
        close(j)
        seq.append(("takeup", tk))
        p_s = float(s[j - 1]) if j > first else 0.0
        p_n = nominal[j - 1] if j > first else np.asarray(move.start_nominal, dtype=float)
        p_q = tk
        a = j
    close(last + 1)
    return seq


def _takeup(j: int, move: PieceInputs, pts: SettledPoints, path: str | None) -> tuple[np.ndarray, np.ndarray]:
    """The take-up before point ``j`` of ``move`` and the commanded point before it: the
    point before ``j`` corrected with the new directions, where an axis that does not
    reverse stays where it is, and so does an axis that runs ahead (its jump back is
    refused where it leaves the path by more than ``move.jump_budget_mm``)."""
    E, D, nominal, first = pts.E, pts.D, pts.nominal, move.first
    cols = list(pts.axes)
    prev_end = E[j - 1] if j > first else np.asarray(move.start, dtype=float)
    prev_dirs = D[j - 1] if j > first else np.asarray(move.start_dirs, dtype=float)
    tk = np.array(pts.takeups[j], dtype=float)
    same = [k for k in cols if D[j, k] == prev_dirs[k]]
    tk[same] = prev_end[same]  # an axis that does not reverse here stays where it is
    # an axis whose take-up goes against its new direction runs ahead: the reversal
    # makes the table jump back by that much, along the path or refused
    ahead = [k for k in cols if k not in same and (tk[k] - prev_end[k]) * D[j, k] < 0]
    if ahead:
        jump = np.zeros(3)
        jump[ahead] = prev_end[ahead] - tk[ahead]
        tk[ahead] = prev_end[ahead]
        here = nominal[j - 1] if j > first else np.asarray(move.start_nominal, dtype=float)
        off = _distance_to_polyline(here + jump, np.vstack([here[None, :], nominal[j:move.last + 1]]))
        if off > move.jump_budget_mm:
            ax = AXES[ahead[0]]
            raise SafetyError(
                f"{ax} runs ahead of its approach direction (reversal b > 0): reversing it here makes the "
                f"tool jump {np.linalg.norm(jump) * 1000:.3g} um, {off * 1000:.3g} um off the path, more than "
                f"the tolerance; no move takes that up (one in the old direction overshoots, one in the new "
                f"direction jumps)", path=move.path or path, lineno=move.lineno,
                hint=f"check the calibration's backlash:{ax}: b > 0 is an axis that runs ahead, as one does "
                     "whose controller compensates more backlash than there is: lower that compensation and "
                     "measure again. Programs that reverse it only into moves along it are corrected")
    return tk, prev_end
