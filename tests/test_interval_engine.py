import numpy as np
import pytest
from numpy.testing import assert_allclose
from test_grid_machine import TABLE1_POINTS, TangentTestMachine, grid_measurements

from postproc.calibration.calfile import load_calibration, save_calibration
from postproc.calibration.measurements import Measurements
from postproc.engine._tangents import parse_intervals
from postproc.engine.interval import IntervalEngine, fit
from postproc.engine.static import fit as static_fit
from postproc.errors import MeasurementError, PostprocError

MACHINE = TangentTestMachine()


@pytest.fixture(scope="module")
def grid_data():
    return grid_measurements(MACHINE, step=15.0, sigma=0.002, seed=3)


def two_cell_engine(shift_mm: float) -> IntervalEngine:
    """Cells split at X = 100; the upper cell's origin is moved by ``shift_mm`` along x."""
    edges = [[0.0, 100.0, 200.0], [0.0, 100.0], [0.0, 100.0]]
    G = np.tile(np.eye(3), (2, 1, 1, 1, 1))
    origin = np.zeros((2, 1, 1, 3))
    origin[1, 0, 0, 0] = shift_mm
    return IntervalEngine(edges, G, origin, np.eye(3), np.zeros(3), [[0, 0, 0], [200, 100, 100]])


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


def test_round_trip_with_border_rule(grid_data):
    res_fit = fit([grid_data], intervals="X=4;Y=4;Z=4")
    eng = res_fit.engine
    rng = np.random.default_rng(9)
    p = rng.uniform(0, 315, (5000, 3))
    res = eng.inverse(p)
    exact = res.residual_mm < 1e-6
    assert_allclose(eng.forward(res.q[exact]), p[exact], atol=1e-6)
    # Exceptions are only targets in the gaps between neighbouring cells' images: the
    # answer lies just beyond a border and the residual is at most the border jump.
    assert exact.mean() > 0.998
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
