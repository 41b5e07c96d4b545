"""The Sinumerik 840D dialect: what it reads, each construct with its
motion worked out by hand, what it keeps byte for byte, and what it refuses by name.

There is no open Sinumerik interpreter to compare with: the expected machine positions
below come from the Programming Manual's rules (Fundamentals: work offsets G54-G57,
G505-G599 and G500; G70 inch; CR= the radius, negative for more than 180 degrees; D the
tool offset, here flat D numbers; AC()/IC() absolute/incremental for one word)."""

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.recognise import dialect_of_file

ROOT = Path(__file__).parents[1]
DATA = ROOT / "tests" / "data" / "sinumerik"
CAL = str(ROOT / "calibrations" / "s500_static.json")
BIG = [[-1e5] * 3, [1e5] * 3]
SETUP = Setup(offsets={"G54": (100.0, 100.0, 100.0), "G505": (10.0, 20.0, 30.0)},
              tool_lengths={1: 100.0, 2: 50.0})


def run(text, setup=SETUP):
    it = Interpreter(setup, "p.mpf", dialect="sinumerik")
    moves = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = it.feed_line(n, line)
        while mv is not None:
            moves.append(mv)
            mv = mv.then
    return it, moves


def ends(moves):
    return [tuple(round(v, 9) for v in mv.q1) for mv in moves]


def correct(text, setup=SETUP, engine=None, cycles="auto"):
    return correct_text(text, engine or IdentityEngine(BIG), setup, CorrectOptions(dialect="sinumerik", cycles=cycles),
                        path="p.mpf")


def body(out):
    return "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln))


def test_bracket_motions_by_hand():
    it, moves = run((DATA / "bracket_contour.mpf").read_text())
    # G54 (100, 100, 100) + D1 tool length 100 along Z
    got = ends(moves)
    assert got[0] == (95.0, 100.0, 220.0)  # N80 G0 X-5 Y0 Z20
    assert got[2] == (95.0, 100.0, 197.0)  # N100 G1 Z-3
    assert got[3] == (180.0, 100.0, 197.0)  # N110 X80
    # N120 G3 X100 Y20 CR=20: a quarter circle about (80, 20), counter-clockwise
    arc = moves[4].arc
    assert got[4] == (200.0, 120.0, 197.0)
    assert arc.center[:2] == pytest.approx((180.0, 120.0))
    assert not arc.clockwise
    # N140 G3 X80 Y80 I-20 J0: centre (80, 60) from (100, 60)
    assert moves[6].arc.center[:2] == pytest.approx((180.0, 160.0))
    assert got[7] == (95.0, 180.0, 197.0)  # N150 X=AC(-5) in G90 is X-5
    assert moves[3].feed == 1200.0
    assert it.ended  # M30


def test_bracket_kept_lines_byte_identical_and_header_in_semicolon_comments():
    text = (DATA / "bracket_contour.mpf").read_text()
    out, _ = correct(text)
    lines = out.splitlines(keepends=True)
    assert lines[:2] == text.splitlines(keepends=True)[:2]  # %_N_ and ;$PATH= stay first
    assert lines[2].startswith(";POSTPROC ")
    assert emit.is_header_start(lines[2])
    assert body(out) == text  # identity: every byte kept
    eng = StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG)
    out, _ = correct(text, Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0}), eng)
    kept = [ln for ln in text.splitlines(keepends=True)
            if any(k in ln for k in ("T=", "MSG", "CYCLE832", "SOFT", "BRISK", "G4 F2", "D1\n", "M30", ";"))]
    for ln in kept:
        assert ln in out.splitlines(keepends=True), ln
    assert "N120 G3 X99.9001 Y19.9800 CR=19.9800" in out  # 100/1.001, 20/1.001, 20/1.001
    assert "N150 G1 X=AC(-4.9950)" in out


def test_absolute_centre_words_by_hand():
    """G2 X20 Y0 I=AC(10) J=AC(0) from (0, 0): the centre (10, 0) in work coordinates, the
    same arc as I10 J0; the block after it reads I/J incremental again."""
    it, moves = run("G54 D1\nG0 X0 Y0 Z0\nG2 X20 Y0 I=AC(10) J=AC(0) F100\nG2 X0 Y0 I-10 J0\n")
    assert moves[1].arc.center[:2] == pytest.approx((110.0, 100.0))
    assert moves[1].arc_absolute
    assert moves[2].arc.center[:2] == pytest.approx((110.0, 100.0))
    assert not it.state.arc_absolute
    with pytest.raises(UnsupportedGcodeError, match="partly =AC"):
        run("G54 D1\nG0 X0 Y0 Z0\nG2 X20 Y0 I=AC(10) J0 F100\n")
    out, _ = correct("G54 D1\nG0 X0 Y0 Z0\nG2 X20 Y0 I=AC(10) J=AC(0) F100\nM30\n",
                     Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0}),
                     StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG))
    assert "I=AC(9.9900) J=AC(0)" in out  # 10 / 1.001; J stays 0


def test_kept_settings_and_compressor():
    _, moves = run("G54 D1\nG642 ADIS=0.05 ADISPOS=0.1\nCOMPCAD\nG0 X0 Y0 Z0\nCOMPOF\n")
    assert len(moves) == 1


