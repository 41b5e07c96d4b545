"""Deflection growing with the load and with an axis position (``loadpos:X``).

Physics: a load bends a beam whose free length changes with an axis: a ram or a
quill carrying a heavy head sags more the further it is extended, a table under a
heavy workpiece more the further the work sits from the column. The deflection is
proportional to the load (a spring) and a smooth function of the position along the
axis: a cantilever's tip sags with the cube of its free length, which over the travel
is a linear term, a bow and a small remainder. For ``loadpos:Y``, with ``u`` the Y
position scaled to [-1, 1] over the travel (``config["center_mm"]``,
``config["half_travel_mm"]``) and ``L`` the ``load`` column::

    d_j = L * (a_j * u + b_j * u^2)          j = x, y, z

The part that does not grow with the position (a constant per unit load) is
``load:load``'s; the shape that does not grow with the load is the axis's own
straightness. Parameters are the deflections per unit of load at the end of the travel
(mm per unit). Compensable for a program run with a known load: ``--context load=VALUE``.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import AXES, context_column
from postproc.effects.straightness import AxisShape

#: the context column of the load
LOAD_COLUMN = "load"


class LoadPosition(AxisShape):
    """A load times the shape of :class:`AxisShape`'s scaled position (its travel
    and testability are that class's)."""

    kind = "loadpos"
    meaning = "deflection growing with the load times the position along an axis (a beam bending under the load)"

    @classmethod
    def candidates(cls, columns: list[str]) -> list[str]:
        # only on data with a load column (load:load already reports its absence)
        return [f"{cls.kind}:{a}" for a in AXES] if LOAD_COLUMN in columns else []

    @property
    def needs(self) -> tuple[str, ...]:
        return (LOAD_COLUMN,)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(f"{k}{c}_mm_per_unit" for c in "xyz" for k in ("lin_", "bow_"))

    @property
    def compensable_reason(self) -> str:
        return f"compensated at the load given as --context {LOAD_COLUMN}=VALUE"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        parts = [f"{c}: linear {p[f'lin_{c}_mm_per_unit'] * 1000:+.3g} um, bow {p[f'bow_{c}_mm_per_unit'] * 1000:+.3g} um"
                 for c in "xyz"]
        return f"deflection per unit of load growing with {self.target} (at the end of travel) " + "; ".join(parts)

    def basis(self, q, r, ctx) -> np.ndarray:
        u = self.scaled_position(q)
        load = context_column(ctx, LOAD_COLUMN, len(q), self.name)
        B = np.zeros((len(q), 3, 6))
        for j in range(3):
            B[:, j, 2 * j] = load * u
            B[:, j, 2 * j + 1] = load * u**2
        return B
