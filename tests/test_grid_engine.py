import json

import numpy as np
import pytest
from conftest import (
    TABLE1_POINTS,
    TangentTestMachine,
    grid_measurements,
)
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration, save_calibration
from postproc.calibration.measurements import Measurements
from postproc.engine.grid import (
    GridEngine,
    fit,
    nodes_from_tangents,
    tangents_from_nodes,
)
from postproc.errors import MeasurementError, PostprocError

MACHINE = TangentTestMachine()


@pytest.fixture(scope="module")
def grid15():
    return fit([grid_measurements(MACHINE, step=15.0, sigma=0.002, seed=11)])


def small_grid(step=20.0, side=60.0, **kw):
    return grid_measurements(MACHINE, step=step, side=side, **kw)


def test_sums_of_tangents_reproduce_the_measured_nodes():
    meas = small_grid(sigma=0.0)
    res = fit([meas])
    eng = res.engine
    u = eng.step
    M = (2, 1, 3)
    # The seed's sum along X first, then Y at that X, then Z at that X, Y.
    R = (eng.r_O1 + u[0] * eng.Q1[: M[0]].sum(0) + u[1] * eng.Q2[M[0], : M[1]].sum(0)
         + u[2] * eng.Q3[M[0], M[1], : M[2]].sum(0))
    q_node = np.array(M) * u
    assert_allclose(R, MACHINE.forward(q_node[None])[0], atol=1e-12)
    assert eng.Q1.shape == (3, 3)
    assert eng.Q2.shape == (4, 3, 3)
    assert eng.Q3.shape == (4, 4, 3, 3)
    r_O1, Q1, Q2, Q3 = tangents_from_nodes(eng.nodes, u)
    assert_allclose(nodes_from_tangents(r_O1, Q1, Q2, Q3, u), eng.nodes, atol=1e-12)
    # Tangents keep the axis scale: |Q1| - 1 is the X scale error between nodes.
    x_scale = np.linalg.norm(eng.Q1, axis=1) - 1
    assert np.all(np.abs(x_scale) > 1e-5)


def test_grid_corrects_table1_points_within_5um(grid15):
    p = TABLE1_POINTS
    before = np.linalg.norm(MACHINE.forward(p) - p, axis=1)
    q = grid15.engine.inverse(p).q
    after = np.linalg.norm(MACHINE.forward(q) - p, axis=1)
    assert before.min() > 0.1
    assert after.max() < 0.005


def test_trilinear_round_trip_and_continuity(grid15):
    eng = grid15.engine
    rng = np.random.default_rng(5)
    p = rng.uniform(0, 315, (3000, 3))
    r = np.array([0.0, 0.0, -30.0])
    res = eng.inverse(p + r, r)
    assert_allclose(eng.forward(res.q, r), p + r, atol=1e-6)
    assert res.residual_mm.max() < 1e-6
    assert res.iterations.max() <= 4
    # continuous across a cell face, and through the nodes
    face = np.array([[45.0, 100.0, 200.0]])
    eps = np.array([[1e-9, 0, 0]])
    assert_allclose(eng.forward(face - eps), eng.forward(face + eps), atol=1e-9)
    nodes_q = np.array([[0, 0, 0], [15, 30, 45], [315, 315, 315]], float)
    idx = (nodes_q / 15).astype(int)
    assert_allclose(eng.forward(nodes_q), eng.nodes[tuple(idx.T)], atol=1e-12)


def test_first_step_is_formula_2(grid15):
    """In the cell model, q = G_M^-1 (p* - R) + u M, the seed's formula (2)."""
    full = grid15.engine
    eng = GridEngine.from_nodes(full.q0, full.step, full.nodes, model="cell")
    p = np.array([[101.0, 52.0, 230.0]])  # well inside cell (6, 3, 15)
    M = np.array([6, 3, 15])
    G = np.column_stack([
        full.nodes[7, 3, 15] - full.nodes[6, 3, 15],
        full.nodes[6, 4, 15] - full.nodes[6, 3, 15],
        full.nodes[6, 3, 16] - full.nodes[6, 3, 15],
    ]) / 15.0
    expected = np.linalg.solve(G, p[0] - full.nodes[6, 3, 15]) + 15.0 * M
    res = eng.inverse(p)
    assert_allclose(res.q[0], expected, atol=1e-12)
    assert res.iterations[0] == 1
    assert res.residual_mm[0] < 1e-9


