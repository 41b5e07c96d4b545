"""Errors found after an expanded program is read name the file of their line.

A program that calls subprograms in other files (LinuxCNC ``o<name> call`` on
--subroutine-path, Fanuc/Haas ``M98 P..`` program files, Sinumerik ``.SPF``
subprograms) is corrected expanded, each line carrying its source line and file. A
refusal found when the chunk is planned or written (outside the calibrated volume, a
canned cycle that cannot carry its correction, a move that must be split on a
tool-change line, a line too long once corrected) names the file, line and column of
its cause; a list of lines names the file of each line that is not the error's own."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.errors import OutOfVolumeError, PostprocError, SafetyError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_file

ROOT = Path(__file__).resolve().parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
PARAMETRIC = str(ROOT / "calibrations" / "s500_parametric.json")
SETUP = Setup(offsets={"G54": (100.0, 100.0, 100.0)}, tool_lengths={1: 0.0, 2: 0.0})


def refusal(tmp_path: Path, name: str, text: str, subs: dict[str, str], dialect: str = "generic",
            calibration: str = STATIC, setup: Setup = SETUP, **options) -> tuple[PostprocError, Path, Path]:
    """The error correcting program ``text`` (written as ``name``) with the files ``subs``
    on its --subroutine-path gives, its column filled in as the CLI fills it; and the
    program's and the subprograms' folder's paths."""
    folder = tmp_path / "subs"
    folder.mkdir(exist_ok=True)
    for sub, body in subs.items():
        (folder / sub).write_text(body)
    prog = tmp_path / name
    prog.write_text(text)
    cal = load_calibration(calibration)
    with pytest.raises(PostprocError) as err:
        correct_file(str(prog), str(tmp_path / "out.nc"), cal.engine, setup,
                     CorrectOptions(dialect=dialect, subroutine_path=[str(folder)], **options))
    return err.value.with_column(), prog, folder


def place(err: PostprocError) -> tuple[str | None, int | None, int | None]:
    return err.path, err.lineno, err.col


# -- LinuxCNC: o<name> call of a file on the subroutine path --------------------------
FAR = "o<far> sub\n  G1 X900 Y10 F100\nG1 X50\no<far> endsub\nM2\n"
NEAR = "o<near> sub\nG1 X90 Y10 F100\nG1 X50\no<near> endsub\nM2\n"


def test_linuxcnc_outside_volume_in_the_subprogram(tmp_path):
    err, _prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<far> call\nG1 X20 F100\nM2\n",
                               {"far.ngc": FAR})
    assert isinstance(err, OutOfVolumeError)
    assert place(err) == (str(subs / "far.ngc"), 2, 3)
    assert "at lines 2: commanded (1000.000, 110.000, 110.000) mm" in err.message


def test_linuxcnc_outside_volume_in_the_main_program_after_the_call(tmp_path):
    err, prog, _subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<near> call\n    G1 X900\nM2\n",
                               {"near.ngc": NEAR})
    assert isinstance(err, OutOfVolumeError)
    assert place(err) == (str(prog), 4, 5)
    assert "at lines 4:" in err.message


def test_linuxcnc_line_list_names_each_file(tmp_path):
    # line 2 of both files and line 4 of the program: the error is the first row's (the
    # program's line 2), the subprogram's line named with its file
    err, prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X900 Y10 Z10\no<far> call\nG1 X950\nM2\n",
                              {"far.ngc": FAR})
    assert place(err) == (str(prog), 2, 1)
    assert f"at lines 2, {subs / 'far.ngc'}:2, 4:" in err.message
    # the first offending line in the subprogram: the program's lines named with its file
    err, prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<far> call\nG1 X950\nM2\n",
                              {"far.ngc": FAR})
    assert place(err) == (str(subs / "far.ngc"), 2, 3)
    assert f"at lines 2, {prog}:4:" in err.message


def test_one_file_expanded_keeps_bare_line_numbers(tmp_path):
    # a subroutine of the program's own file, called twice: its lines are the program's
    text = "o<far> sub\nG1 X900 Y10 F100\no<far> endsub\nG21 G90 G17\nG0 X10 Y10 Z10\no<far> call\nG1 X950\nM2\n"
    err, prog, _subs = refusal(tmp_path, "main.ngc", text, {})
    assert place(err) == (str(prog), 2, 1)
    assert "at lines 2, 7:" in err.message


def test_linuxcnc_cycle_refused_by_the_writer_in_the_subprogram(tmp_path):
    sub = "o<cyc> sub\nG0 X10 Y10 Z10\n  G91 G81 X20 Y0 Z-5 R2 L3 F100\nG80 G90\no<cyc> endsub\nM2\n"
    err, _prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<cyc> call\nM2\n",
                               {"cyc.ngc": sub}, cycles="keep")
    assert isinstance(err, SafetyError)
    assert "canned cycle G81 in G91" in err.message
    assert place(err) == (str(subs / "cyc.ngc"), 3, 3)


def test_linuxcnc_whole_move_split_refused_in_the_subprogram(tmp_path):
    # a tool change on a move that must be split (a calibration whose correction varies)
    sub = "o<tc> sub\nG1 X10 Y10 Z10 F100\n  T2 M6 G1 X300 Y300 Z200\no<tc> endsub\nM2\n"
    err, _prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<tc> call\nM2\n",
                               {"tc.ngc": sub}, calibration=PARAMETRIC,
                               setup=Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0, 2: 0.0}),
                               tolerance_mm=0.0005)
    assert "this move must be split" in err.message
    assert place(err) == (str(subs / "tc.ngc"), 3, 3)


