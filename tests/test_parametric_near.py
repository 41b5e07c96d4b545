"""The parametric engine's tables located again near where the same points lay a step
earlier (StackedErrors.locate with ``near``, as Newton's steps locate them): the same
intervals, positions in them, values and slopes, to the last bit, as located afresh;
the rows the values took a step earlier reused only while no other evaluation has taken
rows since."""

from pathlib import Path

import numpy as np
import pytest
from test_parametric_speed import points, same_bits

from postproc.calfile import load_calibration
from postproc.calibration.axis_tables import AXES

CAL = "calibrations/s500_parametric.json"


@pytest.fixture(scope="module")
def s500():
    return load_calibration(Path(__file__).parents[1] / CAL).engine


def _moved(engine, q, rng):
    """q moved a little (as a Newton step moves it), some positions onto or across a knot
    or beyond the tables' ends."""
    q2 = q + rng.normal(0, 0.3, q.shape)
    n = len(q)
    for i, ax in enumerate(AXES):
        x = engine.tables.position_mm[ax]
        pick = rng.integers(0, n, n // 50 + 1)
        q2[pick, i] = rng.choice(x, len(pick)) + rng.choice([-1e-12, 0.0, 1e-12], len(pick))
    return q2


def _fields(st, loc):
    v = st.values(loc).copy()
    d = st.slopes(loc).copy()
    return [loc.g, loc.s, loc.s2 if loc.s2 is not None else np.zeros(0), loc.h, v, d]


@pytest.mark.parametrize("options", [{}, {"extrapolate": "linear"}, {"interpolation": "linear"}])
@pytest.mark.parametrize("n", [5, 64, 3000])
def test_located_near_a_step_earlier_is_located_afresh(s500, options, n):
    st = s500.with_options(**options)._stacked
    rng = np.random.default_rng(n)
    reused = rows_kept = 0
    lo, hi = s500.volume_mm
    for trial in range(20):
        if trial % 2:
            # a step of a Newton iteration: no position leaves its interval, most likely
            q1 = rng.uniform(lo - 10.0, hi + 10.0, (n, 3))
            q2 = q1 + rng.normal(0, 1e-7, q1.shape)
        else:
            q1 = points(s500, n, rng)
            q2 = _moved(s500, q1, rng)
        near = st.locate(q1)
        st.values(near)
        if trial % 3 == 0:
            # another evaluation in between takes rows of its own: those of near are stale
            st.values(st.locate(points(s500, n, rng)))
        again = st.locate(q2, near)
        if again.g is near.g:
            reused += 1
            # the rows of near: kept unless another evaluation took rows since
            kept = again.rows is not None and again.rows is near.rows
            assert kept == (st.pchip and trial % 3 != 0)
            rows_kept += kept
        ours = _fields(st, again)
        fresh = _fields(st, st.locate(q2))
        assert all(same_bits(a, b) for a, b in zip(ours, fresh, strict=True)), trial
    assert reused >= 8
    assert rows_kept >= 4 or not st.pchip


def test_a_position_that_is_not_finite_is_located_afresh(s500):
    st = s500._stacked
    rng = np.random.default_rng(1)
    q1 = points(s500, 100, rng, outside=False)
    near = st.locate(q1)
    st.values(near)
    q2 = q1.copy()
    q2[7, 1] = np.nan
    with np.errstate(invalid="ignore"):
        again = st.locate(q2, near)
        assert again.g is not near.g
        assert all(same_bits(a, b) for a, b in zip(_fields(st, again), _fields(st, st.locate(q2)), strict=True))
