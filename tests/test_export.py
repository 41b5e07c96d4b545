"""Controller exports: write, read back as the controller reads it, compare along each axis."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.metrology.controllers.fanuc import fanuc_compensation, read_fanuc
from postproc.metrology.controllers.linuxcnc import read_linuxcnc
from postproc.metrology.controllers.siemens import read_siemens

S500 = "calibrations/s500_parametric.json"
TARGETS = np.arange(0.0, 250.0, 25.0)  # evenly spaced, so a Fanuc grid of 25 mm lands on them


def runs_calibration(tmp_path, seed):
    """A calibration fitted from generated X runs, and the measured unidirectional means
    (mm) per target, computed here straight from the generated deviations."""
    rng = np.random.default_rng(seed)
    e = 0.015 * np.sin(TARGETS / 60.0) + 4e-5 * TARGETS
    b = 0.006 + 2e-5 * TARGETS
    lines = ["# postproc iso230 runs v1", "# units: length=mm error=mm", "axis,target,run,direction,deviation"]
    devs = {1: [], -1: []}
    for j in range(5):
        for d in (1, -1):
            x = e + d * b / 2 + rng.normal(0, 0.0004, len(TARGETS))
            x = np.round(x, 6)
            devs[d].append(x)
            order = range(len(TARGETS)) if d > 0 else reversed(range(len(TARGETS)))
            lines += [f"X,{TARGETS[i]:.3f},{j + 1},{'+' if d > 0 else '-'},{x[i]:.6f}" for i in order]
    path = tmp_path / "runs.csv"
    path.write_text("\n".join(lines) + "\n")
    cal = tmp_path / "cal.json"
    res = CliRunner().invoke(main, ["fit", str(path), "-o", str(cal)])
    assert res.exit_code == 0, res.output
    return cal, np.mean(devs[1], axis=0), np.mean(devs[-1], axis=0)


@pytest.mark.parametrize("comp_type", ["0", "1"])
def test_linuxcnc_round_trip(tmp_path, comp_type):
    cal, up, down = runs_calibration(tmp_path, 21)
    out = tmp_path / "comp"
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "linuxcnc", "--comp-type", comp_type, "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "BACKLASH = 0" in res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["joint0_X.comp"]
    text = (out / "joint0_X.comp").read_text()
    assert not any(line.startswith(("#", ";")) for line in text.splitlines())  # LinuxCNC stops at a comment
    nominal, err_up, err_down = read_linuxcnc(text, int(comp_type))
    # the table's nominals are the targets; its errors the measured means in each direction
    assert_allclose(nominal, TARGETS)
    assert_allclose(err_up, up, atol=1.5e-6)
    assert_allclose(err_down, down, atol=1.5e-6)


def test_linuxcnc_types_agree_and_s500_axes(tmp_path):
    for t in ("0", "1"):
        res = CliRunner().invoke(main, ["export", S500, "-f", "linuxcnc", "--comp-type", t, "-o", str(tmp_path / t)])
        assert res.exit_code == 0, res.output
    cal = load_calibration(S500)
    for j, axis in enumerate("XYZ"):
        a = read_linuxcnc((tmp_path / "0" / f"joint{j}_{axis}.comp").read_text(), 0)
        b = read_linuxcnc((tmp_path / "1" / f"joint{j}_{axis}.comp").read_text(), 1)
        assert_allclose(a, b, atol=2e-6)
        # along the axis, from the model's tables: the positioning column at each nominal
        x = cal.engine.tables.position_mm[axis]
        assert_allclose(a[0], x)
        assert_allclose(a[1], cal.engine.tables.column(axis, f"E{axis}"), atol=1e-6)


def test_fanuc_round_trip(tmp_path):
    cal, up, down = runs_calibration(tmp_path, 22)
    out = tmp_path / "pitch.txt"
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "fanuc", "--step", "25", "--reference", "X=0",
                                    "--return", "X=-", "-o", str(out)])
    assert res.exit_code == 0, res.output
    params, data = read_fanuc(out.read_text())
    assert params[3624]["1"] == 25000  # 25 mm in 1 um detection units
    x, c_up, c_down = fanuc_compensation(params, data, "1", return_direction=-1)
    assert_allclose(x, TARGETS)
    # the control's absolute compensation, summed from the increments as the control does,
    # is minus the measured error relative to the reference (approached in -), to 1 unit
    unit = 0.001 * params[3623]["1"]
    assert_allclose(c_down, -(down - down[0]), atol=0.5 * unit + 1e-9)
    assert_allclose(c_up, -(up - down[0]), atol=0.5 * unit + 1e-9)
    assert params[3627]["1"] == round((down[0] - up[0]) / unit)
    assert "reference return X in - (1006#5 ZMI = 1)" in res.stderr


def test_fanuc_reference_at_the_upper_end_and_plus_return(tmp_path):
    cal, up, down = runs_calibration(tmp_path, 23)
    out = tmp_path / "pitch.txt"
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "fanuc", "--step", "25", "--reference", "X=225",
                                    "--return", "X=+", "-o", str(out)])
    assert res.exit_code == 0, res.output
    params, data = read_fanuc(out.read_text())
    x, c_up, c_down = fanuc_compensation(params, data, "1", return_direction=1)
    assert_allclose(x + 225, TARGETS)
    unit = 0.001 * params[3623]["1"]
    assert_allclose(c_up, -(up - up[-1]), atol=0.5 * unit + 1e-9)
    assert_allclose(c_down, -(down - up[-1]), atol=0.5 * unit + 1e-9)


def test_siemens_round_trip_and_remainder(tmp_path):
    out = tmp_path / "enc.spf"
    rest = tmp_path / "rest.json"
    res = CliRunner().invoke(main, ["export", S500, "-f", "siemens", "--step", "4", "-o", str(out),
                                    "--reference", "X=0", "--reference", "Y=0", "--reference", "Z=0",
                                    "--remainder", str(rest)])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert text.startswith("%_N_AX_EEC_INI\nCHANDATA(1)\n")
    assert text.rstrip().endswith("M17")
    tables = read_siemens(text)
    full = load_calibration(S500)
    for axis in "XYZ":
        x, v = tables[f"{axis}1"]
        assert x[0] == pytest.approx(0.0)
        assert x[-1] == pytest.approx(315.0)
        # values are the positioning column, read at the table's positions by the model, zero
        # at the reference point (X=0: the first point)
        pos = full.engine.axis_errors(axis, x)[:, "XYZ".index(axis)]
        assert v[0] == 0.0
        assert_allclose(v, pos - pos[0], atol=1e-6)
    # remainder + the three positioning columns = the full model
    remainder = load_calibration(rest)
    rng = np.random.default_rng(4)
    q = rng.uniform(0, 315, (50, 3))
    r = np.tile([0.0, 0.0, -100.0], (50, 1))
    # (the table holds the positioning minus its value at the reference, which stays in the remainder)
    at_ref = [full.engine.axis_errors(a, [0.0])[0, k] for k, a in enumerate("XYZ")]
    pos = np.column_stack([full.engine.axis_errors(a, q[:, k])[:, k] - at_ref[k] for k, a in enumerate("XYZ")])
    assert_allclose(remainder.engine.forward(q, r) + pos, full.engine.forward(q, r), atol=1e-12)


def test_beckhoff_export_is_read_back_by_fit(tmp_path):
    out = tmp_path / "volcomp.csv"
    res = CliRunner().invoke(main, ["export", S500, "-f", "beckhoff", "-o", str(out)])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert "X EXX EYX EZX EAX EBX ECX" in text
    assert "\n#\nY EXY EYY EZY EAY EBY ECY" in text
    back = tmp_path / "back.json"
    res = CliRunner().invoke(main, ["fit", str(out), "-o", str(back)])
    assert res.exit_code == 0, res.output
    a, b = load_calibration(S500).engine.tables, load_calibration(back).engine.tables
    for axis in "XYZ":
        assert_allclose(b.position_mm[axis], a.position_mm[axis])
        assert_allclose(b.errors[axis], a.errors[axis], rtol=1e-8, atol=1e-15)


def test_isg_reader_errors_name_their_line(tmp_path):
    path = tmp_path / "v.csv"
    path.write_text("// comment\nX EXX EYY\n0 0 0\n10 0.001 0\n")
    res = CliRunner().invoke(main, ["fit", str(path), "-o", str(tmp_path / "c.json")])
    assert res.exit_code == 3
    assert "v.csv:2:7: column 'EYY' is not a component error of X" in res.stderr


def test_export_refuses_tangential_calibrations(tmp_path):
    res = CliRunner().invoke(main, ["export", "calibrations/s500_static.json", "-f", "linuxcnc", "-o", str(tmp_path)])
    assert res.exit_code == 4
    assert "has no axis error tables to export" in res.stderr


def test_remainder_drops_backlash_and_positioning(tmp_path):
    cal, up, down = runs_calibration(tmp_path, 24)
    rest = tmp_path / "rest.json"
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "linuxcnc", "-o", str(tmp_path / "c"),
                                    "--remainder", str(rest)])
    assert res.exit_code == 0, res.output
    data = json.loads(rest.read_text())
    assert data["effects"] == []
    assert data["fit"]["remainder_of"]["in_controller"] == ["EXX", "backlash:X"]
    # with positioning and backlash in the controller, nothing is left along X
    q = np.column_stack([TARGETS, np.full(len(TARGETS), 5.0), np.zeros(len(TARGETS))])
    assert_allclose(load_calibration(rest).engine.forward(q), q, atol=1e-12)


def test_fanuc_magnification_and_detection_unit(tmp_path):
    # 0.01 um detection units: the increments over 25 mm (up to ~7 um) exceed 127 units,
    # so a magnification above 1 is chosen; the tape still sums back to the errors
    cal, up, down = runs_calibration(tmp_path, 25)
    out = tmp_path / "pitch.txt"
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "fanuc", "--step", "25", "--detection-unit", "0.01",
                                    "--reference", "X=225", "--return", "X=+", "-o", str(out)])
    assert res.exit_code == 0, res.output
    params, data = read_fanuc(out.read_text())
    assert params[3623]["1"] > 1
    assert max(abs(v) for v in data.values()) <= 127
    x, c_up, c_down = fanuc_compensation(params, data, "1", detection_unit_mm=0.00001)
    unit = 0.00001 * params[3623]["1"]
    assert_allclose(c_up, -(up - up[-1]), atol=0.5 * unit + 1e-9)
    res = CliRunner().invoke(main, ["export", str(cal), "-f", "fanuc", "--step", "25.00005", "--reference", "X=225",
                                    "--return", "X=+", "-o", str(out)])
    assert res.exit_code == 4
    assert "not a whole number of detection units" in res.stderr
