"""The noise floor: the residual no model can remove.

From repeated points (rows with the same commanded point, tool vector and context,
see :meth:`Dataset.repeat_groups`): the pooled within-group variance per component.
Or from a declared instrument sigma (``--sigma``, per component). Reported as a 3D
RMS, ``sqrt(sx^2 + sy^2 + sz^2)``, comparable with the residual RMS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.diagnose.data import Dataset

# Fewer degrees of freedom than this (repeats minus groups) give a floor uncertain by
# more than ~35 %: not reported as measured.
MIN_REPEAT_DOF = 5


@dataclass
class NoiseFloor:
    rms_mm: float | None  # 3D RMS of the noise, None when unknown
    sigma_mm: tuple[float, float, float] | None  # per component
    source: str  # "repeats", "declared" or "unknown"
    dof: int = 0
    measured_rms_mm: float | None = None  # from repeats, also when a sigma is declared


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
    if sigma_mm is not None:
        return NoiseFloor(float(sigma_mm) * np.sqrt(3.0), (sigma_mm,) * 3, "declared", dof, measured)
    if sig is not None:
        sx, sy, sz = (float(s) for s in sig)
        return NoiseFloor(measured, (sx, sy, sz), "repeats", dof, measured)
    return NoiseFloor(None, None, "unknown", dof, None)