def test_g4_f_is_a_dwell_time_not_a_feed():
    _, moves = run("G54 D1\nG1 X1 Y1 Z1 F500\nG4 F2\nG1 X2\n")
    assert moves[-1].feed == 500.0


def test_inch_g505_d_registers_long_arc_and_ret():
    _, moves = run((DATA / "inch_g505_ret.spf").read_text())
    got = ends(moves)
    # G505 (10, 20, 30) mm, G70 inch, D2 tool length 50
    assert got[0] == pytest.approx((10 + 25.4, 20 + 25.4, 30 + 25.4 + 50))
    assert got[1][2] == pytest.approx(30 - 2.54 + 50)
    arc = moves[2].arc
    assert arc.clockwise
    # CR=-1 (inch): the arc of more than 180 degrees, centre (1, 2) in
    assert arc.center[:2] == pytest.approx((10 + 25.4, 20 + 50.8))
    assert got[3][2] == pytest.approx(30 + 25.4 + 50)
    assert len(moves) == 4  # D0 moves nothing; RET ends the program: N90 is not run


def test_d0_cancels_the_tool_length():
    _, moves = run("G54 D1\nG0 X0 Y0 Z0\nD0\nG0 Z0\n")
    assert ends(moves) == [(100.0, 100.0, 200.0), (100.0, 100.0, 100.0)]


def test_ac_ic_against_the_mode():
    _, moves = run("G54 D1\nG0 X0 Y0 Z0\nG91 G1 X=IC(5) F100\n")
    assert ends(moves)[-1] == (105.0, 100.0, 200.0)
    with pytest.raises(UnsupportedGcodeError, match=r"Sinumerik X=IC\(\) \(incremental for one word\) in G90"):
        run("G54 D1\nG0 X0 Y0 Z0\nG1 X=IC(5) F100\n")
    with pytest.raises(UnsupportedGcodeError, match=r"Sinumerik Y=AC\(\)"):
        run("G54 D1\nG0 X0 Y0 Z0\nG91 G1 Y=AC(5) F100\n")


@pytest.mark.parametrize(("name", "lineno", "construct"), [
    ("drill_plate.mpf", 8, "Sinumerik MCALL CYCLE81 (drilling cycle call): read only when written as its moves"),
    ("pocket_cycle.mpf", 8, "Sinumerik POCKET4 (pocket milling cycle)"),
])
def test_sample_programs_refused_by_name(name, lineno, construct):
    with pytest.raises(UnsupportedGcodeError) as err:
        correct((DATA / name).read_text(), cycles="keep")
    assert err.value.lineno == lineno
    assert construct in str(err.value)
    assert err.value.hint


@pytest.mark.parametrize(("line", "construct"), [
    ("N10 ROT X30", "Sinumerik ROT X (a rotation about X tilts the plane"),
    ("N10 TRANS X10 A5", "frame with A"),
    ("N10 TRANS X10 G1 X5", "frame with G"),
    ("N10 G1 TRANS X10", "TRANS not alone in its block"),
    ("N10 AROT RPL=30 Z10", "Sinumerik AROT with both Z and RPL"),
    ("N10 AROTS X10 Y20", "Sinumerik AROTS (frame rotation by solid angles)"),
    ("N10 R1=R2+5", "R parameter R2 read before the program sets it"),
    ("N10 DEF FRAME F1", "DEF FRAME (only REAL, INT and BOOL"),
    ("N10 G1 X=DEPTH", "DEPTH in an expression (not a variable the program defines)"),
    ("N10 IF R1>5 GOTOF END1", "program control"),
    ("N10 REPEAT LABEL1 P=3", "program control"),
    ("N10 L100", "subprogram call"),
    ("N10 G2 X10 Y10 I5 TURN=2", "TURN= helix"),
    ("N10 G53 X0", "G53"),
    ("N10 G331 Z-10 K1.5", "G331 rigid tapping"),
    ("N10 CYCLE800(1,\"TC1\",0,57,0,0,0,0,30,0,0,0,0,1)", "CYCLE800 (swivel plane)"),
    ("N10 X=R1", "R parameter R1 read before"),
    ("N10 FOO", "FOO (not read by postproc)"),
    ("N10 H5", "address H"),
])
def test_refusals_name_the_sinumerik_construct(line, construct):
    with pytest.raises(UnsupportedGcodeError) as err:
        run(f"G54 D1\nG0 X0 Y0 Z0\n{line}\n")
    assert construct in str(err.value)
    assert str(err.value).split(": ", 1)[1].startswith("Sinumerik ")
    assert err.value.lineno == 3


def test_frames_and_r_parameters_sample_by_hand():
    """DEF SIDE=40, R1=SIDE/2, R2=-3, TRANS X100 Y50: a 40 mm square about (100, 50) in
    G54 (100, 100, 100) with D1 100 along Z."""
    _, moves = run((DATA / "frames_rparam.mpf").read_text())
    assert ends(moves) == [(180.0, 130.0, 205.0), (180.0, 130.0, 197.0), (220.0, 130.0, 197.0),
                           (220.0, 170.0, 197.0), (180.0, 170.0, 197.0), (180.0, 130.0, 197.0),
                           (180.0, 130.0, 220.0)]


