"""Issue 31 items 3, 5 and 6: lathe programs refused by name, the Fadal and Okuma
dialects, and a program of another dialect named when the chosen one meets it.

Motions are worked out by hand: a work offset adds to every program position, a tool
length offset adds along Z; an engine that moves k times what it is told makes the
corrected word the nominal one divided by k."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError, UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.recognise import LatheProgramError

ROOT = Path(__file__).parents[1]
CAL = str(ROOT / "calibrations" / "s500_static.json")
BIG = [[-1e5] * 3, [1e5] * 3]


def moves(text, setup, dialect):
    it = Interpreter(setup, "p.nc", dialect=dialect)
    out = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = it.feed_line(n, line)
        while mv is not None:
            out.append(tuple(round(float(v), 9) for v in mv.q1))
            mv = mv.then
    return out


def correct(text, setup, dialect, engine=None):
    out, rep = correct_text(text, engine or IdentityEngine(BIG), setup, CorrectOptions(dialect=dialect),
                            path="p.nc")
    return out, rep


def body(out):
    return "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln))


# -- lathe programs (item 5) ---------------------------------------------------------------
LATHE = {
    "G50 S": ("%\nO0001\nG21 G99\nG50 S2000\nG96 S180 M3\nG0 X50. Z2.\nG1 Z-20. F0.2\nM30\n%\n", "G50 S2000"),
    "U word": ("G21 G90\nG0 X10 Z5\nG1 U20 W-5 F100\nM30\n", "U word"),
    "W word": ("G21 G90\nG0 X10 Z5\nG1 W-5 F100\nM30\n", "W word"),
    "G96 then G71": ("G21\nG96 S200 M3\nG0 X40 Z2\nG71 P10 Q20\nM30\n", "G71 turning cycle"),
    "arc in XZ": ("G21 G90\nG0 X10 Z5\nG1 X20 Z-5 F100\nG2 X30 Z-10 I5 K0\nM30\n", "an arc in X and Z"),
    "G50 X Z": ("G21\nG50 X100. Z50.\nG0 X20 Z2\nM30\n", "G50 X100."),
}


@pytest.mark.parametrize("dialect", ["generic", "fanuc", "haas"])
@pytest.mark.parametrize("name", sorted(LATHE))
def test_lathe_program_refused_by_name(name, dialect):
    text, mark = LATHE[name]
    if dialect == "haas" and name == "G96 then G71":
        pytest.skip("G71 is a bolt-hole pattern on a Haas mill, not a turning cycle")
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, start={"Y": 0.0} if name != "arc in XZ" else {})
    with pytest.raises(LatheProgramError) as err:
        correct(text, setup, dialect)
    msg = str(err.value)
    assert "lathe program" in msg
    assert "postproc corrects milling machines" in msg
    assert mark in msg


def test_g96_before_turning_cycle_named_with_it():
    with pytest.raises(LatheProgramError, match=r"G71 turning cycle at line 4, G96 \(constant surface speed\) "
                                                r"at line 2"):
        correct(LATHE["G96 then G71"][0], Setup(), "fanuc")


def test_linuxcnc_diameter_mode_and_dialect_fanuc_lathe():
    with pytest.raises(LatheProgramError, match="G7 .diameter mode"):
        correct("G21 G18 G7\nG0 X20 Z2\nM2\n", Setup(), "linuxcnc")
    with pytest.raises(LatheProgramError, match="--dialect fanuc-lathe"):
        correct("G21 G90\nG0 X10 Y10 Z5\nM30\n", Setup(), "fanuc-lathe")


def test_cli_writes_nothing_for_a_lathe_program(tmp_path):
    src = tmp_path / "turn.nc"
    src.write_text(LATHE["G50 S"][0])
    out = tmp_path / "out.nc"
    res = CliRunner().invoke(main, ["correct", str(src), "-c", CAL, "-o", str(out)])
    assert res.exit_code != 0
    assert "postproc corrects milling machines" in res.output
    assert "G50 S2000" in res.output
    assert not out.exists()


def test_mill_programs_with_lathe_like_words_still_corrected():
    """G97 S (spindle rpm), G18 arcs in a program that positions Y, U/V/W as LinuxCNC axes
    (refused as axes, not as a lathe's), G74 left-hand tapping on a Fanuc mill (refused as
    an unknown code, not a lathe's) and G50 scaling cancel alone."""
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
    text = "G21 G90 G17\nG97 S1000 M3\nG50\nG0 X0 Y0 Z5\nG18\nG2 X10 Z-5 I5 K-5\nM30\n"
    out, _ = correct(text, setup, "fanuc")
    assert body(out) == text
    with pytest.raises(UnsupportedGcodeError, match="U axis word") as err:
        correct("G21\nG0 X0 Y0 Z0\nG1 U5 F100\nM2\n", setup, "linuxcnc")
    assert not isinstance(err.value, LatheProgramError)


# -- Fadal (item 3) ----------------------------------------------------------------------------
FADAL = "N1 O2 (BRACKET)\nN2 G90 G80 G40 G17 G0\nN3 E1 X10. Y10.\nN4 G1 Z-2. F300\nN5 E0 X50. Y10.\nN6 M30\n"


def test_fadal_header_and_fixture_offsets_by_hand():
    setup = Setup(offsets={"E1": (100.0, 50.0, -200.0)}, start={"Z": 0.0})
    got = moves(FADAL, setup, "fadal")
    # E1 adds (100, 50, -200); Z not yet positioned keeps the start's machine Z 0
    assert got[0] == (110.0, 60.0, 0.0)
    assert got[1] == (110.0, 60.0, -202.0)
    # E0 cancels the fixture offset: X50 Y10 are machine positions, Z stays where it is
    assert got[2] == (50.0, 10.0, -202.0)


def test_fadal_output_keeps_header_first_and_lines_byte_identical():
    setup = Setup(offsets={"E1": (100.0, 50.0, -200.0)}, start={"Z": 0.0})
    out, _ = correct(FADAL, setup, "fadal")
    lines = out.splitlines(keepends=True)
    assert lines[0] == "N1 O2 (BRACKET)\n"
    assert emit.is_header_start(lines[1])
    assert "(POSTPROC OFFSET E1 X100 Y50 Z-200)" in out
    assert body(out) == FADAL


def test_fadal_missing_fixture_offset_named():
    with pytest.raises(PostprocError, match="work offset E1 is used but its value was not given"):
        correct(FADAL, Setup(start={"Z": 0.0}), "fadal")


# -- Okuma (item 3) ----------------------------------------------------------------------------
OKUMA = "$BRACKET.MIN%\n(OKUMA)\nG15 H1\nG0 X10. Y10.\nG56 H1 Z50.\nG1 Z-2. F300\nG53\nX50.\nM2\n"


def test_okuma_work_coordinates_and_tool_length_by_hand():
    setup = Setup(offsets={"G15H1": (100.0, 50.0, -300.0)}, tool_lengths={1: 120.0}, start={"Z": 0.0})
    got = moves(OKUMA, setup, "okuma")
    assert got[0] == (110.0, 60.0, 0.0)
    assert got[1] == (110.0, 60.0, -300.0 + 50.0 + 120.0)  # G56 H1: tool length 120 along Z
    assert got[2] == (110.0, 60.0, -300.0 - 2.0 + 120.0)
    # G53 (Okuma: tool length offset cancelled) then X50: Z is where it was (nothing moves in Z)
    assert got[3][0] == 150.0
    iso = moves("G54\nG0 X10. Y10.\nG43 H1 Z50.\nG1 Z-2. F300\n", Setup(
        offsets={"G54": (100.0, 50.0, -300.0)}, tool_lengths={1: 120.0}, start={"Z": 0.0}), "fanuc")
    assert got[:3] == iso


def test_okuma_header_first_and_scaled_words():
    setup = Setup(offsets={"G15H1": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0}, start={"Z": 0.0})
    eng = StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG)
    out, _ = correct(OKUMA, setup, "okuma", eng)
    lines = out.splitlines()
    assert lines[0] == "$BRACKET.MIN%"
    assert emit.is_header_start(lines[1] + "\n")
    assert "G0 X9.9900 Y9.9900" in out  # 10 / 1.001


