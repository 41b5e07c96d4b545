"""Tool-vector (Abbe) dependence: angular errors missing from the model acting through r.

Physics: an angular error ``omega`` of the spindle or carriage moves the tool point by
``omega x r``; a model fitted with one tool length cannot tell it from a translation,
so it shows only when the data hold varied tool vectors (lengths and offsets).

``abbe:tilt``: a constant angle (a tilted spindle): displacement = (wx, wy, wz) x r.
``abbe:X`` (``Y``, ``Z``): an angular error of that axis growing linearly with its
position: displacement = (q_axis * (wx, wy, wz)) x r, rates in rad per mm.

Needs varied tool vectors. Compensable: the program's tool vector is known.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AXES, Effect

# Tool vectors spread less than this (mm, max - min of any component) cannot separate
# an angle acting through r from a translation: 1 urad over 10 mm is 0.01 um.
MIN_TOOL_SPREAD_MM = 10.0


class Abbe(Effect):
    kind = "abbe"
    targets = ("tilt", *AXES)
    meaning = "angular error acting through the tool vector (Abbe offset)"

    @property
    def param_names(self) -> tuple[str, ...]:
        if self.target == "tilt":
            return ("wx_rad", "wy_rad", "wz_rad")
        return tuple(f"w{c}_rad_per_mm" for c in "xyz")

    @property
    def compensable_reason(self) -> str:
        return "compensated from the program's tool vector"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        if self.target == "tilt":
            return "tool-vector tilt " + " ".join(f"{k[1]} {v * 1e6:+.2f} urad" for k, v in p.items())
        return (f"angle of {self.target} growing with {self.target}, through the tool vector "
                + " ".join(f"{k[1]} {v * 1e8:+.2f} urad/100mm" for k, v in p.items()))

    def untestable_reason(self, q, r, ctx) -> str | None:
        spread = float(np.max(np.ptp(np.asarray(r), axis=0))) if len(r) else 0.0
        if spread < MIN_TOOL_SPREAD_MM:
            return f"tool vectors vary by only {spread:.1f} mm (measure with several tool lengths/offsets)"
        return None

    def basis(self, q, r, ctx) -> np.ndarray:
        scale = np.ones(len(q)) if self.target == "tilt" else q[:, AXES.index(self.target)]
        cols = []
        for k in range(3):
            ek = np.zeros(3)
            ek[k] = 1.0
            cols.append(scale[:, None] * np.cross(ek[None, :], r))
        return np.stack(cols, axis=2)