def test_r_parameter_arithmetic_by_hand():
    it, moves = run("G54 D1\nDEF REAL A=3, B\nDEF INT N=7\nR1=(A+1)*2.5 R2=N DIV 2 R3=N MOD 4\n"
                    "R4=SIN(30)+SQRT(16)-POT(2) B=ATAN2(1,1)\nG0 X=R1 Y=R2 Z=R3\nG0 X=R4*10 Y=B\n")
    assert it.variables["R1"] == 10.0
    assert ends(moves)[0] == (110.0, 103.0, 203.0)  # 7 DIV 2 = 3, 7 MOD 4 = 3
    assert ends(moves)[1] == pytest.approx((105.0, 145.0, 203.0))  # (0.5 + 4 - 4) * 10, atan2 = 45 deg


def test_expression_words_written_as_numbers_where_moved():
    text = "%_N_E_MPF\nG54 D1\nR1=10\nG0 X=R1 Y=R1*2 Z0\nG0 X=R1\nM30\n"
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0})
    out, _ = correct(text, setup)
    assert body(out) == text  # identity: expressions kept
    out, _ = correct(text, setup, StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG))
    assert "R1=10\n" in out
    assert "G0 X=9.9900 Y=19.9800 Z0" in out


def test_trans_atrans_and_frame_reset_by_hand():
    """TRANS replaces the programmable translation, ATRANS adds to it, ROT alone deletes
    the frame; a move's words are in the frame's coordinates (G54 100, 100, 100; D1 100)."""
    _, moves = run("G54 D1\nTRANS X10 Y20\nG0 X1 Y1 Z0\nATRANS X5\nG0 X1\nTRANS Z-3\nG0 X0 Y0 Z0\n"
                   "ROT\nG0 X0 Y0 Z0\nG70\nTRANS X1\nG0 X0\n")
    assert ends(moves) == [(111.0, 121.0, 200.0), (116.0, 121.0, 200.0), (100.0, 100.0, 197.0),
                           (100.0, 100.0, 200.0), (125.4, 100.0, 200.0)]


def test_trans_output_keeps_frame_words():
    text = "%_N_T_MPF\n;$PATH=/_N_MPF_DIR\nG54 D1\nTRANS X10 Y20\nG0 X1 Y1 Z0\nTRANS\nG0 X1 Y1\nM30\n"
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0})
    out, _ = correct(text, setup, StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG))
    assert "TRANS X10 Y20\n" in out
    # machine (11, 21, 0) / 1.001 less the translation (10, 20)
    assert "G0 X0.9890 Y0.9790 Z0.0000" in out or "G0 X0.9890 Y0.9790 Z0\n" in out


def test_refusals_ignore_strings_and_comments():
    _, moves = run('G54 D1\nMSG("IF THE CALL FAILS: TRANS ROT")\nG0 X0 Y0 Z0 ; TRANS and R1= in a comment\n')
    assert len(moves) == 1


def test_paren_text_is_not_a_comment():
    with pytest.raises(GcodeSyntaxError, match="unexpected character"):
        run("G54 D1\nG0 X0 Y0 Z0 (NOT A COMMENT)\n")


def test_chosen_by_its_header(tmp_path):
    assert dialect_of_file(str(DATA / "bracket_contour.mpf"), "generic") == "sinumerik"
    assert dialect_of_file(str(DATA / "bracket_contour.mpf"), "fanuc") == "fanuc"
    plain = tmp_path / "p.nc"
    plain.write_text("%\nO1000\nG0 X0\n")
    assert dialect_of_file(str(plain), "generic") == "generic"
    # a form feed is a blank inside a line, not a line end: the $PATH line is still the second
    paged = tmp_path / "paged.mpf"
    paged.write_bytes(b"; PART 12\f\f\n;$PATH=/_N_WKS_DIR/_N_PART_WPD\nG0 X0\n")
    assert dialect_of_file(str(paged), "generic") == "sinumerik"
    out = tmp_path / "out.mpf"
    res = CliRunner().invoke(main, ["correct", str(DATA / "bracket_contour.mpf"), "-c", CAL, "-o", str(out),
                                    "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100"])
    assert res.exit_code == 0, res.output
    assert out.read_text().splitlines()[2].startswith(";POSTPROC ")
    res = CliRunner().invoke(main, ["diff", str(DATA / "bracket_contour.mpf"), str(out)])
    assert res.exit_code == 0, res.output


def test_arc_end_point_rule():
    from postproc.gcode import dialect as D

    d = D.DIALECTS["sinumerik"]
    assert d.arc_end_radius_tolerance(5.0) == pytest.approx(0.01)  # CIRCLE_ERROR_CONST
    assert d.arc_end_radius_tolerance(100.0) == pytest.approx(0.1)  # CIRCLE_ERROR_FACTOR * r
    assert math.isinf(d.arc_cap_mm)


