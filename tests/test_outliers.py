"""One outlier rule from check to the controller table.

The data come from the virtual machine (postproc.simulate: runs of an X axis with a
lead error and a reversal; the walkthrough's tracker campaign), with one gross reading
added as a glitch; never from the rule's own formula."""

import json
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from metrology_machines import TARGETS, write_runs, x_machine

from postproc.calfile import load_calibration
from postproc.calibration.measurements import format_measurements, read_measurements
from postproc.cli import main
from postproc.metrology.controllers.linuxcnc import read_linuxcnc
from postproc.metrology.outliers import runs_outliers
from postproc.simulate.runs import simulate_runs

SAMPLE = Path(__file__).parents[1] / "samples" / "walkthrough_points.csv"
I_162 = TARGETS.index(162.2)
GLITCH_MM = 0.080


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def forward_entry(cal, out, at=162.2) -> float:
    """The LinuxCNC forward entry (mm, type 0: actual position moving +) at ``at``."""
    res = run("export", cal, "-f", "linuxcnc", "-o", out, "--keep-outliers")
    assert res.exit_code == 0, res.output
    nominal, fwd_err, _ = read_linuxcnc((out / "joint0_X.comp").read_text(), 0)
    return float(fwd_err[np.argmin(np.abs(nominal - at))])


@pytest.fixture
def glitch(tmp_path):
    """Clean and glitched runs of the same machine and noise: one 80 um reading at 162.2 mm,
    run 3, approached in +."""
    machine = x_machine()
    clean, _ = write_runs(tmp_path / "clean.csv", machine, seed=3)
    bad, runs = write_runs(tmp_path / "glitch.csv", machine, seed=3, glitches={(I_162, 3, 1): GLITCH_MM})
    k = np.flatnonzero((runs.target_mm == 162.2) & (runs.run == 3) & (runs.direction == 1))[0]
    return tmp_path, clean, bad, int(runs.linenos[k])


def test_one_80um_reading_stays_out_of_the_controller_table(glitch):
    tmp, clean, bad, line = glitch
    for name, src, extra in (("clean", clean, []), ("kept", bad, ["--keep-outliers"]), ("excl", bad, [])):
        res = run("fit", src, "-o", tmp / f"{name}.json", *extra)
        assert res.exit_code == 0, res.output
        if name != "clean":
            assert f"glitch.csv:{line}: axis X, target 162.2 mm, run 3 (+): deviation" in res.stderr
    assert "excluded" in run("fit", bad, "-o", tmp / "x.json").stderr
    entry = {n: forward_entry(tmp / f"{n}.json", tmp / f"comp_{n}") for n in ("clean", "kept", "excl")}
    # kept: the 80 um reading moves the mean of five by 16 um; left out: the table is the clean one
    assert (entry["kept"] - entry["clean"]) * 1000 == pytest.approx(GLITCH_MM * 1000 / 5, abs=1.0)
    assert abs(entry["excl"] - entry["clean"]) * 1000 < 0.5
    kept = load_calibration(tmp / "kept.json").fit["outliers"]["kept"]
    assert [o["place"] for o in kept] == [f"{bad}:{line}"]


def test_export_refuses_a_calibration_fitted_from_an_outlier(glitch):
    tmp, _, bad, line = glitch
    cal = tmp / "kept.json"
    assert run("fit", bad, "--keep-outliers", "-o", cal).exit_code == 0
    out = tmp / "comp"
    res = run("export", cal, "-f", "linuxcnc", "-o", out)
    assert res.exit_code == 4
    assert "fitted from a reading beyond the outlier rule" in res.stderr
    assert f"glitch.csv:{line}" in res.stderr
    assert not out.exists()
    res = run("export", cal, "-f", "linuxcnc", "-o", out, "--keep-outliers")
    assert res.exit_code == 0
    assert "warning: kept (--keep-outliers)" in res.stderr
    # a calibration written before the rule was recorded: its runs file is read again
    data = json.loads(cal.read_text())
    del data["fit"]["outliers"]
    cal.write_text(json.dumps(data))
    res = run("export", cal, "-f", "linuxcnc", "-o", tmp / "comp2")
    assert res.exit_code == 4
    assert f"glitch.csv:{line}" in res.stderr
    # fitted without it: exported, and the export says what fit left out
    assert run("fit", bad, "-o", tmp / "excl.json").exit_code == 0
    res = run("export", tmp / "excl.json", "-f", "linuxcnc", "-o", tmp / "comp3")
    assert res.exit_code == 0, res.output
    assert f"excluded by fit (not in the calibration): {bad}:{line}" in res.stderr


