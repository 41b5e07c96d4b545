"""Control-point experiments on a virtual machine (seed 000, Tables 1 and 5).

For each target point ``p*`` the machine is commanded uncorrected (``q = p* - r``) and
with each calibration (``q = inverse(p*)``); a simulated tracker measures where the
functional point went, averaging its shots, and ``Delta = |measured - p*|``. The
report gives Delta per point and calibration, the sum over the points and the
improvement of each calibration over the uncorrected sum, in percent.

Control points file: a CSV with a header row naming at least ``X,Y,Z`` (the target
positions of the functional point, mm), optionally ``tx,ty,tz`` (the tool or reflector
vector for that point); ``#`` comment lines before the header and
``# units: length=um`` are allowed. A formats.md measurement file works too: its
commanded ``X,Y,Z`` are taken as the targets.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.calibration.csvfile import length_scale, read_csv
from postproc.engine.base import Engine, check_points, check_tool_vectors
from postproc.errors import SolverError
from postproc.simulate.machine import Machine

# A calibration whose inverse misses its own model's target by more than this gets a
# note: the experiment then measures the solver (e.g. an approximate astatic law) too.
INVERSE_RESIDUAL_NOTE_MM = 1e-4
# Coordinates of control points within this of a whole mm are printed as whole mm
# (the Table 1 labels "230/230/230"); others with three decimals.
WHOLE_MM_LABEL_TOL = 5e-4


@dataclass
class ControlPoints:
    targets: np.ndarray
    tool: np.ndarray | None = None
    path: str = ""


def read_control_points(path) -> ControlPoints:
    """Targets (N, 3) and optional per-point tool vectors from a control-points CSV."""
    table = read_csv(path)
    table.require_rows("control points", "give one X,Y,Z target per row after the header")
    scale = length_scale(table)
    targets = np.column_stack([table.numeric(c) for c in ("X", "Y", "Z")]) * scale
    tool = None
    if any(table.has(c) for c in ("tx", "ty", "tz")):
        tool = np.column_stack([table.numeric(c, default=0.0) for c in ("tx", "ty", "tz")]) * scale
    return ControlPoints(targets, tool, table.path)


@dataclass
class ControlReport:
    """Delta (mm) per target for the uncorrected machine and for each calibration."""

    targets: np.ndarray
    tool: np.ndarray
    names: list[str]
    deltas: dict[str, np.ndarray]
    shots: int = 1
    sigma_mm: float = 0.0
    notes: list[str] = field(default_factory=list)

    UNCORRECTED = "uncorrected"

    def total(self, name: str) -> float:
        return float(np.sum(self.deltas[name]))

    def improvement_pct(self, name: str) -> float:
        base = self.total(self.UNCORRECTED)
        return 100.0 * (base - self.total(name)) / base if base > 0 else 0.0

    def to_dict(self) -> dict:
        return {
            "targets_mm": self.targets.tolist(),
            "tool_mm": self.tool.tolist(),
            "shots_per_point": self.shots,
            "tracker_sigma_mm": self.sigma_mm,
            "columns": [self.UNCORRECTED, *self.names],
            "delta_mm": {k: v.tolist() for k, v in self.deltas.items()},
            "sum_mm": {k: self.total(k) for k in self.deltas},
            "improvement_pct": {k: self.improvement_pct(k) for k in self.names},
        }


def measure_averaged(machine: Machine, q, r, ctx, rng: np.random.Generator | None, shots: int,
                     noise: bool = True) -> np.ndarray:
    """Where the machine puts the point, as a tracker averaging ``shots`` shots sees it."""
    p = machine.forward(q, r, ctx)
    if noise and machine.noise.tracker_mm > 0 and shots > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        p = p + rng.normal(0.0, machine.noise.tracker_mm, (shots, *p.shape)).mean(axis=0)
    return p


def control_experiment(machine: Machine, targets, calibrations: list[tuple[str, Engine]], r=None,
                       context: dict | None = None, rng: np.random.Generator | None = None, *,
                       shots: int = 12, noise: bool = True) -> ControlReport:
    """Run the targets uncorrected and with each calibration; Delta per point (mm)."""
    p = check_points(targets, "targets")
    rr = check_tool_vectors(r, len(p))
    ctx = {"dirx": 1.0, "diry": 1.0, "dirz": 1.0, **(context or {})}
    ctx = {k: np.broadcast_to(np.asarray(v, dtype=float), (len(p),)).copy() for k, v in ctx.items()}
    rng = rng if rng is not None else np.random.default_rng(0)
    # The tracker's averaged noise at each control point is drawn once and shared by every
    # column (common random numbers): a calibration's Delta then depends neither on which
    # other calibrations are compared nor on their order, only on the machine and itself.
    tracker = measure_averaged(machine, p - rr, rr, ctx, rng, shots, noise) - machine.forward(p - rr, rr, ctx)
    deltas = {}
    measured = machine.forward(p - rr, rr, ctx) + tracker
    deltas[ControlReport.UNCORRECTED] = np.linalg.norm(measured - p, axis=1)
    names, notes = [], []
    for name, engine in calibrations:
        res = engine.inverse(p, rr, ctx)
        if not np.all(np.isfinite(res.q)):
            raise SolverError(f"calibration {name}: its inverse gave no finite position",
                              hint="are the control points inside the calibrated volume?")
        worst = float(np.max(res.residual_mm))
        if not np.isfinite(worst) or worst > INVERSE_RESIDUAL_NOTE_MM:
            notes.append(f"{name}: its inverse misses its own model's target by up to {worst * 1000:.1f} um")
        outside = int(np.count_nonzero(~engine.inside(res.q)))
        if outside:
            notes.append(f"{name}: {outside} point(s) outside its calibrated volume")
        measured = machine.forward(res.q, rr, ctx) + tracker
        key = name
        while key in deltas:
            key += "'"
        deltas[key] = np.linalg.norm(measured - p, axis=1)
        names.append(key)
    return ControlReport(p, rr, names, deltas, shots if noise else 0,
                         machine.noise.tracker_mm if noise else 0.0, notes)


def _coord(v: float) -> str:
    return f"{v:.0f}" if abs(v - round(v)) < WHOLE_MM_LABEL_TOL else f"{v:.3f}"


def format_control_report(report: ControlReport) -> str:
    """Text table in the layout of seed 000's Tables 1 and 5 (mm, 3 decimals)."""
    cols = [report.UNCORRECTED, *report.names]
    labels = ["x_d/y_d/z_d"] + [f"D {c}" for c in cols]
    rows = []
    for i, t in enumerate(report.targets):
        rows.append(["/".join(_coord(v) for v in t)] + [f"{report.deltas[c][i]:.3f}" for c in cols])
    rows.append(["Sum D"] + [f"{report.total(c):.3f}" for c in cols])
    rows.append(["improvement"] + ["-"] + [f"{report.improvement_pct(c):.1f} %" for c in report.names])
    widths = [max(len(r[k]) for r in [labels, *rows]) for k in range(len(labels))]
    lines = ["  ".join(s.rjust(w) if k else s.ljust(w) for k, (s, w) in enumerate(zip(r, widths, strict=True)))
             for r in [labels, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.insert(len(lines) - 2, "  ".join("-" * w for w in widths))
    return "\n".join(lines) + "\n"