def test_split_arc_written_with_cr():
    """An arc the correction cuts into several exact arcs keeps Sinumerik's radius word."""
    from postproc.calfile import load_calibration

    text = (DATA / "inch_g505_ret.spf").read_text()
    setup = Setup(offsets={"G505": (100.0, 100.0, 100.0)}, tool_lengths={2: 100.0})
    out, rep = correct_text(text, load_calibration(CAL).engine, setup, CorrectOptions(dialect="sinumerik"),
                            path="p.spf")
    arcs = [ln for ln in out.splitlines() if ln.lstrip().startswith(("G2", "N50"))]
    assert rep.arcs_split >= 1
    assert len(arcs) >= 2
    assert all("CR=" in ln and " R" not in ln for ln in arcs)


# -- drilling cycles (Programming Guide Cycles, chapter 2 "Drilling cycles") ----------------
def run_cycles(text, setup=SETUP):
    """The interpreter's moves with each drilling cycle's steps after its block: (kind, end)."""
    it = Interpreter(setup, "p.mpf", dialect="sinumerik")
    steps = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = it.feed_line(n, line)
        if mv is not None:
            steps.append(("move", tuple(round(v, 9) for v in mv.q1)))
        if it.cycle_move is not None:
            for kind, q in it.cycle_move.cycle.steps:
                steps.append((kind, tuple(round(v, 9) for v in q)))
    return it, steps


ZERO = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0})


def correct_expanded(text, setup=ZERO, engine=None):
    return correct_text(text, engine or IdentityEngine(BIG), setup,
                        CorrectOptions(dialect="sinumerik", cycles="expand"), path="p.mpf")


def test_mcall_cycle81_drills_after_each_position_block_by_hand():
    """MCALL CYCLE81(RTP=10, RFP=0, SDIS=2, DP=-15, DPR=0): after each block that moves,
    G0 to RFP+SDIS = 2, G1 to DP = -15, G0 to RTP = 10 (Cycles, "Drilling, centering -
    CYCLE81"; section 2.2 "Modal call of drilling cycles"); a bare MCALL ends the call.
    G54 (100, 100, 100) and D1 (100 along Z): work Z z is machine z + 200."""
    it, steps = run_cycles((DATA / "drill_plate.mpf").read_text())
    rapid, feed = 0, 10
    hole = [(rapid, 202.0), (feed, 185.0), (rapid, 210.0)]
    want = [("move", (120.0, 120.0, 250.0)), ("move", (120.0, 120.0, 250.0))]
    want += [(k, (120.0, 120.0, z)) for k, z in hole]
    for x, y in ((180.0, 120.0), (180.0, 160.0), (120.0, 160.0)):
        want += [("move", (x, y, 210.0))] + [(k, (x, y, z)) for k, z in hole]
    want += [("move", (120.0, 160.0, 250.0))]  # N110 G0 Z50 after the bare MCALL: no hole
    assert steps == want
    assert it.modal_call is None


def test_cycle81_expanded_lines_and_kept_lines():
    text = (DATA / "drill_plate.mpf").read_text()
    out, rep = correct_expanded(text)
    assert rep.cycles_expanded == 4
    assert ";POSTPROC CYCLES EXPANDED\n" in out
    lines = body(out).splitlines()
    assert ";N50 MCALL CYCLE81(10,0,2,-15,0)" in lines  # the call stays, as a comment
    k = lines.index("N60 X20 Y20")
    assert lines[k:k + 5] == ["N60 X20 Y20", "G0 Z2.0000", "G1 Z-15.0000", "G0 Z10.0000", "N70 X80 Y20"]
    for ln in text.splitlines():  # every other line byte for byte
        if "CYCLE81" not in ln:
            assert ln in lines
    # corrected: the holes' moves are written in the program's coordinates, each corrected
    eng = StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG)
    out, _ = correct_expanded(text, engine=eng)
    assert "G1 Z-14.9850" in out  # -15 / 1.001


def test_one_shot_cycle82_with_dpr_and_dwell_by_hand():
    """CYCLE82(RTP=15, RFP=1, SDIS=1, DP empty, DPR=4, DTB=0.5) at (5, 5, 20): G0 Z2, G1 to
    RFP - DPR = -3 at the feed before the call, dwell 0.5 s, G0 Z15; the program's G1 mode
    comes back after the cycle (the cycle restores the G codes: PROC ... SAVE)."""
    text = "%_N_C_MPF\nG54 D1\nG0 X5 Y5 Z20\nG1 F100\nN40 CYCLE82(15,1,1,,4,0.5)\nG0 X10\nM30\n"
    _, steps = run_cycles(text, ZERO)
    assert steps[1:] == [(0, (5.0, 5.0, 2.0)), (10, (5.0, 5.0, -3.0)), (-1, (0.5, 0.0, 0.0)),
                         (0, (5.0, 5.0, 15.0)), ("move", (10.0, 5.0, 15.0))]
    out, _ = correct_expanded(text)
    assert body(out) == ("%_N_C_MPF\nG54 D1\nG0 X5 Y5 Z20\nG1 F100\n;N40 CYCLE82(15,1,1,,4,0.5)\n"
                         "G0 Z2.0000\nG1 Z-3.0000\nG4 F0.5\nG0 Z15.0000\nG1\nG0 X10\nM30\n")


