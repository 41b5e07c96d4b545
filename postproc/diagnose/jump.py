"""A step in the measurement frame: the tracker moved during the campaign.

A tracker knocked or set up again halfway sees the machine through one rigid motion
before and another after (:mod:`postproc.diagnose.frame`). One registration for the
whole campaign then leaves a step in time that no effect of the machine explains: a
warm-up (``thermal:t``) takes part of it and the verdict blames the machine.

The test, on the residual of the model (the calibration as it is or refitted, with one
registration), in time order (``t``, else the order of the rows):

- the **step**: one registration before row ``i`` and another from it on (12 parameters),
  for every ``i`` between repeat groups that leaves ``MIN_SEGMENT_ROWS`` and
  ``MIN_SEGMENT_FRACTION`` of the rows on each side; the best ``i`` is kept;
- against **one registration** (6): an F test on ``6`` and ``3N - 12`` degrees of freedom,
  Bonferroni-corrected for the number of ``i`` tried, below ``JUMP_P``;
- against **a drift** that is smooth in time: the registration growing linearly in time
  (also 12 parameters), and a warm-up of the zero point (``thermal:t``'s shape, its time
  constant searched, beside one registration): the step must leave less than either;
- and it must remove at least ``MIN_EXPLAINED`` of the residual variance (a step too
  small to matter is not worth splitting a campaign for, and a misfit of the calibration
  that follows the measuring order is a small step in time too).

All are least-squares fits of rigid motions (first order, ``t + w x p``), so a step in the
frame is told from a drift and from errors of the machine, which depend on the position,
not on when it was measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.diagnose.frame import frame_basis
from postproc.effects.linalg import solve_ls

# Each side of a step holds at least this many rows, and this fraction of them: a
# registration on fewer points is too loose to compare (and a step at the very ends is a
# few bad shots).
MIN_SEGMENT_ROWS = 20
MIN_SEGMENT_FRACTION = 0.1
# Significance of a step (Bonferroni over the rows tried). Stricter than noise alone
# needs: where the campaign's order follows the position (planes measured one after the
# other) a position-dependent misfit of the calibration is a step in time too (on 32 clean
# campaigns one such reached p = 3e-4).
JUMP_P = 1e-4
# A step must remove this fraction of the residual variance at least: a tracker moved by
# 8 um removes 21 % on 5 um noise, 15 um 42 %; misfits of the calibration that follow the
# measuring order as steps: a plane boundary 4 %, an axis coupling no effect models (the
# x*y*z campaign of tests/test_diagnose_campaigns.py) 8.2 %. Between the two groups.
MIN_EXPLAINED = 0.12
# Time constants of the warm-up alternative (s): minutes to hours.
WARMUP_TAUS_S = (300.0, 600.0, 1200.0, 2400.0, 4800.0, 9600.0)


@dataclass
class FrameJump:
    """A step in the registration, found at ``row`` (index into the dataset)."""

    row: int
    place: str  # file:line of the first row after the step
    t_s: float | None  # its time, when the data have one
    rows_before: int
    rows_after: int
    translation_mm: np.ndarray  # the registration after minus before
    rotation_rad: np.ndarray
    size_mm: float  # the largest displacement the step makes over the measured points
    f_stat: float
    p_value: float  # Bonferroni-corrected
    explained: float  # fraction of the residual variance the step removes
    drift_explained: float  # the best smooth drift's, for comparison

    def describe(self) -> str:
        t = self.translation_mm * 1000
        w = self.rotation_rad * 1e6
        when = f", t = {self.t_s:.0f} s" if self.t_s is not None else ""
        return (f"frame jump at row {self.row + 1} ({self.place}{when}; {self.rows_before} rows before, "
                f"{self.rows_after} after): translation x {t[0]:+.2f} y {t[1]:+.2f} z {t[2]:+.2f} um, rotation "
                f"x {w[0]:+.2f} y {w[1]:+.2f} z {w[2]:+.2f} urad, up to {self.size_mm * 1000:.2f} um over the "
                f"points; it removes {self.explained:.1%} of the residual variance (a drift in time "
                f"{self.drift_explained:.1%}; F = {self.f_stat:.1f}, p = {self.p_value:.1g})")

    def to_json(self) -> dict:
        return {"row": self.row + 1, "place": self.place, "t_s": self.t_s, "rows_before": self.rows_before,
                "rows_after": self.rows_after, "translation_mm": self.translation_mm.tolist(),
                "rotation_rad": self.rotation_rad.tolist(), "size_mm": self.size_mm, "f": self.f_stat,
                "p_value": self.p_value, "explained": self.explained, "drift_explained": self.drift_explained}


def _sse(A: np.ndarray, y: np.ndarray) -> float:
    coef = solve_ls(A, y)
    r = y - A @ coef
    return float(r @ r)


def _warmup_sse(F: np.ndarray, t: np.ndarray, y: np.ndarray) -> float:
    """Least SSE of one registration plus a warm-up of the zero point d (1 - exp(-t / tau))."""
    best = float("inf")
    n = len(t)
    for tau in WARMUP_TAUS_S:
        g = 1.0 - np.exp(-(t - t.min()) / tau)
        W = np.zeros((3 * n, 3))
        for j in range(3):
            W[j::3, j] = g
        best = min(best, _sse(np.hstack([F, W]), y))
    return best


def frame_jump(ds: Dataset, resid: np.ndarray) -> FrameJump | None:
    """The step in the measurement frame that best explains ``resid`` (N, 3), when it is
    significant and no smooth drift explains as much; else None."""
    from scipy.stats import f as f_dist

    n = len(ds)
    min_side = max(MIN_SEGMENT_ROWS, int(np.ceil(MIN_SEGMENT_FRACTION * n)))
    if n < 2 * min_side:
        return None
    logged = ds.ctx.get("t")
    timed = logged is not None and bool(np.all(np.isfinite(logged))) and np.ptp(logged) > 0
    t = np.asarray(logged, dtype=float) if timed else np.arange(n, dtype=float)
    order = np.argsort(t, kind="stable")
    groups = ds.repeat_groups()[order]
    q, r, y3 = ds.q[order], ds.r[order], resid[order]
    B = frame_basis(q, r)  # (n, 3, 6)
    y = y3.reshape(-1)
    # prefix sums of the normal equations, row by row
    G = np.cumsum(np.einsum("nji,njk->nik", B, B), axis=0)
    b = np.cumsum(np.einsum("nji,nj->ni", B, y3), axis=0)
    Gt, bt = G[-1], b[-1]
    yy = float(y @ y)
    coef0 = np.linalg.lstsq(Gt, bt, rcond=None)[0]
    sse0 = yy - float(bt @ coef0)
    if sse0 <= 0:
        return None
    cuts = [i for i in range(min_side, n - min_side + 1) if groups[i] != groups[i - 1]]
    if not cuts:
        return None
    best_i, best_sse = -1, float("inf")
    for i in cuts:
        # before and after fitted separately: the normal equations split at row i
        Ga, ba = G[i - 1], b[i - 1]
        Gb, bb = Gt - Ga, bt - ba
        ca = np.linalg.lstsq(Ga, ba, rcond=None)[0]
        cb = np.linalg.lstsq(Gb, bb, rcond=None)[0]
        sse = yy - float(ba @ ca) - float(bb @ cb)
        if sse < best_sse:
            best_i, best_sse = i, sse
    dof = 3 * n - 12
    f_stat = ((sse0 - best_sse) / 6.0) / (best_sse / dof)
    p = min(1.0, len(cuts) * float(f_dist.sf(f_stat, 6, dof)))
    explained = (sse0 - best_sse) / sse0
    F = B.reshape(3 * n, 6)
    s = (t[order] - t.mean()) / np.ptp(t)
    ramp = _sse(np.hstack([F, F * np.repeat(s, 3)[:, None]]), y)
    drift = min(ramp, _warmup_sse(F, t[order], y) if timed else ramp)
    if p >= JUMP_P or explained < MIN_EXPLAINED or best_sse >= drift:
        return None
    i = best_i
    before, after = np.arange(n) < i, np.arange(n) >= i
    ca = np.linalg.lstsq(G[i - 1], b[i - 1], rcond=None)[0]
    cb = np.linalg.lstsq(Gt - G[i - 1], bt - b[i - 1], rcond=None)[0]
    step = cb - ca
    size = float(np.max(np.linalg.norm(B @ step, axis=1)))
    row = int(order[i])
    return FrameJump(row, ds.place(row), float(t[row]) if timed else None, int(before.sum()), int(after.sum()),
                     step[:3], step[3:], size, float(f_stat), p, float(explained), float((sse0 - drift) / sse0))