def test_okuma_call_refused_by_name():
    """CALL O1000 is expanded (tests/test_dialect_okuma.py); not found, it is refused by name."""
    with pytest.raises(PostprocError, match=r"Okuma CALL O1000: subprogram O1000 not found") as err:
        correct("$A.MIN%\nG15 H1\nCALL O1000\nM2\n", Setup(offsets={"G15H1": (0, 0, 0)}), "okuma")
    assert err.value.lineno == 3


# -- another dialect's program (item 6) ----------------------------------------------------------
FOREIGN = [
    ("%_N_PART_MPF\n;$PATH=/_N_MPF_DIR\nN10 G0 X0 Y0\n", 1, "sinumerik", "%_N_"),
    ("G21\n;$PATH=/_N_MPF_DIR\nG0 X0 Y0\n", 2, "sinumerik", ";$PATH="),
    ("G21\nDEF REAL DEPTH\nG0 X0 Y0\n", 2, "sinumerik", "DEF"),
    ("G21\nN20 T=\"CUTTER10\" D1 M6\n", 2, "sinumerik", "Sinumerik"),
    ("$PART.MIN%\nG15 H1\nG0 X0 Y0\n", 1, "okuma", "$NAME.MIN%"),
    ("N1 O2 (PART)\nN2 G0 X0 Y0\n", 1, "fadal", "N1 O.."),
]


