import numpy as np
import pytest
from conftest import TABLE1_POINTS, TangentTestMachine, grid_measurements
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration, save_calibration
from postproc.calibration.measurements import Measurements
from postproc.engine._tangents import parse_intervals
from postproc.engine.interval import IntervalEngine, fit
from postproc.engine.static import fit as static_fit
from postproc.errors import MeasurementError, PostprocError

MACHINE = TangentTestMachine()


@pytest.fixture(scope="module")
def grid_data():
    return grid_measurements(MACHINE, step=15.0, sigma=0.002, seed=3)


def two_cell_engine(shift_mm: float, blend: float = 0.0) -> IntervalEngine:
    """Cells split at X = 100; the upper cell's origin is moved by ``shift_mm`` along x."""
    edges = [[0.0, 100.0, 200.0], [0.0, 100.0], [0.0, 100.0]]
    G = np.tile(np.eye(3), (2, 1, 1, 1, 1))
    origin = np.zeros((2, 1, 1, 3))
    origin[1, 0, 0, 0] = shift_mm
    return IntervalEngine(edges, G, origin, np.eye(3), np.zeros(3), [[0, 0, 0], [200, 100, 100]],
                          border_blend_mm=blend)


def test_parse_intervals():
    assert parse_intervals("X=0,100,200,315;Y=3;z=2") == [[0.0, 100.0, 200.0, 315.0], 3, 2]
    assert parse_intervals(None) == [None, None, None]
    assert parse_intervals("Y=4") == [None, 4, None]
    for bad, msg in [("X=0,100,50", "increase"), ("Q=3", "not an axis"), ("X=2.5", "whole number"),
                     ("X=3;X=2", "given twice"), ("X3", "has no '='"), ("X=a,b", "not a list")]:
        with pytest.raises(PostprocError, match=msg):
            parse_intervals(bad)


def test_fit_recovers_piecewise_pairs():
    rng = np.random.default_rng(0)
    truth = two_cell_engine(0.0)
    truth.G[1, 0, 0] += np.array([[1e-4, 2e-4, 0], [0, -1e-4, 3e-4], [5e-5, 0, 2e-4]])
    truth.origin_mm[1, 0, 0] = [-0.01, 0.03, 0.02]
    q = np.vstack([rng.uniform([1, 1, 1], [99, 99, 99], (40, 3)), rng.uniform([101, 1, 1], [199, 99, 99], (40, 3))])
    meas = Measurements(q=q, m=truth.forward(q), r=np.zeros_like(q))
    res = fit([meas], intervals="X=0,100,200;Y=1;Z=1")
    assert_allclose(res.engine.G, truth.G, atol=1e-10)
    assert_allclose(res.engine.origin_mm, truth.origin_mm, atol=1e-8)
    assert res.max_mm < 1e-9


def test_interval_beats_static_on_curved_machine(grid_data):
    p = TABLE1_POINTS
    before = np.linalg.norm(MACHINE.forward(p) - p, axis=1).sum()
    static = static_fit([grid_data]).engine
    interval = fit([grid_data]).engine
    s = np.linalg.norm(MACHINE.forward(static.inverse(p).q) - p, axis=1).sum()
    i = np.linalg.norm(MACHINE.forward(interval.inverse(p).q) - p, axis=1).sum()
    assert i < 0.5 * s < 0.5 * before
    assert interval.shape == (3, 3, 3)
    assert_allclose(interval.volume_mm, [[0, 0, 0], [315, 315, 315]])


def test_round_trip_blended(grid_data):
    eng = fit([grid_data], intervals="X=4;Y=4;Z=4").engine
    assert eng.blend == 1.0
    rng = np.random.default_rng(9)
    p = rng.uniform(0, 315, (5000, 3))
    # and targets crowded around a border, where the pairs are blended
    near = rng.uniform(0, 315, (2000, 3))
    near[:, 1] = 157.5 + rng.uniform(-0.6, 0.6, 2000)
    p = np.vstack([p, near])
    r = np.array([0.0, 0.0, -10.0])
    res = eng.inverse(p + r, r)
    assert_allclose(eng.forward(res.q, r), p + r, atol=1e-6)
    assert res.residual_mm.max() < 1e-6
    # away from the borders the model is the cell's own pair
    q = np.array([[40.0, 120.0, 200.0]])
    c = eng.cells_of(q)[0]
    assert_allclose(eng.forward(q), eng.origin_mm[tuple(c)] + q @ eng.G[tuple(c)].T, atol=1e-12)


