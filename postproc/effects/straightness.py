"""Higher-order straightness of one axis's motion (bow and S-shape).

Physics: a guideway that is not straight makes the moving axis deviate sideways; the
linear part of that deviation is a squareness/tilt that affine models already hold,
what remains is a bow (quadratic) and an S-shape (cubic). For ``straightness:X`` the
deviations in Y and in Z as functions of X, with ``u`` the position scaled to [-1, 1]
over the travel (``config["center_mm"]``, ``config["half_travel_mm"]``)::

    dy = bow_y * u^2 + s_y * u^3,   dz = bow_z * u^2 + s_z * u^3

Parameters are the deviations at the end of the travel, mm. Compensable from position.
"""

from __future__ import annotations

from typing import Self

import numpy as np

from postproc.effects.base import AXES, AxisEffect
from postproc.errors import CalibrationError

# Fewer distinct positions along the axis than this cannot show a cubic shape beside
# the affine terms of the model.
MIN_DISTINCT_POSITIONS = 5
# Floor of the half travel that scales positions to [-1, 1]: data at one position
# would otherwise give a zero half travel (and a division by zero).
MIN_HALF_TRAVEL_MM = 1e-3


class AxisShape(AxisEffect):
    """Bow (u^2) and S-shape (u^3) along one axis, ``u`` its position scaled to [-1, 1]
    over the travel in ``config``: what straightness and positioning share."""

    def untestable_reason(self, q, r, ctx) -> str | None:
        why = super().untestable_reason(q, r, ctx)  # the context columns it needs, if any
        if why:
            return why
        n = len(np.unique(np.round(np.asarray(q)[:, self.axis], 6)))
        if n < MIN_DISTINCT_POSITIONS:
            return f"only {n} distinct {self.target} positions"
        return None

    def prepare(self, q, r, ctx, resid) -> Self:
        x = np.asarray(q)[:, self.axis]
        lo, hi = float(np.min(x)), float(np.max(x))
        return self.copy(config={"center_mm": 0.5 * (lo + hi), "half_travel_mm": max(0.5 * (hi - lo), MIN_HALF_TRAVEL_MM)})

    def scaled_position(self, q: np.ndarray) -> np.ndarray:
        """The axis position scaled to [-1, 1] over the travel in ``config``."""
        c = float(self.config.get("center_mm", 0.0))
        h = float(self.config.get("half_travel_mm", 1.0))
        if h <= 0:
            raise CalibrationError(f"effect {self.name} has no half_travel_mm > 0 in its config")
        return (q[:, self.axis] - c) / h


class Straightness(AxisShape):
    kind = "straightness"
    meaning = "bow and S-shape of an axis's straightness"

    @property
    def others(self) -> tuple[int, int]:
        a = self.axis
        o1, o2 = (j for j in range(3) if j != a)
        return o1, o2

    @property
    def param_names(self) -> tuple[str, ...]:
        o1, o2 = (AXES[j] for j in self.others)
        return (f"bow_{o1.lower()}_mm", f"s_{o1.lower()}_mm", f"bow_{o2.lower()}_mm", f"s_{o2.lower()}_mm")

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        parts = []
        for j in self.others:
            a = AXES[j].lower()
            parts.append(f"in {a.upper()}: bow {p[f'bow_{a}_mm'] * 1000:+.2f} um, "
                         f"S {p[f's_{a}_mm'] * 1000:+.2f} um")
        return f"straightness of {self.target} (at end of travel) " + "; ".join(parts)

    def basis(self, q, r, ctx) -> np.ndarray:
        u = self.scaled_position(q)
        B = np.zeros((len(q), 3, 4))
        o1, o2 = self.others
        B[:, o1, 0], B[:, o1, 1] = u**2, u**3
        B[:, o2, 2], B[:, o2, 3] = u**2, u**3
        return B


class Positioning(AxisShape):
    """Non-linear positioning error of one axis (``positioning:X``): bow and S-shape of
    the error along the axis itself (the linear part is the scale, held by affine
    models). A screw or scale with a progressive pitch error, or a thermal gradient
    along it::

        d_axis = bow * u^2 + s * u^3      u = position scaled to [-1, 1] over the travel
    """

    kind = "positioning"
    meaning = "non-linear positioning error along an axis (bow and S-shape)"

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("bow_mm", "s_mm")

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return (f"positioning error of {self.target} (at end of travel): bow {p['bow_mm'] * 1000:+.2f} um, "
                f"S {p['s_mm'] * 1000:+.2f} um")

    def basis(self, q, r, ctx) -> np.ndarray:
        u = self.scaled_position(q)
        B = np.zeros((len(q), 3, 2))
        B[:, self.axis, 0], B[:, self.axis, 1] = u**2, u**3
        return B
