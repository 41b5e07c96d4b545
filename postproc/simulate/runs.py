"""Simulated ISO 230-2 interferometer runs on a virtual machine (formats.md section 3).

One axis is run alone, the other two at the low corner of the volume (or at ``at``),
along ISO 230-2's linear cycle: in each run the axis visits the targets moving in +
(increasing), then comes back moving in - (decreasing). The deviation of a reading is
where the machine really puts the functional point along the axis, minus the target,
approached in that direction (the machine's effects see ``dir<axis>`` = +1 or -1), plus
the instrument's length noise. ``glitches`` adds a gross error to chosen readings (a
beam interruption, a misread fringe count): the test data of the outlier rule.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.axis_tables import AXES
from postproc.metrology.runs import Runs
from postproc.simulate.machine import Machine


def simulate_runs(machine: Machine, axis: str, targets, *, n_runs: int = 5, rng: np.random.Generator | None = None,
                  noise_mm: float | None = None, at=None, glitches: dict | None = None,
                  directions=(1, -1)) -> Runs:
    """Runs of ``axis`` over ``targets`` (mm): ``n_runs`` runs per direction in ``directions``.

    ``noise_mm``: one standard deviation per reading (default: the machine's
    ``interferometer_length_mm``). ``glitches``: {(target index, run, direction): mm}
    added to those readings. Rows are in visiting order; ``linenos`` count from the
    first row of a file written by :func:`postproc.metrology.runs.format_runs`
    (three comment and header lines, so the first row is line 4).
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    k = AXES.index(axis)
    t = np.asarray(targets, dtype=float)
    sigma = machine.noise.interferometer_length_mm if noise_mm is None else noise_mm
    base = np.asarray(at if at is not None else machine.volume_mm[0], dtype=float)
    rows = []
    for run in range(1, n_runs + 1):
        for d in directions:
            order = range(len(t)) if d > 0 else reversed(range(len(t)))
            for i in order:
                rows.append((i, run, d))
    idx = np.array([r[0] for r in rows])
    q = np.tile(base, (len(rows), 1))
    q[:, k] = t[idx]
    dirs = np.array([r[2] for r in rows], dtype=float)
    ctx = {f"dir{a.lower()}": (dirs if a == axis else np.zeros(len(rows))) for a in AXES}
    p = machine.forward(q, None, ctx)
    dev = p[:, k] - q[:, k] + rng.normal(0.0, sigma, len(rows))
    for (i, run, d), extra in (glitches or {}).items():
        hit = [n for n, r in enumerate(rows) if r == (i, run, d)]
        dev[hit] += extra
    n = len(rows)
    return Runs(np.array([axis] * n), t[idx], np.array([r[1] for r in rows]), dirs.astype(int), dev,
                np.arange(n, dtype=float), np.arange(4, 4 + n))
