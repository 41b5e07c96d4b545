"""A zero-point shift linear in any other numeric context column (``linear:<column>``).

For context variables without a physical model of their own (humidity, a rotary
table angle, a second temperature sensor...): each axis shifts in proportion to
the column's deviation from its mean over the data (kept in ``config["reference"]``)::

    displacement = (ax, ay, az) * (value - reference)

Compensable for a program run at a known value: ``--context <column>=VALUE``.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import DIR_COLUMNS, ContextLinear

# Context columns with an effect of their own, never offered as linear:<column>.
OWN_COLUMNS = {"t", "load", *DIR_COLUMNS}


class Linear(ContextLinear):
    kind = "linear"
    meaning = "zero-point shift proportional to a context variable"
    param_names_xyz = ("ax_mm_per_unit", "ay_mm_per_unit", "az_mm_per_unit")
    reference_key = "reference"
    describe_head = "shift per unit of"

    @classmethod
    def candidates(cls, columns: list[str]) -> list[str]:
        return [f"linear:{c}" for c in columns if c not in OWN_COLUMNS and not c.startswith("temp")]

    def prepare(self, q, r, ctx, resid) -> Linear:
        return self.copy(config={"reference": float(np.mean(np.asarray(ctx[self.target], dtype=float)))})
