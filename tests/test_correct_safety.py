"""Every safety refusal: a clear message with its place, a non-zero exit, no output file."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import save_calibration
from postproc.cli import main
from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.engine.static import StaticEngine
from postproc.errors import (
    EXIT_CALIBRATION,
    EXIT_INPUT,
    EXIT_SAFETY,
    AlreadyCorrectedError,
    CorrectionTooLargeError,
    MissingSetupError,
    OutOfVolumeError,
    SafetyError,
    SolverError,
    UnsupportedGcodeError,
)
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_file, correct_text

ROOT = Path(__file__).parents[1]
CAL = str(ROOT / "calibrations" / "s500_static.json")
VOLUME = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]
PROGRAM = "G21 G90\nG0 X10 Y10 Z10\nG1 X100 Y20 F300\nG1 X120\n"


def static(offset=(0.01, 0.0, 0.0)):
    return StaticEngine(np.eye(3), offset, VOLUME)


def run(args, tmp_path):
    return CliRunner().invoke(main, args, catch_exceptions=False)


def test_correction_too_large_is_refused_with_line(tmp_path):
    with pytest.raises(CorrectionTooLargeError) as e:
        correct_text(PROGRAM, static((0.0, 0.0, 2.0)), Setup(), path="p.nc")
    assert e.value.lineno == 2
    assert "exceeds --max-correction 1 mm" in str(e.value)
    out, _ = correct_text(PROGRAM, static((0.0, 0.0, 2.0)), Setup(), CorrectOptions(max_correction_mm=3.0))
    assert "Z8.0000" in out


def test_out_of_volume_refused_lists_lines_and_can_be_clamped():
    text = "G0 X10 Y10 Z10\nG1 X400 F100\nG1 X500\nG1 X10\n"
    with pytest.raises(OutOfVolumeError) as e:
        correct_text(text, static(), Setup(), path="p.nc")
    assert str(e.value).startswith("p.nc:2:")
    assert "lines 2, 3" in str(e.value)
    out, rep = correct_text(text, static(), Setup(), CorrectOptions(extrapolate="clamp"))
    assert rep.extrapolated_points == 2
    assert "X399.9900" in out
    _, rep = correct_text(text, static(), Setup(), CorrectOptions(extrapolate="linear"))
    assert rep.extrapolated_points == 2


def test_missing_work_offset_and_tool_length():
    with pytest.raises(MissingSetupError) as e:
        correct_text("G55\nG0 X1 Y1 Z1\n", static(), Setup(), path="p.nc")
    assert (e.value.lineno, "G55") == (2, "G55")
    assert "--offset G55" in str(e.value)
    with pytest.raises(MissingSetupError) as e:
        correct_text("G0 X1 Y1 Z1\nG43 H3\nG0 Z5\n", static(), Setup(), path="p.nc")
    assert e.value.lineno == 2
    assert "--tool-length 3" in str(e.value)
    # an explicitly named G54 must be given too
    with pytest.raises(MissingSetupError):
        correct_text("G54 G0 X1 Y1 Z1\n", static(), Setup())


def test_already_corrected_is_refused_unless_forced():
    out, _ = correct_text(PROGRAM, static(), Setup())
    with pytest.raises(AlreadyCorrectedError) as e:
        correct_text(out, static(), Setup(), path="c.nc")
    assert (e.value.lineno, e.value.col) == (1, 1)
    again, _ = correct_text(out, static(), Setup(), CorrectOptions(force=True))
    assert sum(emit.is_header_start(ln) for ln in again.splitlines()) == 2


class NoConvergence(Engine):
    method = "stuck"

    def forward(self, q, r=None, context=None):
        return check_points(q) + check_tool_vectors(r, len(check_points(q)))

    def inverse(self, p, r=None, context=None):
        p = check_points(p)
        return InverseResult(p - check_tool_vectors(r, len(p)), np.full(len(p), 0.01), np.full(len(p), 50))

    def model_to_dict(self):
        return {}

    @classmethod
    def model_from_dict(cls, model, volume_mm):
        return cls(volume_mm)


def test_solver_that_does_not_converge_is_refused():
    with pytest.raises(SolverError) as e:
        correct_text(PROGRAM, NoConvergence(VOLUME), Setup(), path="p.nc")
    assert e.value.lineno == 2
    assert "did not converge" in str(e.value)


@pytest.mark.parametrize(("program", "construct"), [
    ("G0 X1 Y1 Z1\n#1=5\n", "parameter assignment"),
    ("G0 X1 Y1 Z1\nG1 X[1+2]\n", "expression"),
    ("O100 sub\n", "O-word"),
    ("G0 X1 Y1 Z1\nM98 P100\n", "M98"),
    ("G0 X1 Y1 Z1\nG19 G41 D1\n", "Cutter radius compensation allowed only in XY, XZ planes"),
    ("G0 X1 Y1 Z1\nG68 X0 Y0 R30\n", "G68"),
    ("G0 X1 Y1 Z1\nG51 X0 Y0 P2\n", "G51"),
    ("G0 X1 Y1 Z1\nG76 P0.05 Z-1 I-0.075 J0.008 K0.045\n", "G76 threading cycle"),
    ("G0 X1 Y1 Z1\nG12.3 X1\n", "unknown G code"),
    ("G0 X1 Y1 Z1\nG1 V5\n", "V axis"),  # U/W: a lathe program (tests/test_dialect_programs.py)
])
def test_unsupported_constructs_are_refused_with_line_and_column(program, construct):
    # macros, expressions, O-words and subprograms are expanded by default: --no-expand
    # refuses them, naming what they are
    with pytest.raises(UnsupportedGcodeError) as e:
        correct_text(program, static(), Setup(), CorrectOptions(expand=False), path="p.nc")
    assert construct in str(e.value)
    assert e.value.lineno is not None
    assert e.value.col is not None


# -- through the CLI: exit codes and no output file -----------------------------------
def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_cli_refusals_leave_no_output_and_keep_an_existing_file(tmp_path):
    src = _write(tmp_path, "far.nc", "G0 X10 Y10 Z10\nG1 X900 F100\n")
    out = tmp_path / "out.nc"
    r = run(["correct", src, "-c", CAL, "-o", str(out)], tmp_path)
    assert r.exit_code == EXIT_SAFETY
    assert "far.nc:2:" in r.output
    assert "outside the calibrated volume" in r.output
    assert not out.exists()
    out.write_text("old program\n")
    r = run(["correct", src, "-c", CAL, "-o", str(out)], tmp_path)
    assert r.exit_code == EXIT_SAFETY
    assert out.read_text() == "old program\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_cli_missing_offset_macro_and_bad_calibration(tmp_path):
    out = tmp_path / "o.nc"
    src = _write(tmp_path, "g55.nc", "G55 G0 X1 Y1 Z1\n")
    r = run(["correct", src, "-c", CAL, "-o", str(out)], tmp_path)
    assert r.exit_code == EXIT_SAFETY
    assert "g55.nc:1:" in r.output
    assert not out.exists()
    r = run(["correct", src, "-c", CAL, "-o", str(out), "--offset", "G55=X100,Y100,Z100"], tmp_path)
    assert r.exit_code == 0, r.output
    out.unlink()
    src = _write(tmp_path, "macro.nc", "G0 X1 Y1 Z1\nG0 X#1\n")
    r = run(["correct", src, "-c", CAL, "-o", str(out), "--no-expand"], tmp_path)
    assert r.exit_code == EXIT_INPUT
    assert "macro.nc:2:5: parameter reference" in r.output  # the '#' of X#1
    assert not out.exists()
    bad = tmp_path / "bad.json"
    data = json.loads(Path(CAL).read_text())
    data["units"] = {"length": "um", "angle": "rad"}
    bad.write_text(json.dumps(data))
    r = run(["correct", src, "-c", str(bad), "-o", str(out)], tmp_path)
    assert r.exit_code == EXIT_CALIBRATION
    assert "units" in r.output
    assert not out.exists()


def test_correct_file_removes_its_temp_file_on_failure(tmp_path):
    src = _write(tmp_path, "p.nc", "G0 X10 Y10 Z10\nG1 X900 F100\n")
    with pytest.raises(OutOfVolumeError):
        correct_file(src, tmp_path / "o.nc", static(), Setup())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.nc"]


def test_cli_tool_table_and_context_and_force(tmp_path):
    tbl = _write(tmp_path, "tools.tbl", "T1 P1 Z100.0 D6.0 ;end mill\nT2 P2 Z80 ;drill\n")
    out = tmp_path / "o.ngc"
    src = str(ROOT / "samples" / "g54_g43.ngc")
    r = run(["correct", src, "-c", CAL, "-o", str(out), "--offset", "G54=X100,Y80,Z40", "--tool-table", tbl,
             "--context", "temp=21.5"], tmp_path)
    assert r.exit_code == 0, r.output
    assert emit.is_header_start(out.read_text().splitlines()[1])  # after the '%' line
    r = run(["correct", str(out), "-c", CAL, "-o", str(tmp_path / "twice.ngc")], tmp_path)
    assert r.exit_code == EXIT_SAFETY
    assert "already carries a postproc header" in r.output
    r = run(["correct", src, "-c", CAL, "-o", str(out), "--offset", "G54=X100,Y80"], tmp_path)
    assert r.exit_code == 2  # usage: offsets need X, Y and Z


def test_cli_several_files_in_parallel(tmp_path):
    outdir = tmp_path / "out"
    files = [str(ROOT / "samples" / n) for n in ("pocket.nc", "holes_g91.nc", "inch.nc")]
    r = run(["correct", *files, "-c", CAL, "--output-dir", str(outdir), "-j", "2"], tmp_path)
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in outdir.iterdir()) == ["holes_g91.nc", "inch.nc", "pocket.nc"]


def test_calibration_saved_in_wrong_scale_is_refused_by_max_correction(tmp_path):
    # a calibration whose offsets were written in um instead of mm moves by tens of mm
    cal = tmp_path / "um.json"
    save_calibration(cal, StaticEngine(np.eye(3), [35.0, -22.0, 18.0], VOLUME), name="um")
    src = str(ROOT / "samples" / "pocket.nc")
    r = run(["correct", src, "-c", str(cal), "-o", str(tmp_path / "o.nc")], tmp_path)
    assert r.exit_code == EXIT_SAFETY
    assert "exceeds --max-correction" in r.output
    assert not (tmp_path / "o.nc").exists()


def test_output_gets_a_normal_file_mode_and_a_missing_directory_is_an_input_error(tmp_path):
    import os
    import stat

    out = tmp_path / "o.nc"
    correct_file(ROOT / "samples" / "pocket.nc", out, static(), Setup())
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask
    r = run(["correct", str(ROOT / "samples" / "pocket.nc"), "-c", CAL, "-o", str(tmp_path / "no" / "o.nc")],
            tmp_path)
    assert r.exit_code == EXIT_INPUT
    assert "cannot write the output" in r.output


def test_decimals_too_few_for_the_tolerance_are_refused():
    # one decimal rounds a word by up to 0.05 mm per axis: the 0.001 mm tolerance cannot hold
    text = "G21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nG2 X30 Y10 I5 J0\n"
    with pytest.raises(SafetyError, match=r"words written with 1 decimals in mm are rounded by up to 0.0866 mm") as exc:
        correct_text(text, static(), Setup(), CorrectOptions(decimals=1))
    assert exc.value.lineno == 2
    out, _ = correct_text(text, static(), Setup(), CorrectOptions(decimals=1, tolerance_mm=0.1))
    assert "\nG1 X20 F100\n" in out  # 20 - 0.01 is 20.0 to one decimal: the word stays
    # inch words with 4 decimals round by up to 0.0022 mm: refused at the first inch move only
    inch = "G21 G90\nG0 X10 Y10 Z10\nG20\nG1 X1 F10\n"
    with pytest.raises(SafetyError, match=r"in inch") as exc:
        correct_text(inch, static(), Setup(), CorrectOptions(decimals=4))
    assert exc.value.lineno == 4
    correct_text(inch.replace("G20\nG1 X1", "G1 X11"), static(), Setup(), CorrectOptions(decimals=4))
