"""Out-of-squareness between two axes, when the base model lacks it.

In the formats.md convention (ISO 230-1 names)::

    squareness:XY  (EC0Y, Y to X about z): displacement = (-EC0Y * Y, 0, 0)
    squareness:XZ  (EB0Z, Z to X about y): displacement = (+EB0Z * Z, 0, 0)
    squareness:YZ  (EA0Z, Z to Y about x): displacement = (0, -EA0Z * Z, 0)

The static and interval models already hold squareness (their G is a full matrix);
this effect is for models that do not (identity, parametric tables without a
squareness file). Compensable from the commanded position.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import Effect

# pair -> (parameter name, moving axis index, displaced component, sign)
PAIRS = {"XY": ("EC0Y_rad", 1, 0, -1.0), "XZ": ("EB0Z_rad", 2, 0, 1.0), "YZ": ("EA0Z_rad", 2, 1, -1.0)}


class Squareness(Effect):
    kind = "squareness"
    targets = tuple(PAIRS)
    meaning = "out-of-squareness of two axes"

    @property
    def param_names(self) -> tuple[str, ...]:
        return (PAIRS[self.target][0],)

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        name = self.param_names[0]
        return f"out-of-squareness {self.target} ({name[:4]}): {p[name] * 1e6:+.1f} urad"

    def basis(self, q, r, ctx) -> np.ndarray:
        _, src, comp, sign = PAIRS[self.target]
        B = np.zeros((len(q), 3, 1))
        B[:, comp, 0] = sign * q[:, src]
        return B