def test_cycle89_feeds_back_out_and_dpr_wins_over_dp():
    """CYCLE89(RTP=5, RFP=0, SDIS=1, DP=-20, DPR=8, DTB=1): DPR given, so the depth is
    RFP - 8 = -8 ("if both DP and DPR are given, the depth is derived from DPR"); G1 back
    to RFP+SDIS = 1 at the same feed, then G0 to RTP."""
    _, steps = run_cycles("G54 D1\nG0 X0 Y0 Z10\nG1 F50\nCYCLE89(5,0,1,-20,8,1)\n", ZERO)
    assert steps[1:] == [(0, (0.0, 0.0, 1.0)), (10, (0.0, 0.0, -8.0)), (-1, (1.0, 0.0, 0.0)),
                         (10, (0.0, 0.0, 1.0)), (0, (0.0, 0.0, 5.0))]


def test_cycle_parameters_from_variables_and_inch():
    _, steps = run_cycles("G54 D1\nG70\nDEF REAL DEPTH=-0.5\nR1=0.4\nG0 X1 Y1 Z1\nCYCLE81(R1, 0, 0.1, DEPTH)\n",
                          ZERO)
    assert steps[1:] == pytest.approx([(0, (25.4, 25.4, 2.54)), (10, (25.4, 25.4, -12.7)),
                                       (0, (25.4, 25.4, 0.4 * 25.4))])


@pytest.mark.parametrize(("line", "construct"), [
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,0,0,1,3)", "Sinumerik CYCLE83 with VARI other than 0"),
    ("N10 MCALL CYCLE84(10,0,2,-15,0,0,3,8,0,0,0,0)", "Sinumerik CYCLE84"),
    ("N10 CYCLE840(10,0,2,-15,0,0,3,8,0,0,0,0)", "Sinumerik CYCLE840"),
    ("N10 G0 X5 CYCLE81(10,0,2,-15,0)", "Sinumerik CYCLE81 with other words in its block"),
    ("N10 MCALL CYCLE81(10,0,2,-15,0) X5", "Sinumerik MCALL CYCLE81 with other words"),
    ("N10 CYCLE81(10,0,2)", "Sinumerik CYCLE81 without its final depth (DP or DPR)"),
    ("N10 CYCLE81(,0,2,-15)", "Sinumerik CYCLE81 without its RTP"),
    ("N10 CYCLE82(10,0,2,-15,0,-2)", "dwell in spindle revolutions"),
])
def test_drilling_cycle_refusals(line, construct):
    with pytest.raises((UnsupportedGcodeError, GcodeSyntaxError)) as err:
        run_cycles(f"G54 D1\nG0 X0 Y0 Z0\n{line}\n")
    assert construct in str(err.value)
    assert err.value.lineno == 3


def test_cycles_need_expand():
    """A CYCLE81 call cannot carry each hole's correction: with --cycles keep it is refused,
    by default (auto) and with expand it is written as its moves."""
    with pytest.raises(UnsupportedGcodeError, match=r"Sinumerik CYCLE81 \(drilling cycle call\)") as err:
        correct("G54 D1\nG0 X0 Y0 Z20\nCYCLE81(10,0,2,-15)\nM30\n", cycles="keep")
    assert "--cycles expand" in err.value.hint
    out, report = correct("G54 D1\nG0 X0 Y0 Z20\nCYCLE81(10,0,2,-15)\nM30\n")
    assert ";CYCLE81(10,0,2,-15)" in out
    assert report.cycles_expanded == 1


# -- rotation, scale and mirror (Fundamentals, "Coordinate transformations (frames)") ------
def test_rot_and_atrans_compose_by_hand():
    """TRANS X10 then AROT RPL=90 then ATRANS X5: the programmed point p lands at
    (10, 0) + R90 (p + (5, 0)) = (10 - y, x + 5) (ATRANS after AROT moves in the rotated
    axes); G1 Y5 keeps the programmed X (modal in the frame), G0 X0 Y0 after a bare ROT is
    the work origin."""
    it, moves = run("G54 D1\nG0 X0 Y0 Z0\nTRANS X10\nAROT RPL=90\nATRANS X5\nG0 X2 Y1\nG1 Y5 F100\n"
                    "ROT\nG0 X0 Y0\n", ZERO)
    got = ends(moves)
    assert got[1] == pytest.approx((10 - 1, 2 + 5, 0.0))
    assert got[2] == pytest.approx((10 - 5, 2 + 5, 0.0))
    assert got[3] == (0.0, 0.0, 0.0)
    assert it.state.frame is None


def test_arc_under_rotation_and_mirror_by_hand():
    """ROT Z90: G2 X0 Y15 I-10 J0 from (10, 5): centre (0, 5) and end (0, 15) in the frame,
    (-5, 0) and (-15, 0) in work coordinates, still clockwise. MIRROR X0 (replacing the
    rotation): G2 from (10, 0) about (0, 0) to (0, 10) is at (-10, 0) -> (0, 10) about the
    origin, counter-clockwise (a mirror of one axis reverses the direction: Fundamentals,
    "Programmable mirroring (MIRROR, AMIRROR)")."""
    _, moves = run("G54 D1\nG0 X0 Y0 Z0\nROT Z90\nG0 X10 Y5\nG2 X0 Y15 I-10 J0 F100\nMIRROR X0\n"
                   "G0 X10 Y0\nG2 X0 Y10 I-10\n", ZERO)
    assert ends(moves)[1] == pytest.approx((-5.0, 10.0, 0.0))
    assert moves[2].q1 == pytest.approx((-15.0, 0.0, 0.0))
    assert moves[2].arc.center == pytest.approx((-5.0, 0.0, 0.0))
    assert moves[2].arc.clockwise
    assert moves[3].q1 == pytest.approx((-10.0, 0.0, 0.0))
    assert moves[4].arc.center == pytest.approx((0.0, 0.0, 0.0))
    assert moves[4].q1 == pytest.approx((0.0, 10.0, 0.0))
    assert not moves[4].arc.clockwise


