"""The noise floor: the residual no model can remove.

From repeated points (rows with the same commanded point, tool vector and context,
see :meth:`Dataset.repeat_groups`): the pooled within-group variance per component.
Or from a declared instrument sigma (``--sigma``, per component). Reported as a 3D
RMS, ``sqrt(sx^2 + sy^2 + sz^2)``, comparable with the residual RMS.

**Heavy tails.** A tracker's occasional bad shot gives its noise heavier tails than a
Gaussian's (on the virtual machine: Student t, 4 degrees of freedom). The floor is then
less certain than its degrees of freedom say: a campaign's own noise may sit 8 % above
the floor its repeats give. Beside the pooled RMS the floor is estimated robustly
(:func:`robust_scale`: the Qn scale of Rousseeuw and Croux, 82 % efficient and
consistent for Gaussian noise, of the within-group deviations, each scaled to one shot),
and the tails are measured: the excess kurtosis of the deviations in units of that
scale (:data:`HEAVY_TAIL_KURTOSIS`). The verdict widens its ratio by the floor's extra
uncertainty (:func:`postproc.diagnose.verdict.tolerance`). The RMS ratio itself is kept:
on pure Student-t noise (40 campaigns of 120 pairs) the RMS of the shots over the
pooled floor scatters less (90 % within 0.96-1.03) than a robust scale of the residual
over the robust floor (0.95-1.06), since numerator and floor share the same bad shots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.diagnose.data import Dataset

# Fewer degrees of freedom than this (repeats minus groups) give a floor uncertain by
# more than ~35 %: not reported as measured.
MIN_REPEAT_DOF = 5
# Qn's consistency factor for Gaussian data (Rousseeuw & Croux 1993, JASA 88, 1273-1283).
QN_GAUSSIAN = 2.2219
# Most values Qn is computed on (its pairwise differences are held in memory: 4000 values
# make 8 million); a larger sample is thinned evenly.
QN_MAX_VALUES = 4000
# Excess kurtosis of the within-group deviations above which the noise is heavy-tailed,
# and the verdict judges robust scales: at least this, and at least HEAVY_TAIL_SE standard
# errors of the kurtosis of Gaussian noise (sqrt(24 / n)), so that Gaussian campaigns keep
# the plain RMS (on 360 deviations the kurtosis of Gaussian noise has a standard error
# of 0.26; Student t with 4 degrees of freedom has an infinite one, 2 to 10 in practice).
HEAVY_TAIL_KURTOSIS = 0.5
HEAVY_TAIL_SE = 4.0


@dataclass
class NoiseFloor:
    rms_mm: float | None  # 3D RMS of the noise, None when unknown
    sigma_mm: tuple[float, float, float] | None  # per component
    source: str  # "repeats", "declared" or "unknown"
    dof: int = 0
    measured_rms_mm: float | None = None  # from repeats, also when a sigma is declared
    robust_rms_mm: float | None = None  # Qn scale of the within-group deviations (consistent for Gaussian)
    kurtosis: float | None = None  # excess kurtosis of the deviations (0 for Gaussian noise)
    heavy_tailed: bool = False  # the verdict judges robust scales (HEAVY_TAIL_KURTOSIS)


def qn_scale(x: np.ndarray) -> float:
    """The Qn scale of ``x`` (1-D): 2.2219 times the first quartile of the pairwise
    distances |x_i - x_j|, i < j (the h(h-1)/2-th smallest, h = n // 2 + 1), with the
    small-sample factor of Croux & Rousseeuw (1992). Consistent for the standard
    deviation of Gaussian data, breakdown 50 %, Gaussian efficiency 82 %."""
    x = np.asarray(x, dtype=float).ravel()
    if len(x) > QN_MAX_VALUES:
        x = np.sort(x)[np.linspace(0, len(x) - 1, QN_MAX_VALUES).astype(int)]
    n = len(x)
    if n < 2:
        return float("nan")
    i, j = np.triu_indices(n, 1)
    d = np.abs(x[i] - x[j])
    h = n // 2 + 1
    k = h * (h - 1) // 2
    q = float(np.partition(d, k - 1)[k - 1])
    small = n / (n + 1.4) if n % 2 else n / (n + 3.8)
    return QN_GAUSSIAN * q * (small if n > 9 else 1.0)


def robust_scale(values: np.ndarray) -> float:
    """3D robust RMS about zero of ``values`` (N, 3): per component the Qn scale of the
    values and their negatives (symmetric about zero, so an offset counts, as in an RMS),
    added in quadrature."""
    v = np.asarray(values, dtype=float)
    v = v[np.all(np.isfinite(v), axis=1)]
    if len(v) < 2:
        return float("nan")
    return float(np.sqrt(sum(qn_scale(np.r_[v[:, j], -v[:, j]]) ** 2 for j in range(3))))


def group_deviations(ds: Dataset) -> np.ndarray:
    """(M, 3) within-group deviations from the group mean, each scaled to one shot
    (``sqrt(k / (k - 1))`` for a group of k): rows of groups with repeats only."""
    groups = ds.repeat_groups()
    counts = np.bincount(groups)
    means = np.zeros((len(counts), 3))
    np.add.at(means, groups, ds.m)
    means /= np.maximum(counts, 1)[:, None]
    k = counts[groups]
    rep = k > 1
    return (ds.m[rep] - means[groups[rep]]) * np.sqrt(k[rep] / (k[rep] - 1.0))[:, None]


def excess_kurtosis(dev: np.ndarray, scale: np.ndarray) -> float:
    """Excess kurtosis of the deviations ``dev`` (M, 3) in units of their per-component
    robust ``scale``: 0 for Gaussian noise."""
    z = (dev / np.where(scale > 0, scale, 1.0)).ravel()
    m2 = float(np.mean(z**2))
    return float(np.mean(z**4)) / m2**2 - 3.0 if m2 > 0 else 0.0


def repeat_noise(ds: Dataset) -> tuple[np.ndarray | None, int]:
    groups = ds.repeat_groups()
    counts = np.bincount(groups)
    dof = int(len(ds) - np.count_nonzero(counts))
    if dof < MIN_REPEAT_DOF:
        return None, dof
    means = np.zeros((len(counts), 3))
    np.add.at(means, groups, ds.m)
    means /= np.maximum(counts, 1)[:, None]
    dev = ds.m - means[groups]
    return np.sqrt(np.sum(dev**2, axis=0) / dof), dof


def noise_floor(ds: Dataset, sigma_mm: float | None = None) -> NoiseFloor:
    sig, dof = repeat_noise(ds)
    measured = float(np.sqrt(np.sum(sig**2))) if sig is not None else None
    robust, kurt, heavy = None, None, False
    if sig is not None:
        dev = group_deviations(ds)
        scale = np.array([qn_scale(np.r_[dev[:, j], -dev[:, j]]) for j in range(3)])
        robust = float(np.sqrt(np.sum(scale**2)))
        kurt = excess_kurtosis(dev, scale)
        heavy = bool(kurt > max(HEAVY_TAIL_KURTOSIS, HEAVY_TAIL_SE * np.sqrt(24.0 / (3 * dof))))
    if sigma_mm is not None:
        return NoiseFloor(float(sigma_mm) * np.sqrt(3.0), (sigma_mm,) * 3, "declared", dof, measured,
                          robust, kurt, False)
    if sig is not None:
        sx, sy, sz = (float(s) for s in sig)
        return NoiseFloor(measured, (sx, sy, sz), "repeats", dof, measured, robust, kurt, heavy)
    return NoiseFloor(None, None, "unknown", dof, None)
