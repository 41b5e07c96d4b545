import numpy as np
import pytest

from postproc.diagnose.data import REPEAT_TIME_S, Dataset
from postproc.diagnose.noise import noise_floor


def test_repeats_group_by_point_context_and_close_times():
    q = np.array([[0, 0, 0]] * 4 + [[1, 0, 0]] * 2, float)
    t = np.array([0, 5, 10, 10 + 2 * REPEAT_TIME_S, 0, 1000.0])
    temp = np.array([20, 20, 20, 20, 20, 20.0])
    ds = Dataset(q=q, m=q, r=np.zeros_like(q), ctx={"t": t, "temp": temp})
    g = ds.repeat_groups()
    assert g[0] == g[1] == g[2]
    assert len({g[2], g[3], g[4], g[5]}) == 4
    ds.ctx["temp"] = np.array([20, 21, 20, 20, 20, 20.0])  # another temperature: not a repeat
    g = ds.repeat_groups()
    assert g[0] == g[2] != g[1]


def test_noise_floor_from_repeats_and_declared():
    rng = np.random.default_rng(2)
    sigma = 0.003
    q = np.repeat(rng.uniform(0, 300, (60, 3)), 4, axis=0)
    m = q + rng.normal(0, sigma, q.shape) + np.repeat(rng.normal(0, 0.05, (60, 3)), 4, axis=0)
    ds = Dataset(q=q, m=m, r=np.zeros_like(q))
    nf = noise_floor(ds)
    assert nf.source == "repeats"
    assert nf.dof == 180
    # the between-point scatter (50 um) does not leak into the floor
    assert nf.rms_mm == pytest.approx(sigma * np.sqrt(3), rel=0.1)
    declared = noise_floor(ds, 0.001)
    assert declared.source == "declared"
    assert declared.rms_mm == pytest.approx(0.001 * np.sqrt(3))
    assert declared.measured_rms_mm == pytest.approx(nf.rms_mm)
    unknown = noise_floor(Dataset(q=q[::4], m=m[::4], r=np.zeros((60, 3))))
    assert unknown.rms_mm is None
    assert unknown.source == "unknown"


def test_qn_scale_is_consistent_for_gaussian_noise_and_robust_to_bad_shots():
    from postproc.diagnose.noise import qn_scale

    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 2.0, 3000)
    assert qn_scale(x) == pytest.approx(2.0, rel=0.05)
    x[:300] = 1000.0  # a tenth of the shots wild
    assert qn_scale(x) == pytest.approx(2.0, rel=0.2)


def test_heavy_tails_are_measured_and_gaussian_noise_keeps_the_plain_verdict():
    """Student-t noise (4 degrees of freedom) is flagged by the kurtosis of the repeat
    deviations; Gaussian noise is not, and its verdict keeps CONSISTENT_RATIO exactly."""
    from postproc.diagnose import vm
    from postproc.diagnose.verdict import CONSISTENT_RATIO, tolerance

    heavy = gauss = 0
    for seed in range(6):
        nt = noise_floor(Dataset.from_measurements([vm.campaign("raster", 600 + seed)]))
        ng = noise_floor(Dataset.from_measurements([vm.campaign("raster", 600 + seed, noise_df=None)]))
        heavy += nt.heavy_tailed
        gauss += ng.heavy_tailed
        assert tolerance(ng) == (CONSISTENT_RATIO, "1.15")
        assert ng.robust_rms_mm == pytest.approx(ng.rms_mm, rel=0.08)
        if nt.heavy_tailed:
            tol, why = tolerance(nt)
            assert CONSISTENT_RATIO < tol < 1.4
            assert "heavy-tailed" in why
    assert gauss == 0
    assert heavy >= 4
