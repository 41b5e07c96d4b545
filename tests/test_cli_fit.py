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


def test_fit_tool_vector_fills_files_without_tool_columns(tmp_path):
    rng = np.random.default_rng(9)
    q = rng.uniform(0, 300, (20, 3))
    origin = np.array([0.01, -0.02, 0.03])
    m = origin + q + np.array([0, 0, -100.0])
    text = format_measurements(Measurements(q=q, m=m, r=np.zeros_like(q)))
    lines = text.splitlines()
    header = lines[2].split(",")
    keep = [i for i, h in enumerate(header) if h not in ("tx", "ty", "tz")]
    src = tmp_path / "no_tool.csv"
    src.write_text("\n".join(lines[:2] + [",".join(row.split(",")[i] for i in keep) for row in lines[2:]]) + "\n")
    out = tmp_path / "c.json"
    result = CliRunner().invoke(main, ["fit", str(src), "--tool-vector", "0,0,-100", "-o", str(out)])
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(json.loads(out.read_text())["model"]["r_O1_mm"], origin, atol=1e-6)
    # Without --tool-vector the 100 mm tool ends up in the origin.
    result = CliRunner().invoke(main, ["fit", str(src), "-o", str(out)])
    np.testing.assert_allclose(json.loads(out.read_text())["model"]["r_O1_mm"][2], origin[2] - 100, atol=1e-6)
