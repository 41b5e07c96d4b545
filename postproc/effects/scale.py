"""Linear positioning (scale) error of one axis, when the base model lacks it.

Physics: a scale or screw that is longer or shorter than nominal (or at another
temperature than its reference) makes the positioning error grow linearly with the
position from the axis zero::

    displacement along the axis = s * q_axis          s in mm/mm (reported in ppm)

The static, interval and grid models already hold it. Compensable from position.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AxisEffect, unit_basis


class Scale(AxisEffect):
    kind = "scale"
    meaning = "linear positioning (scale) error of an axis"

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("scale",)

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return f"scale error of {self.target}: {p['scale'] * 1e6:+.2f} ppm"

    def basis(self, q, r, ctx) -> np.ndarray:
        return unit_basis(q[:, self.axis], self.axis)[:, :, None]
