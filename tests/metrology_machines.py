"""Virtual machines and runs files for the metrology tests (outliers, controller
tables, ISO 230-2): the data comes from postproc.simulate, never from the formulas
under test."""

from __future__ import annotations

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS
from postproc.metrology.runs import format_runs
from postproc.simulate.machine import Machine, MachineGeometry, Noise, tables_from_dict
from postproc.simulate.runs import simulate_runs

#: ISO 230-2-style unevenly spaced targets over 0..315 mm (the s500's X travel).
TARGETS = (0.0, 31.4, 62.9, 97.3, 129.6, 162.2, 189.8, 221.3, 252.7, 286.1, 315.0)


def x_machine(reversal_mm: float = 0.008, noise_mm: float = 0.0004, lo: float = 0.0, hi: float = 315.0) -> Machine:
    """A machine whose X axis has a lead error (wave + slope) and a reversal that grows along X."""
    s = np.linspace(lo, hi, 64)
    tables = {}
    for a in AXES:
        pos = s if a == "X" else np.array([-1000.0, 1000.0])
        cols = {c: np.zeros(len(pos)) for c in COLUMNS}
        if a == "X":
            cols["EX"] = 0.012 * np.sin((s - lo) / 70.0) + 2e-5 * (s - lo)
        tables[a] = {"position": pos.tolist(), **{c: v.tolist() for c, v in cols.items()}}
    vol = [[lo, 0.0, -400.0], [hi, 400.0, 0.0]]
    geo = MachineGeometry(tables_from_dict(tables), {}, vol)
    prof = np.linspace(lo, hi, 5)
    effects = [{"name": "backlash:X", "config": {"position_mm": prof.tolist(),
                                                  "shape": np.linspace(1.0, 1.5, 5).tolist()},
                "params": {"b_mm": reversal_mm}}] if reversal_mm else []
    return Machine(geometry=geo, effects=effects, noise=Noise(interferometer_length_mm=noise_mm))


def write_runs(path, machine: Machine, *, targets=TARGETS, seed: int = 1, glitches=None, error_unit="um",
               **kw) -> tuple:
    runs = simulate_runs(machine, "X", targets, rng=np.random.default_rng(seed), glitches=glitches, **kw)
    path.write_text(format_runs(runs, error_unit=error_unit))
    return path, runs
