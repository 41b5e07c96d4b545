"""Okuma OSP programs: the ``$NAME.SSB%`` header read alike by the
expansion stage and the interpreter, and ``CALL O<name> [Q<n>]`` subprograms (ended by
``RTS``) expanded from the program's own file, the .SSB/.SUB/.LIB files beside it or on
``--subroutine-path``. The expected moves are worked out by hand from the Okuma OSP-P
Programming Manual's rules (G15 H work coordinates, a subprogram runs Q times)."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.expand import expand
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
SHOP = ROOT / "tests" / "data" / "shop" / "okuma"
CAL = str(ROOT / "calibrations" / "s500_static.json")
BIG = [[-1e5] * 3, [1e5] * 3]
SETUP = Setup(offsets={"G15H1": (100.0, 100.0, 100.0)}, tool_lengths={1: 0.0})

SUBS = ("$LIB.SUB%\n"
        "OHOLE (ONE HOLE)\nG91 G1 Z-5 F100\nG0 Z5\nG90\nRTS\n"
        "OSQ\nG1 X10\nCALL OHOLE\nG1 Y10\nCALL OHOLE Q2\nRTS\n")
MAIN = "$PART.MIN%\nG15 H1\nG0 X0 Y0 Z50\nG1 Z10 F100\nN10 CALL OSQ\nG1 X5\nM02\n"


def flat(text, folder, path="part.min"):
    return [sl.text for sl in expand(text.splitlines(keepends=True), path=str(folder / path), dialect="okuma",
                                     subroutine_path=[folder])]


def test_header_line_read_by_the_expansion_as_by_the_interpreter(tmp_path):
    """A parameter makes the program go through the expansion; its $OKUMA.SSB% header (an
    SSB, not MIN) stays the first line, as without the expansion."""
    text = "$OKUMA.SSB%\nG15 H1\nG0 X0 Y0 Z50\n#100=5\nG1 X#100 F100\nM2\n"
    out, rep = correct_text(text, IdentityEngine(BIG), SETUP, CorrectOptions(dialect="okuma"), path="p.min")
    assert rep.expanded
    lines = out.splitlines()
    assert lines[0] == "$OKUMA.SSB%"
    assert emit.is_header_start(lines[1] + "\n")
    assert "G1 X5.0 F100" in lines  # X#100 written as the number it reads


def test_call_o_from_the_subroutine_path_by_hand(tmp_path):
    """CALL OSQ runs OSQ (G1 X10, OHOLE once, G1 Y10, OHOLE twice: Q2), each to its RTS;
    the call, the name lines and RTS leave no line in the flat program."""
    (tmp_path / "subs").mkdir()
    (tmp_path / "subs" / "LIB.SUB").write_text(SUBS)
    got = flat(MAIN, tmp_path / "subs", path="../part.min")
    hole = ["G91 G1 Z-5 F100\n", "G0 Z5\n", "G90\n"]
    assert got == (["$PART.MIN%\n", "G15 H1\n", "G0 X0 Y0 Z50\n", "G1 Z10 F100\n", "G1 X10\n"] + hole
                   + ["G1 Y10\n"] + hole * 2 + ["G1 X5\n", "M02\n"])


def test_call_o_corrected_with_a_calibration(tmp_path):
    """The subprogram's moves are corrected as the main program's: a 1.001 scale makes
    every absolute word 1/1.001 of its value in machine coordinates."""
    (tmp_path / "LIB.SUB").write_text(SUBS)
    prog = tmp_path / "part.min"
    prog.write_text(MAIN)
    eng = StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG)
    out, rep = correct_text(MAIN, eng, SETUP, CorrectOptions(dialect="okuma", subroutine_path=(str(tmp_path),)),
                            path=str(prog))
    assert rep.expanded
    body = [ln for ln in out.splitlines() if not emit.is_header(ln + "\n")]
    assert body[0] == "$PART.MIN%"
    # G1 X10 in the subprogram: machine X 110 -> 110 / 1.001 = 109.8901, less the offset 100
    assert any(ln.startswith("G1 X9.8901") for ln in body)
    assert "CALL" not in out


def test_call_o_found_in_the_program_file_after_its_end():
    text = "$P.MIN%\nG15 H1\nG0 X0 Y0 Z10\nCALL OA Q3\nM02\nOA\nG91 G0 X1\nG90\nRTS\n"
    got = [sl.text for sl in expand(text.splitlines(keepends=True), path=None, dialect="okuma")]
    assert got == ["$P.MIN%\n", "G15 H1\n", "G0 X0 Y0 Z10\n"] + ["G91 G0 X1\n", "G90\n"] * 3 + ["M02\n"]


@pytest.mark.parametrize(("line", "message", "at"), [
    ("CALL OABC", "Okuma CALL OABC: subprogram OABC not found", (4, 1)),
    ("N5 CALL OSQ PX=10 PY=2", "Okuma CALL OSQ with arguments (PX=10 PY=2)", (4, 4)),
    ("CALL O../ABC", "Okuma CALL O../ABC: a subprogram name is O and letters or digits", (4, 6)),
    ("CALL OHOLE\nRTS", "Okuma RTS outside a subprogram", (5, 1)),
])
def test_call_refusals_name_file_line_and_column(tmp_path, line, message, at):
    (tmp_path / "LIB.SUB").write_text(SUBS)
    text = f"$P.MIN%\nG15 H1\nG0 X0 Y0 Z10\n{line}\nM02\n"
    with pytest.raises(PostprocError) as err:
        correct_text(text, IdentityEngine(BIG), SETUP,
                     CorrectOptions(dialect="okuma", subroutine_path=(str(tmp_path),)), path="p.min")
    assert message in str(err.value)
    assert (err.value.lineno, err.value.col) == at
    assert err.value.hint


def test_cli_corrects_a_call_and_writes_nothing_when_refused(tmp_path):
    (tmp_path / "LIB.SUB").write_text(SUBS)
    prog = tmp_path / "part.min"
    prog.write_text(MAIN)
    out = tmp_path / "out.min"
    args = ["correct", str(prog), "-c", CAL, "--dialect", "okuma", "--offset", "G15H1=X100,Y100,Z100", "-o", str(out)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert out.read_text().startswith("$PART.MIN%\n")
    (tmp_path / "LIB.SUB").unlink()
    out.unlink()
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 3
    assert "part.min:5:5: Okuma CALL OSQ: subprogram OSQ not found" in res.output
    assert not out.exists()
    res = CliRunner().invoke(main, [*args, "--no-expand"])
    assert res.exit_code == 3
    assert "Okuma CALL O.. subprogram call" in res.output


@pytest.mark.parametrize(("name", "construct"), [
    ("gcodeworkshop__examples__OSP5020M.nc", "Okuma OSTRT subprogram name line"),
    ("gcodeworkshop__examples__FLANGE.nc", "Okuma PRES= local variable setting"),
    ("gcodeworkshop__examples__OSP7000L.nc", "Okuma VGRIN[..] system variable"),
])
def test_shop_corpus_okuma_files_refused_past_their_header(name, construct):
    """The corpus's Okuma programs are read past their $..% header (an SSB library of
    subprograms, macro programs with local and system variables) and refused by what they
    hold, in Okuma's words."""
    text = (SHOP / name).read_text()
    with pytest.raises(PostprocError) as err:
        correct_text(text, IdentityEngine(BIG), Setup(offsets={"G15H1": (0, 0, 0)}), CorrectOptions(dialect="okuma"),
                     path=name)
    assert construct in str(err.value)
    assert err.value.lineno > 1
