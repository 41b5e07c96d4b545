"""Dead-band ("elastic gap") model of the copying chain (seed 003, Fig. 6-8).

The chain is: back-wall surface -> sensor tip -> transducer -> tracking drive W.
The seed models it in Simulink as the ideal sensor signal V (from the pre-measured
back wall along the path) fed through a Backlash block of width ``gap`` (V model),
then a drive model (W model); the computed thickness error is ``E = V - W``.

The Backlash block: the output holds while the input moves inside the gap, then
follows the input at half a gap behind it::

    y_k = x_k - gap/2   if x_k - gap/2 > y_{k-1}
    y_k = x_k + gap/2   if x_k + gap/2 < y_{k-1}
    y_k = y_{k-1}       otherwise

When the table reverses, the ideal signal V reverses too (wherever the wall is not
flat) and the output stands still until the input has travelled the whole gap: the
"plateau" of Fig. 5 and 7. Its width, measured in the input, equals the gap. The
drive is a first-order lag ``tau dW/dt = y - W`` (``tau = 0``: W = y).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.errors import MeasurementError

# The output of the gap is "standing still" while it moves less than this (mm) from
# one sample to the next: far below the sensor resolution (0.1 um), far above round-off.
PLATEAU_STILL_MM = 1e-9


@dataclass
class Plateau:
    """A stretch where the gap output stands still after the input reversed.

    ``start``/``end``: sample indices of the first and last still sample;
    ``input_travel_mm``: how far the input moved meanwhile (equals the gap);
    ``b_start``/``b_end``: table angle at both ends when known.
    """

    start: int
    end: int
    input_travel_mm: float
    b_start: float | None = None
    b_end: float | None = None


@dataclass
class DeadbandResult:
    v_ideal: np.ndarray
    v_model: np.ndarray  # after the gap
    w: np.ndarray  # drive output
    error_mm: np.ndarray  # E = V - W (thickness error, mm), before any correction
    gap_mm: float
    tau_s: float
    reversals: np.ndarray  # sample indices where the input changes direction
    plateaus: list[Plateau] = field(default_factory=list)
    correction_mm: np.ndarray | None = None  # K applied (cut deeper by K)

    @property
    def residual_mm(self) -> np.ndarray:
        """Thickness error after the correction: E - K (E when no correction)."""
        return self.error_mm if self.correction_mm is None else self.error_mm - self.correction_mm


def backlash(x, gap_mm: float, y0: float | None = None) -> np.ndarray:
    """The Backlash block (deadband width ``gap_mm``); initial output ``y0`` (default x[0])."""
    x = np.asarray(x, dtype=float)
    if gap_mm < 0:
        raise MeasurementError("the gap must not be negative", hint="e.g. --gap 0.02 (mm)")
    y = np.empty_like(x)
    half = 0.5 * gap_mm
    prev = float(x[0]) if y0 is None else float(y0)
    for i, xi in enumerate(x):
        if xi - half > prev:
            prev = xi - half
        elif xi + half < prev:
            prev = xi + half
        y[i] = prev
    return y


def drive_lag(u, t_s, tau_s: float) -> np.ndarray:
    """First-order drive ``tau dW/dt = u - W`` (exact for piecewise-constant input)."""
    u = np.asarray(u, dtype=float)
    if tau_s <= 0:
        return u.copy()
    w = np.empty_like(u)
    w[0] = u[0]
    dt = np.diff(np.asarray(t_s, dtype=float))
    a = np.exp(-np.maximum(dt, 0.0) / tau_s)
    for i in range(1, len(u)):
        w[i] = a[i - 1] * w[i - 1] + (1.0 - a[i - 1]) * u[i - 1]
    return w


def reversals(x) -> np.ndarray:
    """Indices where the motion of ``x`` changes direction (ignoring still samples)."""
    d = np.diff(np.asarray(x, dtype=float))
    moving = np.flatnonzero(np.abs(d) > PLATEAU_STILL_MM)
    if len(moving) < 2:
        return np.zeros(0, dtype=int)
    s = np.sign(d[moving])
    flips = np.flatnonzero(s[1:] != s[:-1])
    return moving[flips] + 1  # the sample at the turning point


def find_plateaus(x, y, b=None) -> list[Plateau]:
    """Stretches where ``y`` stands still after each reversal of ``x``."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    out = []
    dy = np.abs(np.diff(y))
    for r in reversals(x):
        start = r
        end = r
        while end < len(y) - 1 and dy[end] <= PLATEAU_STILL_MM:
            end += 1
        # back up to the first still sample at or before the turning point
        while start > 0 and dy[start - 1] <= PLATEAU_STILL_MM:
            start -= 1
        travel = float(np.ptp(x[r:end + 1])) if end > r else 0.0
        if travel <= PLATEAU_STILL_MM:  # the input only paused at the turning point
            continue
        out.append(Plateau(int(start), int(end), travel,
                           None if b is None else float(b[start]), None if b is None else float(b[end])))
    return out


def simulate(v_ideal, gap_mm: float, *, t_s=None, tau_s: float = 0.0, b_deg=None,
             correction_mm=None) -> DeadbandResult:
    """Run the ideal sensor signal through the gap and the drive; E = V - W."""
    v = np.asarray(v_ideal, dtype=float)
    if v.ndim != 1 or len(v) < 2:
        raise MeasurementError("the deadband model needs a signal of at least two samples")
    t = np.arange(len(v), dtype=float) if t_s is None else np.asarray(t_s, dtype=float)
    if tau_s > 0 and np.any(np.diff(t) < 0):
        raise MeasurementError("time column t must not decrease along the path",
                               hint="list the samples in the order the path visits them")
    vm = backlash(v, gap_mm)
    w = drive_lag(vm, t, tau_s)
    corr = None if correction_mm is None else np.asarray(correction_mm, dtype=float)
    return DeadbandResult(v, vm, w, v - w, float(gap_mm), float(tau_s), reversals(v),
                          find_plateaus(v, vm, b_deg), corr)


def plot_deadband(res: DeadbandResult, x=None, ax=None, xlabel: str = "sample"):
    """Fig. 7/8 style: ideal V, V after the gap, drive W, and the thickness error."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    ax0, ax1 = ax
    xs = np.arange(len(res.v_ideal)) if x is None else np.asarray(x)
    ax0.plot(xs, res.v_ideal, "k-", label="V ideal (pre-measured wall)")
    ax0.plot(xs, res.v_model, "0.5", label=f"V after gap {res.gap_mm * 1e3:.1f} um")
    ax0.plot(xs, res.w, "b--", lw=0.8, label="W drive")
    ax0.set_ylabel("mm")
    ax0.legend(loc="best", fontsize=8)
    ax1.plot(xs, res.error_mm * 1e3, "r-", label="E = V - W")
    if res.correction_mm is not None:
        ax1.plot(xs, res.residual_mm * 1e3, "g-", label="E - K (corrected)")
    for p in res.plateaus:
        ax1.axvspan(xs[p.start], xs[p.end], color="0.9")
    ax1.set_ylabel("thickness error, um")
    ax1.set_xlabel(xlabel)
    ax1.legend(loc="best", fontsize=8)
    return ax
