"""Static load deflection: the zero point migrates with the load on the table.

Physics: a heavy workpiece bends the table, the bed and the guides, so the tool
point relative to the work moves in proportion to the load (a spring)::

    displacement = (cx, cy, cz) * load            c in mm per unit of load

Needs the ``load`` column (no load = 0). Compensable for a program run with a known
load: ``--context load=VALUE``.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import Effect, context_column


class Load(Effect):
    kind = "load"
    meaning = "static deflection: zero-point migration proportional to the table load"

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.target,)

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("cx_mm_per_unit", "cy_mm_per_unit", "cz_mm_per_unit")

    @property
    def compensable_reason(self) -> str:
        return f"compensated at the load given as --context {self.target}=VALUE"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return (f"deflection per unit of {self.target} "
                + " ".join(f"{a} {p[k] * 1000:+.3f} um" for a, k in zip("XYZ", self.param_names, strict=True)))

    def basis(self, q, r, ctx) -> np.ndarray:
        w = context_column(ctx, self.target, len(q), self.name)
        return np.einsum("n,jk->njk", w, np.eye(3))
