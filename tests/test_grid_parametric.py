"""The tangential engines against a parametric (21-error) machine with a tool vector."""

import numpy as np
from test_grid_machine import TABLE1_POINTS

from postproc.calibration.measurements import Measurements
from postproc.engine import grid, interval
from postproc.engine.parametric import ParametricEngine
from postproc.simulate.s500 import synthetic_tables

TOOL = np.array([0.0, 0.0, -50.0])


def machine_and_grid(step=15.0, sigma=0.002, seed=4):
    truth = ParametricEngine(*synthetic_tables(seed))
    ax = np.arange(0.0, 315.0 + 1e-9, step)
    q = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    r = np.tile(TOOL, (len(q), 1))
    m = truth.forward(q, r) + np.random.default_rng(seed).normal(0.0, sigma, q.shape)
    return truth, Measurements(q=q, m=m, r=r)


def test_grid_corrects_a_parametric_machine_with_its_tool():
    truth, meas = machine_and_grid()
    eng = grid.fit([meas]).engine
    p = TABLE1_POINTS
    before = np.linalg.norm(truth.forward(p - TOOL, TOOL) - p, axis=1)
    after = np.linalg.norm(truth.forward(eng.inverse(p, TOOL).q, TOOL) - p, axis=1)
    assert before.max() > 0.2
    assert after.max() < 0.005
    ieng = interval.fit([meas]).engine
    inter = np.linalg.norm(truth.forward(ieng.inverse(p, TOOL).q, TOOL) - p, axis=1)
    assert after.sum() < inter.sum() < 0.2 * before.sum()


def test_other_tool_vector_leaves_the_angular_part():
    """Documented limitation: a different tool vector is carried unrotated, so the
    error left is about eps x (r - r_measured)."""
    truth, meas = machine_and_grid()
    eng = grid.fit([meas]).engine
    other = np.array([0.0, 0.0, -150.0])
    p = TABLE1_POINTS - np.array([0.0, 0.0, 100.0])  # keep q = p - r inside the volume
    q = eng.inverse(p, other).q
    err = truth.forward(q, other) - p
    _, eps = truth.errors_at(q)
    predicted = np.cross(eps, other - TOOL)
    assert np.linalg.norm(predicted, axis=1).max() > 0.003  # the effect is visible ...
    # ... and is what is left, to the grid's own accuracy
    assert np.linalg.norm(err - predicted, axis=1).max() < 0.005
