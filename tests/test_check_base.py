"""Re-checks know their base: a calibration written by 'fit --base' records what was held
fixed, and 'check' on it uses that record without flags."""

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from postproc.calibration.measurements import format_measurements
from postproc.cli import main
from postproc.simulate import Machine, load_machine, measurement_plan, random_points, simulate_plan

ROOT = Path(__file__).parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
TABLES_CAL = ROOT / "calibrations" / "s500_parametric.json"


def run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def test_check_of_a_fit_base_calibration_holds_its_base_without_flags(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    base = load_machine(MACHINE)
    mach = Machine(base.geometry, effects=[{"name": "backlash:X", "params": {"b_mm": 0.012}}], noise=base.noise)
    rng = np.random.default_rng(31)
    plan = measurement_plan(random_points(mach.volume_mm, 60, rng), tool_vectors=[(0, 0, -100)],
                            approach="both", repeats=2, time_span_s=3 * 3600)
    Path("pts.csv").write_text(format_measurements(simulate_plan(mach, plan, rng)))
    Path("tables.json").write_text(TABLES_CAL.read_text())
    res = run(["fit", "--base", "tables.json", "pts.csv", "--effect", "backlash:X", "-o", "ext.json"])
    assert res.exit_code == 0, res.output
    record = json.loads(Path("ext.json").read_text())["fit"]["fixed"]
    assert record["base"] == "tables.json"
    assert record["fitted_effects"] == ["backlash:X"]
    assert record["held"][0].startswith("the parametric model")

    text = run(["check", "pts.csv", "-c", "ext.json"]).output
    lines = [ln for ln in text.splitlines() if ln.startswith("made by 'fit --base tables.json'")]
    assert len(lines) == 1, text
    assert "backlash:X" in lines[0]
    data = json.loads(run(["check", "pts.csv", "-c", "ext.json", "--json"]).stdout)
    assert data["fixed_from_file"]["fitted_effects"] == ["backlash:X"]
    assert data["verdict"] == "consistent", data["verdict"]
    assert data["cv_rms_mm"] < 1.15 * data["noise_floor_mm"]
    # the added effect is refitted on the training folds, not held: it is listed as in the model
    assert any(c["effect"] == "backlash:X" and c["status"] == "in model" for c in data["candidates"])

    # --no-fixed refits the whole method, as before
    refit = json.loads(run(["check", "pts.csv", "-c", "ext.json", "--json", "--no-fixed"]).stdout)
    assert refit["fixed_from_file"] is None

    # a file written before the record existed is read from its fit.base
    old = json.loads(Path("ext.json").read_text())
    del old["fit"]["fixed"]
    Path("old.json").write_text(json.dumps(old))
    legacy = json.loads(run(["check", "pts.csv", "-c", "old.json", "--json"]).stdout)
    assert legacy["fixed_from_file"]["fitted_effects"] == ["backlash:X"]
    assert legacy["verdict"] == "consistent"
