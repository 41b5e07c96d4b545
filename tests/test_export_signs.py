"""No sign of a controller table comes from a default, and every export is read back
by a model of its controller before anything is written.
Data: runs of the virtual machine (postproc.simulate.runs)."""

import numpy as np
import pytest
from click.testing import CliRunner
from metrology_machines import TARGETS, write_runs, x_machine
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.errors import CalibrationError
from postproc.metrology.controllers import linuxcnc as lcnc
from postproc.metrology.controllers.axis import AxisErrors
from postproc.metrology.controllers.fanuc import export_fanuc, fanuc_compensation, read_fanuc
from postproc.metrology.controllers.linuxcnc import read_linuxcnc
from postproc.metrology.controllers.siemens import read_siemens


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def runs_cal(tmp_path):
    runs, _ = write_runs(tmp_path / "runs.csv", x_machine(reversal_mm=0.012))
    cal = tmp_path / "cal.json"
    assert run("fit", runs, "-o", cal).exit_code == 0
    return cal


def control_residual(text: str, axis_errors: AxisErrors, control_return: int, ref: float) -> float:
    """Largest |compensation + error| (mm) a control returning in ``control_return`` leaves at
    the table points, both directions: the machine zero is the error at the reference
    approached in the control's own return direction."""
    params, data = read_fanuc(text)
    x, c_up, c_down = fanuc_compensation(params, data, "1", return_direction=control_return)
    x = x + ref
    zero = (axis_errors.up if control_return > 0 else axis_errors.down)([ref])[0]
    return float(max(np.abs(c_up + axis_errors.up(x) - zero).max(), np.abs(c_down + axis_errors.down(x) - zero).max()))


def test_fanuc_needs_reference_and_return(runs_cal, tmp_path):
    out = tmp_path / "pitch.txt"
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "-o", out)
    assert res.exit_code == 4
    assert "needs the reference position and the direction of the reference return" in res.stderr
    assert "missing --reference and --return" in res.stderr
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--reference", "X=0", "-o", out)
    assert res.exit_code == 4
    assert "missing --return" in res.stderr
    assert not out.exists()


@pytest.mark.parametrize(("ref", "ret"), [("0", "+"), ("315", "-"), ("-10", "+"), ("400", "-")])
def test_fanuc_refuses_a_reference_the_return_cannot_reach(runs_cal, tmp_path, ref, ret):
    out = tmp_path / "pitch.txt"
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--reference", f"X={ref}", "--return", f"X={ret}",
              "-o", out)
    assert res.exit_code == 4, res.output
    assert f"a reference return in {ret} cannot reach the reference" in res.stderr
    assert not out.exists()


def test_fanuc_reversal_sign_follows_the_stated_return(runs_cal, tmp_path):
    """A table written for the control's return direction leaves the rounding; read by a
    control that returns the other way it leaves the whole reversal: the direction must
    be stated, never assumed."""
    cal = load_calibration(runs_cal)
    e = AxisErrors(cal, "X")
    out = tmp_path / "pitch.txt"
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--reference", "X=0", "--return", "X=-", "-o", out)
    assert res.exit_code == 0, res.output
    text = out.read_text()
    right = control_residual(text, e, -1, 0.0)
    wrong = control_residual(text, e, +1, 0.0)
    assert right <= 0.0005 + 1e-9  # half a detection unit
    reversal = float(np.abs(e.reversal(np.asarray(TARGETS))).max())
    assert wrong > 0.8 * reversal > 0.008


def test_fanuc_parameter_tape_gives_reference_and_return(runs_cal, tmp_path):
    tape = tmp_path / "params.txt"
    tape.write_text("%\nN1006A1P00100000A2P00000000\nN1240A1P315000A2P0\nN1820A1P2\n%\n")
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--parameters", tape, "-o", a)
    # 1006#5 = 1 (return in -) with the reference at the upper end (315 mm): unreachable
    assert res.exit_code == 4
    assert "cannot reach" in res.stderr
    tape.write_text("%\nN1006A1P00000000\nN1240A1P315000\n%\n")
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--parameters", tape, "-o", a)
    assert res.exit_code == 0, res.output
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--reference", "X=315", "--return", "X=+", "-o", b)
    assert res.exit_code == 0, res.output
    assert a.read_text() == b.read_text()