def test_iso230_keeps_every_reading_and_flags_the_suspicious_one(glitch):
    tmp, clean, bad, line = glitch
    res = run("iso230", bad)
    assert res.exit_code == 0, res.output
    assert "suspicious" in res.output
    assert f"glitch.csv:{line}" in res.output
    assert "kept in the figures" in res.output
    js = json.loads(run("iso230", bad, "--json").stdout)["axes"]["X"]
    cl = json.loads(run("iso230", clean, "--json").stdout)["axes"]["X"]
    assert [s["place"] for s in js["suspicious"]] == [f"{bad}:{line}"]
    assert cl["suspicious"] == []
    t_bad = next(t for t in js["targets"] if t["target"] == 162.2)
    t_clean = next(t for t in cl["targets"] if t["target"] == 162.2)
    assert (t_bad["mean_up"] - t_clean["mean_up"]) == pytest.approx(GLITCH_MM / 5, abs=1e-9)  # all readings kept


def test_rule_false_alarm_rate_on_clean_runs():
    """40 clean campaigns of the virtual machine (110 readings each): the rule flags a clean
    reading in at most 5 % of them (designed for 0.1 %)."""
    machine = x_machine()
    flagged = sum(bool(runs_outliers(simulate_runs(machine, "X", TARGETS, rng=np.random.default_rng(100 + s))))
                  for s in range(40))
    assert flagged <= 2


def test_check_and_the_fit_it_suggests_exclude_the_same_glitch(tmp_path, monkeypatch):
    """The walkthrough campaign (virtual machine, 240 shots) with one shot 200 um off:
    check lists it as excluded, and the fit command it suggests leaves it out too, so the
    calibration is the clean campaign's."""
    monkeypatch.chdir(tmp_path)
    meas = read_measurements(SAMPLE)
    text = SAMPLE.read_text().splitlines()
    i = 100
    meas.m[i, 0] += 0.200
    Path("glitch.csv").write_text(format_measurements(meas, comments=[ln[2:] for ln in text[2:4]]))
    shutil.copy(SAMPLE, "clean.csv")
    line = int(read_measurements("glitch.csv").linenos[i])
    for name in ("clean", "glitch"):
        res = run("fit", f"{name}.csv", "--method", "static", "-o", f"{name}.json")
        assert res.exit_code == 0, res.output
    assert f"glitch.csv:{line}" in CliRunner().invoke(main, ["fit", "glitch.csv", "--method", "static",
                                                             "-o", "g2.json"]).stderr
    res = run("check", "glitch.csv", "-c", "glitch.json", "--json", "--folds", "3")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    places = [o["place"] for o in report["screening"]["outliers"]]
    assert places == [f"glitch.csv:{line}"]
    (sug,) = report["suggestions"]
    args = shlex.split(sug["command"])
    res = run(*args[1:])
    assert res.exit_code == 0, res.output
    assert f"glitch.csv:{line}" in res.stderr
    fitted = load_calibration(args[args.index("-o") + 1])
    assert [o["place"] for o in fitted.fit["outliers"]["excluded"]] == [f"glitch.csv:{line}"]
    # the same suggestion on the clean campaign: the two calibrations agree to a fraction of a micrometre
    res = run("fit", "clean.csv", *args[args.index("--method"):args.index("-o")], "-o", "clean_fx.json")
    assert res.exit_code == 0, res.output
    a, b = fitted.engine, load_calibration("clean_fx.json").engine
    q = np.random.default_rng(3).uniform(0, 315, (200, 3))
    ctx = {k: np.ones(200) for k in ("dirx", "diry", "dirz")}
    assert np.abs(a.forward(q, None, ctx) - b.forward(q, None, ctx)).max() < 0.5e-3


def test_check_fixed_and_fit_base_exclude_the_same_glitch(tmp_path, monkeypatch):
    """check --fixed suggests 'fit --base': both screen against the calibration as it is,
    the frame registered, and leave out the same shot."""
    monkeypatch.chdir(tmp_path)
    meas = read_measurements(SAMPLE)
    text = SAMPLE.read_text().splitlines()
    meas.m[37, 1] -= 0.200
    Path("glitch.csv").write_text(format_measurements(meas, comments=[ln[2:] for ln in text[2:4]]))
    line = int(read_measurements("glitch.csv").linenos[37])
    assert run("fit", "glitch.csv", "--method", "static", "-o", "base.json").exit_code == 0
    res = run("check", "glitch.csv", "-c", "base.json", "--fixed", "--json", "--folds", "3")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert [o["place"] for o in report["screening"]["outliers"]] == [f"glitch.csv:{line}"]
    (sug,) = report["suggestions"]
    args = shlex.split(sug["command"])
    assert "--base" in args
    res = run(*args[1:])
    assert res.exit_code == 0, res.output
    fitted = load_calibration(args[args.index("-o") + 1])
    assert [o["place"] for o in fitted.fit["outliers"]["excluded"]] == [f"glitch.csv:{line}"]
