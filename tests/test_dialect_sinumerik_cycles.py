"""Sinumerik drilling and boring cycles CYCLE83, CYCLE85-CYCLE88 written as their moves,
each against the motion the SINUMERIK 840D Programming Guide Cycles
(PGZ 11.02, chapter 2) defines for its parameters, worked out by hand; and corrected with
a calibration, every step landing where the engine says. CYCLE84/CYCLE840 (tapping) are
refused by name."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from postproc.calfile import load_calibration
from postproc.engine.identity import IdentityEngine
from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.sinumerik_cycles import strokes

ROOT = Path(__file__).parents[1]
BIG = [[-1e5] * 3, [1e5] * 3]
ZERO = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0})
G0, G1, G4 = 0, 10, -1


def steps_of(call, setup=ZERO, before="G0 X5 Y5 Z20\nG1 F100\n"):
    """The steps of the cycle ``call`` at the position ``before`` reaches: ("G0"/"G1", point),
    ("G4", seconds) or ("text", line)."""
    it = Interpreter(setup, "p.mpf", dialect="sinumerik")
    out = []
    for n, line in enumerate(f"G54 D1\n{before}{call}\n".splitlines(keepends=True), start=1):
        it.feed_line(n, line)
        if it.cycle_move is not None:
            for kind, q in it.cycle_move.cycle.steps:
                if kind == G4:
                    out.append(("text", q[0]) if isinstance(q[0], str) else ("G4", q[0]))
                else:
                    out.append(("G0" if kind == G0 else "G1", tuple(round(v, 9) for v in q)))
    return out


def z(kind, level, x=5.0, y=5.0):
    return (kind, (x, y, level))


def expanded(text, engine=None, setup=ZERO):
    out, rep = correct_text(text, engine or IdentityEngine(BIG), setup,
                            CorrectOptions(dialect="sinumerik", cycles="expand"), path="p.mpf")
    return "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln)), rep


# -- CYCLE83 deep-hole drilling ---------------------------------------------------------
def test_strokes_degression_by_hand():
    """First depth -5 from RFP 0 (stroke 5), DAM 2: next stroke 5-2 = 3 (more than DAM), then
    3-2 = 1 is not more than DAM so 2, 2, ... and the last one ends at the final depth."""
    assert strokes(-5.0, -12.0, 0.0, 2.0) == [-5.0, -8.0, -10.0, -12.0]
    assert strokes(-5.0, -13.0, 0.0, 0.0) == [-5.0, -10.0, -13.0]  # no degression: equal strokes
    assert strokes(-40.0, -30.0, 0.0, 5.0) == [-30.0]  # a first depth past the final one: one stroke


def test_cycle83_swarf_removal_by_hand():
    """VARI=1: G0 to RFP+SDIS = 2, the first stroke at F x FRF = 50, dwell DTB at each depth,
    G0 back to 2, dwell DTS, G0 to the depth reached less 0.6 (12 mm deep: up to 30 mm the
    anticipation distance is 0.6 mm), G1 to the next depth; the final dwell DTB (_DTD empty),
    G0 to RTP."""
    got = steps_of("CYCLE83(10,0,2,-12,,-5,,2,0.5,1,0.5,1)")
    want = [z("G0", 2.0), ("text", "F50"), z("G1", -5.0), ("text", "F100"), ("G4", 0.5)]
    for last, depth in ((-5.0, -8.0), (-8.0, -10.0), (-10.0, -12.0)):
        want += [z("G0", 2.0), ("G4", 1.0), z("G0", round(last + 0.6, 9)), z("G1", depth), ("G4", 0.5)]
    want += [z("G0", 10.0)]
    assert got == want


def test_cycle83_chip_breaking_by_hand():
    """VARI=0: after each stroke G1 back by 1 mm (_VRT empty), then on to the next depth."""
    got = steps_of("CYCLE83(10,0,2,-12,,-5,,2,0,0,1,0)")
    assert got == [z("G0", 2.0), z("G1", -5.0), z("G1", -4.0), z("G1", -8.0), z("G1", -7.0), z("G1", -10.0),
                   z("G1", -9.0), z("G1", -12.0), z("G0", 10.0)]
    # DPR 12 and FDPR 5 (relative to RFP), no degression, _VRT 0.5, _DTD 2 at the final depth only
    got = steps_of("CYCLE83(10,0,2,,12,,5,0,0,0,1,0,0,0,0.5,2)")
    assert got == [z("G0", 2.0), z("G1", -5.0), z("G1", -4.5), z("G1", -10.0), z("G1", -9.5), z("G1", -12.0),
                   ("G4", 2.0), z("G0", 10.0)]


def test_cycle83_anticipation_beyond_30mm_and_inch():
    """100 mm deep: the anticipation distance is 100 / 50 = 2 mm; _DIS1 replaces it."""
    got = steps_of("CYCLE83(10,0,2,-100,,-40,,0,0,0,1,1)")
    assert got == [z("G0", 2.0), z("G1", -40.0), z("G0", 2.0), z("G0", -38.0), z("G1", -80.0), z("G0", 2.0),
                   z("G0", -78.0), z("G1", -100.0), z("G0", 10.0)]
    got = steps_of("CYCLE83(10,0,2,-100,,-40,,0,0,0,1,1,0,0,0,0,5)")
    assert [s for s in got if s[0] == "G0"][2] == z("G0", -35.0)
    # inch (G70): the 1 mm chip-breaking retraction is 1/25.4 inch
    got = steps_of("CYCLE83(1,0,0.1,-0.5,,-0.2,,0,0,0,1,0)", before="G70\nG0 X1 Y1 Z2\nG1 F10\n")
    assert got[2] == ("G1", (25.4, 25.4, pytest.approx(-0.2 * 25.4 + 1.0)))


def test_cycle83_as_a_cam_post_writes_it():
    """A CAM post's chip-breaking call: FDEP the first depth, no DAM, _AXN empty, _MDEP equal
    to the stroke (so it changes nothing), _DTD at the bottom; strokes of 3 mm to -10."""
    got = steps_of("MCALL CYCLE83(15., 0., 2., -10., , -3., , 0., , , 1., 0., , 3., 0., 0.5, 0)\nX5 Y5")
    assert got == [z("G0", 2.0), z("G1", -3.0), z("G1", -2.0), z("G1", -6.0), z("G1", -5.0), z("G1", -9.0),
                   z("G1", -8.0), z("G1", -10.0), ("G4", 0.5), z("G0", 15.0)]


# -- boring cycles ------------------------------------------------------------------------
def test_cycle85_feeds_in_and_out_by_hand():
    """CYCLE85(RTP 10, RFP 0, SDIS 2, DP -20, DTB 1, FFR 50, RFF 200): G0 to 2, G1 to -20 at
    FFR, dwell, G1 to 2 at RFF, G0 to 10; the feed before the call (100) written again."""
    assert steps_of("CYCLE85(10,0,2,-20,,1,50,200)") == [
        z("G0", 2.0), ("text", "F50"), z("G1", -20.0), ("G4", 1.0), ("text", "F200"), z("G1", 2.0), z("G0", 10.0),
        ("text", "F100")]


def test_cycle86_oriented_stop_and_plane_retraction_by_hand():
    """CYCLE86(..., DTB 1, SDIR 3, RPA -1, RPO 0.5, RPAP 1, POSS 90): M3, G0 to 2, G1 to -20,
    dwell, SPOS=90, G0 by (-1, 0.5, +1) off the bottom, G0 up to 2, G0 back over the hole,
    G0 to RTP."""
    assert steps_of("CYCLE86(10,0,2,-20,,1,3,-1,0.5,1,90)") == [
        ("text", "M3"), z("G0", 2.0), z("G1", -20.0), ("G4", 1.0), ("text", "SPOS=90"),
        z("G0", -19.0, 4.0, 5.5), z("G0", 2.0, 4.0, 5.5), z("G0", 2.0), z("G0", 10.0)]


def test_cycle87_and_cycle88_stop_for_the_operator_by_hand():
    assert steps_of("CYCLE87(10,0,2,-20,,3)") == [
        ("text", "M3"), z("G0", 2.0), z("G1", -20.0), ("text", "M5"), ("text", "M0"), z("G0", 10.0)]
    assert steps_of("CYCLE88(10,0,2,-20,,2,4)") == [
        ("text", "M4"), z("G0", 2.0), z("G1", -20.0), ("G4", 2.0), ("text", "M5"), ("text", "M0"), z("G0", 10.0)]


def test_expanded_lines_written():
    text = "%_N_C_MPF\nG54 D1\nG0 X5 Y5 Z20\nG1 F100\nN40 CYCLE85(10,0,2,-20,,1,50,200)\nG0 X10\nM30\n"
    out, rep = expanded(text)
    assert rep.cycles_expanded == 1
    assert out == ("%_N_C_MPF\nG54 D1\nG0 X5 Y5 Z20\nG1 F100\n;N40 CYCLE85(10,0,2,-20,,1,50,200)\n"
                   "G0 Z2.0000\nF50\nG1 Z-20.0000\nG4 F1\nF200\nG1 Z2.0000\nG0 Z10.0000\nF100\nG1\nG0 X10\nM30\n")


def test_mcall_cycle86_under_rot_retracts_in_the_frame():
    """ROT Z90: the frame's X is the work's Y. MCALL CYCLE86 at frame (10, 0): the retraction
    (-1, 0.5) is in the frame's axes and written there (X9 Y0.5), in work coordinates it is
    at (-0.5, 9)."""
    text = "G54 D1\nG0 X0 Y0 Z20\nROT Z90\nG1 F100\nMCALL CYCLE86(10,0,2,-5,,0,3,-1,0.5,0,0)\nG0 X10 Y0\nMCALL\nM30\n"
    got = steps_of("", before=text.split("\n", 1)[1])
    assert ("G0", (-0.5, 9.0, -5.0)) in got
    out, _ = expanded(text)
    assert "G0 X9.0000 Y0.5000" in out.replace(" Z-5.0000", "")


# -- corrected with a calibration ----------------------------------------------------------
def _positions(text):
    """The program position after each line that moves, of the written program (G90, no frames)."""
    pos, out = [math.nan] * 3, []
    for ln in text.splitlines():
        code = ln.split(";", 1)[0]
        if re.search(r"[XYZ]-?[\d.]", code):
            for a, v in re.findall(r"([XYZ])(-?[\d.]+)", code):
                pos["XYZ".index(a)] = float(v)
            out.append(tuple(pos))
    return np.array(out)


def test_cycles_corrected_with_the_s500_calibration():
    """Every step of CYCLE83 (two holes of an MCALL) and CYCLE86, corrected with the bundled
    S500 parametric calibration: the forward model of the written points passes through
    each nominal step end, in order, within the tolerance and the rounding of the words."""
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    setup = Setup(offsets={"G54": (100.0, 100.0, 100.0)}, tool_lengths={1: 0.0})
    text = ("G54 D1\nG0 X10 Y20 Z30\nG1 F100\nMCALL CYCLE83(10,0,2,-30,,-8,,2,0.2,0,0.5,1)\nG0 X40 Y20\n"
            "X60 Y50\nMCALL\nCYCLE86(15,0,2,-12,,0.5,3,1,-1,0,45)\nM30\n")
    nominal, _ = expanded(text)
    corrected, _ = expanded(text, engine=cal.engine, setup=setup)
    assert corrected.count("\n") >= nominal.count("\n")
    want = _positions(nominal) + 100.0
    got = cal.engine.forward(_positions(corrected) + 100.0)
    assert np.abs(got - (_positions(corrected) + 100.0)).max() > 0.05  # the calibration moves the points
    k = 0
    for p in want:  # each nominal end reached by the corrected program, in order
        near = np.flatnonzero(np.linalg.norm(got[k:] - p, axis=1) < 0.0015)
        assert near.size, p
        k += int(near[0])
    assert "SPOS=45" in corrected
    assert "M3" in corrected


# -- refused ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("line", "construct"), [
    ("N10 MCALL CYCLE84(10,0,2,-15,0,0,3,8,0,0,0,0)", "Sinumerik CYCLE84 (tapping cycle"),
    ("N10 CYCLE840(10,0,2,-15,0,0,3,8,0,0,0,0)", "Sinumerik CYCLE840 (tapping cycle"),
    ("N10 CYCLE83(10,0,2,-30,0)", "Sinumerik CYCLE83 without its first drilling depth (FDEP or FDPR)"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,0,0,1.5,1)", "feed factor FRF outside"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,0,0,1,2)", "VARI other than 0"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,-0.8,0,0,1,1)", "degression DAM < 0"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,0,0,1,1,1)", "tool axis _AXN"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,0,0,1,1,,4)", "minimum drilling depth _MDEP larger than its strokes"),
    ("N10 CYCLE83(10,0,2,-30,0,-5,0,2,-1,0,1,1)", "dwell in spindle revolutions (DTB < 0)"),
    ("N10 CYCLE83(10,0,2,-30,0,5,0,2,0,0,1,1)", "first drilling depth not below its reference plane"),
    ("N10 CYCLE85(10,0,2,-20,0,1)", "Sinumerik CYCLE85 without its feeds FFR"),
    ("N10 CYCLE86(10,0,2,-20,0,1,5,0,0,0,0)", "Sinumerik CYCLE86 without its spindle direction SDIR"),
    ("N10 CYCLE87(10,0,2,-20,0)", "Sinumerik CYCLE87 without its spindle direction"),
])
def test_cycle_refusals_name_the_cycle_and_line(line, construct):
    with pytest.raises((UnsupportedGcodeError, GcodeSyntaxError)) as err:
        steps_of(line, before="G0 X0 Y0 Z0\nG1 F100\n")
    assert construct in str(err.value)
    assert err.value.lineno == 4
    assert err.value.col is not None


def test_feed_factor_needs_a_feed():
    with pytest.raises(GcodeSyntaxError, match="feed factor FRF before any feed"):
        steps_of("CYCLE83(10,0,2,-30,,-5,,2,0,0,0.5,1)", before="G0 X0 Y0 Z20\n")


def test_tapping_refused_by_the_command_line(tmp_path):
    from click.testing import CliRunner

    from postproc.cli import main

    prog = tmp_path / "tap.mpf"
    prog.write_text("%_N_TAP_MPF\nG54 D1\nG0 X0 Y0 Z20\nCYCLE84(10,0,2,-15,,0,3,,1.25,0,200,500)\nM30\n")
    out = tmp_path / "out.mpf"
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", str(ROOT / "calibrations" / "s500_static.json"),
                                    "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100",
                                    "--cycles", "expand", "-o", str(out)])
    assert res.exit_code == 3
    assert "tap.mpf:4:1: Sinumerik CYCLE84 (tapping cycle" in res.output
    assert not out.exists()


def test_diff_pairs_every_cycle_step(tmp_path):
    """`diff` reads an original's cycle calls as the lines correct writes them (F, SPOS=, M5,
    M0 and G4 F lines included): every step of CYCLE83, CYCLE85, CYCLE86 and CYCLE88 is a
    move paired with its corrected line, none inserted."""
    from click.testing import CliRunner

    from postproc.cli import main

    prog = tmp_path / "t.mpf"
    prog.write_text("%_N_T_MPF\nG54 D1\nG0 X10 Y20 Z30\nG1 F100\nMCALL CYCLE83(10,0,2,-30,,-8,,2,0.2,0,0.5,1)\n"
                    "G0 X40 Y20\nX60 Y50\nMCALL\nCYCLE86(15,0,2,-12,,0.5,3,1,-1,0,45)\n"
                    "CYCLE85(15,0,2,-12,,0.5,30,300)\nCYCLE88(15,0,2,-12,,0.5,3)\nM30\n")
    out = tmp_path / "o.mpf"
    cal = str(ROOT / "calibrations" / "s500_parametric.json")
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", cal, "--offset", "G54=X100,Y100,Z100",
                                    "--tool-length", "1=50", "--cycles", "expand", "-o", str(out)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["diff", str(prog), str(out), "--json"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.output)
    assert report["moves"] == report["moves_moved"] == 70
    assert report["lines_inserted"] == 0
