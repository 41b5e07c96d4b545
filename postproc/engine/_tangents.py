"""Helpers shared by the interval and quasi-differential tangential engines.

- parsing of the ``--intervals``, ``--step`` and ``--screw-pitch`` option values;
- lattice detection on commanded positions;
- cell look-up on a rectilinear partition and the cell-consistent inverse of a
  piecewise-affine model (formula (1) or (2) per cell, with the border rule);
- the seed's practical checks (grid step, lead-screw aliasing) as report lines.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable

import numpy as np

from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM
from postproc.errors import PostprocError

AXES = "XYZ"

# Commanded positions are written with 6 decimals (1 nm); two positions closer than
# 1 um are the same commanded node, far above rounding and far below any grid step.
LATTICE_TOL_MM = 1e-3

# Seed 000, chapter 2: the step of the tangent grid "must be at least 10 mm"; below it
# the method was found less effective (tangents from differences of noisy points).
MIN_GRID_STEP_MM = 10.0


# Newton on the interpolated or blended field stops a hundred times below the solver
# tolerance: the extra iteration costs microseconds and keeps the answer far from the limit.
NEWTON_TOL_MM = SOLVER_TOL_MM / 100


def newton_refine(
    evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    target: np.ndarray,
    q: np.ndarray,
    iters: np.ndarray,
    active: np.ndarray,
) -> np.ndarray:
    """Newton steps on the points ``active`` until ``|evaluate(q) - target| < NEWTON_TOL_MM``.

    ``evaluate(q) -> (value (N, 3), jacobian (N, 3, 3))``. ``q`` and ``iters`` are updated
    in place. Returns the indices that did not converge within SOLVER_MAX_ITER steps
    (empty when all did); the caller names them in its own SolverError.
    """
    for _ in range(SOLVER_MAX_ITER):
        value, jac = evaluate(q[active])
        err = target[active] - value
        done = np.linalg.norm(err, axis=1) < NEWTON_TOL_MM
        active, err, jac = active[~done], err[~done], jac[~done]
        if len(active) == 0:
            return active
        q[active] += np.linalg.solve(jac, err[..., None])[..., 0]
        iters[active] += 1
    return active


def _axis_index(name: str, text: str, what: str) -> int:
    key = name.strip().upper()
    if key not in ("X", "Y", "Z"):
        raise PostprocError(
            f"{what} {text!r}: {name.strip()!r} is not an axis (X, Y or Z)",
            hint=f"write {what} as AXIS=VALUE, e.g. X=5",
        )
    return AXES.index(key)


# Most intervals on one axis: each holds a 3x3 matrix fitted from the points inside it, so
# more intervals than points measured on an axis fit nothing (a laser tracker campaign
# has tens to hundreds of points per axis); a million would ask for terabytes.
MAX_INTERVALS = 1000
# ... and in all (a 3x3 matrix each: 72 MB at this bound)
MAX_INTERVAL_CELLS = 1_000_000


def parse_intervals(spec: str | None) -> list[list[float] | int | None]:
    """``"X=0,100,200,315;Y=3;Z=2"`` -> ``[[0, 100, 200, 315], 3, 2]``.

    Per axis: a single integer is a number of equal intervals over the data range;
    two or more numbers are the interval edges (mm, increasing). Missing axes are
    ``None`` (the default partition).
    """
    out: list[list[float] | int | None] = [None, None, None]
    if spec is None or not spec.strip():
        return out
    hint = "write --intervals as AXIS=EDGES or AXIS=COUNT separated by ';', e.g. 'X=0,100,200,315;Y=3;Z=2'"
    for item in filter(None, (s.strip() for s in spec.split(";"))):
        name, sep, rest = item.partition("=")
        if not sep:
            raise PostprocError(f"--intervals {spec!r}: {item!r} has no '='", hint=hint)
        j = _axis_index(name, spec, "--intervals")
        if out[j] is not None:
            raise PostprocError(f"--intervals {spec!r}: axis {AXES[j]} given twice", hint=hint)
        parts = [p.strip() for p in rest.split(",") if p.strip()]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise PostprocError(f"--intervals {spec!r}: {rest!r} is not a list of numbers", hint=hint) from None
        if len(values) == 1:
            n = values[0]
            if not math.isfinite(n) or n != int(n) or n < 1 or n > MAX_INTERVALS:
                raise PostprocError(
                    f"--intervals {spec!r}: a single value for {AXES[j]} is a count of intervals "
                    f"and must be a whole number from 1 to {MAX_INTERVALS}, got {parts[0]}",
                    hint=hint,
                )
            out[j] = int(n)
        elif len(values) >= 2:
            if not all(math.isfinite(v) for v in values) or np.any(np.diff(values) <= 0):
                raise PostprocError(
                    f"--intervals {spec!r}: edges of {AXES[j]} must increase strictly", hint=hint
                )
            if len(values) > MAX_INTERVALS + 1:
                raise PostprocError(f"--intervals {spec!r}: more than {MAX_INTERVALS} intervals on {AXES[j]}",
                                    hint=hint)
            out[j] = values
        else:
            raise PostprocError(f"--intervals {spec!r}: axis {AXES[j]} has no value", hint=hint)
    cells = math.prod(v if isinstance(v, int) else len(v) - 1 for v in out if v is not None)
    if cells > MAX_INTERVAL_CELLS:
        raise PostprocError(f"--intervals {spec!r}: {cells:,} cells, more than {MAX_INTERVAL_CELLS:,}", hint=hint)
    return out


def parse_step(step) -> np.ndarray | None:
    """``"15"`` or ``"15,15,10"`` (or a number / 3 numbers) -> (3,) steps in mm."""
    if step is None:
        return None
    if isinstance(step, str):
        try:
            values = [float(p) for p in step.split(",") if p.strip()]
        except ValueError:
            values = []
    else:
        values = list(np.atleast_1d(np.asarray(step, dtype=float)))
    if len(values) == 1:
        values = values * 3
    arr = np.asarray(values, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise PostprocError(
            f"--step {step!r}: expected one positive step or three (u1,u2,u3) in mm",
            hint="e.g. --step 15 or --step 15,15,10",
        )
    return arr


def parse_screw_pitch(items: Iterable[str] | None) -> dict[int, float]:
    """``["X=5", "Y=10"]`` (or ``"X=5;Y=10"``) -> ``{0: 5.0, 1: 10.0}`` (mm)."""
    out: dict[int, float] = {}
    if items is None:
        return out
    if isinstance(items, str):
        items = [items]
    for raw in items:
        for item in filter(None, (s.strip() for s in re.split(r"[;,]", raw))):
            name, sep, value = item.partition("=")
            hint = "write --screw-pitch AXIS=PITCH_MM, e.g. --screw-pitch X=10"
            if not sep:
                raise PostprocError(f"--screw-pitch {raw!r}: {item!r} has no '='", hint=hint)
            j = _axis_index(name, raw, "--screw-pitch")
            try:
                pitch = float(value)
            except ValueError:
                pitch = float("nan")
            if not math.isfinite(pitch) or pitch <= 0:
                raise PostprocError(f"--screw-pitch {raw!r}: pitch {value.strip()!r} is not a positive length", hint=hint)
            out[j] = pitch
    return out


def distinct_positions(values: np.ndarray, tol: float = LATTICE_TOL_MM) -> np.ndarray:
    """Sorted distinct values, merging neighbours closer than ``tol`` (their mean)."""
    v = np.sort(np.asarray(values, dtype=float))
    if len(v) == 0:
        return v
    breaks = np.flatnonzero(np.diff(v) > tol) + 1
    return np.array([g.mean() for g in np.split(v, breaks)])


def tool_vector_note(r: np.ndarray, method: str) -> list[str]:
    """Report line on the tool vectors of the measurement (the model carries them unrotated)."""
    distinct = np.unique(np.round(np.asarray(r, dtype=float), 3), axis=0)
    if len(distinct) == 1:
        t = distinct[0]
        return [f"tool vector of the measurement: {t[0]:g},{t[1]:g},{t[2]:g} mm; the {method} model "
                "describes that point and carries any other tool vector unrotated"]
    return [f"note: the points carry {len(distinct)} different tool vectors; the {method} model "
            "removes each and averages, so angular errors acting on their difference are not modelled"]


def format_node(q) -> str:
    return " ".join(f"{a}={v:.3f}" for a, v in zip(AXES, q, strict=True))


# -- the seed's practical rules --------------------------------------------------------

def step_warnings(step_mm: np.ndarray, range_mm: np.ndarray, pitches: dict[int, float]) -> list[str]:
    """Report lines for the grid step rules of seed 000 (chapter 2).

    1. A step under 10 mm was found less effective.
    2. A step that is a multiple of the lead-screw pitch samples the screw's periodic
       error at the same phase at every node. More generally, with ``d`` the distance of
       ``u / pitch`` from the nearest whole number, the nodes see the periodic error as
       a wave of period ``u / d``; when that is longer than the calibrated travel the
       periodic error turns into an offset or a slope that the grid reads as geometry,
       and between nodes it is neither seen nor corrected.
    """
    lines = []
    for j in range(3):
        u = float(step_mm[j])
        if u < MIN_GRID_STEP_MM:
            lines.append(
                f"warning: grid step {u:g} mm on {AXES[j]} is under {MIN_GRID_STEP_MM:g} mm: the seed "
                "experiments found the tangent grid less effective at such steps (tangents are "
                "differences of two noisy points, and measuring takes longer)"
            )
        if j not in pitches:
            continue
        pitch = pitches[j]
        ratio = u / pitch
        d = abs(ratio - round(ratio))
        alias_mm = math.inf if d * pitch < LATTICE_TOL_MM else u / d
        if round(ratio) >= 1 and alias_mm > float(range_mm[j]):
            how = (
                f"a multiple ({round(ratio)} x) of" if math.isinf(alias_mm)
                else f"nearly a multiple ({ratio:.3f} x) of"
            )
            seen = (
                "a constant offset" if math.isinf(alias_mm)
                else f"a slow wave of period {alias_mm:.0f} mm (longer than the {float(range_mm[j]):g} mm travel)"
            )
            lines.append(
                f"warning: grid step {u:g} mm on {AXES[j]} is {how} the lead-screw pitch {pitch:g} mm: "
                f"every node samples the screw's periodic error at (nearly) the same phase, so it "
                f"appears as {seen}, is read as geometry and is not corrected between nodes; "
                f"choose a step that is not a multiple of the pitch"
            )
    return lines


# -- cells and the piecewise-affine inverse --------------------------------------------

def cell_index(q: np.ndarray, edges: list[np.ndarray]) -> np.ndarray:
    """(N, 3) cell indices of points ``q`` on a rectilinear partition.

    Intervals are half-open ``[e_k, e_k+1)`` except the last, which is closed; points
    outside the partition belong to the first or last interval (extrapolation).
    """
    out = np.empty(q.shape, dtype=int)
    for j in range(3):
        e = edges[j]
        out[:, j] = np.clip(np.searchsorted(e, q[:, j], side="right") - 1, 0, len(e) - 2)
    return out


def outside_distance(q: np.ndarray, cells: np.ndarray, edges: list[np.ndarray]) -> np.ndarray:
    """How far (mm, max over axes) each point lies outside the box of its given cell."""
    d = np.zeros(len(q))
    for j in range(3):
        lo = edges[j][cells[:, j]]
        hi = edges[j][cells[:, j] + 1]
        d = np.maximum(d, np.maximum(lo - q[:, j], q[:, j] - hi))
    return np.maximum(d, 0.0)


def piecewise_inverse(
    target: np.ndarray,
    first_cells: np.ndarray,
    solve: Callable[[np.ndarray, np.ndarray], np.ndarray],
    edges: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Cell-consistent inverse of a model that is affine on each cell.

    ``solve(cells, target)`` returns the commanded position that cell's affine map
    sends to ``target``. Starting from ``first_cells``: solve in the cell, look up the
    cell of the answer; if it is the same cell, the answer is consistent and kept,
    otherwise solve again in the new cell.

    Border rule. A piecewise-affine model is discontinuous at cell borders. Where
    neighbouring images overlap, the first consistent cell along this walk wins. Where
    they leave a gap, no cell is consistent and the walk cycles; the answer is then the
    visited cell's solution that lies nearest to its own cell (computed with that
    cell's pair, slightly beyond its border), and the caller's residual shows the gap.

    Returns ``(q, iterations)``.
    """
    n = len(target)
    q = np.zeros((n, 3))
    iters = np.zeros(n, dtype=int)
    cells = first_cells.copy()
    best_q = np.full((n, 3), np.nan)
    best_d = np.full(n, np.inf)
    visited: dict[int, set[tuple[int, int, int]]] = {}
    active = np.arange(n)
    for _ in range(SOLVER_MAX_ITER):
        if len(active) == 0:
            break
        c = cells[active]
        qa = solve(c, target[active])
        iters[active] += 1
        d = outside_distance(qa, c, edges)
        better = d < best_d[active]
        best_d[active[better]] = d[better]
        best_q[active[better]] = qa[better]
        new = cell_index(qa, edges)
        same = np.all(new == c, axis=1)
        q[active[same]] = qa[same]
        still = []
        for i_local in np.flatnonzero(~same):
            i = active[i_local]
            seen = visited.setdefault(int(i), set())
            seen.add(tuple(c[i_local]))
            key = tuple(new[i_local])
            if key in seen:  # a cycle: the target lies in a gap between cells
                q[i] = best_q[i]
            else:
                cells[i] = new[i_local]
                still.append(i)
        active = np.asarray(still, dtype=int)
    if len(active):  # cannot happen with finitely many cells, kept for safety
        q[active] = best_q[active]
    return q, iters
