"""Where a model fails: residual statistics by point, region, direction, time, context.

Every function takes a :class:`Dataset` and its residuals ``measured - model`` (N, 3)
and returns plain data (dicts/lists) that the text and JSON reports render.
"""

from __future__ import annotations

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.effects.base import AXES, DIR_COLUMNS

# Worst points listed in the report.
N_WORST = 5
# Bins along each axis and along time: quarters of the range keep ~N/4 points per bin
# (bin means within noise/sqrt(N/4)) while still showing where along the travel the
# error sits.
N_BINS = 4
# Finer bins for the binned means with error bars (plots and JSON) ...
N_FINE_BINS = 8
# ... and cells per axis of the 2-D residual maps.
N_MAP_BINS = 4
# A correlation between a residual component and a context column above this (in
# absolute value) is flagged; for N = 100 points |r| > 0.33 has p < 0.001 by chance.
CORRELATION_FLAG = 0.33


def components(resid: np.ndarray) -> dict:
    norm = np.linalg.norm(resid, axis=1)
    return {
        "rms_mm": float(np.sqrt(np.mean(norm**2))) if len(norm) else 0.0,
        "max_mm": float(np.max(norm)) if len(norm) else 0.0,
        "rms_xyz_mm": [float(v) for v in np.sqrt(np.mean(resid**2, axis=0))],
        "max_xyz_mm": [float(v) for v in np.max(np.abs(resid), axis=0)],
        "mean_xyz_mm": [float(v) for v in np.mean(resid, axis=0)],
    }


def worst_points(ds: Dataset, resid: np.ndarray, n: int = N_WORST) -> list[dict]:
    norm = np.linalg.norm(resid, axis=1)
    out = []
    for i in np.argsort(-norm)[:n]:
        out.append({
            "place": ds.place(int(i)), "q_mm": ds.q[i].tolist(), "residual_mm": resid[i].tolist(),
            "norm_mm": float(norm[i]),
        })
    return out


def binned(values: np.ndarray, resid: np.ndarray, n_bins: int = N_BINS) -> list[dict]:
    """Residual statistics in ``n_bins`` equal-width bins over the range of ``values``
    (empty bins are left out)."""
    lo, hi = float(np.min(values)), float(np.max(values))
    edges = np.linspace(lo, hi, n_bins + 1)
    which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, n_bins - 1)
    out = []
    for b in range(n_bins):
        sel = which == b
        if not sel.any():
            continue
        r = resid[sel]
        out.append({
            "from": float(edges[b]), "to": float(edges[b + 1]), "n": int(sel.sum()),
            "rms_mm": float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
            "mean_xyz_mm": [float(v) for v in r.mean(axis=0)],
        })
    return out


def by_region(ds: Dataset, resid: np.ndarray) -> dict:
    return {a: binned(ds.q[:, j], resid) for j, a in enumerate(AXES) if np.ptp(ds.q[:, j]) > 0}


def by_direction(ds: Dataset, resid: np.ndarray) -> dict:
    """Mean residual along each axis for +1 and -1 approaches: their difference is the
    reversal error the model misses (ISO 230-2 'B')."""
    out = {}
    for j, col in enumerate(DIR_COLUMNS):
        if col not in ds.ctx:
            continue
        d = ds.ctx[col]
        plus, minus = resid[d > 0, j], resid[d < 0, j]
        if len(plus) < 2 or len(minus) < 2:
            continue
        diff = float(plus.mean() - minus.mean())
        se = float(np.sqrt(plus.var(ddof=1) / len(plus) + minus.var(ddof=1) / len(minus)))
        out[AXES[j]] = {"mean_plus_mm": float(plus.mean()), "mean_minus_mm": float(minus.mean()),
                        "n_plus": int(len(plus)), "n_minus": int(len(minus)),
                        "reversal_mm": diff, "stderr_mm": se}
    return out


def against_context(ds: Dataset, resid: np.ndarray) -> dict:
    """Slope and correlation of each residual component against every context column."""
    out = {}
    for name, v in sorted(ds.ctx.items()):
        if name in DIR_COLUMNS or np.ptp(v) == 0:
            continue
        vc = v - v.mean()
        slopes, corr = [], []
        for j in range(3):
            rc = resid[:, j] - resid[:, j].mean()
            den = float(np.sqrt(np.sum(vc**2) * np.sum(rc**2)))
            slopes.append(float(np.sum(vc * rc) / np.sum(vc**2)))
            corr.append(float(np.sum(vc * rc) / den) if den > 0 else 0.0)
        out[name] = {"slope_xyz_mm_per_unit": slopes, "correlation_xyz": corr,
                     "flagged": bool(max(abs(c) for c in corr) > CORRELATION_FLAG),
                     "bins": binned(v, resid)}
    return out


