"""Backlash (lost motion) of one axis.

Physics: the nut, couplings and guides of an axis leave a gap; the axis stops short
of the commanded position by half the gap, on the side it came from. With ``dir`` the
direction the axis approached the point (+1 / -1, 0 when it did not move)::

    displacement along the axis = b / 2 * dir

``b`` (``b_mm``) is the reversal error that a bidirectional ISO 230-2 test reads.
Needs ``dirx`` / ``diry`` / ``dirz``. Compensable: the correction pipeline knows the
direction of every move of the program.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AXES, DIR_COLUMNS, Effect, context_column, unit_basis

# Fewer rows than this approached from either side cannot show a reversal: the mean on
# that side would rest on one or two noisy shots.
MIN_ROWS_PER_SIDE = 3


class Backlash(Effect):
    kind = "backlash"
    meaning = "lost motion at reversal: the axis lags by b/2 against its approach direction"

    @property
    def axis(self) -> int:
        return AXES.index(self.target)

    @property
    def needs(self) -> tuple[str, ...]:
        return (DIR_COLUMNS[self.axis],)

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("b_mm",)

    @property
    def compensable_reason(self) -> str:
        return f"compensated from the direction of each {self.target} move in the program"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return f"reversal (backlash) of {self.target}: {p['b_mm'] * 1000:+.2f} um"

    def untestable_reason(self, q, r, ctx) -> str | None:
        if self.missing(ctx):
            return super().untestable_reason(q, r, ctx)
        d = np.asarray(ctx[self.needs[0]], dtype=float)
        plus, minus = int(np.sum(d > 0)), int(np.sum(d < 0))
        if 0 < min(plus, minus) < MIN_ROWS_PER_SIDE:
            return (f"{self.target} was approached {plus} times from + and {minus} from -: "
                    f"a reversal needs {MIN_ROWS_PER_SIDE}+ each (approach the points from both sides)")
        return super().untestable_reason(q, r, ctx)

    def basis(self, q, r, ctx) -> np.ndarray:
        d = context_column(ctx, self.needs[0], len(q), self.name)
        return unit_basis(0.5 * d, self.axis)[:, :, None]