def test_scale_ascale_amirror_by_hand():
    """SCALE X2 Y2 then ATRANS X1: the translation is scaled (2, 0); ASCALE X0.5 Y0.5
    multiplies to 1; AMIRROR Y0 then negates the frame's Y. Z keeps its scale 1."""
    _, moves = run("G54 D1\nG0 X0 Y0 Z0\nSCALE X2 Y2\nG0 X3 Y4 Z1\nATRANS X1\nG0 X0 Y0\n"
                   "ASCALE X0.5 Y0.5\nG0 X3 Y4\nAMIRROR Y0\nG0 X3 Y4\n", ZERO)
    assert ends(moves)[1:] == pytest.approx([(6.0, 8.0, 1.0), (2.0, 0.0, 1.0), (5.0, 4.0, 1.0),
                                             (5.0, -4.0, 1.0)])


def test_unequal_scale_refuses_arcs():
    with pytest.raises(UnsupportedGcodeError, match="arc under a frame that does not keep it a circle"):
        run("G54 D1\nG0 X0 Y0 Z0\nSCALE X2\nG0 X10 Y0\nG2 X0 Y10 I-10 F100\n", ZERO)
    with pytest.raises(UnsupportedGcodeError, match="arc under a frame that does not keep it a circle"):
        run("G54 D1\nG0 X0 Y0 Z0\nROT Z30\nG18 G0 X10 Z0\nG2 X0 Z10 I-10 K0 F100\n", ZERO)


def test_mirror_of_z_keeps_xy_arcs_and_reverses_xz_arcs():
    """MIRROR Z0 with G17: the XY arc turns the same way; with G18 (Z, X) it turns the other way."""
    _, moves = run("G54 D1\nG0 X0 Y0 Z0\nMIRROR Z0\nG0 X10 Y0\nG3 X0 Y10 I-10 F100\nG18 G0 X10 Z0\n"
                   "G3 X0 Z10 I-10 K0\n", ZERO)
    assert not moves[2].arc.clockwise
    assert moves[4].arc.clockwise
    assert moves[4].q1 == pytest.approx((0.0, 10.0, -10.0))


def test_rotated_lines_written_in_the_frame():
    """Identity: every byte kept. A 1.001 scale: machine (0, 10) from ROT Z90 G0 X10 Y0 is
    corrected to (0, 9.99001), which is X9.9900 Y0 in the frame again."""
    text = "%_N_R_MPF\nG54 D1\nG0 X0 Y0 Z0\nROT Z90\nG0 X10 Y0\nG1 X10 Y5 F100\nROT\nM30\n"
    out, _ = correct(text, ZERO)
    assert body(out) == text
    out, _ = correct(text, ZERO, StaticEngine(1.001 * np.eye(3), np.zeros(3), BIG))
    assert "G0 X9.9900 Y0" in out
    assert "G1 X9.9900 Y4.9950 F100" in out


def test_drill_cycle_under_rotation():
    text = "%_N_D_MPF\nG54 D1\nG0 X0 Y0 Z20\nROT Z90\nG1 F100\nMCALL CYCLE81(10,0,2,-5)\nG0 X10 Y0\nMCALL\nM30\n"
    _, steps = run_cycles(text, ZERO)
    assert steps[2:] == pytest.approx([(0, (0.0, 10.0, 2.0)), (10, (0.0, 10.0, -5.0)), (0, (0.0, 10.0, 10.0))])
    out, _ = correct_expanded(text)
    assert "G0 X10 Y0\nG0 Z2.0000\nG1 Z-5.0000\nG0 Z10.0000\nMCALL\n" in body(out)  # G0 stays


def test_rpl_only_in_g17():
    with pytest.raises(UnsupportedGcodeError, match="Sinumerik ROT RPL= in a plane other than G17"):
        run("G54 D1\nG18\nROT RPL=30\n", ZERO)


# -- control flow (Job planning, "Program jumps and branches", "Program section repetitions",
# "Control structures"): expanded into a flat program ---------------------------------------
def flat(text):
    from postproc.gcode.expand import expand

    return "".join(sl.text for sl in expand(text.splitlines(keepends=True), path="p.mpf", dialect="sinumerik"))