def test_cli_names_the_subprogram_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "subs").mkdir()
    (tmp_path / "subs" / "far.ngc").write_text("o<far> sub\nG1 X900 Y10\nG1 X50 F100\no<far> endsub\nM2\n")
    (tmp_path / "main.ngc").write_text("G21 G90 G17\nG0 X10 Y10 Z10\no<far> call\nG1 X20 F100\nM2\n")
    res = CliRunner().invoke(main, ["correct", "main.ngc", "-c", STATIC, "-o", "out.ngc", "--subroutine-path", "subs",
                                    "--offset", "G54=X100,Y100,Z100"])
    assert res.exit_code != 0
    assert f"{Path('subs') / 'far.ngc'}:2:1: target outside the calibrated volume at lines 2:" in res.output


# -- Fanuc: M98 P.. of a program file on the subroutine path ---------------------------
def test_fanuc_outside_volume_in_the_program_file_and_after_the_call(tmp_path):
    sub = "%\nO5001 (SUB)\n  G1 X900 Y10 F100\nM99\n%\n"
    err, prog, subs = refusal(tmp_path, "main.nc", "O1\nG21 G90 G17\nG0 X10 Y10 Z10\nM98 P5001\n G1 X950 F100\nM30\n%\n",
                              {"5001.NC": sub}, dialect="fanuc")
    assert isinstance(err, OutOfVolumeError)
    assert place(err) == (str(subs / "5001.NC"), 3, 3)
    assert f"at lines 3, {prog}:5:" in err.message
    ok = "%\nO5002 (SUB)\nG1 X90 Y10 F100\nM99\n%\n"
    err, prog, _subs = refusal(tmp_path, "main.nc", "O1\nG21 G90 G17\nG0 X10 Y10 Z10\nM98 P5002\n G1 X950 F100\nM30\n%\n",
                               {"5002.NC": ok}, dialect="fanuc")
    assert place(err) == (str(prog), 5, 2)
    assert "at lines 5:" in err.message


def test_fanuc_cycle_refused_by_the_writer_in_the_program_file(tmp_path):
    sub = "%\nO5003 (SUB)\nG0 X10 Y10 Z10\n  G91 G81 X20 Y0 Z-5 R2 K3 F100\nG80 G90\nM99\n%\n"
    err, _prog, subs = refusal(tmp_path, "main.nc", "O1\nG21 G90 G17\nG0 X10 Y10 Z10\nM98 P5003\nM30\n%\n",
                               {"5003.NC": sub}, dialect="fanuc", cycles="keep")
    assert "canned cycle G81 in G91" in err.message
    assert place(err) == (str(subs / "5003.NC"), 4, 3)


# -- Sinumerik: a subprogram called by name from its .SPF file -------------------------
def test_sinumerik_outside_volume_in_the_subprogram_and_after_the_call(tmp_path):
    far = "PROC FAR\n  G1 X900 Y10 F100\nRET\n"
    err, prog, subs = refusal(tmp_path, "main.mpf", "G54 D1\nG0 X10 Y10 Z10\nFAR\n  G1 X950 F100\nM30\n",
                              {"FAR.SPF": far}, dialect="sinumerik")
    assert isinstance(err, OutOfVolumeError)
    assert place(err) == (str(subs / "FAR.SPF"), 2, 3)
    assert f"at lines 2, {prog}:4:" in err.message
    near = "PROC NEAR\nG1 X90 Y10 F100\nRET\n"
    err, prog, _subs = refusal(tmp_path, "main.mpf", "G54 D1\nG0 X10 Y10 Z10\nNEAR\n  G1 X950 F100\nM30\n",
                               {"NEAR.SPF": near}, dialect="sinumerik")
    assert place(err) == (str(prog), 4, 3)
    assert "at lines 4:" in err.message


def test_sinumerik_line_too_long_once_corrected_in_the_subprogram(tmp_path):
    long = "G1 X20 Y10" + " " * 497 + "F100\n"  # 511 characters: as long as a line may be
    sub = "PROC LONG\nG0 X10 Y10 Z10\n" + long + "RET\n"
    err, _prog, subs = refusal(tmp_path, "main.mpf", "G54 D1\nG0 X10 Y10 Z10\nLONG\nM30\n", {"LONG.SPF": sub},
                               dialect="sinumerik")
    assert "once corrected" in err.message
    assert place(err)[:2] == (str(subs / "LONG.SPF"), 3)


def test_linuxcnc_cycle_hole_outside_volume_in_the_subprogram(tmp_path):
    # --cycles auto weighs a cycle block's correction as it reads it: its refusal names the file too
    sub = "o<h> sub\nG0 X10 Y10 Z10\n  G81 X900 Y10 Z-5 R2 F100\nG80\no<h> endsub\nM2\n"
    err, _prog, subs = refusal(tmp_path, "main.ngc", "G21 G90 G17\nG0 X10 Y10 Z10\no<h> call\nM2\n", {"h.ngc": sub})
    assert isinstance(err, OutOfVolumeError)
    assert place(err) == (str(subs / "h.ngc"), 3, 3)


def test_sinumerik_drilling_cycle_call_refused_in_the_subprogram(tmp_path):
    # read, not written: --cycles keep cannot keep a CYCLE81 call
    sub = "PROC DRL\nG0 X10 Y10 Z10\nCYCLE81(10, 0, 2, -5)\nRET\n"
    err, _prog, subs = refusal(tmp_path, "main.mpf", "G54 D1\nG0 X10 Y10 Z10\nDRL\nM30\n", {"DRL.SPF": sub},
                               dialect="sinumerik", cycles="keep")
    assert "CYCLE81 (drilling cycle call)" in err.message
    assert place(err) == (str(subs / "DRL.SPF"), 3, 1)