def test_cell_model_round_trip_and_border_rule(grid15):
    full = grid15.engine
    eng = GridEngine.from_nodes(full.q0, full.step, full.nodes, model="cell")
    rng = np.random.default_rng(6)
    p = rng.uniform(0, 315, (3000, 3))
    res = eng.inverse(p)
    cells = np.clip(np.floor(res.q / 15.0), 0, 20)
    lo, hi = cells * 15.0, cells * 15.0 + 15.0
    consistent = np.all((res.q >= lo - 1e-9) & (res.q <= hi + 1e-9), axis=1)
    # Where the answer lies in the cell it was computed in, it is exact.
    assert res.residual_mm[res.residual_mm < 1e-6].size >= consistent.sum() - 5
    assert consistent.mean() > 0.99
    # Elsewhere the target fell into a gap between neighbouring cells' images: the answer
    # sits just beyond a border and its residual is the model's jump there (< 30 um).
    gap = res.residual_mm > 1e-6
    assert np.all(res.residual_mm[gap] < 0.03)
    dist = np.minimum(np.abs(res.q[gap] - np.round(res.q[gap] / 15.0) * 15.0).min(axis=1), 1.0)
    assert np.all(dist < 0.03)


def test_calibration_round_trip(tmp_path, grid15):
    for model in ("trilinear", "cell"):
        eng = GridEngine.from_nodes(grid15.engine.q0, grid15.engine.step, grid15.engine.nodes, model=model)
        path = tmp_path / f"{model}.json"
        save_calibration(path, eng, name="g", fit=grid15.info)
        cal = load_calibration(path)
        assert cal.method == "grid"
        assert cal.engine.model == model
        assert_allclose(cal.engine.volume_mm, [[0, 0, 0], [315, 315, 315]])
        q = np.random.default_rng(1).uniform(-5, 320, (200, 3))
        assert_allclose(cal.engine.forward(q), eng.forward(q), atol=1e-12)
    data = json.loads(path.read_text())
    data["model"]["Q3"] = data["model"]["Q3"][:-1]
    path.write_text(json.dumps(data))
    with pytest.raises(PostprocError, match="grid model"):
        load_calibration(path)


def test_incomplete_grid_names_missing_nodes():
    meas = small_grid()
    drop = np.all(meas.q == [20.0, 40.0, 0.0], axis=1) | np.all(meas.q == [60.0, 0.0, 60.0], axis=1)
    cut = Measurements(q=meas.q[~drop], m=meas.m[~drop], r=meas.r[~drop], path="cut.csv")
    with pytest.raises(MeasurementError) as info:
        fit([cut])
    text = str(info.value)
    assert text.startswith("cut.csv: incomplete grid: 2 of 64 nodes")
    assert "X=20.000 Y=40.000 Z=0.000" in text
    assert "X=60.000 Y=0.000 Z=60.000" in text


def test_irregular_grid_needs_step_and_step_subsamples():
    meas = small_grid(step=10.0, side=60.0, sigma=0.0)
    extra = Measurements(q=np.array([[33.3, 10.0, 10.0]]), m=np.array([[33.3, 10.0, 10.0]]),
                         r=np.zeros((1, 3)))
    both = Measurements.concat([meas, extra])
    with pytest.raises(MeasurementError, match="not evenly spaced"):
        fit([both])
    res = fit([both], step="20")
    assert res.engine.shape.tolist() == [4, 4, 4]
    assert any("left out 280 points" in line for line in res.report)
    q = np.array([[20.0, 40.0, 60.0]])
    assert_allclose(res.engine.forward(q), MACHINE.forward(q), atol=1e-12)


def test_repeated_shots_are_averaged():
    meas = small_grid(sigma=0.002, shots=4, seed=2)
    res = fit([meas])
    assert res.engine.nodes.shape == (4, 4, 4, 3)
    # residuals are shot minus node mean: they sum to zero at each node
    assert_allclose(res.residuals_mm.reshape(64, 4, 3).sum(axis=1), 0, atol=1e-12)
    assert 0.002 < res.rms_mm < 0.004


