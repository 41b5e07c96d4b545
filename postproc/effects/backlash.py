"""Backlash (lost motion) of one axis.

Physics: the nut, couplings and guides of an axis leave a gap. Moving one way, the
drive pushes the axis through the gap and the axis stops short of the commanded
position by half of it; moving the other way, short on the other side. With ``dir``
the direction the axis approached the point (+1 / -1, 0 when it did not move)::

    displacement along the axis = b / 2 * dir

``b`` (``b_mm``) is the reversal value that a bidirectional ISO 230-2 test reads,
with its sign: ``B = x_up - x_down``, the mean positional deviation (reached minus
commanded) approached from + minus that approached from -. Lost motion makes the
axis lag: it falls short moving +, so ``b < 0`` (a gap of 12 um is ``b = -0.012``).
``b > 0`` is an axis that runs ahead of its command, as one does whose controller
compensates more backlash than there is. Needs ``dirx`` / ``diry`` / ``dirz``.
Compensable: the correction pipeline commands each point with the direction the
corrected program moves the axis in, and at a reversal takes the difference up in
the new direction (:mod:`postproc.gcode.directions`); an axis that runs ahead gets no
take-up (one would move on in the old direction and overshoot by ``b``): it jumps back
by ``b`` where it reverses, accepted along the path that follows and refused across it.

A reversal that varies along the axis (the B_i of an ISO 230-2 evaluation, one per
target) is a profile in ``config``: ``position_mm`` (increasing) and ``shape``
(B_i / b at each position, linear in between, held at the ends). ``b`` then scales
the profile, so the effect stays linear in its parameter::

    displacement along the axis = b / 2 * shape(q_axis) * dir
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import DIR_COLUMNS, AxisEffect, context_column, unit_basis
from postproc.errors import CalibrationError

# Fewer rows than this approached from either side cannot show a reversal: the mean on
# that side would rest on one or two noisy shots.
MIN_ROWS_PER_SIDE = 3


class Backlash(AxisEffect):
    kind = "backlash"
    meaning = ("reversal value b = x_up - x_down (ISO 230-2): the axis is displaced by b/2 along its approach "
               "direction; lost motion (the axis lags) has b < 0")

    @property
    def needs(self) -> tuple[str, ...]:
        return (DIR_COLUMNS[self.axis],)

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("b_mm",)

    @property
    def compensable_reason(self) -> str:
        return f"compensated from the direction the corrected program moves {self.target} in"

    def untestable_reason(self, q, r, ctx) -> str | None:
        if self.missing(ctx):
            return super().untestable_reason(q, r, ctx)
        d = np.asarray(ctx[self.needs[0]], dtype=float)
        plus, minus = int(np.sum(d > 0)), int(np.sum(d < 0))
        if 0 < min(plus, minus) < MIN_ROWS_PER_SIDE:
            return (f"{self.target} was approached {plus} times from + and {minus} from -: "
                    f"a reversal needs {MIN_ROWS_PER_SIDE}+ each (approach the points from both sides)")
        return super().untestable_reason(q, r, ctx)

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        text = f"reversal (backlash) of {self.target}: {p['b_mm'] * 1000:+.2f} um"
        if "position_mm" in self.config:
            shape = np.asarray(self.config["shape"], dtype=float) * p["b_mm"] * 1000
            text += (f" at most, varying along {self.target} from {shape.min():+.2f} to {shape.max():+.2f} um "
                     f"over {len(shape)} positions")
        values = p["b_mm"] * np.asarray(self.config.get("shape", [1.0]), dtype=float)
        if np.all(values < 0):
            text += f" (lost motion: {self.target} lags its approach direction)"
        elif np.all(values > 0):
            text += f" ({self.target} runs ahead of its approach direction: a compensation larger than the gap?)"
        return text

    def profile(self, t) -> np.ndarray:
        """The reversal profile shape(t) at axis positions t (1 without a profile)."""
        t = np.asarray(t, dtype=float)
        if "position_mm" not in self.config and "shape" not in self.config:
            return np.ones_like(t)
        x = np.asarray(self.config.get("position_mm", ()), dtype=float)
        shape = np.asarray(self.config.get("shape", ()), dtype=float)
        if x.ndim != 1 or len(x) < 2 or shape.shape != x.shape or np.any(np.diff(x) <= 0):
            raise CalibrationError(
                f"effect {self.name}: a reversal profile needs position_mm (2 or more, increasing) "
                f"and shape of the same length; got {len(x)} positions and {shape.size} shape values")
        return np.interp(t, x, shape)

    def basis(self, q, r, ctx) -> np.ndarray:
        d = context_column(ctx, self.needs[0], len(q), self.name)
        return unit_basis(0.5 * d * self.profile(q[:, self.axis]), self.axis)[:, :, None]
