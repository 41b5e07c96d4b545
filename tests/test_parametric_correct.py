"""The parametric engine through the correction pipeline: lines and an arc with a 100 mm tool."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from postproc.engine.parametric import ParametricEngine
from postproc.simulate.s500 import synthetic_tables

pytest.importorskip("postproc.gcode.pipeline")
from postproc.gcode.path import Setup, program_path  # noqa: E402
from postproc.gcode.pipeline import correct_text  # noqa: E402

PROGRAM = """G21 G90 G94 G17
T1 M6
G43 H1
G0 X20 Y30 Z150
G1 Z60 F500
G1 X280 Y250 Z120 F1200
G2 X200 Y170 I-40 J-40
G1 X40 Y290 Z40
G0 Z200
M30
"""
SETUP = Setup(tool_lengths={1: 100.0})


def feed_points(text, step=0.5):
    path = program_path(text, SETUP, max_step_mm=step)
    feed = ~path.rapid
    return path.points_mm[feed], path.tool_mm[feed]


def distance_to_polyline(poly, pts):
    """Distance of each point to the polyline through ``poly`` (nearest vertex's two segments)."""
    k = cKDTree(poly).query(pts)[1]
    best = np.full(len(pts), np.inf)
    for a, b in ((np.maximum(k - 1, 0), k), (k, np.minimum(k + 1, len(poly) - 1))):
        A, B = poly[a], poly[b]
        d = B - A
        dd = np.maximum(np.sum(d * d, axis=1), 1e-30)
        t = np.clip(np.sum((pts - A) * d, axis=1) / dd, 0, 1)
        best = np.minimum(best, np.linalg.norm(pts - (A + t[:, None] * d), axis=1))
    return best


@pytest.mark.parametrize("order", ["first", "exact"])
def test_corrected_program_lands_on_the_nominal_path(order):
    tables, sq = synthetic_tables(3)
    engine = ParametricEngine(tables, sq, order=order)
    out, report = correct_text(PROGRAM, engine, SETUP)
    nominal, tool = feed_points(PROGRAM)
    actual_before = engine.forward(nominal - tool, tool)
    corrected, tool_c = feed_points(out)
    actual_after = engine.forward(corrected - tool_c, tool_c)
    dense, _ = feed_points(PROGRAM, step=0.05)  # chords of the arc within 0.01 um
    before = np.linalg.norm(actual_before - nominal, axis=1)
    after = distance_to_polyline(dense, actual_after)
    assert before.max() > 0.2
    assert report.lines_inserted > 0  # curved error field: moves are split
    assert after.max() < 0.0011  # the 1 um path tolerance
