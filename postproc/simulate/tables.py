"""Simulated laser-interferometer axis error tables on a virtual machine.

Each axis is measured alone, the other two at the low corner of the volume, moving in
the + direction. The six error motions at each position are the machine's own
(they are the truth the interferometer sees) plus, in the three linear columns, what
the machine's physical effects displace along that line (relative to the start of
the run), plus the instrument noise. Squareness is the machine's plus noise.
The tables are referred to the ideal (tracker) frame: they are not re-zeroed at the
first position, so a fit on them keeps the machine's origin offset.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.axis_tables import AXES, AxisTables, Squareness
from postproc.simulate.machine import Machine
from postproc.simulate.points import SimulationError, check_rows

# The last position of a table run is kept when the step falls short of the end of
# travel by less than this (text round-off of the volume).
_END_SLACK_MM = 1e-9


def table_positions(lo: float, hi: float, step_mm: float) -> np.ndarray:
    """Positions from ``lo`` every ``step_mm``, ending exactly at ``hi``."""
    if step_mm <= 0:
        raise SimulationError(f"table step must be positive, got {step_mm}",
                              hint="give --step in mm, e.g. --step 5")
    with np.errstate(over="ignore"):  # a step of 1e-320 mm: inf positions, refused below
        n = np.floor((hi - lo) / step_mm + _END_SLACK_MM)
    check_rows(float(n) + 1, f"a table step of {step_mm:g} mm", "give a larger --step")
    n = int(n)
    s = lo + step_mm * np.arange(n + 1)
    if hi - s[-1] > _END_SLACK_MM:
        s = np.append(s, hi)
    return s


def simulate_tables(machine: Machine, step_mm: float, rng: np.random.Generator | None = None,
                    *, noise: bool = True, context: dict | None = None
                    ) -> tuple[AxisTables, Squareness]:
    """Axis error tables (per axis, every ``step_mm``) and squareness as measured."""
    rng = rng if rng is not None else np.random.default_rng(0)
    vol = machine.volume_mm
    geo = machine.geometry
    pos, err = {}, {}
    for j, axis in enumerate(AXES):
        s = table_positions(vol[0, j], vol[1, j], step_mm)
        values = geo.tables.at(axis, s) if axis in geo.tables.axes else np.zeros((len(s), 6))
        if machine.effects:
            q = np.tile(vol[0], (len(s), 1))
            q[:, j] = s
            ctx = {"dirx": 1.0, "diry": 1.0, "dirz": 1.0, **(context or {})}
            ctx = {k: np.full(len(s), float(v)) for k, v in ctx.items()}
            moved = machine.model.forward(q, None, ctx) - geo.forward(q, None, ctx)
            values[:, :3] += moved - moved[0]
        if noise:
            n = machine.noise
            values[:, :3] += rng.normal(0.0, n.interferometer_length_mm, (len(s), 3))
            values[:, 3:] += rng.normal(0.0, n.interferometer_angle_rad, (len(s), 3))
        pos[axis], err[axis] = s, values
    squareness = geo.squareness.as_dict()
    if noise:
        for k in squareness:
            squareness[k] += float(rng.normal(0.0, machine.noise.squareness_rad))
    return AxisTables(pos, err), Squareness.from_mapping(squareness)