def test_for_while_if_goto_repeat_flattened_by_hand():
    text = ("G54 D1\nDEF INT I\nG0 X0 Y0 Z5\nFOR I=1 TO 3\nG1 X=I*10 F100\nENDFOR\nR1=0\nWHILE R1<2\n"
            "R1=R1+1\nG0 Y=R1\nENDWHILE\nIF R1==2 GOTOF SKIP\nG0 X99\nSKIP: G0 Z10\nSTART:\nG0 X1\n"
            "REPEAT START P=2\nM30\nG0 X77\n")
    assert flat(text) == ("G54 D1\nDEF INT I\nG0 X0 Y0 Z5\nI=1\nG1 X=I*10 F100\nI=2\nG1 X=I*10 F100\nI=3\n"
                          "G1 X=I*10 F100\nI=4\nR1=0\nR1=R1+1\nG0 Y=R1\nR1=R1+1\nG0 Y=R1\nG0 Z10\n"
                          ";START:\nG0 X1\n;START:\nG0 X1\n;START:\nG0 X1\nM30\n")
    _, moves = run(flat(text), ZERO)
    assert [m.q1 for m in moves][1:4] == [(10.0, 0.0, 5.0), (20.0, 0.0, 5.0), (30.0, 0.0, 5.0)]


def test_if_else_loop_gotob_repeat_two_labels():
    text = ("R1=5\nIF R1>3 AND NOT R1==4\nG0 X1\nELSE\nG0 X2\nENDIF\nIF (R1<0) OR R1>=6\nG0 X3\nELSE\nG0 X4\n"
            "ENDIF\nR2=0\nLOOP\nR2=R2+1\nIF R2>=2 GOTOF OUT\nENDLOOP\nOUT:\nR3=0\nBACK: R3=R3+1\n"
            "IF R3<3 GOTOB BACK\nA1: G0 Y1\nA2: G0 Y2\nREPEAT A1 A2 P=1\nREPEATB A2 P=2\nR4=0\nREPEAT\nR4=R4+1\n"
            "UNTIL R4==2\nM30\n")
    assert flat(text) == ("R1=5\nG0 X1\nG0 X4\nR2=0\nR2=R2+1\nR2=R2+1\n;OUT:\nR3=0\nR3=R3+1\nR3=R3+1\nR3=R3+1\n"
                          "G0 Y1\nG0 Y2\nG0 Y1\nG0 Y2\nG0 Y2\nG0 Y2\nR4=0\nR4=R4+1\nR4=R4+1\nM30\n")


def test_control_flow_corrected_flat_with_header():
    text = "%_N_L_MPF\nG54 D1\nG0 X0 Y0 Z0\nR1=0\nLAB1: G0 X=R1\nR1=R1+1\nIF R1<3 GOTOB LAB1\nM30\n"
    out, rep = correct(text, ZERO)
    assert rep.expanded
    assert ";POSTPROC EXPANDED SUBPROGRAMS LOOPS AND MACROS\n" in out
    assert body(out) == "%_N_L_MPF\nG54 D1\nG0 X0 Y0 Z0\nR1=0\n" + "G0 X=R1\nR1=R1+1\n" * 3 + "M30\n"


@pytest.mark.parametrize(("text", "message"), [
    ("GOTOF NOWHERE\n", "GOTOF NOWHERE: jump label not found after"),
    ("IF R1==0\nG0 X1\n", "IF without its ENDIF"),
    ("ENDWHILE\n", "ENDWHILE without its WHILE"),
    ("FOR J=1 TO 2\nENDFOR\n", "FOR variable J is not defined"),
    ("LAB: G0 X1\nGOTOB LAB\n", "program runs more than 1000 blocks"),
    ("N10REPEAT NOLBL P=2\n", "REPEAT NOLBL: jump label not found"),
])
def test_control_flow_errors(text, message):
    from postproc.gcode.sinumerik_expand import expand_sinumerik

    with pytest.raises((GcodeSyntaxError, UnsupportedGcodeError), match=message):
        list(expand_sinumerik(("R1=0\n" + text).splitlines(keepends=True), "p.mpf", 1000))


# -- subprograms (Job planning, "Subprogram technique") ----------------------------------------
SUBS = DATA / "subprograms"


def test_subprogram_calls_by_hand():
    """HOLE(-4, 10): DEPTH=-4 and XP=10 by value, HALF=-2: G0 X10, G1 Z-2, G1 Z-4, G0 Z5;
    CALL "HOLE" without arguments: both parameters 0; L12 P2: the L12 subprogram twice
    (G91 X1 each); after the calls the caller's DEPTH (99) is its own again."""
    text = (SUBS / "CALLS.MPF").read_text()
    flat_text = "".join(sl.text for sl in __import__("postproc.gcode.expand", fromlist=["expand"]).expand(
        text.splitlines(keepends=True), path=str(SUBS / "CALLS.MPF"), dialect="sinumerik"))
    assert ";HOLE(-4, 10)\nDEF REAL DEPTH=-4\nDEF REAL XP=10\n;%_N_HOLE_SPF\n" in flat_text
    assert ";RET\nDEPTH=99\n" in flat_text
    _, moves = run(flat_text, ZERO)
    assert ends(moves) == [(0.0, 0.0, 5.0), (10.0, 0.0, 5.0), (10.0, 0.0, -2.0), (10.0, 0.0, -4.0),
                           (10.0, 0.0, 5.0), (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 5.0),
                           (1.0, 0.0, 5.0), (2.0, 0.0, 5.0), (2.0, 0.0, 99.0)]


