import json

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import save_calibration
from postproc.cli import main
from postproc.engine.parametric import ParametricEngine
from postproc.engine.parametric_orders import SEED_ORDER_POINTS_MM, compare_orders
from postproc.engine.static import StaticEngine
from postproc.errors import EXIT_CALIBRATION
from postproc.simulate.s500 import synthetic_tables


@pytest.fixture
def cal(tmp_path):
    tables, sq = synthetic_tables(0)
    path = tmp_path / "tables.json"
    save_calibration(path, ParametricEngine(tables, sq), name="synthetic")
    return path


def test_orders_json_matches_the_engine_and_shows_the_seed_finding(cal):
    result = CliRunner().invoke(main, ["orders", "-c", str(cal), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert [p["q_mm"] for p in data["points"]] == [list(map(float, p)) for p in SEED_ORDER_POINTS_MM]
    assert data["k"] == 1000
    real = np.array([[p["measured"]["rel_plus_pct"], p["measured"]["rel_minus_pct"]] for p in data["points"]])
    scaled = np.array([[p["scaled"]["rel_plus_pct"], p["scaled"]["rel_minus_pct"]] for p in data["points"]])
    assert real.max() < 1e-4
    assert scaled.max() > 1.0
    tables, sq = synthetic_tables(0)
    comp = compare_orders(ParametricEngine(tables, sq), np.array(SEED_ORDER_POINTS_MM, float), [0, 0, -100.0])
    np.testing.assert_allclose([p["measured"]["delta_um"] for p in data["points"]], comp.delta_first_mm * 1000)


def test_orders_text_with_points_file_in_micrometres(cal, tmp_path):
    pts = tmp_path / "pts.csv"
    pts.write_text("# units: length=um\nX,Y,Z\n100000,50000,20000\n")
    result = CliRunner().invoke(main, ["orders", "-c", str(cal), "--points", str(pts), "-k", "10",
                                       "--tool-vector", "0,0,-50"])
    assert result.exit_code == 0, result.output
    assert "100/50/20" in result.output
    assert "k = 10 " in result.output
    assert "r = 0,0,-50 mm" in result.output


def test_tool_vector_zero_leaves_no_angular_difference(cal):
    result = CliRunner().invoke(main, ["orders", "-c", str(cal), "--point", "100,100,100",
                                       "--tool-vector", "0,0,0", "--json"])
    row = json.loads(result.output)["points"][0]
    assert row["scaled"]["rel_plus_pct"] == 0.0
    assert row["scaled"]["delta_um"] == row["measured"]["delta_um"]


def test_orders_refuses_a_static_calibration(tmp_path):
    path = tmp_path / "static.json"
    save_calibration(path, StaticEngine(np.eye(3), np.zeros(3), [[0, 0, 0], [100, 100, 100]]))
    result = CliRunner().invoke(main, ["orders", "-c", str(path)])
    assert result.exit_code == EXIT_CALIBRATION
    assert "parametric" in result.output
