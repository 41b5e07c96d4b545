"""A zero-point shift linear in any other numeric context column (``linear:<column>``).

For context variables without a physical model of their own (humidity, a rotary
table angle, a second temperature sensor...): each axis shifts in proportion to
the column's deviation from its mean over the data (kept in ``config["reference"]``)::

    displacement = (ax, ay, az) * (value - reference)

Compensable for a program run at a known value: ``--context <column>=VALUE``.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import Effect, context_column


class Linear(Effect):
    kind = "linear"
    meaning = "zero-point shift proportional to a context variable"

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.target,)

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("ax_mm_per_unit", "ay_mm_per_unit", "az_mm_per_unit")

    @property
    def compensable_reason(self) -> str:
        return f"compensated at the value given as --context {self.target}=VALUE"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return (f"shift per unit of {self.target} "
                + " ".join(f"{a} {p[k] * 1000:+.3f} um" for a, k in zip("XYZ", self.param_names, strict=True)))

    def basis(self, q, r, ctx) -> np.ndarray:
        v = context_column(ctx, self.target, len(q), self.name)
        ref = float(self.config.get("reference", 0.0))
        return np.einsum("n,jk->njk", v - ref, np.eye(3))

    def prepare(self, q, r, ctx, resid) -> Linear:
        return self.copy(config={"reference": float(np.mean(np.asarray(ctx[self.target], dtype=float)))})