def test_round_trip_refuses_a_table_the_controller_reads_otherwise(runs_cal, tmp_path, monkeypatch):
    """A defect between writer and controller model (here: the loader reads the trims with
    the other sign) stops the export before any file is written."""
    real = lcnc.linuxcnc_loader

    def flipped(text, comp_type, path=""):
        nom, up, down, errors = real(text, comp_type, path)
        return nom, -up, -down, errors

    monkeypatch.setattr(lcnc, "linuxcnc_loader", flipped)
    out = tmp_path / "comp"
    res = run("export", runs_cal, "-f", "linuxcnc", "-o", out)
    assert res.exit_code == 4
    assert "round trip of the linuxcnc table of X" in res.stderr
    assert "nothing written" in res.stderr
    assert not out.exists() or not any(out.iterdir())


def test_fanuc_round_trip_is_checked_in_the_writer(runs_cal):
    cal = load_calibration(runs_cal)
    e = AxisErrors(cal, "X")
    exp = export_fanuc([e], interval_mm=5.0, reference_mm={"X": 100.0}, return_direction={"X": -1})
    assert "pitch.txt" in exp.files
    with pytest.raises(CalibrationError, match="needs the reference position"):
        export_fanuc([e], interval_mm=5.0, reference_mm={}, return_direction={"X": -1})


def test_linuxcnc_nominals_strictly_increase_for_runs_in_mm_and_tables_in_um(tmp_path):
    """Runs in mm and a straightness table in um give 31.4 and 31.400000000000002: one node."""
    runs, _ = write_runs(tmp_path / "runs.csv", x_machine())
    tables = tmp_path / "straight.csv"
    rows = "".join(f"X,{p * 1000:.1f},{0.5 * np.sin(p / 40):.4f}\n" for p in TARGETS)
    tables.write_text("# postproc axis error tables v1\n# units: length=um\naxis,position,EY\n" + rows)
    cal = tmp_path / "cal.json"
    res = run("fit", runs, tables, "-o", cal)
    assert res.exit_code == 0, res.output
    out = tmp_path / "comp"
    res = run("export", cal, "-f", "linuxcnc", "-o", out)
    assert res.exit_code == 0, res.output
    text = (out / "joint0_X.comp").read_text()
    nominal, _, _ = read_linuxcnc(text, 0)  # raises on a nominal LinuxCNC would drop
    assert np.all(np.diff(nominal) > 0)
    assert_allclose(nominal, TARGETS)


def test_linuxcnc_reader_refuses_repeated_nominals():
    with pytest.raises(Exception, match="compensation values must increase"):
        read_linuxcnc("0 0 0\n31.4 31.4 31.4\n31.4 31.4 31.4\n50 50 50\n", 0)


def test_siemens_needs_the_reference_and_is_zero_there(runs_cal, tmp_path):
    out = tmp_path / "enc.spf"
    res = run("export", runs_cal, "-f", "siemens", "--step", "5", "-o", out)
    assert res.exit_code == 4
    assert "zero at the reference point" in res.stderr
    res = run("export", runs_cal, "-f", "siemens", "--step", "5", "--reference", "X=150", "-o", out)
    assert res.exit_code == 0, res.output
    x, v = read_siemens(out.read_text())["X1"]
    e = AxisErrors(load_calibration(runs_cal), "X")
    assert np.interp(150.0, x, v) == pytest.approx(0.0, abs=1e-6)
    assert_allclose(v, e.positioning(x) - e.positioning([150.0])[0], atol=1e-6)


def test_beckhoff_states_negate_and_alternative_model(runs_cal, tmp_path):
    out = tmp_path / "volcomp.csv"
    res = run("export", runs_cal, "-f", "beckhoff", "-o", out)
    assert res.exit_code == 0, res.output
    comments = [ln for ln in out.read_text().splitlines() if ln.startswith("//")]
    assert any("negate: leave unset" in ln for ln in comments)
    assert any("alternative_model: 0" in ln for ln in comments)
    assert "negate" in res.stderr
    assert "alternative_model" in res.stderr


