"""Static load deflection: the zero point migrates with the load on the table.

Physics: a heavy workpiece bends the table, the bed and the guides, so the tool
point relative to the work moves in proportion to the load (a spring)::

    displacement = (cx, cy, cz) * load            c in mm per unit of load

Needs the ``load`` column (no load = 0). Compensable for a program run with a known
load: ``--context load=VALUE``.
"""

from __future__ import annotations

from postproc.effects.base import ContextLinear


class Load(ContextLinear):
    kind = "load"
    meaning = "static deflection: zero-point migration proportional to the table load"
    param_names_xyz = ("cx_mm_per_unit", "cy_mm_per_unit", "cz_mm_per_unit")
    given_as = ("the load", "VALUE")
    describe_head = "deflection per unit of"

    @classmethod
    def candidates(cls, columns: list[str]) -> list[str]:
        return ["load:load"]
