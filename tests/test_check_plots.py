"""The plots of 'check' a metrologist reads at a glance: one colour scale
across the residual map panels, counts per cell, a periodogram threshold that accounts for
the effects still open, and a 3-D view of exaggerated error vectors with a printed scale."""

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from postproc.diagnose import vm  # noqa: E402
from postproc.diagnose.plots import (  # noqa: E402
    periodogram_level,
    plot_map,
    plot_periodogram,
    plot_residual_slices,
    write_plots,
)
from postproc.effects.periodic import periodogram, search_frequencies  # noqa: E402


def test_residual_maps_share_one_colour_scale_and_show_counts(tmp_path):
    mach = vm.machine_with([{"name": "backlash:X", "params": {"b_mm": 0.012}}])
    res = vm.check_campaign(vm.campaign("random", 3, machine=mach), max_selected=1, offer_empirical=False)
    written = {p.name for p in write_plots(res, tmp_path)}
    assert {"residual_slices.png", "residual_map_XY.png", "periodogram_Y.png"} <= written
    assert "residual_vectors.png" not in written  # the unreadable 3-D quiver is gone
    maps = res.where["maps_2d"]
    ax = plot_map(res.ds.q, res.resid, "XY", maps["XY"], limit_um=20.0)
    fig = ax.figure
    panels = [a for a in fig.axes if a.collections and a.get_title().startswith("mean")]
    assert len(panels) == 3
    assert {p.collections[0].get_clim() for p in panels} == {(-20.0, 20.0)}
    counts = np.asarray(maps["XY"]["n"])
    texts = sorted(int(t.get_text()) for t in panels[0].texts)
    assert texts == sorted(int(v) for v in counts.ravel() if v)
    # without a shared limit given, the three panels still share one
    ax = plot_map(res.ds.q, res.resid, "XZ", maps["XZ"])
    clims = {a.collections[0].get_clim() for a in ax.figure.axes if a.collections and a.get_title().startswith("mean")}
    assert len(clims) == 1


def test_periodogram_threshold_accounts_for_open_effects():
    """A warm-up drift left open in the residual (sorted in time, random in position) raises
    the periodogram everywhere; the line drawn from the instrument noise would be crossed by
    many peaks, the line from the background by none beyond its 0.1 % level."""
    rng = np.random.default_rng(4)
    crossings_noise, crossings_bg = 0, 0
    for _ in range(20):
        x = rng.uniform(0, 315, 240)
        t = np.arange(240) * 30.0
        y = rng.normal(0, 0.005, 240) + 0.015 * (1 - np.exp(-t / 2400.0)) + 0.006 * rng.choice([-1, 1], 240)
        freqs = search_frequencies(x)
        p = periodogram(x, y, freqs)
        m = np.ptp(x) * (freqs[-1] - freqs[0])
        crossings_noise += int(np.any(p > 0.005**2 * np.log(m / 1e-3)))
        crossings_bg += int(np.any(p > periodogram_level(p, m)))
    assert crossings_noise >= 15
    assert crossings_bg <= 1
    ax = plot_periodogram(x, y, "X", sigma_mm=0.005)
    assert any("open effects" in t.get_text() for t in ax.get_legend().get_texts())


def test_3d_view_exaggerates_vectors_on_slices_with_a_printed_scale():
    rng = np.random.default_rng(2)
    q = rng.uniform(0, 300, (150, 3))
    resid = rng.normal(0, 0.004, (150, 3))
    ax = plot_residual_slices(q, resid)
    title = ax.get_title()
    assert "magnified x" in title
    assert "3 Z slices" in title
    assert any(t.get_text().endswith(" um") for t in ax.texts)  # the scale bar's label
    assert len(ax.get_legend().get_texts()) == 3
