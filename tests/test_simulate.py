import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calibration.axis_tables import AxisTables
from postproc.calibration.measurements import read_measurements
from postproc.calibration.tables import read_squareness, read_tables
from postproc.cli import main
from postproc.engine.static import fit as fit_static
from postproc.simulate import (
    Machine,
    MachineError,
    MachineGeometry,
    Noise,
    grid_points,
    load_machine,
    measurement_plan,
    random_points,
    save_machine,
    simulate_plan,
    simulate_points,
    static_set,
)
from postproc.simulate.s500 import s500_machine
from postproc.simulate.tables import simulate_tables

REPO = Path(__file__).parents[1]
S500 = REPO / "calibrations" / "s500.machine.json"
VOLUME = [[0, 0, 0], [300, 300, 300]]
# Table 1 of seed 000: the control points of the S500 experiment.
TABLE1 = np.array([[230, 230, 230], [110, 170, 185], [170, 125, 200], [198, 196, 140],
                   [130, 140, 106], [50, 50, 50], [133, 198, 176], [80, 112, 118],
                   [162, 168, 210], [108, 136, 168]], float)


def affine_machine(sigma=0.002):
    """Linear positioning/straightness errors + squareness: an affine machine for r = 0."""
    s = np.array([0.0, 300.0])
    slopes = {"X": [3e-4, -1e-4, 5e-5], "Y": [2e-4, 4e-4, -8e-5], "Z": [-6e-5, 1e-4, 2.5e-4]}
    errors = {}
    for ax, sl in slopes.items():
        v = np.zeros((2, 6))
        v[:, :3] = np.outer(s, sl) + np.array([0.01, -0.02, 0.015])
        errors[ax] = v
    geo = MachineGeometry(AxisTables(dict.fromkeys(slopes, s), errors), {"EC0Y": 1e-4, "EB0Z": -5e-5, "EA0Z": 8e-5}, VOLUME)
    return Machine(geo, noise=Noise(tracker_mm=sigma))


def test_point_sets():
    g = grid_points(VOLUME, 100)
    assert g.shape == (64, 3)
    assert_allclose(g.min(axis=0), [0, 0, 0])
    assert_allclose(g.max(axis=0), [300, 300, 300])
    assert_allclose(g[1] - g[0], [100, 0, 0])  # X fastest
    s = static_set(VOLUME)
    assert s.shape == (6, 3)
    # Two points per axis: each pair differs along exactly its own axis.
    for j in range(3):
        d = s[2 * j + 1] - s[2 * j]
        assert np.count_nonzero(d) == 1
        assert d[j] == 300
    r = random_points(VOLUME, 500, np.random.default_rng(1))
    assert r.min() >= 0
    assert r.max() <= 300
    assert np.ptp(r[:, 2]) > 250


def test_plan_expands_context_in_measuring_order():
    pts = np.array([[0, 0, 0], [10, 20, 30.0]])
    plan = measurement_plan(pts, tool_vectors=[(0, 0, -100), (0, 0, 0)], approach="both", repeats=3,
                            time_span_s=100, temp_profile="20:22", load_values=[0, 500])
    assert len(plan.q) == 2 * 2 * 2 * 2 * 3  # loads x tools x points x approaches x repeats
    assert_allclose(plan.q[:6], np.repeat(pts[:1], 6, axis=0))
    assert_allclose(plan.direction[:6, 0], [1, 1, 1, -1, -1, -1])
    assert_allclose(plan.r[0], [0, 0, -100])
    assert_allclose(plan.r[12], [0, 0, 0])
    assert_allclose(plan.context["load"][[0, 23, 24, 47]], [0, 0, 500, 500])
    t = plan.context["t"]
    assert t[0] == 0
    assert t[-1] == 100
    assert np.all(np.diff(t) > 0)
    assert_allclose(plan.context["temp"][[0, -1]], [20, 22])
    warm = measurement_plan(pts, time_span_s=3600, temp_profile="20:23:1800", repeats=10)
    temp = warm.context["temp"]
    assert temp[0] == pytest.approx(20)
    assert temp[-1] == pytest.approx(23 - 3 * np.exp(-2))
    assert np.all(np.diff(temp) > 0)


