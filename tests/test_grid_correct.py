"""The tangential engines through the correction pipeline: a move crossing cell borders."""

import numpy as np
import pytest
from conftest import TangentTestMachine, grid_measurements

from postproc.engine import grid, interval
from postproc.errors import PostprocError
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import correct_text

MACHINE = TangentTestMachine()
A, B = np.array([10.0, 20.0, 30.0]), np.array([300.0, 290.0, 250.0])
PROGRAM = "G21 G90 G94\nG0 X10 Y20 Z30\nG1 X300 Y290 Z250 F1000\nM30\n"


@pytest.fixture(scope="module")
def data():
    return grid_measurements(MACHINE, step=15.0, sigma=0.002, seed=8)


def distance_to_segment(p):
    d = B - A
    t = np.clip((p - A) @ d / (d @ d), 0, 1)
    return np.linalg.norm(p - (A + t[:, None] * d), axis=1)


def run(text, forward):
    path = program_path(text, Setup())
    feed = ~path.rapid
    q = path.points_mm[feed] - path.tool_mm[feed]
    return distance_to_segment(forward(q, path.tool_mm[feed]))


@pytest.mark.parametrize("method", ["interval", "grid"])
def test_move_across_cells_is_corrected(data, method):
    engine = (interval.fit([data]) if method == "interval" else grid.fit([data])).engine
    out, report = correct_text(PROGRAM, engine)
    assert report.lines_inserted > 10  # the move was split to follow the curved correction
    before = run(PROGRAM, MACHINE.forward)
    model = run(out, engine.forward)
    after = run(out, MACHINE.forward)
    assert before.max() > 0.3
    assert model.max() < 0.001  # the emitted path follows the model within the 1 um tolerance
    assert after.max() < (0.03 if method == "interval" else 0.008)


def test_pure_piecewise_interval_model_is_refused_at_a_gap(data):
    engine = interval.fit([data], border_blend_mm=0.0).engine
    with pytest.raises(PostprocError):
        correct_text(PROGRAM, engine)
