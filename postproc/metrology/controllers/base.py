"""What every controller export returns, and the calibration that stays with the program."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

from postproc.calibration.axis_tables import AXES, COLUMNS


@dataclass
class Export:
    """Files to write (name relative to the output -> text), notes for the user, and
    what the controller now compensates: ``columns`` (axis, column) pairs taken from
    the tables, ``backlash`` axes whose backlash effect the table holds."""

    files: dict[str, str]
    notes: list[str] = field(default_factory=list)
    columns: set[tuple[str, str]] = field(default_factory=set)
    backlash: set[str] = field(default_factory=set)
    #: constant part of a column the table leaves out (axis -> mm; a table zeroed at its
    #: reference point): it stays in the remainder
    offsets: dict[str, float] = field(default_factory=dict)


def remainder_dict(data: dict, export: Export) -> dict:
    """The calibration (as its JSON dict) without what the controller table compensates:
    those columns set to zero and those backlash effects dropped. Correcting programs
    with it while the controller holds the table compensates each error once."""
    out = copy.deepcopy(data)
    tables = out["model"]["tables"]
    for axis, column in export.columns:
        unit = "mm" if COLUMNS.index(column) < 3 else "rad"
        key = f"{column}_{unit}"
        keep = export.offsets.get(axis, 0.0) if column == f"E{axis}" else 0.0
        tables[axis][key] = [keep] * len(tables[axis][key])
    out["effects"] = [e for e in out.get("effects") or []
                      if not (e["name"].startswith("backlash:") and e["name"].split(":")[1] in export.backlash)]
    taken = sorted(f"{c}{a}" for a, c in export.columns) + sorted(f"backlash:{a}" for a in export.backlash)
    out["name"] = f"{data.get('name', 'calibration')}_remainder"
    out.setdefault("fit", {})["remainder_of"] = {"name": data.get("name"), "in_controller": taken}
    return out


def axis_order(axes) -> list[str]:
    return [a for a in AXES if a in axes]
