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


# Horizontal slices of the 3-D view (bottom, middle, top of the measured Z extent) ...
N_SLICES = 3
# ... each holding the points within this fraction of the Z extent of its level.
SLICE_HALF_WIDTH = 1.0 / 6.0
# The largest drawn error vector is this fraction of the volume's largest side.
VECTOR_FRACTION = 0.12


def nice_length(x: float) -> float:
    """1, 2 or 5 times a power of ten, at most ``x`` (a scale bar's length)."""
    if not x > 0:
        return 1.0
    p = 10.0 ** np.floor(np.log10(x))
    return float(max(m * p for m in (1, 2, 5) if m * p <= x))


def slice_levels(z: np.ndarray, n: int = N_SLICES) -> list[tuple[float, np.ndarray]]:
    """(level, row mask) of ``n`` slices across the Z extent of the points."""
    lo, span = float(z.min()), float(np.ptp(z))
    if span == 0:
        return [(lo, np.ones(len(z), dtype=bool))]
    out = []
    for level in np.linspace(lo, lo + span, n):
        mask = np.abs(z - level) <= SLICE_HALF_WIDTH * span + 1e-9
        if mask.any():
            out.append((float(level), mask))
    return out


def plot_residual_slices(q: np.ndarray, resid: np.ndarray, ax=None):
    """3-D view of the residual: error vectors on a few horizontal slices of the volume,
    exaggerated by a stated factor, with a printed scale bar (a vector of a round number
    of micrometres drawn at the same exaggeration)."""
    ax = _axes(ax, "3d")
    span = float(np.max(np.ptp(q, axis=0))) or 1.0
    norm = np.linalg.norm(resid, axis=1)
    biggest = float(norm.max()) if len(norm) else 0.0
    k = VECTOR_FRACTION * span / (biggest or 1.0)
    k = nice_length(k)  # a round exaggeration, printed
    for level, mask in slice_levels(q[:, 2]):
        qs, rs = q[mask], resid[mask] * k
        line = ax.plot([], [], [], "-", lw=0.6)[0]
        color = line.get_color()
        ax.scatter(qs[:, 0], qs[:, 1], np.full(len(qs), level), s=4, color=color)
        ax.quiver(qs[:, 0], qs[:, 1], np.full(len(qs), level), rs[:, 0], rs[:, 1], rs[:, 2],
                  color=color, arrow_length_ratio=0.25, linewidth=0.9, label=f"Z {level:.0f} mm (n {len(qs)})")
    bar_um = nice_length(biggest * 1000 / 2) if biggest else 1.0
    lo = q.min(axis=0)
    ax.quiver(lo[0], lo[1] - 0.08 * span, q[:, 2].min(), bar_um / 1000 * k, 0, 0, color="k", linewidth=2,
              arrow_length_ratio=0.15)
    ax.text(lo[0], lo[1] - 0.14 * span, q[:, 2].min(), f"{bar_um:g} um", color="k")
    ax.set_xlabel("X mm")
    ax.set_ylabel("Y mm")
    ax.set_zlabel("Z mm")
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title(f"residual vectors on {N_SLICES} Z slices, magnified x{k:g} (bar: {bar_um:g} um; "
                 f"largest {biggest * 1000:.1f} um)", fontsize="medium")
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
# ln 2: the median of an exponential distribution of mean 1 (the white-noise periodogram).
LN2 = float(np.log(2.0))


def periodogram_level(power: np.ndarray, n_independent: float, alpha: float = PERIODOGRAM_ALPHA) -> float:
    """The power a background peak exceeds with probability ``alpha`` over
    ``n_independent`` frequencies. The background is the periodogram's own median
    (/ ln 2), not the instrument's noise: effects still open in the residual (a drift, a
    reversal, a shape) raise it at every pitch, and a line drawn at the instrument's noise
    would be crossed by a dozen of their peaks."""
    background = float(np.median(power)) / LN2 if len(power) else 0.0
    return background * float(np.log(max(n_independent, 1.0) / alpha))


