"""Calibrations as machine models: the chain's calibration element, predict init, and
verify --machine CAL. Each prediction is compared with the calibration engine's own
forward model, evaluated directly."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.errors import EXIT_CALIBRATION, EXIT_NOT_HELD
from postproc.predict.chain import chain_from_dict
from postproc.predict.operation import load_chain, load_operation

ROOT = Path(__file__).parents[1]
PARAMETRIC = ROOT / "calibrations" / "s500_parametric.json"
STATIC = ROOT / "calibrations" / "s500_static.json"


def run(*args):
    return CliRunner().invoke(main, [*map(str, args)])


def axes_and(calibration_element) -> dict:
    return {"format": "postproc chain", "version": 1, "modules": [
        {"name": "axes", "elements": [{"linear": {"axis": a, "var": a.upper()}} for a in "xyz"]},
        {"name": "measured", "elements": [calibration_element]}]}


@pytest.mark.parametrize("cal_path", [PARAMETRIC, STATIC])
def test_calibration_element_is_the_forward_model_at_the_commanded_position(cal_path):
    rng = np.random.default_rng(7)
    chain = chain_from_dict(axes_and({"calibration": str(cal_path)}))
    engine = load_calibration(cal_path).engine
    q = rng.uniform(0, 315, (50, 3))
    r = rng.uniform(-120, 120, (50, 3))
    got = chain.transform(r, {"X": q[:, 0], "Y": q[:, 1], "Z": q[:, 2]})
    assert_allclose(got, engine.forward(q, r), atol=1e-10)


def test_calibration_element_with_effects_takes_their_context(tmp_path):
    rng = np.random.default_rng(8)
    data = json.loads(STATIC.read_text())
    data["effects"] = [{"name": "backlash:X", "config": {}, "params": {"b_mm": 0.012}}]
    cal = tmp_path / "backlash.json"
    cal.write_text(json.dumps(data))
    with pytest.raises(Exception, match=r"modules\[1\] \(measured\)\.elements\[0\]: the effects of calibration .* "
                                        r"need the context value\(s\) \['dirx'\]"):
        chain_from_dict(axes_and({"calibration": str(cal)}))
    chain = chain_from_dict(axes_and({"calibration": {"file": str(cal), "context": {"dirx": "dx"}}}))
    engine = load_calibration(cal).engine
    q = rng.uniform(0, 315, (20, 3))
    dx = rng.choice([-1.0, 1.0], 20)
    got = chain.transform([0, 0, -100], {"X": q[:, 0], "Y": q[:, 1], "Z": q[:, 2], "dx": dx})
    assert_allclose(got, engine.forward(q, [0, 0, -100], {"dirx": dx}), atol=1e-10)
    plus, minus = (chain.transform([0, 0, 0], {"X": 100, "Y": 100, "Z": 100, "dx": d}) for d in (1.0, -1.0))
    assert_allclose(plus[0] - minus[0], 0.012, atol=1e-12)  # the reversal it was given


def test_calibration_path_is_relative_to_the_chain_file_and_round_trips(tmp_path):
    shutil.copy(STATIC, tmp_path / "cal.json")
    path = tmp_path / "machine.json"
    path.write_text(json.dumps(axes_and({"calibration": "cal.json"})))
    chain = load_chain(path)
    assert chain.to_dict()["modules"][1]["elements"][0] == {"calibration": "cal.json"}


def test_a_missing_calibration_names_the_chain_file_and_the_element(tmp_path):
    path = tmp_path / "machine.json"
    path.write_text(json.dumps(axes_and({"calibration": "nowhere.json"})))
    res = run("predict", "point", path)
    assert res.exit_code == EXIT_CALIBRATION
    assert str(path) in res.output
    assert "modules[1] (measured).elements[0]: calibration" in res.output
    assert "nowhere.json" in res.output


def test_a_position_outside_the_calibrated_volume_is_refused_by_name(tmp_path):
    path = tmp_path / "machine.json"
    path.write_text(json.dumps(axes_and({"calibration": str(STATIC)})))
    res = run("predict", "point", path, "--set", "X=400", "--set", "Y=0", "--set", "Z=0")
    assert res.exit_code == 3
    assert "outside the calibrated volume" in res.output
    assert "modules[1]" in res.output


def test_bore_on_a_calibrated_vertical_mill_moves_with_the_calibration():
    # The tool hangs 100 mm below the spindle (overhang -100 along z); the tips are
    # F(q, (r cos S, r sin S, -100)), an ellipse whose centre is F(q, (0, 0, -100)):
    # the engine's own forward model at the axis point.
    op = load_operation(ROOT / "samples" / "predict" / "s500_bore.operation.json")
    res = run("predict", "bore", op.path, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    q = np.array([[op.context["X"], op.context["Y"], op.context["Z"]]])
    axis_point = load_calibration(PARAMETRIC).engine.forward(q, [0, 0, -100])[0]
    assert_allclose(out["mid_field"]["error_mm"], axis_point[:2] - [200, 250], atol=1e-9)
    assert_allclose(out["mid_field"]["axis_point_mm"], axis_point, atol=1e-9)
    assert out["deterministic"] is True
    assert run("predict", "bore", op.path, "--check").exit_code == EXIT_NOT_HELD


@pytest.mark.parametrize("layout", ["vertical-mill", "horizontal-boring"])
def test_init_writes_a_commented_chain_that_predict_reads(tmp_path, layout):
    out = tmp_path / "chain.json"
    res = run("predict", "init", "--layout", layout, "-o", out)
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert data["_comment"]
    for mod in data["modules"]:
        assert mod["_comment"]
        for el in mod["elements"]:
            assert el["comment"], el
    chain = load_chain(out)
    res = run("predict", "point", out, "--set", "X=120", "--tool", "0,0,-100")
    assert res.exit_code == 0, res.output
    if layout == "vertical-mill":
        # zero errors: the tool point is q + r, with Y and Z at their defaults (0)
        assert "point: 120.000000 0.000000 -100.000000" in res.output
    else:
        assert set(chain.random) == {"g1", "g2", "g3", "g4"}


def test_init_with_a_calibration_from_another_directory(tmp_path):
    (tmp_path / "sub").mkdir()
    out = tmp_path / "sub" / "chain.json"
    res = run("predict", "init", "--layout", "vertical-mill", "-c", STATIC, "-o", out)
    assert res.exit_code == 0, res.output
    chain = load_chain(out)
    engine = load_calibration(STATIC).engine
    assert_allclose(chain.transform([0, 0, -100]), engine.forward(engine.volume_mm.mean(axis=0), [0, 0, -100])[0],
                    atol=1e-10)  # X, Y, Z default to the middle of the calibrated volume
    q = np.array([10.0, 300.0, 20.0])
    assert_allclose(chain.transform([5, 0, -80], dict(zip("XYZ", q, strict=True))),
                    engine.forward(q, [5, 0, -80])[0], atol=1e-10)


def test_init_horizontal_boring_gives_a_bore_with_monte_carlo(tmp_path):
    out = tmp_path / "hb.json"
    assert run("predict", "init", "--layout", "horizontal-boring", "-o", out).exit_code == 0
    op = {"format": "postproc operation", "kind": "bore", "machine": "hb.json", "diameter_mm": 40,
          "overhang_mm": 80, "axis": "x", "nominal_centre_mm": [200, 560], "tolerance_mm": [0.1, 0.1],
          "monte_carlo": {"n": 300, "seed": 2}}
    (tmp_path / "op.json").write_text(json.dumps(op))
    res = run("predict", "bore", tmp_path / "op.json", "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    # The guide corners lie in [0, 0.05]: mid-field the plane is 0.025 mm higher, level.
    assert_allclose(out["mid_field"]["error_mm"], [0.0, 0.025], atol=1e-9)
    assert out["monte_carlo"]["n"] == 300


def test_bore_takes_another_machine_with_the_option(tmp_path):
    out = tmp_path / "flat.json"
    assert run("predict", "init", "--layout", "vertical-mill", "-o", out).exit_code == 0
    sample = ROOT / "samples" / "predict" / "s500_bore.operation.json"
    res = run("predict", "bore", sample, "--machine", out, "--json", "--check")
    assert res.exit_code == 0, res.output  # a machine without errors cuts the nominal hole
    assert_allclose(json.loads(res.output)["mid_field"]["error_mm"], [0.0, 0.0], atol=1e-12)


def test_verify_points_on_a_calibration_as_the_machine():
    # no tracker noise: the deltas are the calibration's own errors at the targets
    res = run("verify", "--points", ROOT / "samples" / "s500_control_points.csv", "--machine", PARAMETRIC,
              "--tool-vector", "0,0,-100", "--no-noise", "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.output)
    p = np.asarray(out["targets_mm"])
    r = np.array([0.0, 0.0, -100.0])
    expected = np.linalg.norm(load_calibration(PARAMETRIC).engine.forward(p - r, r) - p, axis=1)
    assert_allclose(out["delta_mm"]["uncorrected"], expected, atol=1e-12)


def test_verify_program_on_a_calibration_as_the_machine():
    res = run("verify", ROOT / "samples" / "pocket.nc", "-c", PARAMETRIC, "--machine", PARAMETRIC, "--json")
    assert res.exit_code == 0, res.output
    runs = {r["label"]: r for r in json.loads(res.output)["runs"]}
    # Corrected with the very model it runs on, the program lands within the
    # correction's path tolerance (1 um) of the nominal path.
    corrected = next(v for k, v in runs.items() if k.startswith("corrected"))
    assert corrected["max_mm"] < 0.001
    assert runs["uncorrected"]["max_mm"] > 0.3


def test_the_corrected_program_bores_the_hole_where_it_belongs(tmp_path):
    # correct puts the bottom of the plunge (gauge point X200 Y250 Z180, tool 100 mm
    # down) where the calibration's inverse says; predicting the bore there through
    # the chain's calibration element brings the centre back to the nominal, to the
    # 0.05 um the corrected program's 4 decimals allow.
    out = tmp_path / "bore_corrected.nc"
    res = run("correct", ROOT / "samples" / "predict" / "s500_bore.nc", "-c", PARAMETRIC, "--tool-vector", "0,0,-100",
              "-o", out)
    assert res.exit_code == 0, res.output
    bottom = min((line for line in out.read_text().splitlines() if line.startswith("G1") and " Z" in line),
                 key=lambda line: float(line.split(" Z")[1].split()[0]))
    words = {w[0]: w[1:] for w in bottom.split()[1:] if w[0] in "XYZ"}
    sample = ROOT / "samples" / "predict" / "s500_bore.operation.json"
    before = json.loads(run("predict", "bore", sample, "--json").output)
    assert np.max(np.abs(before["mid_field"]["error_mm"])) > 0.2
    res = run("predict", "bore", sample, *[f"--set={k}={v}" for k, v in words.items()], "--check", "--json")
    assert res.exit_code == 0, res.output
    assert_allclose(json.loads(res.output)["mid_field"]["error_mm"], [0, 0], atol=1e-4)


def test_docs_walkthrough_from_a_calibration_to_a_predicted_bore(tmp_path, monkeypatch):
    text = (ROOT / "docs" / "predict.md").read_text(encoding="utf-8")
    section = text.split("**From a calibration to a predicted bore.**", 1)[1].split("The 21-parameter model", 1)[0]
    blocks = section.split("```\n")[1::2]
    commands = [line.split("postproc ", 1)[1].split() for line in blocks[0].splitlines()]
    printed = blocks[1].splitlines()
    monkeypatch.chdir(ROOT)
    for args in commands:  # fit, init, bore: outputs go to tmp_path
        args = [str(tmp_path / a) if a.endswith((".chain.json", "s500_tables.json")) else a for a in args]
        res = run(*args)
    assert res.exit_code == EXIT_NOT_HELD, res.output
    assert printed[0] in res.output
    assert printed[-1] in res.output
    second = blocks[2].replace("\\\n", " ").splitlines()
    correct = second[0].split("postproc ", 1)[1].split()
    correct = [str(tmp_path / a) if a.endswith((".nc", ".json")) and not a.startswith("samples") else a
               for a in correct]
    assert run(*correct).exit_code == 0
    expected_line = second[1].split("# ", 1)[1]
    assert expected_line in (tmp_path / "bore_corrected.nc").read_text().splitlines()
    bore = [str(tmp_path / a) if a.endswith(".chain.json") else a for a in second[2].split("postproc ", 1)[1].split()]
    res = run(*bore)
    assert res.exit_code == 0, res.output
    assert "centre error X    0.013 um, Y    0.018 um" in res.output
