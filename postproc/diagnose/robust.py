"""Duplicates and outliers in a measurement campaign, found before anything is fitted.

- **Duplicates**: rows equal in every column (commanded point, measured point, tool
  vector, context) are one shot written twice (a copy-paste, an exporter repeating a
  row). Kept once: as repeats they would pull the noise floor toward zero.
- **Outliers in repeat groups**: a shot that departs from the other shots of its
  group (same point, approach and context) by far more than the pooled within-group
  scatter. The scatter is estimated robustly (median absolute deviation), so one glitch
  cannot inflate the yardstick it is measured with. In a pair the two shots depart
  from each other alike: the one farther from the model is taken.
- **Outliers among single shots**: a residual (against the calibration) far outside its
  robust spread. The spread (median absolute deviation per component) includes any
  systematic error the model misses, so an unmodelled effect does not become outliers;
  a tracker glitch of tens of sigma does.

Both tests flag a row when its standardised squared deviation exceeds the chi-square
(3 degrees of freedom) quantile at ``FAMILY_ALPHA / N``: on clean data the chance of one
false flag in the whole campaign is about FAMILY_ALPHA.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.diagnose.data import Dataset

# The rule and its constants are postproc.metrology.outliers' (one rule for check, fit and iso230).
from postproc.metrology.outliers import FAMILY_ALPHA, MAD_TO_SIGMA, MIN_READINGS, MIN_SIGMA_MM  # noqa: F401
from postproc.metrology.outliers import robust_sigma as _robust_sigma
from postproc.metrology.outliers import threshold as _threshold

# Fewer rows than this give no robust spread.
MIN_ROWS = MIN_READINGS


@dataclass
class Screening:
    keep: np.ndarray  # (N,) bool: rows used by the analysis
    duplicates: list[dict] = field(default_factory=list)
    outliers: list[dict] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"duplicates": self.duplicates, "outliers": self.outliers, "n_excluded": int(np.sum(~self.keep))}


def threshold(n: int) -> float:
    """The rule's limit for a campaign of ``n`` points in space (3 components), the
    spread estimated from those ``n``."""
    return _threshold(n, 3, n)


def duplicate_rows(ds: Dataset) -> np.ndarray:
    """(N,) True for a row equal in every column to an earlier row."""
    cols = [ds.q, ds.m, ds.r] + [v[:, None] for _, v in sorted(ds.ctx.items())]
    _, first = np.unique(np.hstack(cols), axis=0, return_index=True)
    dup = np.ones(len(ds), dtype=bool)
    dup[first] = False
    return dup


def screen(ds: Dataset, resid: np.ndarray) -> Screening:
    """Duplicates and outliers of ``ds`` given its residual ``resid`` (N, 3) against the model."""
    n = len(ds)
    dup = duplicate_rows(ds)
    out = Screening(~dup)
    for i in np.nonzero(dup)[0]:
        out.duplicates.append({"place": ds.place(int(i)), "row": int(i)})
    if n - dup.sum() < MIN_ROWS:
        return out
    live = np.nonzero(~dup)[0]
    sub = ds.subset(live)
    groups = sub.repeat_groups()
    counts = np.bincount(groups)
    limit = threshold(len(live))
    flagged = np.zeros(len(live), dtype=bool)
    reason: dict[int, str] = {}
    # repeat groups: each shot against the mean of the others in its group. A glitch pulls
    # the others' mean too, so one shot per group is taken at a time (the farthest; in a
    # pair, the one farther from the model) and the group looked at again without it.
    rnorm = np.linalg.norm(resid[live], axis=1)
    while True:
        active = ~flagged
        counts_a = np.bincount(groups[active], minlength=len(counts))
        multi = active & (counts_a[groups] >= 2)
        if np.count_nonzero(multi) < MIN_ROWS:
            break
        sums = np.zeros((len(counts), 3))
        np.add.at(sums, groups[active], sub.m[active])
        k = counts_a[groups][:, None].astype(float)
        loo = (sums[groups] - sub.m) / np.maximum(k - 1, 1)
        d = sub.m - loo  # variance sigma^2 * k / (k - 1)
        dstd = d * np.sqrt((k - 1) / np.maximum(k, 1))
        sigma = _robust_sigma(dstd[multi])
        z2 = np.where(multi, np.sum((dstd / sigma) ** 2, axis=1), 0.0)
        new = []
        for g in np.unique(groups[multi & (z2 > limit)]):
            rows = np.nonzero(multi & (groups == g))[0]
            bad = rows[z2[rows] > limit]
            key = -rnorm[bad] if counts_a[g] == 2 else -z2[bad]
            new.append(int(bad[np.argsort(key)][0]))
        if not new:
            break
        for shot in new:
            flagged[shot] = True
            reason[shot] = f"departs from the other shots at this point by {np.sqrt(z2[shot]):.1f} within-group sigma"
    # single shots (and the rest): the residual against its robust spread
    sigma = _robust_sigma(resid[live][~flagged])
    z2 = np.sum(((resid[live] - np.median(resid[live][~flagged], axis=0)) / sigma) ** 2, axis=1)
    single = (counts[groups] == 1) & (z2 > limit) & ~flagged
    for i in np.nonzero(single)[0]:
        flagged[i] = True
        reason[int(i)] = f"residual {np.sqrt(z2[i]):.1f} robust sigma from the others"
    for i in np.nonzero(flagged)[0]:
        row = int(live[i])
        out.keep[row] = False
        out.outliers.append({"place": ds.place(row), "row": row, "q_mm": [float(v) for v in ds.q[row]],
                             "residual_mm": [float(v) for v in resid[row]], "reason": reason[int(i)]})
    return out