def test_step_and_screw_pitch_warnings():
    fine = fit([small_grid(step=5.0, side=20.0)])
    assert sum("under 10 mm" in line for line in fine.report) == 3
    res = fit([small_grid(step=15.0, side=315.0)], screw_pitch=["X=5", "Y=7.4", "Z=16"])
    warn = [line for line in res.report if line.startswith("warning")]
    assert len(warn) == 2
    assert "on X is a multiple (3 x) of the lead-screw pitch 5 mm" in warn[0]
    assert "constant offset" in warn[0]
    assert "on Y is nearly a multiple (2.027 x)" in warn[1]
    assert "slow wave of period 555 mm" in warn[1]
    with pytest.raises(PostprocError, match="not an axis"):
        fit([small_grid()], screw_pitch=["W=5"])


def test_other_tool_vector_is_carried_unrotated(grid15):
    eng = grid15.engine
    q = np.array([[100.0, 200.0, 50.0]])
    r1, r2 = np.zeros(3), np.array([10.0, 0.0, -120.0])
    assert_allclose(eng.forward(q, r2) - eng.forward(q, r1), r2[None], atol=1e-12)


def test_report_names_the_tool_vectors():
    one = fit([small_grid(tool=(0.0, 0.0, -80.0))])
    assert any("tool vector of the measurement: 0,0,-80 mm" in line for line in one.report)
    two = Measurements.concat([small_grid(tool=(0.0, 0.0, -80.0)), small_grid(tool=(0.0, 0.0, 0.0))])
    res = fit([two])
    assert any("2 different tool vectors" in line for line in res.report)
    # both tool vectors are averaged into one node position per lattice node
    assert res.engine.nodes.shape == (4, 4, 4, 3)


def test_fill_missing_nodes_from_neighbours():
    meas = small_grid(sigma=0.0)
    drop = (np.all(meas.q == [20.0, 40.0, 0.0], axis=1) | np.all(meas.q == [60.0, 0.0, 60.0], axis=1)
            | np.all(meas.q == [20.0, 20.0, 20.0], axis=1))
    cut = Measurements(q=meas.q[~drop], m=meas.m[~drop], r=meas.r[~drop])
    res = fit([cut], fill_missing=True)
    warn = [line for line in res.report if "filled from their neighbours" in line]
    assert len(warn) == 1
    assert warn[0].startswith("warning: 3 node(s)")
    assert "X=60.000 Y=0.000 Z=60.000" in warn[0]
    full = fit([meas]).engine
    # interior node: midpoints of its neighbours on three axes; corner: extrapolated
    i = (1, 1, 1)
    expected = np.mean([(full.nodes[0, 1, 1] + full.nodes[2, 1, 1]) / 2,
                        (full.nodes[1, 0, 1] + full.nodes[1, 2, 1]) / 2,
                        (full.nodes[1, 1, 0] + full.nodes[1, 1, 2]) / 2], axis=0)
    assert_allclose(res.engine.nodes[i], expected, atol=1e-12)
    filled = np.array([[1, 2, 0], [3, 0, 3], [1, 1, 1]])
    err = np.linalg.norm(res.engine.nodes[tuple(filled.T)] - full.nodes[tuple(filled.T)], axis=1)
    assert err.max() < 0.01  # a smooth machine: neighbours predict a 20 mm node to ~um
    assert res.info["n_filled_nodes"] == 3
    two = np.all(meas.q == 0, axis=1) | np.all(meas.q == 60, axis=1)
    with pytest.raises(MeasurementError, match="too few to fill"):
        fit([Measurements(q=meas.q[two], m=meas.m[two], r=meas.r[two])], step="20", fill_missing=True)


def test_unequal_steps_per_axis_reproduce_the_nodes():
    """Steps of 10, 15 and 20 mm: each axis's tangents are scaled by its own step."""
    steps = np.array([10.0, 15.0, 20.0])
    axes = [np.arange(4) * steps[j] for j in range(3)]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    nodes = q + np.stack([1e-3 * np.sin(y / 20) + 2e-4 * z, 3e-4 * x + 1e-3 * np.cos(z / 30),
                          -2e-4 * y + 1e-3 * np.sin(x / 25)], axis=-1)
    eng = GridEngine.from_nodes([0, 0, 0], steps, nodes)
    assert_allclose(eng.nodes, nodes, atol=1e-12)
    flat_q, flat_nodes = q.reshape(-1, 3), nodes.reshape(-1, 3)
    assert_allclose(eng.forward(flat_q), flat_nodes, atol=1e-9)