def plot_periodogram(x: np.ndarray, y: np.ndarray, axis: str, ax=None, sigma_mm: float | None = None,
                     label: str = "residual", y_after: np.ndarray | None = None):
    """Periodogram of the residual along an axis against that axis's position, by pitch,
    with the level its background exceeds at PERIODOGRAM_ALPHA over all pitches
    (:func:`periodogram_level`; about travel * frequency span independent frequencies).
    ``y_after``: the held-out residual the suggestions leave, drawn beside it;
    ``sigma_mm`` (the instrument's noise) is drawn for reference."""
    ax = _axes(ax)
    freqs = search_frequencies(x)
    if len(freqs):
        power = periodogram(x, y, freqs)
        ax.plot(1.0 / freqs, power * 1e6, lw=0.9, label=label)
        if y_after is not None:
            ax.plot(1.0 / freqs, periodogram(x, y_after, freqs) * 1e6, lw=0.9, alpha=0.8,
                    label="held-out residual after the suggestions")
        ax.set_xscale("log")
        m = max(1.0, float(np.ptp(x)) * float(freqs[-1] - freqs[0]))
        level = periodogram_level(power, m)
        ax.axhline(level * 1e6, color="r", ls="--", lw=0.8,
                   label=f"p = {PERIODOGRAM_ALPHA:g} over all pitches (background incl. open effects)")
        if sigma_mm:
            ax.axhline(sigma_mm**2 * 1e6, color="0.5", ls=":", lw=0.8, label="instrument noise (mean power)")
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


def map_limit_um(maps: dict) -> float:
    """One colour limit (um) for every residual map panel: the largest |cell mean|."""
    values = [abs(v) for cells in maps.values() for rows in cells["mean_mm"].values()
              for row in rows for v in row if v is not None]
    return max(values) * 1000 if values else 1.0


def plot_map(ds_q: np.ndarray, resid: np.ndarray, pair: str, cells: dict, figure=None,
             limit_um: float | None = None, sigma_um: float | None = None):
    """2-D residual map: the mean of each component over cells of two axes (um), on one
    colour scale for the three panels (``limit_um``, shared with the other maps when given),
    with the number of points in each cell written in it: a mean of n points scatters by
    sigma / sqrt(n), so a sparse cell's colour is mostly noise."""
    from matplotlib.figure import Figure

    fig = figure or Figure(figsize=(13, 4.4), layout="constrained")
    axes = fig.subplots(1, 3)
    ea, eb = (np.asarray(e) for e in cells["edges_mm"])
    counts = np.asarray(cells["n"])
    grids = {c: np.array([[np.nan if v is None else v * 1000 for v in row] for row in cells["mean_mm"][c]])
             for c in "xyz"}
    lim = limit_um or max((float(np.nanmax(np.abs(g))) for g in grids.values() if np.isfinite(g).any()),
                          default=1.0)
    for c, ax in zip("xyz", axes, strict=True):
        im = ax.pcolormesh(ea, eb, grids[c].T, cmap="coolwarm", vmin=-lim, vmax=lim)
        for i in range(counts.shape[0]):
            for j in range(counts.shape[1]):
                if counts[i, j]:
                    ax.text(0.5 * (ea[i] + ea[i + 1]), 0.5 * (eb[j] + eb[j + 1]), str(counts[i, j]),
                            ha="center", va="center", fontsize=7, color="k")
        ax.set_xlabel(f"{pair[0]} mm")
        ax.set_ylabel(f"{pair[1]} mm")
        ax.set_title(f"mean {c} residual over {pair}")
    fig.colorbar(im, ax=list(axes), label="mean residual um (one scale for all panels)")
    noise = f"; a cell of n points scatters by {sigma_um:.1f}/sqrt(n) um" if sigma_um else ""
    fig.suptitle(f"numbers: points per cell{noise}", fontsize="small")
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

    rk = res.ranking
    save(plot_residual_slices(ds.q, resid), "residual_slices.png")
    after = None
    if rk is not None and rk.selected and rk.final_cv_resid is not None:
        after = rk.final_cv_resid  # what the suggestions leave
    for j, a in enumerate(AXES):
        save(plot_residual_vs(ds.q[:, j], resid, f"{a} mm"), f"residual_vs_{a}.png")
        sigma = res.noise.sigma_mm[j] if res.noise.sigma_mm else None
        save(plot_periodogram(ds.q[:, j], resid[:, j], a, sigma_mm=sigma, label="residual of the calibration",
                              y_after=None if after is None else after[:, j]), f"periodogram_{a}.png")
    for name, v in sorted(ds.ctx.items()):
        if np.ptp(v) > 0:
            save(plot_residual_vs(v, resid, name), f"residual_vs_{name}.png")
    maps = res.where.get("maps_2d", {})
    limit = map_limit_um(maps)
    sigma_um = float(np.mean(res.noise.sigma_mm)) * 1000 if res.noise.sigma_mm else None
    for pair, cells in maps.items():
        save(plot_map(ds.q, resid, pair, cells, limit_um=limit, sigma_um=sigma_um), f"residual_map_{pair}.png")
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
