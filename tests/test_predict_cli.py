"""The predict command: its subcommands, their JSON output, plots and errors."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calibration.tables import format_squareness, format_tables
from postproc.cli import main
from postproc.cli.predict import predict
from postproc.engine.parametric import ParametricEngine
from postproc.errors import EXIT_INPUT
from postproc.simulate.s500 import synthetic_tables

SAMPLES = Path(__file__).parents[1] / "samples" / "predict"
BORE = str(SAMPLES / "bore_50H7.operation.json")
FLANK = str(SAMPLES / "flank_5mm.operation.json")


def run(*args):
    return CliRunner().invoke(main, ["predict", *map(str, args)], catch_exceptions=False)


def test_every_subcommand_has_help_with_an_example():
    assert "Example:" in predict.help
    for name, cmd in predict.commands.items():
        assert "Example:" in (cmd.help or ""), name
        res = run(name, "--help")
        assert res.exit_code == 0
        assert "Example:" in res.output


def test_bore_reports_the_seed_conclusion_as_json():
    res = run("bore", BORE, "-n", 500, "--seed", 4, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["worst_case"]["within"] is False
    assert_allclose(out["worst_case"]["max_abs_mm"], [0.0825, 0.11], atol=1e-5)
    assert out["monte_carlo"]["n"] == 500
    assert out["monte_carlo"]["seed"] == 4
    assert_allclose(out["mid_field"]["error_mm"], [0.0, 0.025], atol=1e-6)
    again = json.loads(run("bore", BORE, "-n", 500, "--seed", 4, "--json").output)
    assert again["monte_carlo"] == out["monte_carlo"]


def test_bore_text_and_plot(tmp_path):
    png = tmp_path / "bore.png"
    res = run("bore", BORE, "-n", 300, "--plot", png)
    assert res.exit_code == 0, res.output
    assert "NOT met in the worst case" in res.output
    assert "P(centre within tolerance)" in res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind


def test_trace_prints_the_cusp_of_the_seed_example(tmp_path):
    png = tmp_path / "wall.png"
    res = run("trace", FLANK, "--heights", 5, "--windows", 8, "--json", "--plot", png)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert out["feed_per_edge_mm"] == pytest.approx(1e-3)
    assert out["cusp_formula_mm"] == pytest.approx(2.5 - np.sqrt(2.5**2 - 0.0005**2))
    plain = out["cases"]["no runout"]
    assert plain["cusp_median_mm"] == pytest.approx(out["cusp_formula_mm"], rel=1e-3)
    runout = out["cases"]["runout A = 5e-05 rad"]
    # the deepest point is at the top of the 5 mm flank: A p = 5e-5 * 5
    assert runout["deepest_mm"] == pytest.approx(2.5e-4, rel=1e-3)
    assert png.exists()
    res = run("trace", FLANK, "--heights", 3, "--windows", 6, "--runout", 0)
    assert res.exit_code == 0
    assert "runout A" not in res.output


def test_tolerance_worst_case_only():
    res = run("tolerance", BORE, "--worst-case", "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    assert "monte_carlo" not in out
    assert out["worst_case"]["within"] is False


def test_tolerance_of_a_point_operation(tmp_path):
    op = {
        "format": "postproc operation", "kind": "point",
        "machine": {"format": "postproc chain",
                    "random": {"a": {"uniform": [-0.01, 0.01]}, "b": {"normal": [0.0, 0.002]}},
                    "modules": [{"name": "slide", "elements": [
                        {"linear": {"axis": "x", "var": "X"}}, {"error": {"u": "a", "w": "b"}}]}]},
        "tool_point_mm": [0, 0, -50], "nominal_mm": [100, 0, -50], "tolerance_mm": [0.012, 0.1, 0.005],
        "context": {"X": 100}, "monte_carlo": {"n": 2000, "seed": 1},
    }
    path = tmp_path / "point.operation.json"
    path.write_text(json.dumps(op))
    out = json.loads(run("tolerance", path, "--json").output)
    assert_allclose(out["worst_case"]["max_abs_mm"], [0.01, 0.0, 0.006])
    mc = out["monte_carlo"]
    assert mc["std_mm"][0] == pytest.approx(0.02 / np.sqrt(12), rel=0.1)
    # P(|b| <= 0.005) for b ~ N(0, 0.002): 2 Phi(2.5) - 1 = 0.9876
    assert mc["p_within"] == pytest.approx(0.9876, abs=0.01)


def test_chain_command_reproduces_the_parametric_engine(tmp_path):
    tables, sq = synthetic_tables(2)
    (tmp_path / "t.csv").write_text(format_tables(tables))
    (tmp_path / "t_squareness.csv").write_text(format_squareness(sq))
    out = tmp_path / "machine.chain.json"
    res = run("chain", tmp_path / "t.csv", "-o", out)
    assert res.exit_code == 0, res.output
    res = run("point", out, "--set", "X=120.5", "--set", "Y=33", "--set", "Z=250", "--tool", "10,0,-100")
    assert res.exit_code == 0, res.output
    p = np.array([float(v) for v in res.output.splitlines()[0].split()[1:]])
    engine = ParametricEngine(tables, sq, order="exact", interpolation="linear")
    assert_allclose(p, engine.forward([120.5, 33, 250], [10, 0, -100])[0], atol=2e-6)  # printed to 1e-6


def test_wrong_operation_kind_is_an_input_error():
    res = run("trace", BORE)
    assert res.exit_code == EXIT_INPUT
    assert "needs a flank operation" in res.output


def test_broken_machine_file_names_its_place(tmp_path):
    shutil.copy(BORE, tmp_path / "op.json")
    data = json.loads((SAMPLES / "mc12.machine.json").read_text())
    data["modules"][3]["elements"][1] = {"rotary": {"axis": "w", "var": "S"}}
    (tmp_path / "mc12.machine.json").write_text(json.dumps(data))
    res = run("bore", tmp_path / "op.json", "-n", 10)
    assert res.exit_code == EXIT_INPUT
    assert "mc12.machine.json" in res.output
    assert "modules[3]" in res.output
    assert "axis must be x, y or z" in res.output


def test_flank_operation_with_straight_flutes_and_a_conical_cutter(tmp_path):
    op = json.loads(Path(FLANK).read_text())
    op["machine"] = str(SAMPLES / "mill3.machine.json")
    op["cutter"] = {"kind": "conical", "d_mm": 4, "D_mm": 6, "length_mm": 4, "flutes": 2}  # no pitch: straight
    op["rpm"], op["feed_mm_min"] = 2000, 200
    path = tmp_path / "cone.operation.json"
    path.write_text(json.dumps(op))
    out = json.loads(run("trace", path, "--heights", 3, "--windows", 8, "--runout", 0, "--json").output)
    fz = 200 / 4000
    # heights 0, 2, 4 mm have radii 2, 2.5, 3: the largest cusp is at the tip. The
    # trochoid's radius of curvature at the wall is R (1 - f / (2 pi R))^2, so its cusp
    # exceeds the circles' by up to 2 f / (2 pi R) = 0.8 %
    trochoid = 2 * fz / (2 * np.pi * 2.0)
    assert out["cases"]["no runout"]["cusp_max_mm"] == pytest.approx(2 - np.sqrt(4 - (fz / 2) ** 2), rel=trochoid)


def test_plot_files_are_readable_like_any_output(tmp_path):
    import os
    import stat

    png = tmp_path / "bore.png"
    assert run("bore", BORE, "-n", 50, "--plot", png).exit_code == 0
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(png.stat().st_mode) == 0o666 & ~umask


def test_bore_checks_the_diameter_against_its_limits():
    op = SAMPLES / "bore_50H7_rotating_load.operation.json"
    out = json.loads(run("bore", op, "-n", 100, "--json").output)
    assert out["mid_field"]["diameter_mm"] == pytest.approx(49.9965, abs=1e-6)
    assert out["mid_field"]["diameter_within_limits"] is False
    assert "diameter_within_limits" not in json.loads(run("bore", BORE, "-n", 100, "--json").output)["mid_field"]
    assert "OUTSIDE 50.0000..50.0250 mm" in run("bore", op, "-n", 100).output