def test_round_trip_pure_piecewise_with_border_rule(grid_data):
    eng = fit([grid_data], intervals="X=4;Y=4;Z=4", border_blend_mm=0.0).engine
    rng = np.random.default_rng(9)
    p = rng.uniform(0, 315, (5000, 3))
    near = rng.uniform(0, 315, (2000, 3))
    near[:, 0] = 78.75 + rng.uniform(-0.03, 0.03, 2000)
    p = np.vstack([p, near])
    res = eng.inverse(p)
    exact = res.residual_mm < 1e-6
    assert_allclose(eng.forward(res.q[exact]), p[exact], atol=1e-6)
    assert exact[:5000].mean() > 0.998
    # Any exceptions are targets in the gaps between neighbouring cells' images: the
    # answer lies just beyond a border and the residual is at most the border jump.
    jump = eng.border_jumps().max()
    assert np.all(res.residual_mm[~exact] <= jump)
    for n in np.flatnonzero(~exact):
        d = np.min([np.abs(eng.edges[j] - res.q[n, j]).min() for j in range(3)])
        assert d < jump


def test_border_gap_and_overlap():
    # gap: the upper cell's image starts 10 um beyond the lower cell's
    eng = two_cell_engine(+0.010)
    res = eng.inverse([[100.004, 50.0, 50.0]])
    assert_allclose(res.q, [[100.004, 50.0, 50.0]], atol=1e-12)  # lower cell's pair, 4 um beyond
    assert res.residual_mm[0] == pytest.approx(0.010, abs=1e-9)
    # overlap: two consistent answers; the walk from the static cell keeps the first
    eng = two_cell_engine(-0.010)
    res = eng.inverse([[99.996, 50.0, 50.0]])
    assert_allclose(res.q, [[99.996, 50.0, 50.0]], atol=1e-12)
    assert res.residual_mm[0] < 1e-12
    assert eng.border_jumps()[0] == pytest.approx(0.010)


def test_blend_makes_the_border_continuous():
    eng = two_cell_engine(+0.010, blend=1.0)
    x = np.linspace(99.0, 101.0, 2001)
    q = np.column_stack([x, np.full_like(x, 50.0), np.full_like(x, 50.0)])
    f = eng.forward(q)[:, 0]
    assert np.all(np.diff(f) > 0)  # monotone, no gap
    assert np.abs(np.diff(f)).max() < 0.001 * 1.02  # slope at most 1 + jump/width * 1.5
    assert f[0] == pytest.approx(99.0)  # the lower pair ...
    assert f[-1] == pytest.approx(101.010)  # ... and the upper pair outside the zone
    res = eng.inverse([[100.004, 50.0, 50.0]])  # the former gap now has an answer
    assert res.residual_mm[0] < 1e-6
    assert 99.5 < res.q[0, 0] < 100.5
    with pytest.raises(PostprocError, match="border blend"):
        IntervalEngine([[0, 1.5, 3], [0, 1], [0, 1]], np.tile(np.eye(3), (2, 1, 1, 1, 1)),
                       np.zeros((2, 1, 1, 3)), np.eye(3), np.zeros(3), [[0, 0, 0], [3, 1, 1]])


def test_cell_with_too_few_points_is_refused():
    rng = np.random.default_rng(1)
    q = np.vstack([rng.uniform(0, 100, (30, 3)), [[250, 50, 50], [260, 60, 50], [270, 50, 60]]])
    q[0] = [0, 0, 0]
    meas = Measurements(q=q, m=q + 0.01, r=np.zeros_like(q), path="few.csv")
    with pytest.raises(MeasurementError) as info:
        fit([meas], intervals="X=0,200,270;Y=1;Z=1")
    text = str(info.value)
    assert text.startswith("few.csv: 3 points in interval cell X[200,270]")
    assert "give fewer intervals" in text


def test_calibration_round_trip(tmp_path, grid_data):
    eng = fit([grid_data], intervals="X=0,100,200,315;Y=3;Z=2").engine
    path = tmp_path / "interval.json"
    save_calibration(path, eng, name="i")
    cal = load_calibration(path)
    assert cal.method == "interval"
    assert [len(e) for e in cal.engine.edges] == [4, 4, 3]
    q = np.random.default_rng(2).uniform(0, 315, (300, 3))
    assert_allclose(cal.engine.forward(q), eng.forward(q), atol=1e-12)
    assert_allclose(cal.engine.inverse(q).q, eng.inverse(q).q, atol=1e-12)


def test_cells_are_half_open_except_the_last():
    from postproc.engine._tangents import cell_index

    edges = [np.array([0.0, 100.0, 200.0]), np.array([0.0, 50.0]), np.array([0.0, 10.0, 20.0, 30.0])]
    q = np.array([[100.0, 0.0, 10.0], [99.999, 50.0, 30.0], [200.0, 25.0, 20.0], [-5.0, 60.0, 35.0]])
    assert cell_index(q, edges).tolist() == [[1, 0, 1], [0, 0, 2], [1, 0, 2], [0, 0, 2]]