def binned_means(values: np.ndarray, resid: np.ndarray, n_bins: int = N_FINE_BINS) -> list[dict]:
    """Mean residual per bin of ``values`` with its standard error (the error bar)."""
    if np.ptp(values) == 0:
        return []
    edges = np.linspace(values.min(), values.max(), n_bins + 1)
    which = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, n_bins - 1)
    out = []
    for b in range(n_bins):
        r = resid[which == b]
        if len(r) == 0:
            continue
        se = r.std(axis=0, ddof=1) / np.sqrt(len(r)) if len(r) > 1 else np.full(3, np.nan)
        out.append({"from": float(edges[b]), "to": float(edges[b + 1]), "n": int(len(r)),
                    "mean_xyz_mm": [float(v) for v in r.mean(axis=0)],
                    "stderr_xyz_mm": [float(v) for v in se]})
    return out


def maps_2d(ds: Dataset, resid: np.ndarray, n_bins: int = N_MAP_BINS) -> dict:
    """Mean of each residual component over a grid of cells in each pair of axes."""
    out = {}
    for i, j in ((0, 1), (0, 2), (1, 2)):
        a, b = ds.q[:, i], ds.q[:, j]
        if np.ptp(a) == 0 or np.ptp(b) == 0:
            continue
        ea, eb = np.linspace(a.min(), a.max(), n_bins + 1), np.linspace(b.min(), b.max(), n_bins + 1)
        ia = np.clip(np.searchsorted(ea, a, side="right") - 1, 0, n_bins - 1)
        ib = np.clip(np.searchsorted(eb, b, side="right") - 1, 0, n_bins - 1)
        cell = ia * n_bins + ib
        n = np.bincount(cell, minlength=n_bins * n_bins)
        mean = np.full((3, n_bins, n_bins), np.nan)
        for c in range(3):
            sums = np.bincount(cell, weights=resid[:, c], minlength=n_bins * n_bins)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean[c] = np.where(n > 0, sums / np.maximum(n, 1), np.nan).reshape(n_bins, n_bins)
        out[AXES[i] + AXES[j]] = {"edges_mm": [[float(v) for v in ea], [float(v) for v in eb]],
                                  "n": n.reshape(n_bins, n_bins).tolist(),
                                  "mean_mm": {AXES[c].lower(): [[None if not np.isfinite(v) else float(v)
                                                                 for v in row] for row in mean[c]]
                                              for c in range(3)}}
    return out


def by_tool(ds: Dataset, resid: np.ndarray) -> list[dict]:
    """Residual per distinct tool vector."""
    tools, inv = np.unique(np.round(ds.r, 3), axis=0, return_inverse=True)
    if len(tools) < 2:
        return []
    out = []
    for k, t in enumerate(tools):
        r = resid[inv.ravel() == k]
        out.append({"tool_mm": [float(v) for v in t], "n": int(len(r)),
                    "mean_xyz_mm": [float(v) for v in r.mean(axis=0)],
                    "rms_mm": float(np.sqrt(np.mean(np.sum(r**2, axis=1))))})
    return out


def by_approach(ds: Dataset, resid: np.ndarray) -> list[dict]:
    """Residual per combination of approach directions (dirx, diry, dirz)."""
    cols = [c for c in DIR_COLUMNS if c in ds.ctx]
    if not cols:
        return []
    key = np.column_stack([ds.ctx[c] for c in cols])
    pats, inv = np.unique(key, axis=0, return_inverse=True)
    if len(pats) < 2:
        return []
    out = []
    for k, p in enumerate(pats):
        r = resid[inv.ravel() == k]
        se = r.std(axis=0, ddof=1) / np.sqrt(len(r)) if len(r) > 1 else np.full(3, np.nan)
        out.append({"approach": {c: int(v) for c, v in zip(cols, p, strict=True)}, "n": int(len(r)),
                    "mean_xyz_mm": [float(v) for v in r.mean(axis=0)],
                    "stderr_xyz_mm": [float(v) for v in se]})
    return out


def where_it_fails(ds: Dataset, resid: np.ndarray) -> dict:
    return {
        "worst": worst_points(ds, resid),
        "by_region": by_region(ds, resid),
        "by_direction": by_direction(ds, resid),
        "along_time": binned(ds.ctx["t"], resid) if "t" in ds.ctx and np.ptp(ds.ctx["t"]) > 0 else [],
        "context": against_context(ds, resid),
        "binned_means": {a: binned_means(ds.q[:, j], resid) for j, a in enumerate(AXES) if np.ptp(ds.q[:, j]) > 0},
        "maps_2d": maps_2d(ds, resid),
        "by_tool": by_tool(ds, resid),
        "by_approach": by_approach(ds, resid),
    }
