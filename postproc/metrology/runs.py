"""Interferometer runs for ISO 230-2 (formats.md section 3): reading and writing.

One row per measurement: ``axis,target,run,direction,deviation``; ``target`` is the
commanded target position P_i, ``direction`` ``+`` or ``-`` (the direction in which
the axis approached the target), ``deviation`` x_ij = measured - target. Positions are
in the ``length`` unit, deviations in the ``error`` unit (default: ``length``).
Optional ``t`` (s) orders the measurements in time; without it the file's row order
is *not* taken as the visiting order (exporters sort rows by target or by run).
Optional ``temp`` (any name starting ``temp``: the air) and ``material_temp`` (the
machine or its scale), in °C, are kept for the ISO 230-2 §4.2 report.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.calibration.csvfile import (
    CsvTable,
    check_position_span,
    error_scale,
    format_csv,
    length_scale,
    read_csv,
)
from postproc.errors import MeasurementError

MAGIC = "postproc iso230 runs v1"
REQUIRED = ("axis", "target", "run", "direction", "deviation")
DIRECTIONS = {"+": 1, "-": -1}


@dataclass
class Runs:
    """Measurements of one file: arrays of equal length, lengths in mm.

    ``direction`` is +1 (approached moving in +) or -1; ``order`` is the time order of
    the rows (``t`` when given, else the file's row order); ``timed``: whether ``order``
    comes from a ``t`` column; ``linenos`` the file lines; ``env``: the temperature
    columns (°C) by name (``temp...``, ``material_temp``).
    """

    axis: np.ndarray  # (N,) str
    target_mm: np.ndarray
    run: np.ndarray  # (N,) int
    direction: np.ndarray  # (N,) int, +1 / -1
    deviation_mm: np.ndarray
    order: np.ndarray
    linenos: np.ndarray
    path: str = ""
    timed: bool = False
    env: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.target_mm)

    @property
    def axes(self) -> list[str]:
        """Axis names in the order they first appear."""
        seen: list[str] = []
        for a in self.axis:
            if a not in seen:
                seen.append(str(a))
        return seen

    def select(self, axis: str) -> Runs:
        return self.subset(self.axis == axis)

    def subset(self, mask) -> Runs:
        """The rows where ``mask`` is True (a boolean array over the rows)."""
        m = np.asarray(mask, dtype=bool)
        return Runs(self.axis[m], self.target_mm[m], self.run[m], self.direction[m], self.deviation_mm[m],
                    self.order[m], self.linenos[m], self.path, self.timed, {k: v[m] for k, v in self.env.items()})


def runs_from_table(table: CsvTable) -> Runs:
    table.require_rows("measurement rows", "give one measurement per row: axis,target,run,direction,deviation")
    for name in REQUIRED:
        if name not in table.header:
            raise MeasurementError(
                f"required column {name!r} is missing (header: {','.join(table.header)})",
                path=table.path, lineno=table.header_lineno, col=1,
                hint="interferometer runs need the columns axis,target,run,direction,deviation "
                     "(formats.md section 3)",
            )
    lscale, escale = length_scale(table), error_scale(table)
    target = table.numeric("target") * lscale
    deviation = table.numeric("deviation") * escale
    run_f = table.numeric("run")
    jrun, jdir, jaxis = (table.header.index(c) for c in ("run", "direction", "axis"))
    axes, dirs = [], []
    for i, row in enumerate(table.rows):
        lineno = table.linenos[i]
        if run_f[i] != int(run_f[i]) or run_f[i] < 1:
            raise MeasurementError(f"run {row[jrun].strip()!r} is not a run number (1, 2, 3 ...)",
                                   col=table.col_starts[i][jrun], path=table.path, lineno=lineno)
        d = row[jdir].strip()
        if d not in DIRECTIONS:
            raise MeasurementError(f"direction {d!r} is not '+' or '-'", col=table.col_starts[i][jdir],
                                   hint="'+': the axis approached the target moving in +; '-': moving in -",
                                   path=table.path, lineno=lineno)
        a = row[jaxis].strip()
        if not a:
            raise MeasurementError("empty axis name", col=table.col_starts[i][jaxis], path=table.path, lineno=lineno)
        axes.append(a)
        dirs.append(DIRECTIONS[d])
    for a in dict.fromkeys(axes):
        check_position_span(table, target[np.array(axes) == a], f"axis {a}: targets")
    order = table.numeric("t") if table.has("t") else np.arange(len(table.rows), dtype=float)
    env = {name: table.numeric(name) for name in table.header if name.startswith("temp") or name == "material_temp"}
    runs = Runs(np.array(axes), target, run_f.astype(int), np.array(dirs), deviation, order,
                np.asarray(table.linenos), table.path, table.has("t"), env)
    _refuse_repeats(runs)
    return runs


def _refuse_repeats(runs: Runs) -> None:
    """One row per (axis, target, run, direction): a repeat is an error naming both lines."""
    seen: dict[tuple, int] = {}
    for k in range(len(runs)):
        key = (runs.axis[k], runs.target_mm[k], runs.run[k], runs.direction[k])
        if key in seen:
            sign = "+" if runs.direction[k] > 0 else "-"
            raise MeasurementError(
                f"axis {runs.axis[k]}, target {runs.target_mm[k]:g} mm, run {runs.run[k]} ({sign}) "
                f"is given twice (first on line {seen[key]})",
                path=runs.path, lineno=int(runs.linenos[k]), col=1,
                hint="give each run's measurement at a target once; number repeated runs 1, 2, 3 ...",
            )
        seen[key] = int(runs.linenos[k])


def read_runs(path) -> Runs:
    """Read an ISO 230-2 runs file (formats.md section 3), lengths in mm."""
    return runs_from_table(read_csv(path))


def format_runs(runs: Runs, *, error_unit: str = "um", decimals: int = 4,
                comments: list[str] | None = None) -> str:
    """Render runs in the formats.md form: positions in mm, deviations in ``error_unit``."""
    scale = {"mm": 1.0, "um": 1e3}[error_unit]

    def num(v: float, places: int) -> str:
        s = f"{v:.{places}f}"
        return s[1:] if s.startswith("-") and float(s) == 0 else s

    rows = [[str(runs.axis[k]), num(runs.target_mm[k], 4), str(int(runs.run[k])),
             "+" if runs.direction[k] > 0 else "-", num(runs.deviation_mm[k] * scale, decimals)]
            for k in range(len(runs))]
    meta = [MAGIC, f"units: length=mm error={error_unit}", *(comments or [])]
    return format_csv(meta, list(REQUIRED), rows)