def test_forward_follows_formats_md_signs():
    s = np.array([0.0, 300.0])
    geo = MachineGeometry({}, {"EC0Y": 1e-4, "EB0Z": 2e-4, "EA0Z": 3e-4}, VOLUME)
    p = geo.forward([[0, 100, 200]])
    assert_allclose(p, [[0 - 1e-4 * 100 + 2e-4 * 200, 100 - 3e-4 * 200, 200]])
    v = np.zeros((2, 6))
    v[:, 4] = [0, 3e-4]  # EB of X: pitch about y grows with X
    geo = MachineGeometry(AxisTables({"X": s}, {"X": v}), {}, VOLUME, rotation="first")
    p = geo.forward([[150, 0, 0]], [0, 0, -100])
    # eps x r = (0, 1.5e-4, 0) x (0, 0, -100) = (-0.015, 0, 0)
    assert_allclose(p, [[150 - 0.015, 0, -100]], atol=1e-12)


def test_machine_inverse_lands_on_target():
    m = s500_machine()
    p = random_points([[10, 10, 10], [300, 300, 300]], 200, np.random.default_rng(3))
    r = [0, 0, -100]
    res = m.inverse(p, r)
    assert res.residual_mm.max() < 1e-6
    assert_allclose(m.forward(res.q, r), p, atol=1e-6)


def test_s500_file_is_the_generated_machine_with_seed_magnitudes():
    a, b = load_machine(S500), s500_machine()
    q = random_points(a.volume_mm, 300, np.random.default_rng(4))
    assert_allclose(a.forward(q, [0, 0, -100]), b.forward(q, [0, 0, -100]), atol=1e-12)
    err = np.linalg.norm(a.forward(TABLE1) - TABLE1, axis=1)
    # Seed 000, Table 1: uncorrected 0.132..0.436 mm at these points, sum 3.100 mm.
    assert err.min() > 0.1
    assert err.max() < 0.45
    assert 2.5 < err.sum() < 4.0


