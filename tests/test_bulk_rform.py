"""R-form arcs (G2/G3 with an R word) are read in bulk with the plain lines around them,
their centre the one the interpreter finds (one formula: geometry.r_center), and written
by the general emitter from their plan: the output and every refusal are the general
path's, byte for byte."""

import numpy as np
import pytest
from conftest import both_lanes

from postproc.engine.static import StaticEngine
from postproc.gcode import bulk
from postproc.gcode.moves import Kind
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

G = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])
SETUP = Setup(offsets={"G54": (100.0, 80.0, 40.0)})


def _engine():
    return StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])


def _both(text, **options):
    """The output (or the refusal) of the bulk lane and of the general path."""
    return both_lanes(text, _engine(), SETUP, **options)


def _cam(rng, n):
    """A FreeCAD-like pass: short lines and R arcs both ways, some the long way round,
    some helical, some with a feed."""
    out, x, y, z = ["G21 G90 G17\n", "G0 X10 Y10 Z5\n", "G1 Z-1 F300\n"], 10.0, 10.0, -1.0
    for k in range(n):
        dx, dy = rng.uniform(-2, 2, 2)
        out.append(f"G1 X{x + dx:.3f} Y{y + dy:.3f}\n")
        x, y = round(x + dx, 3), round(y + dy, 3)
        ex, ey = x + rng.uniform(-1.5, 1.5), y + rng.uniform(-1.5, 1.5)
        half = 0.5 * float(np.hypot(ex - x, ey - y))
        r = half * rng.uniform(1.0, 3.0) * (-1 if k % 7 == 3 else 1)
        dz = f" Z{z - 0.01:.3f}" if k % 5 == 2 else ""
        f = " F250." if k % 4 == 1 else ""
        out.append(f"G{2 + k % 2} X{ex:.3f} Y{ey:.3f}{dz} R{r:.3f}{f}\n")
        x, y = round(ex, 3), round(ey, 3)
        z = z - 0.01 if dz else z
    out.append("M2\n")
    return "".join(out)


@pytest.mark.parametrize("seed", range(4))
def test_r_arcs_in_bulk_give_the_general_paths_output(seed):
    text = _cam(np.random.default_rng(seed), 60)
    a, b = _both(text)
    assert a == b
    assert a.count("R") >= 60  # written as R arcs


def test_r_arcs_are_read_in_runs(planned_tables):
    text = _cam(np.random.default_rng(1), 40)
    correct_text(text, _engine(), SETUP, CorrectOptions())
    (tab,) = planned_tables
    arcs = np.flatnonzero((tab.kind == Kind.ARC_CW) | (tab.kind == Kind.ARC_CCW))
    assert len(arcs) == 40
    in_runs = {i for r in tab.runs for i in range(r.trow, r.trow + len(r))}
    assert set(arcs.tolist()) <= in_runs  # none read line by line
    # each is cut from its run and written by the general emitter, from its plan
    cut = {r.trow + j for r in tab.runs for j in r.cut}
    assert set(arcs.tolist()) <= cut


@pytest.mark.parametrize("arc", [
    "G2 X20 Y10 R5",  # exactly half the chord: the centre on it
    "G2 X20 Y10 R4.99999",  # short by less than the controllers' tolerance
    "G3 X20 Y10 R-7",  # the long way round
    "G2 X20 Y10 Z4 R6 F100",  # helical, with a feed
    "g3x20y10r6",  # lower case, no blanks
    "N40 G03 X20 Y10 R6",
])
def test_r_arc_forms_agree(arc):
    text = f"G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\n{arc}\nG1 X25\nM2\n"
    a, b = _both(text)
    assert a == b
    assert "Error" not in a


@pytest.mark.parametrize(("arc", "message"), [
    ("G2 X20 Y10 R4", "smaller than half the chord"),
    ("G2 X10 Y10 R4", "start = end"),
    ("G2 X20 Y10 I5 R5", "both R and centre offsets"),
])
def test_r_arc_refusals_are_the_interpreters(arc, message):
    text = f"G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\n{arc}\nG1 X25\nM2\n"
    a, b = _both(text)
    assert a == b
    assert message in a


def test_r_arc_in_inch_and_a_modal_r_arc_line(planned_tables):
    # a line without its motion word after an R arc is an R arc too, read in the same run
    text = "G20 G90 G17\nG0 X1 Y1 Z0.5\nG1 X1.1 F20\nG2 X1.5 Y1.2 R0.3\nX1.9 Y1.0 R0.3\nG1 X2\nM2\n"
    a, b = _both(text)
    assert a == b
    blk = bulk.scan(text.splitlines(True))
    assert blk is not None
    assert blk.plain.tolist() == [False, True, True, True, True, True, False]
    correct_text(text, _engine(), SETUP, CorrectOptions())
    tab = planned_tables[-1]
    assert tab.kind.tolist()[-3:] == [Kind.ARC_CW, Kind.ARC_CW, Kind.FEED]
    (run,) = tab.runs
    assert len(run) == 4  # from G1 X1.1 to G1 X2
    assert sorted(run.arcs) == [1, 2]


@pytest.mark.parametrize("line", ["G1 X1 Y2 R3\n", "G2 X1 Y1 I1 R1\n", "G2 X1 Y1 R1 I1\n",
                                  "G2 X1 Y1 F100 R1\n", "R1\n"])
def test_an_r_word_that_is_no_arcs_radius_is_not_plain(line):
    blk = bulk.scan(["G0 X1 Y1 Z1\n", line, "N10 G1 X 1 Y-.5 F100\n"])
    assert blk is not None
    assert blk.plain.tolist() == [True, False, True]
