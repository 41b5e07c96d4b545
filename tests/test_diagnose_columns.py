"""Temperature, load and time columns are checked before they are used:
a column logged in few rows, or by sample and hold, is warned about with its count and
interpolated in time where a time column exists; a fit that depends on it says so in the
calibration's notes."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calibration.measurements import format_measurements
from postproc.cli import main
from postproc.diagnose import vm
from postproc.diagnose.data import screen_columns


def run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def warm(t):
    return 23.0 - 3.0 * np.exp(-t / 2400.0)


def write_with_gaps(meas, path: Path, column: str, keep: np.ndarray) -> None:
    """The campaign as a CSV file whose ``column`` is empty except in rows ``keep``."""
    lines = format_measurements(meas).splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    j = lines[head].split(",").index(column)
    for i in range(len(meas.q)):
        if i not in keep:
            cells = lines[head + 1 + i].split(",")
            cells[j] = ""
            lines[head + 1 + i] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def test_screen_columns_interpolates_sparse_and_held_columns_in_time():
    t = np.arange(240) * 30.0
    temp = warm(t)
    sparse = np.full(240, np.nan)
    sparse[[0, 60, 120, 180, 239]] = temp[[0, 60, 120, 180, 239]]
    held = temp[np.searchsorted(np.floor(t / 1200), np.floor(t / 1200))]
    load = np.full(240, np.nan)
    load[::10] = np.repeat([0.0, 500.0], 12)
    ctx, notes = screen_columns({"t": t, "temp": sparse, "temp_air": held, "load": load})
    by = {n["column"]: n for n in notes}
    assert by["temp"]["present"] == 5
    assert by["temp"]["kind"] == "sparse"
    assert "present in 5 of 240 rows" in by["temp"]["message"]
    assert np.max(np.abs(ctx["temp"] - temp)) < 0.25  # linear between 5 readings of a warm-up
    assert by["temp_air"]["kind"] == "held"
    assert by["temp_air"]["changes"] == 6
    assert np.max(np.abs(ctx["temp_air"] - temp)) < np.max(np.abs(held - temp)) / 3
    assert by["load"]["kind"] == "sparse"
    assert set(np.unique(ctx["load"])) == {0.0, 500.0}  # a setting is held, never interpolated
    # without a time column a gappy column is not used, and that is said
    ctx, notes = screen_columns({"temp": sparse})
    assert "temp" not in ctx
    assert notes[0]["used"] is False
    assert "no time column" in notes[0]["message"]
    # a column logged per shot is left alone
    ctx, notes = screen_columns({"t": t, "temp": temp + np.random.default_rng(1).normal(0, 0.02, 240)})
    assert notes == []


def test_sparse_temperature_is_warned_about_used_and_noted_in_the_calibration(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mach = vm.machine_with([{"name": "thermal:temp", "params": {"kx_mm_per_C": 0.0, "ky_mm_per_C": 0.0,
                                                                "kz_mm_per_C": 0.008}}])
    meas = vm.campaign("random", 5, machine=mach, context={"temp": lambda t, rng: warm(t)}, frame=False)
    keep = np.arange(0, len(meas.q), len(meas.q) // 5)[:5]
    write_with_gaps(meas, tmp_path / "pts.csv", "temp", set(keep.tolist()))
    vm.write_tables_calibration("tables.json")
    text = run(["check", "pts.csv", "-c", "tables.json", "--fixed"]).output
    assert "temp is present in 5 of 240 rows (fewer than 80%): interpolated linearly in time" in text, text
    res = run(["fit", "--base", "tables.json", "pts.csv", "--effect", "thermal:temp", "-o", "cal.json"])
    assert res.exit_code == 0, res.output
    assert "note: thermal:temp depend(s) on temp is present in 5 of 240 rows" in res.output
    notes = json.loads(Path("cal.json").read_text())["fit"]["notes"]
    assert len(notes) == 1
    assert "5 of 240" in notes[0]
    fitted = json.loads(Path("cal.json").read_text())["effects"][-1]["params"]["kz_mm_per_C"]
    assert fitted == pytest.approx(0.008, rel=0.25)


def test_sample_and_hold_temperature_is_warned_about_and_interpolated(tmp_path, monkeypatch):
    """Logged every 20 min while it ramps: said with its count, interpolated, and the expansion fitted."""
    monkeypatch.chdir(tmp_path)
    ramp = lambda t: 20.0 + 4.0 * t / 7200.0  # noqa: E731
    mach = vm.machine_with([{"name": "expansion:temp", "params": {"ax_per_C": 2.5e-5, "ay_per_C": 0.0,
                                                                  "az_per_C": 0.0}}])

    def held(t, rng):
        k = np.floor(t / 1200.0)
        return ramp(t), ramp(t)[np.searchsorted(k, k)]
    meas = vm.campaign("random", 6, machine=mach, context={"temp": held}, frame=False)
    Path("pts.csv").write_text(format_measurements(meas))
    vm.write_tables_calibration("tables.json")
    res = run(["fit", "--base", "tables.json", "pts.csv", "--effect", "expansion:temp", "-o", "cal.json"])
    assert res.exit_code == 0, res.output
    assert "temp is piecewise constant: 6 values over 240 rows (sample and hold, about every 20 min)" in res.output
    a = json.loads(Path("cal.json").read_text())["effects"][-1]["params"]["ax_per_C"]
    assert a == pytest.approx(2.5e-5, rel=0.12)


def test_sample_and_hold_in_a_fast_warm_up_documents_its_bias():
    """Issue 30 reported a temperature logged every 20 min giving an expansion 30 % low with
    no warning. Tried where it should be worst, a 2 K/h warm-up, 12 ppm/K in X, logged by
    sample and hold every 20 min over the 2 h campaign: it does not reproduce. Measured on
    seeds 1-3: per-shot logging 91-98 % of the truth (the registration takes a little of the
    expansion's mean), the held column interpolated in time 92-102 %, the held column used
    as it is (no time column) 95-106 %; an exponential warm-up of 3 K (1 h) 85-95 % in all
    three. The held column is warned about and interpolated; the fitted size stays within
    15 % of the truth either way."""
    mach = vm.machine_with([{"name": "expansion:temp", "params": {"ax_per_C": 1.2e-5, "ay_per_C": 0.0,
                                                                  "az_per_C": 0.0}}])

    def held(t, rng):
        v = 20.0 + 2.0 * t / 3600.0 + rng.normal(0, 0.02, len(t))
        k = np.floor(t / 1200.0)
        return v, v[np.searchsorted(k, k)]

    for drop_t in (False, True):
        meas = vm.campaign("random", 2, machine=mach, context={"temp": held})
        if drop_t:
            meas.context.pop("t")
        res = vm.check_campaign(meas, offer_empirical=False, candidates=["expansion:temp", "thermal:temp"])
        (sug,) = [s for s in res.suggestions if s["effect"] == "expansion:temp"]
        assert sug["parameters"]["ax_per_C"] == pytest.approx(1.2e-5, rel=0.15)
        held_notes = [w for w in res.warnings if w.get("kind") == "held"]
        if drop_t:
            assert not held_notes  # without a time column a hold cannot be told from a constant
        else:
            (note,) = held_notes
            assert "sample and hold, about every 20 min" in note["message"]