def test_subprograms_corrected_flat_and_sources(tmp_path):
    out, rep = correct_text((SUBS / "CALLS.MPF").read_text(), IdentityEngine(BIG), ZERO,
                            CorrectOptions(dialect="sinumerik"), path=str(SUBS / "CALLS.MPF"))
    assert rep.expanded
    assert "G1 Z=DEPTH\n" in out  # identity: the subprogram's lines as they are
    # elsewhere, the subprograms are found on --subroutine-path; without it the call is named
    out2, _ = correct_text((SUBS / "CALLS.MPF").read_text(), IdentityEngine(BIG), ZERO,
                           CorrectOptions(dialect="sinumerik", subroutine_path=[str(SUBS)]),
                           path=str(tmp_path / "CALLS.MPF"))
    assert body(out2) == body(out)
    with pytest.raises(UnsupportedGcodeError, match="Sinumerik HOLE"):
        correct_text((SUBS / "CALLS.MPF").read_text(), IdentityEngine(BIG), ZERO,
                     CorrectOptions(dialect="sinumerik"), path=str(tmp_path / "CALLS.MPF"))


@pytest.mark.parametrize(("sub", "message"), [
    ("PROC S1(REAL A) SAVE\nG0 X=A\nRET\n", "PROC S1 SAVE"),
    ("PROC S1(VAR REAL A)\nG0 X=A\nRET\n", "PROC parameter 'VAR REAL A'"),
    ("PROC S1(REAL A)\nG0 X=A RET\n", "M17/RET with other words"),
])
def test_subprogram_refusals(tmp_path, sub, message):
    from postproc.gcode.sinumerik_expand import expand_sinumerik

    (tmp_path / "S1.SPF").write_text(sub)
    with pytest.raises(UnsupportedGcodeError, match=message):
        list(expand_sinumerik(["S1(1)\n", "M30\n"], str(tmp_path / "M.MPF"), 1000))


def test_missing_subprogram_named(tmp_path):
    from postproc.gcode.sinumerik_expand import expand_sinumerik

    with pytest.raises(UnsupportedGcodeError, match="L99: subprogram call, L99.SPF not found"):
        list(expand_sinumerik(["L99\n"], str(tmp_path / "M.MPF"), 1000))
    out = list(expand_sinumerik(["EXTERN S2(REAL)\n", "G0 X1\n"], str(tmp_path / "M.MPF"), 1000))
    assert [t for _k, _f, t, _o in out] == [";EXTERN S2(REAL)\n", "G0 X1\n"]
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "s2.spf").write_text("PROC S2(REAL A)\nG0 X=A\nM17\n")
    out = list(expand_sinumerik(["S2(3)\n"], str(tmp_path / "M.MPF"), 1000, [tmp_path / "lib"]))
    assert [t for _k, _f, t, _o in out][-2:] == ["G0 X=A\n", ";M17\n"]
    assert out[-2][1] == str(tmp_path / "lib" / "s2.spf")


def test_subprogram_file_corrected_on_its_own():
    """A PROC file without parameters read as the program: PROC kept as a comment, RET its end."""
    text = "%_N_SUB_SPF\nPROC SUB\nG54 D1\nG0 X1 Y1 Z1\nRET\n"
    out, rep = correct(text, ZERO)
    assert rep.expanded
    assert body(out) == "%_N_SUB_SPF\n;PROC SUB\nG54 D1\nG0 X1 Y1 Z1\nRET\n"


def test_diff_reads_expanded_cycles_and_frames(tmp_path):
    """diff pairs a corrected program's cycle moves with the original's MCALL holes, and
    reads plain lines under MCALL or ROT one at a time (not as a plain stretch)."""
    for name, text in (("drill", (DATA / "drill_plate.mpf").read_text()),
                       ("rot", "%_N_R_MPF\nG54 D1\nG0 X0 Y0 Z0\nROT Z90\nG0 X10 Y0\nG1 X10 Y5 F100\nX20\nROT\nM30\n")):
        src = tmp_path / f"{name}.mpf"
        src.write_text(text)
        out = tmp_path / f"{name}_out.mpf"
        res = CliRunner().invoke(main, ["correct", str(src), "-c", CAL, "-o", str(out), "--cycles", "expand",
                                        "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100"])
        assert res.exit_code == 0, res.output
        res = CliRunner().invoke(main, ["diff", str(src), str(out)])
        assert res.exit_code == 0, res.output
        assert "moves: " in res.output


@pytest.mark.parametrize(("line", "construct"), [
    ("LAB1: G0 X1", "Sinumerik program control (label, IF/WHILE/LOOP/FOR/REPEAT/GOTO)"),
    ("WHILE R1<2", "Sinumerik program control"),
    ("L12", "Sinumerik subprogram call, PROC or EXTERN"),
    ("HOLE(1, 2)", "Sinumerik HOLE() call"),
])
def test_no_expand_refuses_control_and_calls_by_name(line, construct):
    with pytest.raises(UnsupportedGcodeError) as err:
        correct_text(f"G54 D1\nR1=0\n{line}\nM30\n", IdentityEngine(BIG), ZERO,
                     CorrectOptions(dialect="sinumerik", expand=False), path="p.mpf")
    assert construct in str(err.value)
    assert err.value.lineno == 3
