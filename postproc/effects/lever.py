"""Cross-axis lever-arm coupling (``lever:AB``).

Physics: an angular error motion of axis A (pitch, yaw, roll) that grows linearly
with A's position tilts everything carried over axis B's travel, so the error grows
with the product of the two positions (an Abbe offset made by the other axis)::

    omega(qA) = qA * (wx, wy, wz)          (rad)
    displacement = omega(qA) x (qB e_B)    only the two components of omega not about B act

``lever:XZ`` is e.g. a pitch of X that grows with X, times the Z position. The
parameters are the rates of the angular error, rad per mm of A travel. Compensable
from the commanded position.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AXES, Effect

ROT_NAMES = ("EA", "EB", "EC")  # rotation about x, y, z (ISO 230-1)
#: every ordered pair of two axes: XY, XZ, YX ...
PAIRS = tuple(a + b for a in AXES for b in AXES if a != b)


class Lever(Effect):
    kind = "lever"
    targets = PAIRS
    meaning = "angular error of one axis growing with its travel, acting over another axis's travel"

    @property
    def a(self) -> int:
        return AXES.index(self.target[0])

    @property
    def b(self) -> int:
        return AXES.index(self.target[1])

    @property
    def rotations(self) -> tuple[int, int]:
        k1, k2 = (k for k in range(3) if k != self.b)
        return k1, k2

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(f"{ROT_NAMES[k]}{self.target[0]}_rad_per_mm" for k in self.rotations)

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        parts = [f"{k[:3]} {v * 1e6 * 100:+.2f} urad per 100 mm" for k, v in p.items()]
        return f"angle of {self.target[0]} growing with {self.target[0]}, over the {self.target[1]} travel: " + ", ".join(parts)

    def basis(self, q, r, ctx) -> np.ndarray:
        eb = np.zeros(3)
        eb[self.b] = 1.0
        lever = q[:, self.a] * q[:, self.b]
        cols = []
        for k in self.rotations:
            ek = np.zeros(3)
            ek[k] = 1.0
            cols.append(lever[:, None] * np.cross(ek, eb)[None, :])
        return np.stack(cols, axis=2)
