import json

import numpy as np
from click.testing import CliRunner
from conftest import TangentTestMachine, grid_measurements

from postproc.calfile import load_calibration
from postproc.calibration.measurements import format_measurements
from postproc.cli import main
from postproc.errors import EXIT_INPUT

MACHINE = TangentTestMachine()


def write_grid(path, step=15.0, side=90.0):
    path.write_text(format_measurements(grid_measurements(MACHINE, step=step, side=side, seed=4)))
    return path


def test_fit_grid_prints_warnings_and_writes_calibration(tmp_path):
    src = write_grid(tmp_path / "grid.csv")
    out = tmp_path / "grid.cal"
    result = CliRunner().invoke(main, ["fit", str(src), "--method", "grid", "--screw-pitch", "X=5",
                                       "--screw-pitch", "Y=6.5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "quasi-differential (trilinear) fit: 7 x 7 x 7 nodes" in result.output
    assert "on X is a multiple (3 x) of the lead-screw pitch 5 mm" in result.output
    assert "on Y is nearly a multiple" not in result.output  # 15/6.5: the phase moves
    cal = load_calibration(out)
    assert cal.method == "grid"
    np.testing.assert_allclose(cal.engine.volume_mm, [[0, 0, 0], [90, 90, 90]])
    q = np.array([[30.0, 45.0, 60.0]])
    np.testing.assert_allclose(cal.engine.forward(q), MACHINE.forward(q), atol=0.01)


def test_fit_grid_small_step_and_subsampling(tmp_path):
    src = write_grid(tmp_path / "fine.csv", step=5.0, side=30.0)
    out = tmp_path / "g.json"
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "grid", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "grid step 5 mm on X is under 10 mm" in result.output
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "grid", "--step", "10", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "under 10 mm" not in result.output
    assert json.loads(out.read_text())["model"]["shape"] == [4, 4, 4]


def test_fit_grid_incomplete_is_an_input_error(tmp_path):
    src = write_grid(tmp_path / "grid.csv")
    lines = src.read_text().splitlines(keepends=True)
    src.write_text("".join(line for line in lines if not line.startswith("15.000000,30.000000,45.000000,")))
    out = tmp_path / "g.json"
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "grid", "-o", str(out)])
    assert result.exit_code == EXIT_INPUT
    assert f"{src}: incomplete grid: 1 of 343 nodes" in result.output
    assert "X=15.000 Y=30.000 Z=45.000" in result.output
    assert not out.exists()


def test_fit_interval(tmp_path):
    src = write_grid(tmp_path / "grid.csv")
    out = tmp_path / "i.json"
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "interval", "--intervals", "X=0,45,90;Y=2;Z=1",
                                       "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "interval fit: 2 x 2 x 1 cells on 343 points" in result.output
    cal = load_calibration(out)
    assert cal.engine.shape == (2, 2, 1)
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "interval", "--intervals", "X=0,50,40",
                                       "-o", str(out)])
    assert result.exit_code == EXIT_INPUT
    assert "edges of X must increase strictly" in result.output
