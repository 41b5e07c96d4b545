import json
from pathlib import Path

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
    # Without --tool-vector the 100 mm tool ends up in the origin: a 100 mm correction,
    # refused unless --max-correction allows it.
    out.unlink()
    result = CliRunner().invoke(main, ["fit", str(src), "-o", str(out)])
    assert result.exit_code != 0
    assert "--max-correction" in result.output
    assert not out.exists()
    result = CliRunner().invoke(main, ["fit", str(src), "-o", str(out), "--max-correction", "200"])
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(json.loads(out.read_text())["model"]["r_O1_mm"][2], origin[2] - 100, atol=1e-6)


def write_lattice(path, step=50.0, n=5, drop=None):
    """Points on an n x n x n lattice (no noise) of a machine with smooth, curved errors."""
    g = np.arange(n) * step
    q = np.array(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1).T
    if drop is not None:
        q = q[~np.all(q == drop, axis=1)]
    m = q + 1e-3 * np.column_stack([np.sin(q[:, 0] / 40), q[:, 0] * q[:, 1] / 4e4, np.cos(q[:, 2] / 60)])
    path.write_text(format_measurements(Measurements(q=q, m=m, r=np.zeros_like(q))))


def test_fit_border_blend_reaches_the_interval_model(tmp_path):
    src = tmp_path / "lattice.csv"
    write_lattice(src)
    outs = {}
    for blend in (None, "0", "3.5"):
        out = tmp_path / f"interval_{blend}.json"
        args = ["fit", str(src), "-m", "interval", "--intervals", "X=2;Y=2;Z=2", "-o", str(out)]
        result = CliRunner().invoke(main, args + (["--border-blend", blend] if blend else []))
        assert result.exit_code == 0, result.output
        outs[blend] = json.loads(out.read_text())["model"]["border_blend_mm"]
    assert outs == {None: 1.0, "0": 0.0, "3.5": 3.5}
    # A blend wider than half an interval (100 mm here) is a usage error, and nothing is written.
    out = tmp_path / "wide.json"
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "interval", "--intervals", "X=2;Y=2;Z=2",
                                       "--border-blend", "150", "-o", str(out)])
    assert result.exit_code == 2
    assert "--border-blend 150: interval model: border blend 150 mm must be >= 0 and at most half" in result.output
    assert not out.exists()
    result = CliRunner().invoke(main, ["fit", str(src), "-m", "interval", "--border-blend", "-1", "-o", str(out)])
    assert result.exit_code == 2


def test_fit_grid_model_and_fill_missing(tmp_path):
    src = tmp_path / "lattice.csv"
    write_lattice(src)
    out = tmp_path / "grid.json"
    for model in ("trilinear", "cell"):
        result = CliRunner().invoke(main, ["fit", str(src), "-m", "grid", "--grid-model", model, "-o", str(out)])
        assert result.exit_code == 0, result.output
        assert f"quasi-differential ({model}) fit" in result.output
        assert json.loads(out.read_text())["model"]["interpolation"] == model
    holed = tmp_path / "holed.csv"
    write_lattice(holed, drop=[100.0, 150.0, 50.0])
    out = tmp_path / "holed.json"
    result = CliRunner().invoke(main, ["fit", str(holed), "-m", "grid", "-o", str(out)])
    assert result.exit_code == EXIT_INPUT
    assert not out.exists()
    result = CliRunner().invoke(main, ["fit", str(holed), "-m", "grid", "--fill-missing", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "warning: 1 node(s) without measurement filled from their neighbours" in result.output
    assert json.loads(out.read_text())["model"]["shape"] == [5, 5, 5]


def test_fit_tangential_options_of_another_method_are_usage_errors(tmp_path):
    src = tmp_path / "lattice.csv"
    write_lattice(src, n=3)
    out = tmp_path / "c.json"
    cases = [
        (["-m", "grid", "--border-blend", "0"], "--border-blend applies to the interval method only"),
        (["--border-blend", "0"], "--border-blend applies to the interval method only (this fit is static)"),
        (["-m", "interval", "--grid-model", "cell"], "--grid-model applies to the grid method only"),
        (["-m", "interval", "--fill-missing"], "--fill-missing applies to the grid method only"),
        (["-m", "parametric", "--fill-missing"], "--fill-missing applies to the grid method only"),
    ]
    for extra, message in cases:
        result = CliRunner().invoke(main, ["fit", str(src), *extra, "-o", str(out)])
        assert result.exit_code == 2, (extra, result.output)
        assert message in result.output, extra
        assert not out.exists()
    tables = Path(__file__).parents[1] / "calibrations" / "s500_tables.csv"
    result = CliRunner().invoke(main, ["fit", str(tables), "--grid-model", "cell", "-o", str(out)])
    assert result.exit_code == 2
    assert "--grid-model applies to the grid method only (this fit is parametric)" in result.output
