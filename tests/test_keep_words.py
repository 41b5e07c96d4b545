"""A word whose corrected value is within half an output step of its own keeps its text
: a calibration that is the identity only to 1e-14 leaves a program of
15-decimal words byte-identical, in the run writer and the general writer alike, while a
correction of half a step or more still rewrites the word (with the word's own decimals
when it has more than the output's)."""

import numpy as np
import pytest

from postproc.engine.static import StaticEngine
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

VOLUME = [[-1000.0, -1000.0, -1000.0], [1000.0, 1000.0, 1000.0]]
SETUP = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, start={"X": 0.0, "Y": 0.0, "Z": 0.0})

# plain CAM lines (a run of the bulk lane), then lines the interpreter reads one by one
# (a comment between words, G92, a cycle) and arcs with long words
PROGRAM = (
    "G21 G90 G17 G54\n"
    "G0 X1.123456789012345 Y2.000000000000001 Z5.5\n"
    "G1 X10.987654321098765 Y-3.141592653589793 F500\n"
    "X11.000000000000002\n"
    "Y7.777777777777777 Z1.000000000000003\n"
    "G1 X12.5 (a comment) Y8.123456789012345\n"
    "G2 X22.5 Y8.123456789012345 I5.000000000000001 J0\n"
    "G3 X12.5 Y8.123456789012345 R5.000000000000001\n"
    "G92 X0.000000000000001 Y0\n"
    "G1 X3.333333333333333 Y4.444444444444444\n"
    "G81 X5.555555555555555 Y6.666666666666666 Z-1.000000000000001 R2.000000000000001 F100\n"
    "G80\n"
    "M2\n"
)


def _engine(eps: float) -> StaticEngine:
    """A static calibration that is the identity but for ``eps`` in its matrix and origin."""
    G = np.eye(3) + eps * np.array([[1.0, 0.3, -0.2], [0.1, -1.0, 0.4], [0.2, 0.5, 1.0]])
    return StaticEngine(G, np.array([eps, -eps, 2 * eps]), VOLUME)


def _body(text: str) -> list[str]:
    """The program's lines after the header the correction writes."""
    return [ln for ln in text.splitlines(keepends=True) if not emit.is_header(ln)]


@pytest.mark.parametrize("bulk_lane", [True, False], ids=["runs", "interpreter"])
@pytest.mark.parametrize("eps", [1e-14, 1e-12, 1e-9])
def test_near_identity_keeps_every_word(eps, bulk_lane):
    opts = CorrectOptions(bulk_lane=bulk_lane, cycles="keep", dialect="linuxcnc")
    out, rep = correct_text(PROGRAM, _engine(eps), SETUP, opts)
    assert _body(out) == PROGRAM.splitlines(keepends=True)
    assert rep.words_changed == 0
    assert rep.lines_changed == 0


@pytest.mark.parametrize("bulk_lane", [True, False], ids=["runs", "interpreter"])
def test_half_a_step_still_changes_the_word(bulk_lane):
    """An origin shift of 0.6 of the output step (4 decimals in mm) moves every absolute
    X word; a word with more decimals than the output keeps its own count."""
    eng = StaticEngine(np.eye(3), np.array([-0.00006, 0.0, 0.0]), VOLUME)
    prog = "G21 G90 G54\nG1 X1.123456789012345 Y2 Z3 F100\nX4.5\nX4.5 (c) Y2\nM2\n"
    out, rep = correct_text(prog, eng, SETUP, CorrectOptions(bulk_lane=bulk_lane))
    body = _body(out)
    assert body[1] == "G1 X1.123516789012345 Y2 Z3 F100\n"
    assert body[2] == "X4.5001\n"  # 4.50006 rounded to the output's 4 decimals
    assert body[3] == "X4.5001 (c) Y2\n"
    assert rep.words_changed == 3


def test_below_half_a_step_keeps_a_long_word():
    """A correction of 0.4 of the output step leaves a 15-decimal word as written: the
    word is then within half a step of the corrected value, as any rounded word is."""
    eng = StaticEngine(np.eye(3), np.array([-0.00004, 0.0, 0.0]), VOLUME)
    prog = "G21 G90 G54\nG1 X1.123456789012345 Y2 Z3 F100\nM2\n"
    out, rep = correct_text(prog, eng, SETUP, CorrectOptions())
    assert _body(out)[1] == "G1 X1.123456789012345 Y2 Z3 F100\n"
    assert rep.words_changed == 0
