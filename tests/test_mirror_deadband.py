import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.mirror.deadband import PLATEAU_STILL_MM, backlash, drive_lag, reversals, simulate

STEP_DEG = 0.01
WALL_SLOPE = 0.01  # mm of back wall per degree of table


def zigzag(n_rows=4, span_deg=10.0):
    """Table B forward and back over span_deg, the ideal sensor V = slope * B + row offset."""
    up = np.arange(0.0, span_deg + 1e-9, STEP_DEG)
    b = np.concatenate([up if k % 2 == 0 else up[::-1] for k in range(n_rows)])
    row = np.repeat(np.arange(n_rows), len(up))
    return b, row, WALL_SLOPE * b


@pytest.mark.parametrize("gap", [0.005, 0.02, 0.037])
def test_plateau_width_equals_the_gap(gap):
    b, _, v = zigzag()
    res = simulate(v, gap, b_deg=b)
    assert len(res.reversals) == 3
    assert len(res.plateaus) == 3
    step_mm = WALL_SLOPE * STEP_DEG
    for p in res.plateaus:
        # the output stands still until the input has travelled the gap (one sample of slack)
        assert gap - step_mm <= p.input_travel_mm <= gap + 1e-12
        assert abs(p.b_end - p.b_start) == pytest.approx(gap / WALL_SLOPE, abs=STEP_DEG + 1e-9)
        assert np.ptp(res.v_model[p.start:p.end + 1]) <= PLATEAU_STILL_MM


def test_thickness_error_is_half_a_gap_each_way():
    gap = 0.02
    b, _, v = zigzag()
    res = simulate(v, gap, b_deg=b)
    forward = np.diff(b, prepend=b[0]) > 0
    backward = np.diff(b, prepend=b[0]) < 0
    settled = np.ones(len(b), bool)
    for p in res.plateaus:
        settled[p.start:p.end + 1] = False
    settled[: int(0.5 * gap / (WALL_SLOPE * STEP_DEG)) + 1] = False  # the first half gap from rest
    assert_allclose(res.error_mm[forward & settled], gap / 2, atol=1e-12)
    assert_allclose(res.error_mm[backward & settled], -gap / 2, atol=1e-12)
    assert np.ptp(res.error_mm) == pytest.approx(gap, abs=1e-12)


def test_a_map_learned_on_one_pass_removes_it_a_smooth_one_does_not():
    gap = 0.02
    b, row, v = zigzag()
    first = simulate(v, gap, b_deg=b)
    # the same path on the next pocket: the error repeats, a point-by-point map removes it
    learned = first.error_mm.copy()
    again = simulate(v, gap, b_deg=b, correction_mm=learned)
    assert np.max(np.abs(again.residual_mm)) < 1e-12
    # a correction smooth in B (what a disturbance correction can give) cannot: the error
    # changes sign with the direction of travel at the same B
    smooth = np.full(len(b), np.mean(first.error_mm))
    third = simulate(v, gap, b_deg=b, correction_mm=smooth)
    assert np.max(np.abs(third.residual_mm)) > 0.4 * gap


def test_no_gap_no_plateau_and_backlash_block_rules():
    b, _, v = zigzag(2)
    res = simulate(v, 0.0)
    assert res.plateaus == []
    assert np.max(np.abs(res.error_mm)) == 0.0
    y = backlash([0.0, 0.3, 1.0, 0.8, 0.5, 0.0], 0.4)
    assert_allclose(y, [0.0, 0.1, 0.8, 0.8, 0.7, 0.2])
    assert list(reversals([0, 1, 2, 2, 1, 0, 1])) == [2, 5]


def test_drive_lag_is_first_order():
    t = np.linspace(0, 1, 1001)
    u = np.ones_like(t)
    u[0] = 0.0
    w = drive_lag(np.where(t > 0, 1.0, 0.0), t, 0.1)
    assert_allclose(w[1:], 1 - np.exp(-(t[1:] - t[1]) / 0.1), atol=1e-12)
