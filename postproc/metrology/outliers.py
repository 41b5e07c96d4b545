"""One robust outlier rule for every reading postproc takes in: ``check``, ``fit`` and
``iso230`` (and, through ``fit``, ``export``) use this rule and no other.

**The rule.** A reading is compared with the other readings of its group (the same
target and approach direction of interferometer runs; the same point, approach and
context of tracker shots, or, for single shots, the residual against the model). Its
deviation is divided by the robust spread of all such deviations in the campaign,
``MAD_TO_SIGMA`` x the median absolute deviation (one glitch cannot inflate the
yardstick it is measured with). The reading is an outlier when the standardised
squared deviation exceeds the quantile at ``FAMILY_ALPHA / N``, N readings in the
campaign (Bonferroni), of ``dof`` times an F distribution: dof = 1 for a reading along
one axis, 3 for a point in space, and the spread's own degrees of freedom
MAD_EFFICIENCY x N (the chi-square quantile, widened because the spread is
estimated, as a t quantile widens a normal one). On clean Gaussian data the chance of
one false flag anywhere in the campaign is about FAMILY_ALPHA = 0.1 %. For 110
interferometer readings (11 targets x 5 runs x 2 directions) the limit is 5.08 robust
sigma; for 240 tracker shots, 5.69.

**Who does what with it.** ``check`` and ``fit`` leave outliers out of the data and
list them (file:line, value, why); ``fit --keep-outliers`` keeps them and records
that in the calibration; ``export`` refuses a calibration fitted from runs that used
such a reading unless ``--keep-outliers``; ``iso230`` keeps every reading, as ISO 230-2
asks, and flags the suspicious ones in its report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Chance of flagging one clean reading anywhere in the campaign (Bonferroni over readings).
FAMILY_ALPHA = 1e-3
#: Consistency factor of the median absolute deviation for a Gaussian (MAD * 1.4826 = sigma).
MAD_TO_SIGMA = 1.4826
#: Asymptotic efficiency of the median absolute deviation against the standard deviation
#: for Gaussian data: a MAD from N deviations is as good as a standard deviation from
#: 0.37 N (its degrees of freedom in the F quantile of :func:`threshold`).
MAD_EFFICIENCY = 0.367
#: Spreads below this (mm, a nanometre: below any instrument) are rounding, not noise:
#: noise-free simulated data must not make outliers of rounding differences.
MIN_SIGMA_MM = 1e-6
#: A run group needs this many readings to say which one departs: in a pair both depart alike.
MIN_GROUP = 3
#: Fewer deviations than this give no robust spread.
MIN_READINGS = 8

RULE = (f"robust z (deviation from the median of the other readings of its group, over {MAD_TO_SIGMA} x the "
        f"median absolute deviation of all such deviations) beyond the quantile at {FAMILY_ALPHA:g}/N "
        "(Bonferroni over the N readings) of the F distribution that allows for the spread being estimated")


def threshold(n: int, dof: int = 1, n_scale: int | None = None) -> float:
    """The limit of the squared robust z for a campaign of ``n`` readings of ``dof``
    components. ``n_scale``: the number of deviations the spread was estimated from;
    the estimate's own scatter (the MAD has MAD_EFFICIENCY of the efficiency of a
    standard deviation) widens the limit from the chi-square to ``dof`` times the F
    quantile, as a t replaces a normal quantile when sigma is estimated."""
    from scipy.stats import chi2, f

    alpha = FAMILY_ALPHA / max(n, 1)
    if n_scale is None:
        return float(chi2.isf(alpha, dof))
    return float(dof * f.isf(alpha, dof, max(MAD_EFFICIENCY * n_scale, 1.0)))


def robust_sigma(dev: np.ndarray) -> np.ndarray:
    """MAD_TO_SIGMA x the median absolute deviation (per column), at least MIN_SIGMA_MM."""
    dev = np.asarray(dev, dtype=float)
    s = MAD_TO_SIGMA * np.median(np.abs(dev - np.median(dev, axis=0)), axis=0)
    return np.maximum(s, MIN_SIGMA_MM)


@dataclass
class Outlier:
    """One reading beyond the rule: where it is, its value, and why."""

    path: str
    lineno: int
    axis: str
    target_mm: float
    run: int
    direction: int
    deviation_mm: float
    z: float
    limit: float
    others_mm: float  # the median of the other readings of its group

    def describe(self) -> str:
        side = "+" if self.direction > 0 else "-"
        return (f"{self.path}:{self.lineno}: axis {self.axis}, target {self.target_mm:g} mm, run {self.run} ({side}): "
                f"deviation {self.deviation_mm * 1000:+.2f} um, the other runs {self.others_mm * 1000:+.2f} um: "
                f"{self.z:.1f} robust sigma (limit {self.limit:.2f})")

    def to_json(self) -> dict:
        return {"place": f"{self.path}:{self.lineno}", "axis": self.axis, "target_mm": self.target_mm,
                "run": self.run, "direction": "+" if self.direction > 0 else "-",
                "deviation_mm": self.deviation_mm, "robust_z": self.z, "limit": self.limit,
                "why": self.describe()}


def runs_outliers(runs) -> list[Outlier]:
    """Readings of interferometer runs (:class:`postproc.metrology.runs.Runs`) beyond the
    rule, per axis: each reading against the median of the other runs at its target and
    direction (groups of at least MIN_GROUP), over the robust spread of those
    deviations on the axis."""
    out: list[Outlier] = []
    for axis in runs.axes:
        k = np.flatnonzero(runs.axis == axis)
        dev = np.full(len(k), np.nan)
        others = np.full(len(k), np.nan)
        keys: dict[tuple[float, int], list[int]] = {}
        for j, i in enumerate(k):
            keys.setdefault((runs.target_mm[i], runs.direction[i]), []).append(j)
        for rows in keys.values():
            if len(rows) < MIN_GROUP:
                continue
            x = runs.deviation_mm[k[rows]]
            for n, j in enumerate(rows):
                med = float(np.median(np.delete(x, n)))
                others[j], dev[j] = med, x[n] - med
        live = np.isfinite(dev)
        if live.sum() < MIN_READINGS:
            continue
        sigma = float(robust_sigma(dev[live]))
        centre = float(np.median(dev[live]))
        limit = float(np.sqrt(threshold(len(k), 1, int(live.sum()))))
        z = np.abs(dev - centre) / sigma
        for hit in np.flatnonzero(live & (z > limit)):
            row = int(k[hit])
            out.append(Outlier(runs.path, int(runs.linenos[row]), str(axis), float(runs.target_mm[row]),
                               int(runs.run[row]), int(runs.direction[row]), float(runs.deviation_mm[row]),
                               float(z[hit]), limit, float(others[hit])))
    return out


def runs_without(runs, outliers: list[Outlier]):
    """``runs`` without the rows of ``outliers`` (matched by line)."""
    drop = {o.lineno for o in outliers}
    return runs.subset(np.array([int(n) not in drop for n in runs.linenos], dtype=bool))


def runs_outliers_used(cal, cal_path: str) -> tuple[list[str], list[str], list[str]]:
    """For ``export``: (readings beyond the rule the calibration was fitted from, readings
    fit left out, notes). A calibration written by this version records both in its
    fit information; an older one fitted from runs has its runs files read again (each
    of its readings was used)."""
    from pathlib import Path

    from postproc.errors import PostprocError
    from postproc.metrology.runs import read_runs

    info = cal.fit or {}
    sources = info.get("runs_sources") or []
    if not sources:
        return [], [], []
    record = info.get("outliers")
    if record is not None:
        return ([o["why"] for o in record.get("kept", [])], [o["why"] for o in record.get("excluded", [])], [])
    used, notes = [], []
    for src in sources:
        path = Path(src)
        if not path.is_file() and cal_path:
            path = Path(cal_path).parent / src
        try:
            runs = read_runs(path)
        except PostprocError:
            notes.append(f"warning: runs file {src} of the calibration cannot be read: its readings were not "
                         "checked against the outlier rule")
            continue
        used += [o.describe() for o in runs_outliers(runs)]
    return used, [], notes

