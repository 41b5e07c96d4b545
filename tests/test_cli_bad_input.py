"""Bad input to the commands other than correct/diff: a one-line `postproc: error:`,
a non-zero exit code, no traceback and no output file left behind."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.effects import get_effect
from postproc.errors import (
    EXIT_CALIBRATION,
    EXIT_INTERNAL,
    EXIT_USAGE,
    CalibrationError,
    OutputError,
)
from postproc.fileio import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
WALKTHROUGH = ROOT / "samples" / "walkthrough_points.csv"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_user_error(result, code: int, *fragments: str) -> None:
    """A PostprocError reported on one `postproc: error:` line, not an internal error."""
    assert result.exit_code == code, result.output
    assert result.exit_code != EXIT_INTERNAL
    assert "internal error" not in result.output
    assert "Traceback" not in result.output
    assert "postproc: error: " in result.output, result.output
    for fragment in fragments:
        assert fragment in result.output, result.output


def test_atomic_write_into_a_missing_directory_is_an_output_error(tmp_path):
    target = tmp_path / "missing" / "out.txt"
    with pytest.raises(OutputError) as exc:
        atomic_write_text(target, "x\n")
    assert exc.value.exit_code == EXIT_USAGE
    assert str(exc.value).startswith(f"{target}: cannot write the output: directory")
    assert not (tmp_path / "missing").exists()


def test_fit_into_a_missing_directory(tmp_path):
    out = tmp_path / "missing" / "cal.json"
    result = run("fit", WALKTHROUGH, "-o", out)
    assert_user_error(result, EXIT_USAGE, f"{out}: cannot write the output")
    assert not out.parent.exists()


def test_simulate_tables_into_a_missing_directory(tmp_path):
    out = tmp_path / "missing" / "t.csv"
    result = run("simulate", MACHINE, "--tables", "--step", "100", "-o", out)
    assert_user_error(result, EXIT_USAGE, "cannot write the output")
    assert not out.parent.exists()


def _static_calibration_with(tmp_path, effects) -> Path:
    data = json.loads((ROOT / "calibrations" / "s500_static.json").read_text())
    data["effects"] = effects
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(("effect", "fragment"), [
    ({"name": "backlash:X", "params": {"b_mm": "x"}}, "params.b_mm is 'x', not a finite number"),
    ({"name": "backlash:X", "params": {"b_mm": float("nan")}}, "params.b_mm is nan, not a finite number"),
    ({"name": "backlash:X", "params": {"b_mm": [1, 2]}}, "params.b_mm is [1, 2], not a finite number"),
    ({"name": "thermal:t", "config": {"tau_s": "x"}, "params": {"dx_mm": 0.01}},
     "config.tau_s is 'x', not a finite number"),
])
def test_calibration_effect_values_must_be_finite_numbers(tmp_path, effect, fragment):
    cal = _static_calibration_with(tmp_path, [effect])
    result = run("check", WALKTHROUGH, "-c", cal)
    assert_user_error(result, EXIT_CALIBRATION, f"{cal}: effect {effect['name']}: {fragment}")


def test_straightness_needs_a_positive_half_travel():
    effect = get_effect("straightness:X", config={"center_mm": 100.0, "half_travel_mm": 0.0})
    with pytest.raises(CalibrationError, match="no half_travel_mm > 0"):
        effect.basis(np.array([[10.0, 20.0, 30.0]]), None, None)


MIRROR = ROOT / "samples" / "mirror"


@pytest.mark.parametrize("args", [
    ["mirror", "kfb", MIRROR / "P01_semi.csv", "--t-ref", "nan", "--allowance", "0.3", "--origin", "3,100"],
    ["mirror", "kfb", MIRROR / "P01_semi.csv", "--t-ref", "2", "--allowance", "0.3", "--origin", "3,inf"],
    ["mirror", "kdist", MIRROR / "backwall_sensor.csv", "--cutter-radius", "nan", "--diameter", "2000"],
    ["mirror", "deadband", MIRROR / "zigzag_sensor.csv", "--gap", "nan"],
    ["simulate", MACHINE, "--random", "2", "--tool-vector", "nan,0,0"],
    ["simulate", MACHINE, "--random", "2", "--context", "t=inf"],
    ["orders", "-c", ROOT / "calibrations" / "s500_parametric.json", "--point", "60,50,50", "-k", "inf"],
    ["orders", "-c", ROOT / "calibrations" / "s500_parametric.json", "--point", "nan,50,50"],
    ["verify", ROOT / "samples" / "pocket.nc", "-c", ROOT / "calibrations" / "s500_static.json",
     "--machine", MACHINE, "--tool-length", "1=nan"],
])
def test_non_finite_option_values_are_usage_errors(tmp_path, args):
    out = tmp_path / "out.csv"
    result = run(*args, "-o", out) if args[0] in ("mirror", "simulate") and args[1] != "deadband" else run(*args)
    assert result.exit_code == EXIT_USAGE, result.output
    assert "Invalid value" in result.output
    assert "internal error" not in result.output
    assert not out.exists()


@pytest.mark.parametrize(("args", "option"), [
    (["simulate", MACHINE, "--random", "5", "--seed", "-1"], "--seed"),
    (["simulate", MACHINE, "--random", "5", "--time-span", "-1"], "--time-span"),
    (["verify", "--points", ROOT / "samples" / "s500_control_points.csv", "-c",
      ROOT / "calibrations" / "s500_static.json", "--machine", MACHINE, "--seed", "-1"], "--seed"),
    (["verify", "--points", ROOT / "samples" / "s500_control_points.csv", "-c",
      ROOT / "calibrations" / "s500_static.json", "--machine", MACHINE, "--shots", "0"], "--shots"),
    (["verify", ROOT / "samples" / "pocket.nc", "-c", ROOT / "calibrations" / "s500_static.json",
      "--machine", MACHINE, "--tolerance", "0"], "--tolerance"),
    (["predict", "bore", ROOT / "samples" / "predict" / "bore_50H7.operation.json", "--seed", "-1"], "--seed"),
    (["predict", "tolerance", ROOT / "samples" / "predict" / "bore_50H7.operation.json", "-n", "0"], "-n"),
    (["mirror", "deadband", MIRROR / "zigzag_sensor.csv", "--gap", "0.02", "--drive-tau", "-1"], "--drive-tau"),
    (["mirror", "kfb", MIRROR / "P01_semi.csv", "--t-ref", "2", "--allowance", "-0.3", "--origin", "3,100"],
     "--allowance"),
    (["mirror", "pockets", MIRROR / "plan.csv", "-c", MIRROR / "shell_static.json", "--program",
      MIRROR / "pocket.nc", "--t-ref", "2", "--band", "1.98,2.02", "--allowance", "-0.3"], "--allowance"),
])
def test_out_of_range_options_are_usage_errors(tmp_path, args, option):
    out = tmp_path / "out.csv"
    result = run(*args, "-o", out) if args[0] in ("simulate", "mirror") else run(*args)
    assert result.exit_code == EXIT_USAGE, result.output
    assert f"Invalid value for '{option}'" in result.output
    assert not out.exists()


def test_mirror_synth_refuses_a_negative_seed(tmp_path):
    result = run("mirror", "synth", tmp_path / "shell", "--seed", "-1")
    assert result.exit_code == EXIT_USAGE, result.output
    assert "Invalid value for '--seed'" in result.output
    assert not (tmp_path / "shell").exists()


def test_verify_refuses_a_corrected_program_without_feed_moves(tmp_path):
    """An empty or rapid-only corrected program must not be reported as 0.00 um off the path."""
    corrected = tmp_path / "corrected.nc"
    for text in ("", "G0 X10 Y10 Z10\nG0 X20 Y20\n"):
        corrected.write_text(text)
        result = run("verify", ROOT / "samples" / "pocket.nc", "--corrected", corrected, "--machine", MACHINE)
        assert_user_error(result, 3, f"{corrected}: the corrected program has no feed moves")
        assert "0.00 um" not in result.output


def test_verify_refuses_a_program_without_feed_moves(tmp_path):
    program = tmp_path / "rapids.nc"
    program.write_text("G0 X10 Y10 Z10\nG0 X20 Y20\n")
    result = run("verify", program, "-c", ROOT / "calibrations" / "s500_static.json", "--machine", MACHINE)
    assert_user_error(result, 3, f"{program}: the program has no feed moves to verify")


@pytest.mark.parametrize("command", ["verify", "orders"])
def test_point_files_without_rows(tmp_path, command):
    points = tmp_path / "points.csv"
    points.write_text("# units: length=mm\nX,Y,Z\n")
    if command == "verify":
        result = run("verify", "--points", points, "-c", ROOT / "calibrations" / "s500_static.json",
                     "--machine", MACHINE)
    else:
        result = run("orders", "-c", ROOT / "calibrations" / "s500_parametric.json", "--points", points)
    assert_user_error(result, 3, f"{points}:2:1: no ")


def test_kfb_from_a_thickness_file_without_rows(tmp_path):
    semi = tmp_path / "semi.csv"
    semi.write_text("# units: length=mm\nB,Z,T\n")
    out = tmp_path / "kfb.csv"
    result = run("mirror", "kfb", semi, "--t-ref", "2", "--allowance", "0.3", "--origin", "3,100", "-o", out)
    assert_user_error(result, 3, f"{semi}:2:1: no thickness rows")
    assert not out.exists()


def test_pockets_leaves_no_output_directory_when_the_job_fails(tmp_path):
    out = tmp_path / "next"
    result = run("mirror", "pockets", MIRROR / "plan.csv", "-c", MIRROR / "shell_static.json",
                 "--program", MIRROR / "pocket.nc", "--t-ref", "2.0", "--band", "1.98,2.02", "--allowance", "0.3",
                 "--max-correction", "0.01", "-o", out)
    assert_user_error(result, 5, "exceeds --max-correction 0.01 mm")
    assert not out.exists()


@pytest.mark.parametrize(("units_line", "col", "message"), [
    ("# units: length=inch", 10, "length unit 'inch' is not one of mm, um"),
    ("# units: angle=rad length=inch", 20, "length unit 'inch' is not one of mm, um"),
    ("# units: length mm", 10, "units entry 'length' is not key=value"),
])
def test_a_bad_units_line_is_named_by_line_and_column(tmp_path, units_line, col, message):
    src = tmp_path / "m.csv"
    src.write_text(f"# postproc measurements v1\n{units_line}\nX,Y,Z,mx,my,mz\n1,2,3,1,2,3\n")
    out = tmp_path / "cal.json"
    result = run("fit", src, "-o", out)
    assert_user_error(result, 3, f"{src}:2:{col}: {message}")
    assert not out.exists()


@pytest.mark.parametrize(("method", "message"), [
    ("bogus", "unknown calibration method 'bogus'"),
    (["static"], "calibration method ['static'] is not a name"),
])
def test_calibration_method_errors_name_the_file(tmp_path, method, message):
    data = json.loads((ROOT / "calibrations" / "s500_static.json").read_text())
    data["method"] = method
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(data))
    result = run("check", WALKTHROUGH, "-c", cal)
    assert_user_error(result, EXIT_CALIBRATION, f"{cal}: {message}")


@pytest.mark.parametrize("tables", [5, [1]])
def test_machine_tables_of_the_wrong_type(tmp_path, tables):
    data = json.loads(MACHINE.read_text())
    data["tables"] = tables
    machine = tmp_path / "m.machine.json"
    machine.write_text(json.dumps(data))
    out = tmp_path / "pts.csv"
    result = run("simulate", machine, "--random", "3", "-o", out)
    assert_user_error(result, EXIT_CALIBRATION, f"{machine}: malformed machine definition")
    assert not out.exists()


@pytest.mark.parametrize(("source", "key", "value", "fragment"), [
    ("calibrations/s500_parametric.json", "astatic", 5, "astatic settings must be an object"),
    ("calibrations/s500_parametric.json", "squareness_rad", [1, 2], "malformed parametric model"),
    ("calibrations/s500_parametric.json", "tables", 5, "malformed parametric model"),
])
def test_malformed_model_fields_are_calibration_errors(tmp_path, source, key, value, fragment):
    data = json.loads((ROOT / source).read_text())
    data["model"][key] = value
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(data))
    result = run("check", WALKTHROUGH, "-c", cal)
    assert_user_error(result, EXIT_CALIBRATION, f"{cal}: ", fragment)


@pytest.mark.parametrize("r_o1", [5.0, [1.0]])
def test_grid_model_needs_a_three_vector_origin(r_o1):
    from postproc.engine.grid import GridEngine

    nodes = np.stack(np.meshgrid([0.0, 10.0], [0.0, 10.0], [0.0, 10.0], indexing="ij"), axis=-1)
    engine = GridEngine.from_nodes([0, 0, 0], [10, 10, 10], nodes)
    model = engine.model_to_dict()
    model["r_O1_mm"] = r_o1
    with pytest.raises(CalibrationError, match=r"r_O1_mm \(3,\)"):
        GridEngine.model_from_dict(model, engine.volume_mm.tolist())


PREDICT = ROOT / "samples" / "predict"


@pytest.mark.parametrize(("command", "source", "key"), [
    ("trace", "flank_5mm.operation.json", "runout"),
    ("bore", "bore_50H7.operation.json", "monte_carlo"),
])
def test_operation_sub_objects_of_the_wrong_type(tmp_path, command, source, key):
    data = json.loads((PREDICT / source).read_text())
    data[key] = "x"
    for machine in PREDICT.glob("*.machine.json"):
        (tmp_path / machine.name).write_text(machine.read_text())
    op = tmp_path / source
    op.write_text(json.dumps(data))
    result = run("predict", command, op)
    assert_user_error(result, 3, f'{op}: operation: "{key}" must be an object')


# Disk full (ENOSPC): its own exit code, one line, nothing left behind


def _runs_writing_to(out):
    return {
        "correct": ["correct", ROOT / "samples" / "pocket.nc", "-c", ROOT / "calibrations" / "s500_static.json",
                    "-o", out],
        "fit": ["fit", WALKTHROUGH, "-o", out],
        "simulate": ["simulate", MACHINE, "--random", "5", "-o", out],
    }


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
@pytest.mark.parametrize("command", ["correct", "fit", "simulate"])
def test_disk_full_has_its_own_exit_code(command):
    from postproc.errors import EXIT_DISK_FULL

    result = run(*_runs_writing_to("/dev/full")[command])
    assert_user_error(result, EXIT_DISK_FULL, "/dev/full: disk full")


@pytest.mark.parametrize("command", ["correct", "fit"])
def test_disk_full_while_writing_leaves_no_temporary_file(tmp_path, monkeypatch, command):
    """A regular output on a full disk: the temporary file beside it is removed."""
    import builtins
    import errno

    from postproc.errors import EXIT_DISK_FULL

    real_open = open

    def full_open(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        if "w" in mode and str(file).startswith(str(tmp_path)):
            def write(_text):
                raise OSError(errno.ENOSPC, "No space left on device")
            fh.write = write
        return fh

    monkeypatch.setattr(builtins, "open", full_open)
    out = tmp_path / "out.txt"
    result = run(*_runs_writing_to(out)[command])
    monkeypatch.undo()
    assert_user_error(result, EXIT_DISK_FULL, "disk full")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_disk_full_writing_to_stdout():
    import subprocess
    import sys

    from postproc.errors import EXIT_DISK_FULL

    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "postproc", "correct", str(ROOT / "samples" / "pocket.nc"), "-c",
                               str(ROOT / "calibrations" / "s500_static.json"), "-o", "-"],
                              stdout=full, stderr=subprocess.PIPE, text=True, env={**os.environ,
                                                                                  "PYTHONPATH": str(ROOT)})
    assert proc.returncode == EXIT_DISK_FULL, proc.stderr
    assert proc.stderr.startswith("postproc: error: "), proc.stderr
    assert "disk full" in proc.stderr
    assert "Traceback" not in proc.stderr
