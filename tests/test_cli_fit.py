import json

import numpy as np
from click.testing import CliRunner

from postproc.calibration.measurements import Measurements, format_measurements
from postproc.cli import main
from postproc.errors import EXIT_INPUT


def write_points(path, G, origin, n=30, seed=3, tool=True):
    rng = np.random.default_rng(seed)
    q = rng.uniform(0, 300, (n, 3))
    r = np.tile([0, 0, -100.0], (n, 1))
    m = origin + q @ np.asarray(G).T + r
    path.write_text(format_measurements(Measurements(q=q, m=m, r=r)))


def test_fit_static_writes_calibration(tmp_path):
    G = np.eye(3) + 1e-4 * np.array([[1, 2, 0], [0, -1, 1], [0, 0, 3]])
    src = tmp_path / "points.csv"
    write_points(src, G, np.array([0.01, 0.02, -0.03]))
    out = tmp_path / "my.cal"
    result = CliRunner().invoke(main, ["fit", str(src), "--method", "static", "-o", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["method"] == "static"
    # The file holds 6 decimals (1 nm); over 300 mm of travel that limits G to ~1e-8.
    np.testing.assert_allclose(data["model"]["G"], G, atol=2e-8)
    assert "fit residual" in result.output


def test_fit_bad_cell_names_place_and_writes_nothing(tmp_path):
    src = tmp_path / "points.csv"
    write_points(src, np.eye(3), np.zeros(3))
    lines = src.read_text().splitlines(keepends=True)
    lines[5] = "oops," + lines[5].split(",", 1)[1]
    src.write_text("".join(lines))
    out = tmp_path / "cal.json"
    result = CliRunner().invoke(main, ["fit", str(src), "-o", str(out)])
    assert result.exit_code == EXIT_INPUT
    assert f"{src}:6:1: column 'X': 'oops' is not a number" in result.output
    assert not out.exists()


def test_fit_unknown_file_kind(tmp_path):
    src = tmp_path / "what.csv"
    src.write_text("a,b\n1,2\n")
    result = CliRunner().invoke(main, ["fit", str(src), "-o", str(tmp_path / "c.json")])
    assert result.exit_code == EXIT_INPUT
    assert "cannot tell what this file holds" in result.output
