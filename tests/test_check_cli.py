import json
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.calibration.measurements import format_measurements, read_measurements
from postproc.cli import main
from postproc.diagnose import demo
from postproc.diagnose.refit import fit_with_effects
from postproc.diagnose.synthetic import SPECS, make_data
from postproc.errors import EXIT_INPUT

SAMPLE = Path(__file__).parents[1] / "samples" / "walkthrough_points.csv"


def run(args, cwd):
    result = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return result


@pytest.fixture
def walk(tmp_path, monkeypatch):
    shutil.copy(SAMPLE, tmp_path / SAMPLE.name)
    monkeypatch.chdir(tmp_path)
    res = run(["fit", SAMPLE.name, "--method", "static", "-o", "walk.json"], tmp_path)
    assert res.exit_code == 0, res.output
    return tmp_path


def test_sample_is_reproducible():
    text = SAMPLE.read_text()
    regenerated = format_measurements(demo.walkthrough_points(), comments=text.splitlines()[2:4])
    assert regenerated.replace("# ", "").splitlines()[4:] == text.splitlines()[4:]


def test_walkthrough_suggest_add_and_check_again(walk):
    res = run(["check", SAMPLE.name, "-c", "walk.json", "--json", "--folds", "4"], walk)
    assert res.exit_code == 0, res.output
    before = json.loads(res.stdout)
    assert before["n_points"] == 240
    assert before["noise_floor_mm"] == pytest.approx(demo.SIGMA_MM * np.sqrt(3), rel=0.15)
    (sug,) = before["suggestions"]
    assert sug["effect"] == "backlash:X"
    assert sug["parameters"]["b_mm"] == pytest.approx(demo.BACKLASH_X_MM, abs=0.001)
    assert 0.5 < sug["explained"] <= 1
    assert sug["rms_after_mm"] < 1.15 * before["noise_floor_mm"]
    args = shlex.split(sug["command"])
    assert args[:2] == ["postproc", "fit"]
    assert "--effect" in args
    res = run(args[1:], walk)
    assert res.exit_code == 0, res.output
    out = args[args.index("-o") + 1]
    cal = load_calibration(out)
    assert [e["name"] for e in cal.effects] == ["backlash:X"]
    res = run(["check", SAMPLE.name, "-c", out, "--json", "--folds", "4"], walk)
    after = json.loads(res.stdout)
    assert after["suggestions"] == []
    assert after["rms_mm"] < 0.5 * before["rms_mm"]
    assert after["cv_rms_mm"] < 1.15 * after["noise_floor_mm"]
    assert after["effects_in_calibration"] == ["backlash:X"]


def test_text_report_says_where(walk):
    res = run(["check", SAMPLE.name, "-c", "walk.json", "--folds", "3"], walk)
    assert res.exit_code == 0, res.output
    text = res.stdout
    assert f"{SAMPLE.name}:" in text.split("worst points:")[1].splitlines()[1]
    x_line = next(line for line in text.splitlines() if line.strip().startswith("X: +1"))
    assert "reversal error" in x_line
    assert "1. backlash:X" in text
    assert "load:load: no load column" in text


def test_plots_and_declared_sigma(walk):
    res = run(["check", SAMPLE.name, "-c", "walk.json", "--json", "--folds", "3", "--sigma", "0.002",
               "--plot", "plots"], walk)
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["noise_floor_source"] == "declared"
    assert data["noise_floor_mm"] == pytest.approx(0.002 * np.sqrt(3))
    names = {p.name for p in (walk / "plots").iterdir()}
    assert {"residual_slices.png", "before_after.png", "periodogram_X.png", "residual_vs_t.png",
            "residual_vs_temp.png", "residual_map_XY.png", "residual_map_YZ.png",
            "after_suggestions_vs_X.png"} <= names
    assert all((walk / "plots" / n).stat().st_size > 1000 for n in names)


