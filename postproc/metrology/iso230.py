"""ISO 230-2:2014 evaluation of bidirectional positioning runs of one numerically
controlled axis.

For target P_i (i = 1..m), run j (1..n) and approach direction up (moving in +) or
down (moving in -), x_ij is the positional deviation (measured - target). Clause 2 of
the standard defines, per target::

    mean unidirectional positional deviation   xm_up_i = (1/n) sum_j x_ij_up      (likewise down)
    reversal value                             B_i = xm_up_i - xm_down_i
    estimator of the unidirectional
    axis repeatability                          s_up_i = sqrt(sum_j (x_ij_up - xm_up_i)^2 / (n - 1))
    unidirectional repeatability                R_up_i = 4 s_up_i                  (likewise down)
    bidirectional repeatability                 R_i = max(2 s_up_i + 2 s_down_i + |B_i|, R_up_i, R_down_i)
    mean bidirectional positional deviation     xm_i = (xm_up_i + xm_down_i) / 2

and per axis::

    B = max_i |B_i|,  B_mean = (1/m) sum_i B_i
    R_up = max_i R_up_i,  R_down = max_i R_down_i,  R = max_i R_i
    E_up = max_i xm_up_i - min_i xm_up_i           (unidirectional systematic deviation; likewise E_down)
    E = max(xm_up, xm_down) - min(xm_up, xm_down)  (bidirectional systematic deviation)
    M = max_i xm_i - min_i xm_i                    (range of the mean bidirectional deviation)
    A_up = max_i(xm_up_i + 2 s_up_i) - min_i(xm_up_i - 2 s_up_i)   (likewise A_down)
    A = max(xm_up + 2 s_up, xm_down + 2 s_down) - min(xm_up - 2 s_up, xm_down - 2 s_down)

All lengths are in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from postproc.errors import MeasurementError
from postproc.metrology.iso230_env import (
    UncertaintyInputs,
    environment,
    material_temperature,
    normal_temperature_correction,
    report_lines,
    uncertainty,
)
from postproc.metrology.outliers import runs_outliers
from postproc.metrology.runs import Runs

#: ISO 230-2:2014, 3.2: five runs in each direction (axes up to 2000 mm).
ISO_RUNS = 5
#: ISO 230-2:2014, 3.3: at least five target positions per metre, and at least five in all.
ISO_TARGETS_PER_M = 5
ISO_MIN_TARGETS = 5
#: Target intervals that differ by less than this are taken as equal (a 0.1 um
#: resolution is finer than any interferometer's target setting).
EQUAL_SPACING_MM = 1e-4
#: The estimator s needs two runs in a direction.
MIN_RUNS = 2

AXIS_KEYS = ("A", "A_up", "A_down", "E", "E_up", "E_down", "M", "R", "R_up", "R_down", "B", "B_mean")


@dataclass
class AxisResult:
    """The ISO 230-2 figures of one axis; per-target arrays over the sorted targets.

    ``directions``: the approach directions measured, (1, -1) for bidirectional runs,
    (1,) or (-1,) for unidirectional ones (the arrays of the other direction are NaN
    and only the one-direction figures are given). ``suspicious``: readings beyond the
    outlier rule (kept in the figures, as the standard asks). ``environment``: the
    temperature columns; ``uncertainty``: expanded uncertainties (k = 2) of the figures.
    """

    axis: str
    target_mm: np.ndarray
    n_up: np.ndarray
    n_down: np.ndarray
    mean_up: np.ndarray
    mean_down: np.ndarray
    s_up: np.ndarray
    s_down: np.ndarray
    figures: dict[str, float]
    warnings: list[str] = field(default_factory=list)
    directions: tuple[int, ...] = (1, -1)
    suspicious: list = field(default_factory=list)
    environment: dict = field(default_factory=dict)
    uncertainty: dict = field(default_factory=dict)
    temperature_corrected: bool = False

    @property
    def bidirectional(self) -> bool:
        return len(self.directions) == 2

    @property
    def reversal(self) -> np.ndarray:
        """B_i = xm_up_i - xm_down_i (zero for unidirectional runs: not measured)."""
        if not self.bidirectional:
            return np.zeros(len(self.target_mm))
        return self.mean_up - self.mean_down

    @property
    def mean(self) -> np.ndarray:
        """Mean bidirectional positional deviation xm_i (unidirectional runs: the one
        direction's mean)."""
        if not self.bidirectional:
            return self.mean_up if self.directions == (1,) else self.mean_down
        return 0.5 * (self.mean_up + self.mean_down)

    @property
    def R_up(self) -> np.ndarray:
        return 4.0 * self.s_up

    @property
    def R_down(self) -> np.ndarray:
        return 4.0 * self.s_down

    @property
    def R_bi(self) -> np.ndarray:
        return np.maximum.reduce([2 * self.s_up + 2 * self.s_down + np.abs(self.reversal),
                                  self.R_up, self.R_down])

    def targets_json(self) -> list[dict]:
        out = []
        for i, p in enumerate(self.target_mm):
            row = {"target": float(p), "n_up": int(self.n_up[i]), "n_down": int(self.n_down[i]),
                   "mean_up": self.mean_up[i], "mean_down": self.mean_down[i], "mean": self.mean[i],
                   "B": self.reversal[i] if self.bidirectional else math.nan, "s_up": self.s_up[i],
                   "s_down": self.s_down[i], "R_up": self.R_up[i], "R_down": self.R_down[i],
                   "R": self.R_bi[i] if self.bidirectional else math.nan}
            out.append({k: _finite(v) for k, v in row.items()})
        return out

    def to_json(self) -> dict:
        return {**{k: _finite(self.figures.get(k, math.nan)) for k in AXIS_KEYS},
                "directions": ["+" if d > 0 else "-" for d in self.directions],
                "warnings": list(self.warnings), "suspicious": [o.to_json() for o in self.suspicious],
                "environment": {k: {"mean_C": m, "min_C": lo, "max_C": hi} for k, (m, lo, hi) in self.environment.items()},
                "temperature_corrected": self.temperature_corrected,
                "uncertainty_k2": dict(self.uncertainty),
                "targets": self.targets_json()}


def _finite(v):
    """A JSON value: a float, or None for a figure the runs do not define (NaN)."""
    if isinstance(v, int | np.integer):
        return int(v)
    v = float(v)
    return v if math.isfinite(v) else None


def axis_figures(mean_up, mean_down, s_up, s_down) -> dict[str, float]:
    """The axis figures of ISO 230-2:2014 from the per-target means and estimators;
    with one direction's arrays all NaN (unidirectional runs) only the other
    direction's figures (A, E, R of that direction)."""
    mu, md, su, sd = (np.asarray(v, dtype=float) for v in (mean_up, mean_down, s_up, s_down))
    has_up, has_down = bool(np.isfinite(mu).all()), bool(np.isfinite(md).all())
    out: dict[str, float] = {}
    if has_up:
        out.update({"A_up": float((mu + 2 * su).max() - (mu - 2 * su).min()), "E_up": float(mu.max() - mu.min()),
                    "R_up": float(4 * su.max())})
    if has_down:
        out.update({"A_down": float((md + 2 * sd).max() - (md - 2 * sd).min()), "E_down": float(md.max() - md.min()),
                    "R_down": float(4 * sd.max())})
    if not (has_up and has_down):
        return out
    b = mu - md
    xm = 0.5 * (mu + md)
    r_bi = np.maximum.reduce([2 * su + 2 * sd + np.abs(b), 4 * su, 4 * sd])
    both_hi = np.concatenate([mu + 2 * su, md + 2 * sd])
    both_lo = np.concatenate([mu - 2 * su, md - 2 * sd])
    means = np.concatenate([mu, md])
    out.update({
        "A": float(both_hi.max() - both_lo.min()),
        "E": float(means.max() - means.min()),
        "M": float(xm.max() - xm.min()),
        "R": float(r_bi.max()),
        "B": float(np.abs(b).max()),
        "B_mean": float(b.mean()),
    })
    return out


def evaluate_axis(runs: Runs, axis: str, *, inputs: UncertaintyInputs | None = None,
                  correct_temperature: bool = False) -> AxisResult:
    """ISO 230-2 evaluation of ``axis`` (the rows of that axis in ``runs``): every reading
    counts (suspicious ones are flagged, not dropped). Runs with one approach direction
    only are evaluated with the one-direction figures. ``correct_temperature``: apply
    the normal-temperature correction when the runs give ``material_temp``."""
    inputs = inputs or UncertaintyInputs()
    sub = runs.select(axis)
    dev = sub.deviation_mm
    corrected = bool(correct_temperature and material_temperature(sub) is not None)
    if corrected:
        dev = dev + normal_temperature_correction(sub, inputs.alpha_um_per_m_k)
    targets = np.unique(sub.target_mm)
    m = len(targets)
    present = tuple(d for d in (+1, -1) if np.any(sub.direction == d))
    n = {+1: np.zeros(m, int), -1: np.zeros(m, int)}
    mean = {+1: np.full(m, np.nan), -1: np.full(m, np.nan)}
    s = {+1: np.full(m, np.nan), -1: np.full(m, np.nan)}
    for i, p in enumerate(targets):
        at = sub.target_mm == p
        for d in present:
            x = dev[at & (sub.direction == d)]
            n[d][i] = len(x)
            if len(x) < MIN_RUNS:
                line = int(sub.linenos[at][0])
                side = "+" if d > 0 else "-"
                raise MeasurementError(
                    f"axis {axis}, target {p:g} mm: {len(x)} run(s) approached it in the {side} direction; "
                    f"the evaluation needs at least {MIN_RUNS} in each direction measured (ISO 230-2 asks "
                    f"for {ISO_RUNS})",
                    path=runs.path, lineno=line, col=1,
                    hint="measure every target in the same directions, in every run",
                )
            mean[d][i] = x.mean()
            s[d][i] = x.std(ddof=1)
    figures = axis_figures(mean[+1], mean[-1], s[+1], s[-1])
    result = AxisResult(axis, targets, n[+1], n[-1], mean[+1], mean[-1], s[+1], s[-1], figures,
                        directions=present, temperature_corrected=corrected)
    result.warnings = standard_warnings(sub, result)
    result.suspicious = runs_outliers(sub)
    result.environment = environment(sub)
    t = material_temperature(sub)
    result.uncertainty = uncertainty(result, inputs, None if t is None else float(np.mean(t)))
    return result


def standard_warnings(sub: Runs, res: AxisResult) -> list[str]:
    """Where the runs fall short of ISO 230-2:2014 (run count, targets, spacing, order).
    The visiting order is checked only when the file gives the time (``t``): the row
    order of a file is not the order the axis moved in (exporters sort by target)."""
    ax = res.axis
    out = []
    counts = [c for d, c in ((1, res.n_up), (-1, res.n_down)) if d in res.directions]
    fewest = int(min(c.min() for c in counts))
    most = int(max(c.max() for c in counts))
    if not res.bidirectional:
        side = "+" if res.directions == (1,) else "-"
        out.append(f"{ax}: unidirectional runs (approached in {side} only): evaluated with the one-direction "
                   f"figures A{side}, E{side}, R{side}; B, M and the bidirectional A, E, R need both directions")
    if fewest < ISO_RUNS:
        out.append(f"{ax}: {fewest} run(s) at some target and direction; ISO 230-2 asks for {ISO_RUNS} "
                   "in each direction: the repeatability figures (s, R, A) are uncertain")
    if fewest != most:
        out.append(f"{ax}: the run count differs between targets or directions ({fewest} to {most})")
    travel = float(res.target_mm[-1] - res.target_mm[0])
    needed = max(ISO_MIN_TARGETS, math.ceil(ISO_TARGETS_PER_M * travel / 1000.0))
    if len(res.target_mm) < needed:
        out.append(f"{ax}: {len(res.target_mm)} targets over {travel:g} mm; ISO 230-2 asks for at least "
                   f"{needed} (five per metre and at least five)")
    steps = np.diff(res.target_mm)
    if len(steps) >= 2 and np.ptp(steps) < EQUAL_SPACING_MM:
        out.append(f"{ax}: the targets are evenly spaced ({steps[0]:g} mm); ISO 230-2 spaces them unevenly "
                   "so that periodic errors (lead-screw pitch, scale period) are not sampled at one phase")
    if not sub.timed:
        return out
    for run in np.unique(sub.run):
        for d in (+1, -1):
            k = np.flatnonzero((sub.run == run) & (sub.direction == d))
            if len(k) < 2:
                continue
            visited = sub.target_mm[k[np.argsort(sub.order[k], kind="stable")]]
            if np.any(d * np.diff(visited) <= 0):
                side, way = ("+", "increasing") if d > 0 else ("-", "decreasing")
                out.append(f"{ax}: run {run} ({side}) does not visit its targets in {way} order by its times t "
                           f"(line {int(sub.linenos[k[0]])}); ISO 230-2's linear cycle approaches "
                           f"each target moving in the run's direction")
                break
    return out


def evaluate(runs: Runs, *, inputs: UncertaintyInputs | None = None,
             correct_temperature: bool = False) -> dict[str, AxisResult]:
    """Every axis of the file, in the order of first appearance."""
    return {a: evaluate_axis(runs, a, inputs=inputs, correct_temperature=correct_temperature) for a in runs.axes}


def results_json(results: dict[str, AxisResult]) -> dict:
    return {"units": "mm", "axes": {a: r.to_json() for a, r in results.items()}}


def _um(v: float, width: int) -> str:
    return f"{v * 1000:{width}.2f}" if math.isfinite(v) else f"{'-':>{width}}"


def format_results(results: dict[str, AxisResult], inputs: UncertaintyInputs | None = None) -> list[str]:
    """Text report in micrometres, one block per axis."""
    inputs = inputs or UncertaintyInputs()
    lines = []
    for a, r in results.items():
        counts = [c for d, c in ((1, r.n_up), (-1, r.n_down)) if d in r.directions]
        kind = "" if r.bidirectional else f", unidirectional ({'+' if r.directions == (1,) else '-'})"
        lines.append(f"axis {a}: {len(r.target_mm)} targets, runs per direction "
                     f"{int(min(c.min() for c in counts))}..{int(max(c.max() for c in counts))}{kind} "
                     "(ISO 230-2:2014; values in um)")
        lines.append(f"  {'target mm':>10} {'mean+':>8} {'mean-':>8} {'mean':>8} {'B_i':>8} "
                     f"{'s+':>7} {'s-':>7} {'R+':>7} {'R-':>7} {'R_i':>7}")
        for i, p in enumerate(r.target_mm):
            b = r.reversal[i] if r.bidirectional else math.nan
            rb = r.R_bi[i] if r.bidirectional else math.nan
            lines.append(f"  {p:10.3f} " + " ".join(_um(v, 8) for v in (r.mean_up[i], r.mean_down[i], r.mean[i], b))
                         + " " + " ".join(_um(v, 7) for v in (r.s_up[i], r.s_down[i], r.R_up[i], r.R_down[i], rb)))
        f = {k: v * 1000 for k, v in r.figures.items()}
        if r.bidirectional:
            lines.append(f"  A {f['A']:.2f} (A+ {f['A_up']:.2f}, A- {f['A_down']:.2f})   "
                         f"E {f['E']:.2f} (E+ {f['E_up']:.2f}, E- {f['E_down']:.2f})   M {f['M']:.2f}")
            lines.append(f"  R {f['R']:.2f} (R+ {f['R_up']:.2f}, R- {f['R_down']:.2f})   "
                         f"B {f['B']:.2f}   mean reversal {f['B_mean']:+.2f}")
        else:
            side = "+" if r.directions == (1,) else "-"
            tag = "up" if side == "+" else "down"
            lines.append(f"  A{side} {f['A_' + tag]:.2f}   E{side} {f['E_' + tag]:.2f}   R{side} {f['R_' + tag]:.2f}"
                         "   (unidirectional: no B, M or bidirectional A, E, R)")
        lines += [f"  {ln}" for ln in report_lines(r, inputs, r.temperature_corrected)]
        if r.suspicious:
            lines.append(f"  suspicious readings (outlier rule: {len(r.suspicious)}; kept in the figures, as ISO "
                         "230-2 asks; 'fit' leaves them out):")
            lines += [f"    {o.describe()}" for o in r.suspicious]
        for w in r.warnings:
            lines.append(f"  warning: {w}")
    return lines


def _span(ax, x: float, lo: float, hi: float, label: str, color: str) -> None:
    """A vertical double arrow from lo to hi at x (um) with its label beside it."""
    ax.annotate("", xy=(x, hi), xytext=(x, lo), arrowprops={"arrowstyle": "<->", "color": color, "lw": 1.2},
                annotation_clip=False)
    ax.annotate(label, xy=(x, 0.5 * (lo + hi)), xytext=(4, 0), textcoords="offset points", color=color,
                fontsize=8, va="center", annotation_clip=False)


def plot_axis(res: AxisResult, ax=None):
    """The ISO 230-2 graph as Renishaw CARTO and XCal-View draw it: per direction the mean
    positional deviation at each target with its mean +- 2s band, the mean bidirectional
    deviation, and the figures annotated where they are read (A and E as spans at the
    right edge, R and B at the target where they occur) with a table of the figures
    and their expanded uncertainty. matplotlib is imported here, only when plotting."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(9, 5))
    p = res.target_mm
    f = {k: v * 1000 for k, v in res.figures.items()}
    u = {k: v * 1000 for k, v in res.uncertainty.items() if k != "k"}
    styles = {1: ("tab:blue", "o", "forward (+)"), -1: ("tab:red", "s", "reverse (-)")}
    hi_all, lo_all = [], []
    for d in res.directions:
        mean, s = (res.mean_up, res.s_up) if d > 0 else (res.mean_down, res.s_down)
        color, marker, label = styles[d]
        m_um, s_um = mean * 1000, s * 1000
        ax.plot(p, m_um, "-", marker=marker, ms=4, color=color, label=f"mean {label}")
        ax.plot(p, m_um + 2 * s_um, "--", color=color, lw=0.8, label=f"mean ± 2s {label}")
        ax.plot(p, m_um - 2 * s_um, "--", color=color, lw=0.8)
        ax.errorbar(p, m_um, yerr=2 * s_um, fmt="none", ecolor=color, elinewidth=0.6, capsize=2)
        hi_all.append(m_um + 2 * s_um)
        lo_all.append(m_um - 2 * s_um)
    if res.bidirectional:
        ax.plot(p, res.mean * 1000, ":", color="k", lw=1, label="mean bidirectional")
    hi, lo = np.concatenate(hi_all), np.concatenate(lo_all)
    means = np.concatenate([(res.mean_up if d > 0 else res.mean_down) * 1000 for d in res.directions])
    span = float(p[-1] - p[0]) or 1.0
    x_a, x_e = p[-1] + 0.04 * span, p[-1] + 0.12 * span
    tag = "" if res.bidirectional else ("+" if res.directions == (1,) else "-")
    key = "" if res.bidirectional else ("_up" if tag == "+" else "_down")
    _span(ax, x_a, float(lo.min()), float(hi.max()), f"A{tag}", "tab:green")
    _span(ax, x_e, float(means.min()), float(means.max()), f"E{tag}", "tab:purple")
    if res.bidirectional:
        i = int(np.argmax(res.R_bi))
        top = max(res.mean_up[i] + 2 * res.s_up[i], res.mean_down[i] + 2 * res.s_down[i]) * 1000
        _span(ax, float(p[i]), top - f["R"], top, "R", "tab:orange")
        j = int(np.argmax(np.abs(res.reversal)))
        _span(ax, float(p[j]) + 0.015 * span, float(res.mean_down[j] * 1000), float(res.mean_up[j] * 1000), "B",
              "tab:brown")
        rows = [("A", "A"), ("E", "E"), ("M", "M"), ("R", "R"), ("B", "B")]
    else:
        i = int(np.argmax(res.s_up if tag == "+" else res.s_down))
        mean_i = (res.mean_up if tag == "+" else res.mean_down)[i] * 1000
        _span(ax, float(p[i]), mean_i - 0.5 * f["R" + key], mean_i + 0.5 * f["R" + key], f"R{tag}", "tab:orange")
        rows = [(f"A{tag}", "A" + key), (f"E{tag}", "E" + key), (f"R{tag}", "R" + key)]
    table = "\n".join(f"{name:<3} {f[k]:7.2f} µm  (U {u.get(k, math.nan):.2f})" for name, k in rows)
    if res.bidirectional:
        table += f"\nmean reversal {f['B_mean']:+.2f} µm"
    ax.text(0.01, 0.98, table + "\nU: expanded, k = 2", transform=ax.transAxes, va="top", ha="left", fontsize=8,
            family="monospace", bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.set_xlim(p[0] - 0.03 * span, p[-1] + 0.2 * span)
    ax.set_xlabel(f"target position {res.axis} (mm)")
    ax.set_ylabel("positional deviation (µm)")
    kind = "bidirectional" if res.bidirectional else f"unidirectional ({tag})"
    ax.set_title(f"ISO 230-2 {kind} positioning, axis {res.axis}: mean ± 2s per target")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, frameon=False)
    return ax


def plot_results(results: dict[str, AxisResult], path) -> None:
    """One panel per axis, written atomically to ``path``."""
    import matplotlib.pyplot as plt

    from postproc.fileio import save_figure

    fig, axes = plt.subplots(len(results), 1, figsize=(9, 5.6 * len(results)), squeeze=False)
    for ax, res in zip(axes[:, 0], results.values(), strict=True):
        plot_axis(res, ax)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
