"""Modal interpreter semantics (LinuxCNC where it matters)."""

import math

import numpy as np
import pytest

from postproc.errors import GcodeSyntaxError, MissingSetupError, UnsupportedGcodeError
from postproc.gcode import lexer
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup, program_path


def ends(text, setup=None):
    """End point (functional point, mm) of every move."""
    it = Interpreter(setup or Setup())
    out = []
    for i, line in enumerate(lexer.split_lines(text), 1):
        mv = it.feed_line(i, line)
        if mv is not None:
            out.append(np.array(mv.q1) + np.array(mv.r))
    return np.array(out)


def test_units_switch_mid_program():
    e = ends("G21 G0 X10 Y0 Z0\nG20 G1 X1 F10\nG21 G1 X5\n")
    np.testing.assert_allclose(e[:, 0], [10, 25.4, 5])


def test_g92_sets_and_clears_an_offset_and_is_not_a_move():
    e = ends("G0 X10 Y10 Z10\nG92 X0 Y0\nG1 X5 F10\nG92.1\nG1 X5\n")
    assert len(e) == 3
    np.testing.assert_allclose(e[:, 0], [10, 15, 5])


def test_work_offsets_g10_and_g54_1():
    setup = Setup(offsets={"G55": (100, 0, 0), "G54.1P2": (0, 50, 0)})
    e = ends("G0 X0 Y0 Z0\nG55 G0 X1\nG54.1 P2 G0 Y1\nG10 L2 P3 X7 Y8 Z9\nG56 G0 X0 Y0 Z0\n", setup)
    np.testing.assert_allclose(e[1], [101, 0, 0])
    np.testing.assert_allclose(e[2], [101, 51, 0])  # X does not move
    np.testing.assert_allclose(e[3], [7, 8, 9])


def test_g53_is_machine_coordinates_without_offsets_or_tool_length():
    setup = Setup(offsets={"G54": (100, 0, -50)}, tool_lengths={2: 80.0})
    it = Interpreter(setup)
    it.feed_line(1, "G54 T2 M6 G43\n")
    mv = it.feed_line(2, "G0 X1 Y2 Z3\n")
    np.testing.assert_allclose(mv.q1, [101, 2, -50 + 3 + 80])  # gauge point
    np.testing.assert_allclose(mv.r, [0, 0, -80])
    mv = it.feed_line(3, "G53 G0 Z200\n")
    assert mv.q1[2] == 200.0  # LinuxCNC: G53 coordinates are not tool-length compensated


def test_g43_without_h_uses_the_loaded_tool_and_h0_is_no_length():
    it = Interpreter(Setup(tool_lengths={5: 42.0}))
    it.feed_line(1, "T5 M6\n")
    it.feed_line(2, "G43\n")
    assert it.state.tlo == 42.0
    it.feed_line(3, "G43 H0\n")
    assert it.state.tlo == 0.0
    with pytest.raises(MissingSetupError):
        Interpreter(Setup()).feed_line(1, "G43\n")


def test_negative_r_gives_the_long_way_round():
    short = program_path("G0 X0 Y0 Z0\nG2 X10 Y0 R5.1 F10\n", max_step_mm=0.1).points_mm
    long = program_path("G0 X0 Y0 Z0\nG2 X10 Y0 R-5.1 F10\n", max_step_mm=0.1).points_mm
    assert len(long) > len(short)
    # clockwise from (0,0) to (10,0) both go over the top: centre (5, -h) or (5, +h)
    h = math.sqrt(5.1**2 - 25)
    assert short[:, 1].max() == pytest.approx(5.1 - h, abs=1e-3)
    assert long[:, 1].max() == pytest.approx(5.1 + h, abs=1e-3)


@pytest.mark.parametrize(("plane", "words", "axis", "sign"), [
    ("G17", "X10 Y0 I5 J0", 1, +1),  # XY: CW seen from +Z goes through +Y
    ("G18", "X10 Z0 I5 K0", 2, -1),  # ZX: CW seen from +Y goes through -Z
    ("G19", "Y10 Z0 J5 K0", 2, +1),  # YZ: CW seen from +X goes through +Z
])
def test_g2_direction_in_each_plane(plane, words, axis, sign):
    pts = program_path(f"G0 X0 Y0 Z0\n{plane} G2 {words} F10\n", max_step_mm=0.1).points_mm
    mid = pts[len(pts) // 2]
    assert sign * mid[axis] == pytest.approx(5.0, abs=0.01)


def test_turns_and_helix_and_absolute_centre():
    pts = program_path("G0 X10 Y0 Z0\nG3 X10 Y0 Z-3 I-10 J0 P3 F10\n", max_step_mm=0.5).points_mm
    length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert length == pytest.approx(math.hypot(3 * 2 * math.pi * 10, 3), rel=1e-3)
    pts = program_path("G90.1 G0 X10 Y0 Z0\nG3 X0 Y10 I0 J0 F10\n", max_step_mm=0.5).points_mm
    np.testing.assert_allclose(np.hypot(pts[1:, 0], pts[1:, 1]), 10, atol=1e-9)


def test_modal_motion_and_program_end():
    e = ends("G1 X1 Y1 Z1 F10\nX2\nY3\nM30\nG0 X99\n#1=2\n")
    np.testing.assert_allclose(e[-1], [2, 3, 1])
    assert len(e) == 3


@pytest.mark.parametrize(("text", "err"), [
    ("X1 Y1 Z1\n", GcodeSyntaxError),  # no motion mode yet
    ("G0 X1 X2\n", GcodeSyntaxError),
    ("G0 X1 Y1 Z1\nG2 X5 Y5 I0 J0.1\n", GcodeSyntaxError),  # end not on the circle
    ("G0 X1 Y1 Z1\nG1 X2 (open comment\n", GcodeSyntaxError),
    ("G91 G0 X1\n", MissingSetupError),  # incremental from an unknown position
    ("G0 X1 Y1 Z1\nG33 Z-5 K1\n", UnsupportedGcodeError),
])
def test_errors_name_their_place(text, err):
    with pytest.raises(err) as e:
        ends(text)
    assert e.value.lineno is not None


def test_an_arc_mode_block_of_rotary_words_only_is_refused_as_rs274_refuses_it():
    """G2 modal, then a block naming only A: LinuxCNC says "R, I, J, K words all missing
    for arc"; the interpreter refuses it at the block's first word (it raised an internal
    error before)."""
    text = "G21 G90 G17\nG0 X0 Y0 Z0\nG2 X10 Y0 I5 J0 F100\nA10\nM2\n"
    with pytest.raises(GcodeSyntaxError, match="arc without centre") as err:
        ends(text)
    assert (err.value.lineno, err.value.col) == (4, 1)
