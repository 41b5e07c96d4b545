"""Periodic (cyclic) error of a lead screw or a scale along one axis.

Physics: the screw's thread form, wobble and bearing run-out repeat with every turn,
so the positioning error of the axis has a component periodic in its position, with
the screw pitch ``P`` (or a sub-multiple)::

    displacement along the axis = c cos(2 pi q / P) + s sin(2 pi q / P)

``c``, ``s`` (``cos_mm``, ``sin_mm``) are linear parameters; the pitch is a
non-linear setting (``config["pitch_mm"]``), found from the peak of a
periodogram of the residual along the axis against the axis position. Needs only
positions. Compensable from the commanded position.

The pitch can only be resolved if the positions sample it: with points on a regular
grid of step ``u`` pitches below ``2u`` alias, so the search stops at the grid's
Nyquist pitch (seed 000 warns to choose a grid step that is no multiple of the pitch).
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AxisEffect, unit_basis
from postproc.errors import CalibrationError

# Shortest pitch searched: ball screws on machine tools have leads of 2 mm and more.
PITCH_MIN_MM = 2.0
# Longest pitch searched, as a fraction of the travel: three periods at least, so that a
# period is told from a straightness or scale shape (one or two humps over the travel,
# which the bow/S-shape effects and the base model hold). Ball screws of long-travel and
# fast axes have leads of 40-80 mm, rack-and-pinion and scale errors longer still: the
# search is bounded by the travel, not by a typical lead.
PITCH_MAX_TRAVEL_FRACTION = 1.0 / 3.0
# Frequency grid oversampling over the natural resolution 1/travel: 3 points per
# peak width so the peak is not missed between grid frequencies ...
PERIODOGRAM_OVERSAMPLING = 3
# ... then refined on this many frequencies across one coarse step either side.
PEAK_REFINE_POINTS = 25
# At least this many distinct positions are needed to see a period at all.
MIN_DISTINCT_POSITIONS = 12
# Positions closer than this are the same position (repeated points).
SAME_POSITION_MM = 1e-6
# Steps between positions whose spread is under this fraction of the median step form a
# regular grid (which aliases above its Nyquist frequency).
REGULAR_STEP_SPREAD = 0.05
# Relative spread of frequency steps under which the frequency grid is evenly spaced
# (np.linspace output differs from even by rounding only).
EVEN_FREQUENCY_RTOL = 1e-9


def search_frequencies(x: np.ndarray) -> np.ndarray:
    """Candidate frequencies (cycles/mm) for the periodogram of positions ``x``."""
    travel = float(np.ptp(x))
    u = np.unique(np.round(x / SAME_POSITION_MM) * SAME_POSITION_MM)
    steps = np.diff(u)
    f_max = 1.0 / PITCH_MIN_MM
    if len(steps):
        # Regular grids alias above their Nyquist frequency; random positions do not.
        step = float(np.median(steps))
        regular = np.std(steps) < REGULAR_STEP_SPREAD * step
        if regular:
            f_max = min(f_max, 0.5 / step)
    f_min = 1.0 / (PITCH_MAX_TRAVEL_FRACTION * travel) if travel > 0 else np.inf
    if f_max <= f_min:
        return np.zeros(0)
    n = int(np.ceil((f_max - f_min) * travel * PERIODOGRAM_OVERSAMPLING)) + 1
    return np.linspace(f_min, f_max, n)


def periodogram(x: np.ndarray, y: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """Power |sum (y - mean) exp(-2 pi i f x)|^2 / N at ``freqs`` (cycles per unit of x).

    The classical periodogram: on irregularly spaced positions it peaks at the true
    frequency as the Lomb-Scargle one does. On an evenly spaced frequency grid the
    phasors are advanced by one complex multiplication per point and frequency
    (rounding grows by ~1e-16 per step: negligible over thousands of frequencies).
    """
    x = np.asarray(x, dtype=float)
    if len(freqs) == 0 or len(x) == 0:
        return np.zeros(len(freqs))
    yc = np.asarray(y, dtype=float) - np.mean(y)
    steps = np.diff(freqs)
    if len(freqs) > 2 and np.allclose(steps, steps[0], rtol=EVEN_FREQUENCY_RTOL, atol=0.0):
        w = yc * np.exp(-2j * np.pi * freqs[0] * x)
        advance = np.exp(-2j * np.pi * steps[0] * x)
        out = np.empty(len(freqs))
        for k in range(len(freqs)):
            out[k] = abs(w.sum()) ** 2
            w *= advance
        return out / len(x)
    phase = np.outer(freqs, 2 * np.pi * x)
    return ((np.cos(phase) @ yc) ** 2 + (np.sin(phase) @ yc) ** 2) / len(x)


class Periodic(AxisEffect):
    kind = "periodic"
    meaning = "periodic positioning error repeating with the lead-screw pitch"

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("cos_mm", "sin_mm")

    @property
    def compensable_reason(self) -> str:
        return f"compensated from the commanded {self.target} position"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        amp = float(np.hypot(p["cos_mm"], p["sin_mm"]))
        pitch = self.config.get("pitch_mm", float("nan"))
        return f"periodic error of {self.target}: amplitude {amp * 1000:.2f} um at pitch {pitch:.3f} mm"

    def untestable_reason(self, q, r, ctx) -> str | None:
        x = np.asarray(q)[:, self.axis]
        n = len(np.unique(np.round(x / SAME_POSITION_MM)))
        if n < MIN_DISTINCT_POSITIONS:
            return f"only {n} distinct {self.target} positions (a period needs {MIN_DISTINCT_POSITIONS}+)"
        if len(search_frequencies(x)) == 0:
            return f"the {self.target} positions are too coarse to resolve any pitch >= {PITCH_MIN_MM} mm"
        return None

    def basis(self, q, r, ctx) -> np.ndarray:
        pitch = self.config.get("pitch_mm")
        if not pitch or pitch <= 0:
            raise CalibrationError(f"effect {self.name} has no pitch_mm > 0 in its config")
        phase = 2 * np.pi * q[:, self.axis] / pitch
        return np.stack([unit_basis(np.cos(phase), self.axis), unit_basis(np.sin(phase), self.axis)], axis=2)

    def prepare(self, q, r, ctx, resid) -> Periodic:
        x = np.asarray(q)[:, self.axis]
        freqs = search_frequencies(x)
        power = periodogram(x, np.asarray(resid)[:, self.axis], freqs)
        i = int(np.argmax(power))
        lo, hi = freqs[max(i - 1, 0)], freqs[min(i + 1, len(freqs) - 1)]
        fine = np.linspace(lo, hi, PEAK_REFINE_POINTS)
        f = float(fine[int(np.argmax(periodogram(x, np.asarray(resid)[:, self.axis], fine)))])
        return self.copy(config={"pitch_mm": 1.0 / f})
