"""Issue 31 item 4: machine-state variables given on the command line (--var, --vars).

Each read of machine state is satisfied by the value given, the header records it, and
a probe result is refused whatever is given. Motions by hand: X = the value read + 2."""

from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.cli.options import build_setup
from postproc.engine.identity import IdentityEngine
from postproc.errors import PostprocError, UnsupportedGcodeError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.variables import parse_var, read_vars

ROOT = Path(__file__).parents[1]
CAL = str(ROOT / "calibrations" / "s500_static.json")
BIG = [[-1e5] * 3, [1e5] * 3]
ZERO = {"G54": (0.0, 0.0, 0.0)}

HAAS = "%\nO01000 (TOOL LIFE)\nG90 G54 G17\nG0 X0 Y0 Z5\n#100 = #5405 + 2.\nG1 X#100 F200\nM30\n%\n"
RETAINED = "G90 G54 G17\nG0 X0 Y0 Z5\n#100 = #650 + 2.\nG1 X#100 F200\nM30\n"
LINUXCNC = "G90 G54 G17\nG0 X0 Y0 Z5\n#100 = [#5221 + 2]\nG1 X#100 F200\nM2\n"


def correct(text, variables, dialect):
    setup = Setup(offsets=ZERO, variables=variables)
    return correct_text(text, IdentityEngine(BIG), setup, CorrectOptions(dialect=dialect), path="p.nc")[0]


@pytest.mark.parametrize(("text", "index", "dialect"), [(HAAS, 5405, "haas"), (RETAINED, 650, "fanuc"),
                                                         (LINUXCNC, 5221, "linuxcnc")])
def test_machine_state_read_satisfied_and_recorded(text, index, dialect):
    with pytest.raises(UnsupportedGcodeError, match=f"#{index}") as err:
        correct(text, {}, dialect)
    assert f"--var {index}=VALUE" in err.value.hint
    out = correct(text, {index: 12.5}, dialect)
    assert "G1 X14.5000 F200" in out or "G1 X14.5 F200" in out  # 12.5 + 2
    assert f"(POSTPROC VARIABLES {index} 12.5)" in out


@pytest.mark.parametrize(("text", "dialect"), [
    ("G90 G54\nG0 X0 Y0 Z5\n#100 = #5063\nG1 Z#100 F100\nM30\n", "fanuc"),
    ("G90 G54\nG0 X0 Y0 Z5\n#100 = #5063\nG1 Z#100 F100\nM2\n", "linuxcnc"),
])
def test_probe_result_refused_whatever_is_given(text, dialect):
    for given in ({}, {5063: 1.0}):
        with pytest.raises(UnsupportedGcodeError, match="probe result: a program that depends on what it will "
                                                        "measure cannot be corrected ahead of time"):
            correct(text, given, dialect)


def test_var_option_parsing():
    assert parse_var("5405=12.5") == (5405, 12.5)
    assert parse_var("#650=-1") == (650, -1.0)
    for bad in ("5405", "x=1", "5405=nan", "0=1"):
        with pytest.raises(ValueError, match="expected NUMBER=VALUE"):
            parse_var(bad)
    with pytest.raises(ValueError, match="probe result"):
        parse_var("5061=0")
    with pytest.raises(click.BadParameter, match="probe result"):
        build_setup(var=("5062=1",))


def test_vars_files(tmp_path):
    lcnc = tmp_path / "linuxcnc.var"
    lcnc.write_text("5161\t0.000000\n5221\t-12.250000\n5063\t3.0\n")
    fanuc = tmp_path / "macro.txt"
    fanuc.write_text("%\nO9999 (MACRO VARIABLES)\n#500 = 1.5\n#650 12.5 (PART COUNT)\nN5405 3.\n; end\n%\n")
    assert read_vars(lcnc) == {5161: 0.0, 5221: -12.25}  # the probe result is left out
    assert read_vars(fanuc) == {500: 1.5, 650: 12.5, 5405: 3.0}
    bad = tmp_path / "bad.txt"
    bad.write_text("#500 = 1\nhello\n")
    with pytest.raises(PostprocError, match="not a variable number") as err:
        read_vars(bad)
    assert err.value.lineno == 2
    setup = build_setup(var=("650=7",), vars_file=str(fanuc))
    assert setup.variables == {500: 1.5, 650: 7.0, 5405: 3.0}  # --var overrides the file


def test_cli_var_on_correct_diff_and_verify(tmp_path):
    src = tmp_path / "tl.nc"
    src.write_text(HAAS.replace("G0 X0 Y0 Z5", "G0 X100 Y100 Z100"))
    out = tmp_path / "out.nc"
    run = CliRunner().invoke
    res = run(main, ["correct", str(src), "-c", CAL, "-o", str(out), "--dialect", "haas",
                     "--offset", "G54=X0,Y0,Z0", "--var", "5405=12.5"])
    assert res.exit_code == 0, res.output
    assert "(POSTPROC VARIABLES 5405 12.5)" in out.read_text()
    res = run(main, ["diff", str(src), str(out), "--dialect", "haas", "--var", "5405=12.5"])
    assert res.exit_code == 0, res.output
    res = run(main, ["diff", str(src), str(out), "--dialect", "haas"])  # the header's VARIABLES
    assert res.exit_code == 0, res.output
    from postproc.gcode.compare import header_setup

    assert header_setup(str(out)).variables == {5405: 12.5}
    for cmd in ("correct", "diff", "verify"):
        assert "--vars FILE" in run(main, [cmd, "--help"]).output