def test_missing_columns_are_clear_errors(walk):
    res = run(["fit", SAMPLE.name, "--effect", "load:load", "-o", "x.json"], walk)
    assert res.exit_code == EXIT_INPUT
    assert "load:load" in res.output
    assert "no load column" in res.output
    res = run(["fit", SAMPLE.name, "--effect", "wobble:X", "-o", "x.json"], walk)
    assert res.exit_code != 0
    assert "unknown effect" in res.output
    # a calibration with a thermal effect checked against data without a t column
    res = run(["fit", SAMPLE.name, "--effect", "thermal:t", "-o", "thermal.json"], walk)
    assert res.exit_code == 0, res.output
    meas = read_measurements(SAMPLE.name)
    meas.context.pop("t")
    Path("no_t.csv").write_text(format_measurements(meas))
    res = run(["check", "no_t.csv", "-c", "thermal.json"], walk)
    assert res.exit_code == EXIT_INPUT
    assert "'t'" in res.output


def test_alternating_refit_for_a_non_linear_method():
    meas, (truth,) = make_data([(SPECS["backlash:X"], 4.0)], seed=9, n_points=60)
    res = fit_with_effects("parametric", [meas], ["backlash:X"])
    (eff,) = res.effects
    assert eff["name"] == "backlash:X"
    assert eff["params"]["b_mm"] == pytest.approx(truth.params["b_mm"], rel=0.1)
    plain = fit_with_effects("parametric", [meas], [])
    assert res.rms_mm < 0.7 * plain.rms_mm


def test_interval_calibration_is_refitted_with_its_own_partition(walk):
    res = run(["fit", SAMPLE.name, "--method", "interval", "--intervals", "X=2;Y=2;Z=2", "-o", "wi.json"], walk)
    assert res.exit_code == 0, res.output
    res = run(["check", SAMPLE.name, "-c", "wi.json", "--json", "--folds", "4", "--max-effects", "1"], walk)
    data = json.loads(res.stdout)
    assert data["cv_rms_mm"] is not None, data["cv_note"]
    (sug,) = data["suggestions"]
    assert sug["effect"] == "backlash:X"
    args = shlex.split(sug["command"])
    assert args[args.index("--method") + 1] == "interval"
    assert "--intervals" in args
    res = run(args[1:], walk)
    assert res.exit_code == 0, res.output
    assert load_calibration(args[args.index("-o") + 1]).effects[0]["name"] == "backlash:X"


def test_fixed_ranks_effects_on_the_calibration_as_it_is(tmp_path, monkeypatch):
    from postproc.calfile import save_calibration
    from postproc.diagnose.synthetic import static_machine

    monkeypatch.chdir(tmp_path)
    # calibrated cold (the true geometry), measured while warming up
    save_calibration("cold.json", static_machine())
    meas, (truth,) = make_data([(SPECS["thermal:t"], 3.0)], seed=31)
    Path("warm.csv").write_text(format_measurements(meas))
    res = run(["check", "warm.csv", "-c", "cold.json", "--fixed", "--no-register", "--json", "--folds", "4"],
              tmp_path)
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert "held fixed" in data["cv_note"]
    assert data["registration"] is None
    assert data["cv_rms_mm"] == pytest.approx(data["rms_mm"])  # nothing refitted
    assert data["suggestions"][0]["effect"] == "thermal:t"
    assert data["suggestions"][0]["config"]["tau_s"] == pytest.approx(truth.config["tau_s"], rel=0.3)
    assert data["cv_rms_after_mm"] < 1.15 * data["noise_floor_mm"]
    # registered (the default with --fixed): the drift's settled part is a frame offset, its
    # transient is still the warm-up
    res = run(["check", "warm.csv", "-c", "cold.json", "--fixed", "--json", "--folds", "4"], tmp_path)
    data = json.loads(res.stdout)
    assert data["registration"] is not None
    assert data["suggestions"][0]["effect"] == "thermal:t"
    assert data["cv_rms_after_mm"] < 1.15 * data["noise_floor_mm"]


def test_effect_with_axis_tables_is_a_usage_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tables = Path(__file__).parents[1] / "calibrations" / "s500_tables.csv"
    if not tables.exists():
        pytest.skip("no S500 tables in calibrations/")
    res = run(["fit", str(tables), "--effect", "thermal:t", "-o", "x.json"], tmp_path)
    assert res.exit_code == 2
    assert "--effect is fitted from point measurements" in res.output
    assert not Path("x.json").exists()