@pytest.mark.parametrize("reversal_mm", [0.012, -0.012])
def test_fanuc_on_a_minus_l_to_zero_axis(tmp_path, reversal_mm):
    """The common -L..0 layout, reference at 0 reached in +: the table lies on the - side of
    the reference, and the control's summation gives back the correction at every point,
    both directions, for a reversal of either sign."""
    targets = tuple(t - 315.0 for t in TARGETS)
    runs, _ = write_runs(tmp_path / "runs.csv", x_machine(reversal_mm=reversal_mm, lo=-315.0, hi=0.0),
                         targets=targets, at=[-315.0, 0.0, -400.0])
    cal = tmp_path / "cal.json"
    assert run("fit", runs, "-o", cal).exit_code == 0
    out = tmp_path / "pitch.txt"
    res = run("export", cal, "-f", "fanuc", "--step", "5", "--reference", "X=0", "--return", "X=+", "-o", out)
    assert res.exit_code == 0, res.output
    params, data = read_fanuc(out.read_text())
    x, c_up, c_down = fanuc_compensation(params, data, "1", return_direction=1)
    assert x.min() == pytest.approx(-315.0)
    assert x.max() == pytest.approx(0.0)
    # every section on the - side: the farthest + point is the reference's own number
    assert params[3622]["1"] == params[3620]["1"]
    assert params[3621]["1"] == params[3620]["1"] - 315 // 5 + 1
    e = AxisErrors(load_calibration(cal), "X")
    assert control_residual(out.read_text(), e, +1, 0.0) <= 0.0005 + 1e-9
    res = run("export", cal, "-f", "fanuc", "--step", "5", "--reference", "X=0", "--return", "X=-", "-o", out)
    assert res.exit_code == 4  # the upper end cannot be reached moving -


@pytest.mark.parametrize(("args", "words"), [
    (["-f", "fanuc", "--reference", "X=nan", "--return", "X=+"], "must be a finite number of mm"),
    (["-f", "fanuc", "--reference", "X=300", "--return", "X=up"], "the return direction is + or -"),
    (["-f", "siemens", "--reference", "X=0", "--return", "X=+"], "--return is a setting of fanuc tables; drop it for --format siemens"),
    (["-f", "linuxcnc", "--reference", "X=0"], "--reference is a setting of fanuc and siemens tables"),
    # a setting the format does not read is refused, not ignored
    (["-f", "beckhoff", "--step", "5"], "--step is a setting of linuxcnc and fanuc and siemens tables; drop it for "
                                        "--format beckhoff"),
    (["-f", "fanuc", "--reference", "X=0", "--return", "X=-", "--comp-type", "1"],
     "--comp-type is a setting of linuxcnc tables"),
    (["-f", "siemens", "--reference", "X=0", "--detection-unit", "0.5"], "--detection-unit is a setting of fanuc"),
    (["-f", "beckhoff", "--axis-name", "X=X1"], "--axis-name is a setting of linuxcnc and fanuc and siemens"),
])
def test_export_settings_are_checked(runs_cal, tmp_path, args, words):
    res = run("export", runs_cal, *args, "-o", tmp_path / "out")
    assert res.exit_code == 2, res.output
    assert words in res.stderr
    assert not (tmp_path / "out").exists()


def test_a_registered_format_is_built_with_the_settings(runs_cal, tmp_path, monkeypatch):
    """A format is one registry entry and its builder: export calls the builder with the
    settings it was given (the defaults filled by the builder, not by the command)."""
    from postproc.cli import export as export_cli
    from postproc.metrology.controllers import formats
    from postproc.metrology.controllers.base import Export

    seen = {}

    def build(axis_errors, settings):
        seen["axes"] = [e.axis for e in axis_errors]
        seen["settings"] = settings
        return Export({"table.txt": "X 0.0\n"})

    monkeypatch.setattr(export_cli, "FORMATS", dict(formats.FORMATS))
    module = type(formats)("postproc_test_table_format")
    module.build = build
    monkeypatch.setitem(__import__("sys").modules, "postproc_test_table_format", module)
    export_cli.FORMATS["fanuc"] = formats.TableFormat("fanuc", "postproc_test_table_format:build",
                                                      frozenset({"step", "reference", "detection_unit"}))
    out = tmp_path / "t.txt"
    res = run("export", runs_cal, "-f", "fanuc", "--step", "5", "--reference", "X=12.5", "--detection-unit", "0.1",
              "-o", out)
    assert res.exit_code == 0, res.output
    assert out.read_text() == "X 0.0\n"
    s = seen["settings"]
    assert seen["axes"] == ["X"]
    assert (s.step_mm, s.reference_mm, s.detection_unit_mm, s.return_direction) == (5.0, {"X": 12.5}, 0.0001, {})
    res = run("export", runs_cal, "-f", "fanuc", "--return", "X=+", "-o", out)
    assert res.exit_code == 2
    assert "--return is a setting of" in res.stderr


def test_the_choices_are_the_registry():
    from postproc.cli.export import export
    from postproc.metrology.controllers.formats import FORMATS, SETTING_OPTIONS

    fmt = next(p for p in export.params if p.name == "fmt")
    assert list(fmt.type.choices) == list(FORMATS) == ["linuxcnc", "fanuc", "siemens", "beckhoff"]
    flags = {o for p in export.params for o in p.opts}
    assert set(SETTING_OPTIONS.values()) <= flags
