"""The path API: nominal functional-point samples along every move."""

import numpy as np
import pytest

from postproc.errors import MissingSetupError, UnsupportedGcodeError
from postproc.gcode.path import Setup, program_path


def test_line_samples_are_spaced_and_end_on_targets():
    pp = program_path("G21 G90\nG0 X0 Y0 Z10\nG1 X10 F100\n", max_step_mm=0.5)
    assert pp.points_mm.shape == (21, 3)
    np.testing.assert_allclose(pp.points_mm[-1], [10, 0, 10])
    assert np.all(np.diff(pp.points_mm[1:, 0]) <= 0.5 + 1e-12)
    assert pp.rapid.tolist() == [True] + [False] * 20
    assert pp.lineno.tolist() == [2] + [3] * 20
    assert np.all(pp.context["dirx"][1:] == 1)


def test_arc_samples_lie_on_the_circle_and_turn_the_right_way():
    pp = program_path("G17 G90 G0 X10 Y0 Z0\nG3 X0 Y10 I-10 J0 F100\n", max_step_mm=0.2)
    pts = pp.points_mm[1:]
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 10.0, atol=1e-12)
    ang = np.arctan2(pts[:, 1], pts[:, 0])
    assert np.all(np.diff(ang) > 0)  # counter-clockwise
    assert np.all(np.diff(pts, axis=0).max(axis=1) <= 0.2 + 1e-9)


def test_offsets_tool_length_units_and_tool_vector():
    setup = Setup(offsets={"G54": (100.0, 50.0, -300.0)}, tool_lengths={1: 120.0})
    pp = program_path("G20 G54 G43 H1\nG0 X1 Y2 Z3\n", setup)
    # functional point = program x 25.4 + work offset; tool vector (0, 0, -L)
    np.testing.assert_allclose(pp.points_mm[0], [125.4, 100.8, -300 + 76.2])
    np.testing.assert_allclose(pp.tool_mm[0], [0, 0, -120.0])
    q = pp.points_mm - pp.tool_mm
    np.testing.assert_allclose(q[0], [125.4, 100.8, -300 + 76.2 + 120.0])


def test_g91_g92_and_g53():
    pp = program_path("G90 G0 X10 Y10 Z10\nG91 G1 X5 F10\nG90 G92 X0\nG1 X1\nG53 G0 X200\n", max_step_mm=100)
    np.testing.assert_allclose(pp.points_mm[:, 0], [10, 15, 16, 200])


def test_missing_offset_and_unsupported_are_refused_with_place():
    with pytest.raises(MissingSetupError) as e:
        program_path("G55\nG0 X1 Y1 Z1\n")
    assert e.value.lineno == 2
    assert "G55" in str(e.value)
    with pytest.raises(UnsupportedGcodeError) as e:
        program_path("G0 X1 Y1 Z1\nG0 X@1\n")  # polar words: not expanded
    assert e.value.lineno == 2
    # parameters are expanded, as correct expands them (unset #1 reads 0, as in LinuxCNC)
    assert program_path("G0 X1 Y1 Z1\nG0 X#1\n").points_mm[-1].tolist() == [0.0, 1.0, 1.0]
