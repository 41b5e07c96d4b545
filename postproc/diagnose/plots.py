"""Plots of a check (matplotlib is imported only here, inside each function).

Each ``plot_*(..., ax=None) -> ax``; :func:`write_plots` saves the set as PNGs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from postproc.effects.base import AXES
from postproc.effects.periodic import periodogram, search_frequencies


def _axes(ax, projection=None):
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 5), layout="constrained")
    return fig.add_subplot(projection=projection) if projection else fig.add_subplot()


def plot_residual_vectors(q: np.ndarray, resid: np.ndarray, ax=None):
    """Residual vectors at the commanded points, scaled so the largest is 10 % of the volume."""
    ax = _axes(ax, "3d")
    span = float(np.max(np.ptp(q, axis=0))) or 1.0
    norm = np.linalg.norm(resid, axis=1)
    k = 0.1 * span / (float(norm.max()) or 1.0)
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], resid[:, 0] * k, resid[:, 1] * k, resid[:, 2] * k,
              arrow_length_ratio=0.2, linewidth=0.8)
    ax.set_xlabel("X mm")
    ax.set_ylabel("Y mm")
    ax.set_zlabel("Z mm")
    ax.set_title(f"residual vectors (x{k:.0f}; largest {norm.max() * 1000:.1f} um)")
    return ax


def plot_residual_vs(values: np.ndarray, resid: np.ndarray, name: str, ax=None, title: str | None = None):
    """Residual components (um) against one variable, with binned means and their error
    bars (2 standard errors)."""
    from postproc.diagnose.where import binned_means

    ax = _axes(ax)
    bins = binned_means(values, resid)
    for j, a in enumerate(AXES):
        line = ax.plot(values, resid[:, j] * 1000, ".", ms=3, alpha=0.5, label=f"{a.lower()} residual")[0]
        if bins:
            mid = [0.5 * (b["from"] + b["to"]) for b in bins]
            mean = [b["mean_xyz_mm"][j] * 1000 for b in bins]
            err = [2 * b["stderr_xyz_mm"][j] * 1000 if np.isfinite(b["stderr_xyz_mm"][j]) else 0.0 for b in bins]
            ax.errorbar(mid, mean, yerr=err, fmt="o-", color=line.get_color(), ms=4, capsize=3, lw=1.2)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel(name)
    ax.set_ylabel("residual um")
    ax.legend(loc="best", fontsize="small")
    ax.set_title(title or f"residual vs {name} (binned means +- 2 standard errors)")
    return ax


# Family-wise level of the periodogram's significance line (over all pitches searched).
PERIODOGRAM_ALPHA = 1e-3


def plot_periodogram(x: np.ndarray, y: np.ndarray, axis: str, ax=None, sigma_mm: float | None = None):
    """Periodogram of the residual along an axis against that axis's position, by pitch,
    with the level white noise of ``sigma_mm`` exceeds at PERIODOGRAM_ALPHA over all pitches
    (the power at one frequency is sigma^2 * Exp(1); about travel * frequency span
    independent frequencies)."""
    ax = _axes(ax)
    freqs = search_frequencies(x)
    if len(freqs):
        ax.plot(1.0 / freqs, periodogram(x, y, freqs) * 1e6)
        ax.set_xscale("log")
        s2 = sigma_mm**2 if sigma_mm else float(np.var(y))
        m = max(1.0, float(np.ptp(x)) * float(freqs[-1] - freqs[0]))
        level = s2 * np.log(m / PERIODOGRAM_ALPHA) * 1e6
        ax.axhline(level, color="r", ls="--", lw=0.8, label=f"p = {PERIODOGRAM_ALPHA:g} over all pitches")
        ax.legend(loc="best", fontsize="small")
    ax.set_xlabel(f"pitch (mm of {axis} travel)")
    ax.set_ylabel("power um^2")
    ax.set_title(f"periodogram of the {axis} residual along {axis}")
    return ax


def plot_before_after(labels: list[str], rms_mm: list[float], floor_mm: float | None, ax=None):
    """Cross-validated RMS before and after each added effect, with the noise floor."""
    ax = _axes(ax)
    ax.bar(range(len(labels)), [v * 1000 for v in rms_mm])
    ax.set_xticks(range(len(labels)), labels, rotation=20, ha="right")
    if floor_mm:
        ax.axhline(floor_mm * 1000, color="r", ls="--", label="noise floor")
        ax.legend()
    ax.set_ylabel("cross-validated RMS um")
    ax.set_title("before / after")
    return ax


def plot_map(ds_q: np.ndarray, resid: np.ndarray, pair: str, cells: dict, figure=None):
    """2-D residual map: the mean of each component over cells of two axes (um)."""
    from matplotlib.figure import Figure

    fig = figure or Figure(figsize=(12, 4), layout="constrained")
    axes = fig.subplots(1, 3)
    ea, eb = (np.asarray(e) for e in cells["edges_mm"])
    for c, ax in zip("xyz", axes, strict=True):
        grid = np.array([[np.nan if v is None else v * 1000 for v in row] for row in cells["mean_mm"][c]])
        lim = float(np.nanmax(np.abs(grid))) if np.isfinite(grid).any() else 1.0
        im = ax.pcolormesh(ea, eb, grid.T, cmap="coolwarm", vmin=-lim, vmax=lim)
        fig.colorbar(im, ax=ax, label="um")
        ax.set_xlabel(f"{pair[0]} mm")
        ax.set_ylabel(f"{pair[1]} mm")
        ax.set_title(f"mean {c} residual over {pair}")
    return axes[0]


def write_plots(res, directory) -> list[Path]:
    """Write the check's plots as PNG files in ``directory``; returns their paths."""
    from postproc.fileio import save_figure

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    ds = res.ds
    resid = res.resid_registered if getattr(res, "resid_registered", None) is not None else res.resid
    written = []

    def save(ax, name):
        path = d / name
        save_figure(ax.figure, path, dpi=100)
        written.append(path)

    save(plot_residual_vectors(ds.q, resid), "residual_vectors.png")
    for j, a in enumerate(AXES):
        save(plot_residual_vs(ds.q[:, j], resid, f"{a} mm"), f"residual_vs_{a}.png")
        sigma = res.noise.sigma_mm[j] if res.noise.sigma_mm else None
        save(plot_periodogram(ds.q[:, j], resid[:, j], a, sigma_mm=sigma), f"periodogram_{a}.png")
    for name, v in sorted(ds.ctx.items()):
        if np.ptp(v) > 0:
            save(plot_residual_vs(v, resid, name), f"residual_vs_{name}.png")
    for pair, cells in res.where.get("maps_2d", {}).items():
        save(plot_map(ds.q, resid, pair, cells), f"residual_map_{pair}.png")
    rk = res.ranking
    if rk is not None and rk.selected and rk.final_cv_resid is not None:
        names = ", ".join(c.name for c in rk.selected)
        for j, a in enumerate(AXES):
            save(plot_residual_vs(ds.q[:, j], rk.final_cv_resid, f"{a} mm",
                                  title=f"held-out residual after {names} vs {a}"), f"after_suggestions_vs_{a}.png")
    if rk is not None:
        labels = ["calibration"] + [f"+ {c.name}" for c in rk.selected]
        values = [rk.base_cv_rms_mm] + [c.rms_after_mm for c in rk.selected]
        save(plot_before_after(labels, values, res.noise.rms_mm), "before_after.png")
    return written