def test_simulated_file_reads_back_as_simulated(tmp_path):
    out = tmp_path / "grid.csv"
    args = ["simulate", str(S500), "--grid", "105", "--repeats", "2", "--approach", "both",
            "--tool-vector", "0,0,-100", "--time-span", "600", "--temp-profile", "20:21",
            "--seed", "5", "-o", str(out)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    meas = read_measurements(out)
    m = load_machine(S500)
    plan = measurement_plan(grid_points(m.volume_mm, 105), tool_vectors=[(0, 0, -100)], approach="both",
                            repeats=2, time_span_s=600, temp_profile="20:21")
    ref = simulate_plan(m, plan, np.random.default_rng(5))
    assert len(meas) == len(ref) == 64 * 4
    assert_allclose(meas.q, ref.q, atol=1e-12)
    assert_allclose(meas.m, ref.m, atol=6e-7)  # the file holds 6 decimals
    assert_allclose(meas.r, ref.r)
    assert_allclose(meas.direction, ref.direction)
    assert_allclose(meas.context["t"], ref.context["t"])
    assert_allclose(meas.context["temp"], ref.context["temp"])
    # Noise present and of the machine's size: the deviation from the noise-free forward.
    dev = meas.m - m.forward(meas.q, meas.r, meas.context_full())
    assert np.std(dev) == pytest.approx(m.noise.tracker_mm, rel=0.15)


def test_tables_file_reads_back_and_matches_machine(tmp_path):
    m = s500_machine()
    out = tmp_path / "tables.csv"
    res = CliRunner().invoke(main, ["simulate", str(S500), "--tables", "--step", "7", "--no-noise",
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    tabs = read_tables(out)
    sq = read_squareness(tmp_path / "tables_squareness.csv")
    assert tabs.position_mm["X"][-1] == 315  # the end of travel is always measured
    assert_allclose(np.diff(tabs.position_mm["Y"])[:-1], 7)
    for ax in "XYZ":
        assert_allclose(tabs.errors[ax], m.geometry.tables.at(ax, tabs.position_mm[ax]), atol=1e-15)
    assert sq.as_dict() == pytest.approx(m.geometry.squareness.as_dict())
    noisy, sqn = simulate_tables(m, 7, np.random.default_rng(0))
    dev = noisy.errors["Z"] - m.geometry.tables.at("Z", noisy.position_mm["Z"])
    assert np.std(dev[:, :3]) == pytest.approx(m.noise.interferometer_length_mm, rel=0.25)
    assert np.std(dev[:, 3:]) == pytest.approx(m.noise.interferometer_angle_rad, rel=0.25)


def test_static_fit_on_simulated_affine_machine_recovers_it():
    m = affine_machine(sigma=0.002)
    rng = np.random.default_rng(6)
    meas = simulate_points(m, grid_points(VOLUME, 50), None, None, rng)
    res = fit_static([meas])
    # Pure noise left: 3D residual RMS is sigma * sqrt(3).
    assert res.rms_mm == pytest.approx(0.002 * np.sqrt(3), rel=0.1)
    p = random_points(VOLUME, 200, rng)
    err = np.linalg.norm(m.forward(res.engine.inverse(p).q) - p, axis=1)
    assert err.max() < 0.002  # 343 points average the noise down well below sigma
    # The six-point set with 12 shots each, as in the seed, also recovers it.
    six = simulate_plan(m, measurement_plan(static_set(VOLUME), repeats=12), rng)
    res6 = fit_static([six])
    err6 = np.linalg.norm(m.forward(res6.engine.inverse(p).q) - p, axis=1)
    assert err6.max() < 0.005
    assert np.linalg.norm(m.forward(p) - p, axis=1).min() > 0.02  # there was something to correct


def test_machine_file_round_trip_and_errors(tmp_path):
    m = affine_machine()
    path = tmp_path / "m.machine.json"
    save_machine(path, m)
    back = load_machine(path)
    q = random_points(VOLUME, 20, np.random.default_rng(7))
    assert_allclose(back.forward(q), m.forward(q))
    assert back.noise == m.noise
    data = json.loads(path.read_text())
    data["format"] = "something else"
    path.write_text(json.dumps(data))
    with pytest.raises(MachineError, match="not a machine definition") as info:
        load_machine(path)
    assert str(info.value).startswith(str(path))
    data["format"] = "postproc machine"
    data["noise"] = {"tracker_um": 1}
    path.write_text(json.dumps(data))
    with pytest.raises(MachineError, match="unknown noise"):
        load_machine(path)
    path.write_text('{"format": "postproc machine",\n "version": 1,,}')
    with pytest.raises(MachineError, match="not valid JSON") as info:
        load_machine(path)
    assert str(info.value).startswith(f"{path}:2:")


def test_simulate_cli_needs_exactly_one_kind(tmp_path):
    res = CliRunner().invoke(main, ["simulate", str(S500), "--grid", "50", "--static-set",
                                    "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2
    assert "exactly one" in res.output
    assert not (tmp_path / "x.csv").exists()


def test_warm_machine_effects_show_in_simulated_data(tmp_path):
    from postproc.errors import MissingSetupError

    m = load_machine(REPO / "calibrations" / "s500_warm.machine.json")
    q = np.array([[100.0, 100.0, 100.0]])
    plan = measurement_plan(q, approach="both", time_span_s=7200.0, load_values=[0, 500], repeats=2)
    meas = simulate_plan(m, plan, noise=False)
    geo = m.geometry.forward(meas.q, meas.r)
    extra = meas.m - geo
    t, load, dx = meas.context["t"], meas.context["load"], meas.direction[:, 0]
    expect = np.column_stack([
        0.004 * dx + 0.012 * (1 - np.exp(-t / 1800)),
        0.003 * dx - 0.008 * (1 - np.exp(-t / 1800)),
        0.020 * (1 - np.exp(-t / 1800)) - 2e-5 * load,
    ])
    assert_allclose(extra, expect, atol=1e-12)
    with pytest.raises(MissingSetupError, match="'t'"):
        simulate_points(m, q, None, {"dirx": 1, "diry": 1, "dirz": 1, "load": 0.0})
    out = tmp_path / "w.csv"
    res = CliRunner().invoke(main, ["simulate", str(REPO / "calibrations" / "s500_warm.machine.json"),
                                    "--random", "5", "-o", str(out)])
    assert res.exit_code == MissingSetupError.exit_code
    assert "--context t=" in res.output
    assert not out.exists()


def test_random_points_in_a_sub_volume_on_the_command_line(tmp_path):
    out = tmp_path / "r.csv"
    res = CliRunner().invoke(main, ["simulate", str(S500), "--random", "40", "--volume", "10,20,30,110,220,130",
                                    "--context", "probe=2", "--seed", "9", "-o", str(out)])
    assert res.exit_code == 0, res.output
    meas = read_measurements(out)
    assert len(meas) == 40
    assert np.all(meas.q >= [10, 20, 30])
    assert np.all(meas.q <= [110, 220, 130])
    assert np.ptp(meas.q[:, 1]) > 150
    assert_allclose(meas.context["probe"], 2.0)
    again = tmp_path / "again.csv"
    CliRunner().invoke(main, ["simulate", str(S500), "--random", "40", "--volume", "10,20,30,110,220,130",
                              "--context", "probe=2", "--seed", "9", "-o", str(again)])
    assert again.read_text() == out.read_text()  # --seed makes it reproducible