@pytest.mark.parametrize(("text", "lineno", "name", "construct"), FOREIGN)
@pytest.mark.parametrize("chosen", ["generic", "linuxcnc", "fanuc"])
def test_other_dialect_named(text, lineno, name, construct, chosen):
    with pytest.raises(UnsupportedGcodeError) as err:
        correct(text, Setup(offsets={"G54": (0, 0, 0)}), chosen)
    assert err.value.lineno == lineno
    assert construct in str(err.value)
    assert f"--dialect {name}" in (err.value.hint or "")


@pytest.mark.parametrize(("line", "construct"), [
    ("N50 POCKET4(10,0,1,-5,,20,50,50,6,2,2,0,500,200,0,21,5,0,0,0,0,0,0)", "Sinumerik POCKET4 (pocket milling cycle)"),
    ("N50 SLOT1(10,0,2,-5,,4,30,10,50,50,20,0,45,1,1,200,100,0,1,2)", "Sinumerik SLOT1 (slot milling cycle)"),
    ("N50 CYCLE71(50,2,2,0,0,0,80,60,0,4,10,5,0,2000,31,5)", "Sinumerik CYCLE71 (contour/face milling cycle)"),
    ("N50 TRAORI", "Sinumerik TRAORI (5-axis transformation)"),
    ("N50 CYCLE800(1,\"TC1\",0,57,0,0,0,0,30,0,0,0,0,1)", "Sinumerik CYCLE800 (swivel plane)"),
])
def test_sinumerik_refusals_in_its_words(line, construct):
    with pytest.raises(UnsupportedGcodeError) as err:
        correct(f"%_N_P_MPF\n;$PATH=/_N_MPF_DIR\nN10 G17 G90\n{line}\nM30\n", Setup(), "sinumerik")
    assert str(err.value).split(": ", 1)[1].startswith(construct)
    assert err.value.lineno == 4
    assert err.value.hint


@pytest.mark.parametrize(("dialect", "line", "construct"), [
    ("fadal", "#R1=R1+1", "Fadal # macro statement (Fadal macro language)"),
    ("fadal", "N5 L0102", "Fadal L subroutine call (format 1)"),
    ("okuma", "VC1=10", "Okuma VC/VS common variable"),
    ("okuma", "IF [VC1 GT 5] NLAB1", "Okuma IF/GOTO program control"),
    ("okuma", "MODIN O1000", "Okuma MODIN modal subprogram call"),
])
def test_fadal_and_okuma_constructs_refused_in_their_words(dialect, line, construct):
    with pytest.raises(UnsupportedGcodeError) as err:
        correct(f"G90\nG0 X0 Y0 Z0\n{line}\nM30\n", Setup(offsets={"G54": (0, 0, 0)}), dialect)
    assert str(err.value).split(": ", 1)[1].startswith(construct)
    assert err.value.lineno == 3
