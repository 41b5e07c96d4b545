"""A grid calibration can be cross-validated: training folds fill the nodes they leave empty."""

import json

from click.testing import CliRunner

from postproc.cli import main

MACHINE = "calibrations/s500.machine.json"


def test_check_cross_validates_a_grid_calibration(tmp_path, monkeypatch):
    from pathlib import Path

    monkeypatch.chdir(Path(__file__).parents[1])
    pts, cal = tmp_path / "g.csv", tmp_path / "g.json"
    run = CliRunner().invoke
    assert run(main, ["simulate", MACHINE, "--grid", "63", "--repeats", "2", "--seed", "4", "-o", str(pts)]).exit_code == 0
    assert run(main, ["fit", str(pts), "-m", "grid", "-o", str(cal)]).exit_code == 0
    result = run(main, ["check", str(pts), "-c", str(cal), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert "not possible" not in (data["cv_note"] or "")
    assert data["cv_folds"] >= 2
    # Held-out nodes are filled from neighbours 63 mm away: the cross-validated RMS must
    # exceed the in-sample residual (the grid passes through its own nodes' means).
    assert data["cv_rms_mm"] > data["rms_mm"]
