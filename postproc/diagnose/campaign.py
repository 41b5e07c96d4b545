"""What a measurement campaign cannot show, said as warnings before any effect is named.

- **Time/tool confounding**: tool vectors measured one after the other make a drift in
  time and an error of one tool (its length) the same columns of the data.
- **Time/position confounding**: when the measurement order follows the position (a
  raster), a drift in time and an error along the axes are the same columns of the data:
  a warm-up is absorbed into scale and squareness and never seen as drift.
- **Aliasing**: positions on a regular grid of step ``u`` along an axis cannot show a
  periodic error with a pitch shorter than ``2u`` (it aliases to a longer pitch): the
  shortest detectable pitch is reported.
- **Too-coarse knots**: a parametric model refitted on data with few distinct positions
  per axis gets one or two B-spline spans over the travel: axis shapes shorter than the
  travel are not resolved.
- **Points outside the calibrated volume**: the calibration extrapolates there.
- **Unknown approach state**: rows before an axis's first move with ``dir`` 0.
- **Context columns** logged in few rows or by sample and hold (see
  :func:`postproc.diagnose.data.screen_columns`), with their counts.
"""

from __future__ import annotations

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.effects.base import AXES, DIR_COLUMNS
from postproc.effects.periodic import PITCH_MAX_TRAVEL_FRACTION, PITCH_MIN_MM, REGULAR_STEP_SPREAD

# Share of the variance of ``t`` explained by the positions (quadratic in each axis)
# above which time and position are confounded.
CONFOUNDED_R2 = 0.5
# Fewer B-spline knot intervals than this along an axis resolve no shape shorter than the travel.
MIN_KNOT_INTERVALS = 2
# Places listed in a warning (the JSON lists them all).
N_LISTED = 5


def _r2_on_positions(t: np.ndarray, q: np.ndarray) -> float:
    qc = (q - q.mean(axis=0)) / np.maximum(np.ptp(q, axis=0), 1e-12)
    A = np.column_stack([np.ones(len(t)), qc, qc**2])
    coef, *_ = np.linalg.lstsq(A, t, rcond=None)
    tc = t - t.mean()
    den = float(tc @ tc)
    return 1.0 - float(np.sum((t - A @ coef) ** 2)) / den if den > 0 else 0.0


def regular_step(x: np.ndarray) -> float | None:
    """The step of positions ``x`` on a regular grid, None when they are irregular."""
    u = np.unique(np.round(x, 6))
    if len(u) < 3:
        return None
    steps = np.diff(u)
    step = float(np.median(steps))
    return step if np.std(steps) < REGULAR_STEP_SPREAD * step else None


def campaign_warnings(ds: Dataset, cal, data, res) -> list[dict]:
    out: list[dict] = [{"kind": "context column", **n} for n in ds.column_notes]
    if "t" in ds.ctx and np.ptp(ds.ctx["t"]) > 0 and len(ds) > 10:
        r2 = _r2_on_positions(ds.ctx["t"], ds.q)
        if r2 > CONFOUNDED_R2:
            per_axis = [_r2_on_positions(ds.ctx["t"], ds.q[:, [j]]) for j in range(3)]
            axis = AXES[int(np.argmax(per_axis))]
            out.append({"kind": "time-position confounding", "r2": r2, "axis": axis,
                        "message": f"the measurement order follows the position ({r2:.0%} of the time "
                                   f"is predicted by X, Y, Z; most by {axis}): a drift in time cannot be "
                                   "told apart from errors along the axes (a warm-up is taken for scale "
                                   "and squareness); measure in a random order, or come back to a "
                                   "reference point through the campaign"})
    tools, inv = np.unique(np.round(ds.r, 3), axis=0, return_inverse=True)
    if "t" in ds.ctx and np.ptp(ds.ctx["t"]) > 0 and len(tools) > 1:
        t = ds.ctx["t"]
        inv = inv.ravel()
        means = np.bincount(inv, weights=t) / np.bincount(inv)
        r2 = float(np.sum((means[inv] - t.mean()) ** 2) / np.sum((t - t.mean()) ** 2))
        if r2 > CONFOUNDED_R2:
            out.append({"kind": "time-tool confounding", "r2": r2,
                        "message": f"the tool vectors were measured one after the other ({r2:.0%} of the time "
                                   "is predicted by the tool vector): a drift in time cannot be told apart "
                                   "from an error of one tool (its length, say); alternate the tools"})
    for j, a in enumerate(AXES):
        step = regular_step(ds.q[:, j])
        if step is not None and 2 * step > PITCH_MIN_MM:
            shortest = 2 * step
            out.append({"kind": "aliasing", "axis": a, "step_mm": step, "shortest_pitch_mm": shortest,
                        "message": f"{a} positions lie on a regular {step:g} mm grid: a periodic error "
                                   f"(lead screw) with a pitch shorter than {shortest:g} mm cannot be "
                                   f"seen{' at all' if shortest > PITCH_MAX_TRAVEL_FRACTION * np.ptp(ds.q[:, j]) else ''} (it aliases to a "
                                   "longer one); use a step that is no divisor of the screw pitch, or "
                                   "irregular positions"})
    if cal.method == "parametric" and not res.fixed:
        from postproc.engine.parametric_fit import POSITIONS_PER_INTERVAL

        for j, a in enumerate(AXES):
            distinct = len(np.unique(np.round(ds.q[:, j], 3)))
            n_int = (distinct - 1) // POSITIONS_PER_INTERVAL
            if n_int < MIN_KNOT_INTERVALS and np.ptp(ds.q[:, j]) > 0:
                out.append({"kind": "coarse knots", "axis": a, "distinct_positions": distinct,
                            "message": f"only {distinct} distinct {a} positions: the parametric model "
                                       f"refitted on them has {max(n_int, 1)} B-spline span over the {a} "
                                       "travel, so the cross-validation tests a model stiffer than the "
                                       "calibration; measure more positions along the axis"})
    if res.outside:
        listed = ", ".join(res.outside[:N_LISTED]) + (" ..." if len(res.outside) > N_LISTED else "")
        what = "excluded from the ranking" if res.outside_excluded else "kept"
        out.append({"kind": "outside volume", "n": len(res.outside), "rows": list(res.outside),
                    "message": f"{len(res.outside)} point(s) lie outside the calibrated volume, where the "
                               f"calibration extrapolates ({what}): {listed}"})
    unknown = sum(int(np.sum(m.unknown_direction_rows())) for m in data if hasattr(m, "unknown_direction_rows"))
    if unknown and any(c in ds.ctx for c in DIR_COLUMNS):
        out.append({"kind": "unknown approach", "n": unknown,
                    "message": f"{unknown} row(s) have dir 0 before the axis's first move: their backlash "
                               "state is unknown (taken as none)"})
    return out
