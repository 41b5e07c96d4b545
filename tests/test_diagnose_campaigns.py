"""`check` and `fit` on campaigns measured as they really are, made with the virtual machine
(postproc.simulate): a re-set-up tracker frame, rasters with dir=0 rows, a calibration
extended by an effect, a degenerate joint fit."""

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.calibration.measurements import Measurements, format_measurements
from postproc.cli import main
from postproc.simulate import Machine, load_machine, measurement_plan, random_points, simulate_plan

ROOT = Path(__file__).parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
TABLES_CAL = ROOT / "calibrations" / "s500_parametric.json"  # fitted from the S500's interferometer tables


def run(args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def rotation_matrix(axis, angle):
    """Exact rotation (Rodrigues), independent of the first-order registration model."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def write(meas: Measurements, path: Path) -> Path:
    path.write_text(format_measurements(meas))
    return path


def tracker_campaign(rng, n=70, machine=None):
    mach = machine or load_machine(MACHINE)
    plan = measurement_plan(random_points(mach.volume_mm, n, rng), tool_vectors=[(0, 0, -100)],
                            approach="both", repeats=2, time_span_s=3 * 3600)
    return simulate_plan(mach, plan, rng)


def test_frame_offset_and_rotation_are_registered_not_named(tmp_path):
    rng = np.random.default_rng(7)
    meas = tracker_campaign(rng)
    # the tracker set up 5 um off and turned 20 urad about z: m' = R m + t
    R, t = rotation_matrix([0, 0, 1], 20e-6), np.array([0.005, 0.0, 0.0])
    meas.m = meas.m @ R.T + t
    pts = write(meas, tmp_path / "frame.csv")
    from postproc.diagnose.check import json_safe, run_check
    from postproc.diagnose.text import format_report

    # without registration the frame is taken for a machine effect
    plain = run_check(load_calibration(TABLES_CAL), [meas], [str(pts)], fixed=True, register=False,
                      max_selected=1, offer_empirical=False,
                      candidates=["thermal:t", "straightness:X", "straightness:Y", "lever:XZ", "squareness:XY"])
    assert plain.suggestions

    res = run_check(load_calibration(TABLES_CAL), [meas], [str(pts)], fixed=True)  # registered by default
    data = json.loads(json.dumps(json_safe(res.to_json())))
    assert data["suggestions"] == []
    assert data["verdict"] == "consistent"
    reg = data["registration"]
    # rotation about the frame origin: t stays the offset, w the 20 urad
    assert np.allclose(reg["translation_mm"], t, atol=1.5 * max(reg["translation_u_k2_mm"]))
    assert np.allclose(reg["rotation_rad"], [0, 0, 20e-6], atol=1.5 * max(reg["rotation_u_k2_rad"]))
    assert 0.004 < reg["size_mm"] < 0.012
    text = "\n".join(format_report(res))
    assert "measurement frame registered" in text
    assert "thermal" not in text.split("missing effects")[1].split("untestable")[0]


def raster_with_dir0(machine, rng, step=35.0, repeats=2):
    """A raster campaign as a tracker records it: X serpentine along each row, Y rising in
    even Z layers and falling in odd ones. The machine moves with the approach state of
    every axis carried from its last move (as a controller's backlash state is); the file
    records 1/-1 only for axes that moved on the way to a point, 0 for the others."""
    axis = np.arange(0.0, 315.0 + 1e-9, step)
    rows = []
    for k, z in enumerate([0.0, 157.5, 315.0]):
        ys = axis if k % 2 == 0 else axis[::-1]
        for i, y in enumerate(ys):
            xs = axis if i % 2 == 0 else axis[::-1]
            rows += [(x, y, z) for x in xs]
    q = np.array(rows)
    moves = np.diff(np.vstack([q[:1] - 1.0, q]), axis=0)  # from home, below the first point
    recorded = np.sign(moves)
    state = recorded.copy()
    for j in range(1, len(state)):
        state[j] = np.where(recorded[j] != 0, recorded[j], state[j - 1])
    q, recorded, state = (np.repeat(a, repeats, axis=0) for a in (q, recorded, state))
    recorded[1::repeats] = 0  # a repeat shot: nothing moved
    t = np.linspace(0, 3 * 3600, len(q))
    r = np.tile([0.0, 0.0, -100.0], (len(q), 1))
    truth = machine.forward(q, r, {"dirx": state[:, 0], "diry": state[:, 1], "dirz": state[:, 2], "t": t})
    m = truth + rng.normal(0, machine.noise.tracker_mm, q.shape)
    return Measurements(q=q, m=m, r=r, direction=recorded, context={"t": t}), state


def machine_with(effects):
    base = load_machine(MACHINE)
    return Machine(base.geometry, effects=effects, noise=base.noise)


def test_dir0_raster_backlash_is_named_backlash(tmp_path):
    rng = np.random.default_rng(11)
    mach = machine_with([{"name": "backlash:Y", "params": {"b_mm": 0.015}}])
    meas, state = raster_with_dir0(mach, rng)
    assert np.mean(meas.direction[:, 1] == 0) > 0.8  # Y moves only between rows
    np.testing.assert_array_equal(meas.context_full()["diry"], state[:, 1])
    pts = write(meas, tmp_path / "raster.csv")
    res = run(["check", pts, "-c", TABLES_CAL, "--fixed", "--json", "--max-effects", "2"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    first = data["suggestions"][0]
    assert first["effect"] == "backlash:Y"
    assert first["parameters"]["b_mm"] == pytest.approx(0.015, abs=first["parameters_u_k2"]["b_mm"] * 1.5)
    assert data["cv_rms_after_mm"] < 1.15 * data["noise_floor_mm"]


def test_fit_base_adds_the_effect_and_delivers_the_promised_figure(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(12)
    mach = machine_with([{"name": "backlash:X", "params": {"b_mm": 0.012}}])
    write(tracker_campaign(rng, n=60, machine=mach), tmp_path / "pts.csv")
    cal = tmp_path / "tables.json"
    cal.write_text(TABLES_CAL.read_text())
    res = run(["check", "pts.csv", "-c", "tables.json", "--fixed", "--json", "--max-effects", "1"])
    data = json.loads(res.stdout)
    (sug,) = data["suggestions"]
    assert sug["effect"] == "backlash:X"
    args = shlex.split(sug["command"])
    assert args[:4] == ["postproc", "fit", "--base", "tables.json"]
    assert "--method" not in args
    res = run(args[1:])
    assert res.exit_code == 0, res.output
    out = args[args.index("-o") + 1]
    new, old = load_calibration(out), load_calibration("tables.json")
    assert new.method == "parametric"
    assert json.loads(Path(out).read_text())["model"] == json.loads(cal.read_text())["model"]  # base kept
    assert [e["name"] for e in new.effects] == ["backlash:X"]
    assert new.effects[0]["params"]["b_mm"] == pytest.approx(0.012, abs=0.002)
    after = json.loads(run(["check", "pts.csv", "-c", out, "--fixed", "--json"]).stdout)
    # the figure check promised is the one the extended calibration delivers
    assert after["cv_rms_mm"] == pytest.approx(sug["rms_after_mm"], rel=0.05)
    assert after["suggestions"] == []
    assert after["cv_rms_mm"] < 1.15 * after["noise_floor_mm"]
    assert old.effects == []
    # a static calibration is extended the same way
    assert run(["fit", "pts.csv", "--method", "static", "-o", "st.json"]).exit_code == 0
    res = run(["fit", "--base", "st.json", "pts.csv", "--effect", "backlash:X", "-o", "st_b.json"])
    assert res.exit_code == 0, res.output
    assert "measurement frame registered" in res.output
    st = json.loads(Path("st_b.json").read_text())
    assert st["model"] == json.loads(Path("st.json").read_text())["model"]
    assert st["effects"][0]["params"]["b_mm"] == pytest.approx(0.012, abs=0.002)


def test_degenerate_joint_fit_is_regularised_and_named(tmp_path, monkeypatch):
    """straightness:X + straightness:Y beside a parametric model that holds both shapes
    already: once a bow of metres balanced by an alignment of radians."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(3)
    write(tracker_campaign(rng, n=45), tmp_path / "r60.csv")
    mach = load_machine(MACHINE)
    q = random_points(mach.volume_mm, 300, rng)
    r = np.tile([0.0, 0.0, -100.0], (len(q), 1))
    truth = mach.forward(q, r)
    res = run(["fit", "r60.csv", "-m", "parametric", "--effect", "straightness:Y", "--effect", "straightness:X",
               "-o", "deg.json"])
    assert res.exit_code == 0, res.output
    assert "condition number" in res.output
    assert "not determined by these data" in res.output
    assert "straightness:X.bow_y_mm" in res.output
    info = json.loads(Path("deg.json").read_text())["fit"]["conditioning"]
    assert "straightness:Y.bow_x_mm" in info["undetermined"]
    assert run(["fit", "r60.csv", "-m", "parametric", "-o", "plain.json"]).exit_code == 0
    err = {}
    for name in ("deg", "plain"):
        pred = load_calibration(f"{name}.json").engine.forward(q, r, {})
        err[name] = float(np.sqrt(np.mean(np.sum((pred - truth) ** 2, axis=1))))
    assert err["deg"] < 1.1 * err["plain"]
    assert err["deg"] < 0.02
    # the last guard: no calibration that corrects by more than --max-correction is written
    res = run(["fit", "r60.csv", "-m", "parametric", "--max-correction", "0.001", "-o", "tight.json"])
    assert res.exit_code != 0
    assert "--max-correction" in res.output
    assert not Path("tight.json").exists()


def test_glitch_duplicates_and_per_shot_temperature_are_handled():
    from postproc.diagnose.check import run_check

    rng = np.random.default_rng(5)
    meas = tracker_campaign(rng, n=60)
    n = len(meas.q)
    # temperature logged with every shot (0.01 degC sensor noise on a slow rise)
    meas.context["temp"] = 20.0 + 2.0 * meas.context["t"] / meas.context["t"].max() + rng.normal(0, 0.01, n)
    meas.m[17] += [0.2, -0.05, 0.1]  # one 200 um tracker glitch inside a repeat group
    dup = [30, 31, 32]
    for name in ("q", "m", "r", "direction"):
        setattr(meas, name, np.vstack([getattr(meas, name), getattr(meas, name)[dup]]))
    meas.context = {k: np.concatenate([v, v[dup]]) for k, v in meas.context.items()}
    meas.path, meas.linenos = "g.csv", np.arange(len(meas.q)) + 4
    res = run_check(load_calibration(TABLES_CAL), [meas], ["g.csv"], fixed=True, candidates=["backlash:X"])
    sc = res.screening
    assert [o["place"] for o in sc.outliers] == ["g.csv:21"]
    assert [d["place"] for d in sc.duplicates] == [f"g.csv:{n + 4 + i}" for i in range(3)]
    assert len(res.ds) == n - 1
    # the floor is the tracker's (5 um per axis), neither inflated by the glitch nor
    # shrunk by the duplicates, and the per-shot temperature does not break the repeat groups
    assert res.noise.source == "repeats"
    assert res.noise.dof >= n // 2 - 2
    assert res.noise.rms_mm == pytest.approx(0.005 * np.sqrt(3), rel=0.12)
    data = res.to_json()
    assert data["screening"]["n_excluded"] == 4


def test_single_shot_glitch_is_excluded_and_clean_rows_are_not():
    from postproc.diagnose.check import run_check

    rng = np.random.default_rng(6)
    mach = load_machine(MACHINE)
    plan = measurement_plan(random_points(mach.volume_mm, 120, rng), tool_vectors=[(0, 0, -100)])
    meas = simulate_plan(mach, plan, rng)
    meas.m[40] += [0.0, 0.2, 0.0]
    meas.path, meas.linenos = "s.csv", np.arange(len(meas.q)) + 4
    res = run_check(load_calibration(TABLES_CAL), [meas], ["s.csv"], fixed=True, candidates=["squareness:XY"],
                    sigma_mm=0.005)
    assert [o["row"] for o in res.screening.outliers] == [40]
    assert res.suggestions == []


def test_unexplained_verdict_offers_an_empirical_correction(tmp_path, monkeypatch):
    """A coupling of the axes that no effect of the catalogue has (z error growing with
    x*y*z, x error over the Y-Z plane): said in words, and the empirical field offered."""
    from postproc.diagnose.check import json_safe, run_check
    from postproc.diagnose.text import format_report

    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(32)
    meas = tracker_campaign(rng, n=60)
    u = meas.q / 315.0
    meas.m[:, 2] += 0.24 * np.prod(u - 0.5, axis=1)
    meas.m[:, 0] += 0.030 * np.sin(np.pi * u[:, 1]) * np.sin(np.pi * u[:, 2])
    write(meas, tmp_path / "c.csv")
    cal = tmp_path / "tables.json"
    cal.write_text(TABLES_CAL.read_text())
    res = run_check(load_calibration("tables.json"), [meas], ["c.csv"], fixed=True)
    data = json.loads(json.dumps(json_safe(res.to_json())))
    assert data["verdict"] == "unexplained"
    assert data["cv_ratio_to_floor"] > 1.15
    emp = data["empirical"]
    assert emp["effect"].startswith("empirical:")
    assert emp["cv_rms_after_mm"] < 1.15 * data["noise_floor_mm"]
    assert all(not s["effect"].startswith("empirical") for s in data["suggestions"])
    where = data["where"]
    assert set(where["maps_2d"]) == {"XY", "XZ", "YZ"}
    assert len(where["by_approach"]) >= 2
    assert all("stderr_xyz_mm" in b for b in where["binned_means"]["X"])
    text = "\n".join(format_report(res))
    assert "verdict: unexplained" in text
    assert "empirical correction" in text
    # the user can still add it, and watch the error fall
    args = shlex.split(emp["command"])
    assert run(args[1:]).exit_code == 0
    out = args[args.index("-o") + 1]
    after = json.loads(run(["check", "c.csv", "-c", out, "--fixed", "--json", "--max-effects", "0"]).stdout)
    assert after["cv_rms_mm"] < 1.2 * data["noise_floor_mm"]
    assert after["effects_in_calibration"][-1] == emp["effect"]


def test_two_pitches_on_one_axis_are_found():
    from postproc.diagnose.check import run_check

    mach = machine_with([
        {"name": "periodic:Y", "config": {"pitch_mm": 16.0}, "params": {"cos_mm": 0.006, "sin_mm": 0.0}},
        {"name": "periodic:Y", "config": {"pitch_mm": 5.3}, "params": {"cos_mm": 0.0, "sin_mm": 0.005}},
    ])
    rng = np.random.default_rng(41)
    meas = simulate_plan(mach, measurement_plan(random_points(mach.volume_mm, 150, rng),
                                                tool_vectors=[(0, 0, -100)], repeats=2), rng)
    res = run_check(load_calibration(TABLES_CAL), [meas], ["p.csv"], fixed=True,
                    candidates=["periodic:X", "periodic:Y", "straightness:Y", "positioning:Y"])
    sug = res.suggestions
    assert [s["effect"] for s in sug] == ["periodic:Y", "periodic:Y"]
    assert sorted(s["config"]["pitch_mm"] for s in sug) == pytest.approx([5.3, 16.0], rel=0.01)
    assert res.verdict == "missing-effect"
    assert sug[-1]["command"].count("--effect periodic:Y") == 2


def test_campaign_warnings(tmp_path):
    from postproc.diagnose.check import run_check

    rng = np.random.default_rng(13)
    warm = machine_with([{"name": "thermal:t", "config": {"tau_s": 2400.0},
                          "params": {"dx_mm": 0.012, "dy_mm": -0.006, "dz_mm": 0.02}}])
    meas, _ = raster_with_dir0(warm, rng, step=35.0)
    # two points beyond the calibrated travel of X
    extra = Measurements(q=np.array([[330.0, 10.0, 0.0], [340.0, 10.0, 0.0]]), m=np.array([[330.0, 10, 0], [340, 10, 0]]),
                         r=np.tile([0.0, 0.0, -100.0], (2, 1)), direction=np.zeros((2, 3)),
                         context={"t": np.full(2, meas.context["t"].max() + 60.0)})
    for name in ("q", "m", "r", "direction"):
        setattr(meas, name, np.vstack([getattr(meas, name), getattr(extra, name)]))
    meas.context = {"t": np.concatenate([meas.context["t"], extra.context["t"]])}
    meas.path, meas.linenos = "raster.csv", np.arange(len(meas.q)) + 4
    res = run_check(load_calibration(TABLES_CAL), [meas], ["raster.csv"], fixed=True, candidates=[],
                    offer_empirical=False)
    kinds = {w["kind"]: w for w in res.warnings}
    assert kinds["time-position confounding"]["r2"] > 0.9
    aliasing = {w["axis"]: w["shortest_pitch_mm"] for w in res.warnings if w["kind"] == "aliasing"}
    assert aliasing == pytest.approx({"X": 70.0, "Y": 70.0, "Z": 315.0})
    out = kinds["outside volume"]
    assert out["rows"] == [f"raster.csv:{len(meas.q) + 2}", f"raster.csv:{len(meas.q) + 3}"]
    assert len(res.ds) == len(meas.q) - 2
    assert "unknown approach" not in kinds  # the raster records its first move


def test_suggested_size_is_the_joint_one_fit_delivers():
    """A backlash held out of a parametric calibration refitted from points: the
    suggestion's size is sized jointly with the base, exactly as 'fit --effect' sizes it."""
    from postproc.calfile import calibration_from_dict, calibration_to_dict
    from postproc.diagnose.check import run_check
    from postproc.diagnose.refit import fit_with_effects

    rng = np.random.default_rng(17)
    mach = machine_with([{"name": "backlash:Y", "params": {"b_mm": 0.012}}])
    meas = tracker_campaign(rng, n=40, machine=mach)
    plain = fit_with_effects("parametric", [meas], [])
    cal = calibration_from_dict(calibration_to_dict(plain.engine, name="p", fit={}), path="p.json")
    res = run_check(cal, [meas], ["w.csv"], folds=4, max_selected=1, candidates=["backlash:Y", "backlash:X"],
                    offer_empirical=False)
    (sug,) = res.suggestions
    assert sug["effect"] == "backlash:Y"
    b, u = sug["parameters"]["b_mm"], sug["parameters_u_k2"]["b_mm"]
    assert 0 < u < 0.004
    assert b == pytest.approx(0.012, abs=1.5 * u)
    (eff,) = fit_with_effects("parametric", [meas], ["backlash:Y"]).effects
    assert eff["params"]["b_mm"] == pytest.approx(b, rel=1e-6)


def test_coarse_raster_warns_about_knots():
    from types import SimpleNamespace

    from postproc.diagnose.campaign import campaign_warnings
    from postproc.diagnose.data import Dataset
    from postproc.simulate import grid_points

    rng = np.random.default_rng(19)
    mach = load_machine(MACHINE)
    q = grid_points(mach.volume_mm, [63.0, 105.0, 105.0])  # a 6 x 4 x 4 raster
    meas = simulate_plan(mach, measurement_plan(q, tool_vectors=[(0, 0, -100)]), rng)
    ds = Dataset.from_measurements([meas])
    res = SimpleNamespace(fixed=False, outside=[], outside_excluded=False)
    warn = campaign_warnings(ds, SimpleNamespace(method="parametric"), [meas], res)
    coarse = {w["axis"]: w["distinct_positions"] for w in warn if w["kind"] == "coarse knots"}
    assert coarse == {"X": 6, "Y": 4, "Z": 4}
    held = campaign_warnings(ds, SimpleNamespace(method="parametric"), [meas], SimpleNamespace(**{**vars(res), "fixed": True}))
    assert not any(w["kind"] == "coarse knots" for w in held)  # a calibration held as it is is not refitted


def test_tools_measured_one_after_the_other_warn():
    from types import SimpleNamespace

    from postproc.diagnose.campaign import campaign_warnings
    from postproc.diagnose.data import Dataset

    rng = np.random.default_rng(23)
    mach = load_machine(MACHINE)
    res = SimpleNamespace(fixed=True, outside=[], outside_excluded=False)
    cal = SimpleNamespace(method="parametric")
    plan = measurement_plan(random_points(mach.volume_mm, 40, rng), tool_vectors=[(0, 0, -100), (0, 0, -200)],
                            time_span_s=3600)
    meas = simulate_plan(mach, plan, rng)
    kinds = {w["kind"] for w in campaign_warnings(Dataset.from_measurements([meas]), cal, [meas], res)}
    assert "time-tool confounding" in kinds
    # the same rows in a shuffled order: no confounding
    order = rng.permutation(len(meas.q))
    meas.q, meas.m, meas.r, meas.direction = meas.q[order], meas.m[order], meas.r[order], meas.direction[order]
    kinds = {w["kind"] for w in campaign_warnings(Dataset.from_measurements([meas]), cal, [meas], res)}
    assert "time-tool confounding" not in kinds


def test_dir0_carries_the_last_move_and_leading_zeros_are_unknown():
    from postproc.calibration.measurements import carried_directions

    d = np.array([[0, 0, 1], [1, 0, 0], [0, -1, 0], [-1, 0, 0], [0, 0, -1]], dtype=float)
    expected = np.array([[0, 0, 1], [1, 0, 1], [1, -1, 1], [-1, -1, 1], [-1, -1, -1]], dtype=float)
    np.testing.assert_array_equal(carried_directions(d), expected)
    meas = Measurements(q=np.zeros((5, 3)), m=np.zeros((5, 3)), r=np.zeros((5, 3)), direction=d)
    np.testing.assert_array_equal(meas.unknown_direction_rows(), [True, True, False, False, False])
    np.testing.assert_array_equal(meas.context_full()["diry"], expected[:, 1])
