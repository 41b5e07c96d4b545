"""Seed 004: the bored 50H7 hole, Monte Carlo and worst case over tolerance fields and clearances.

The sample machine (samples/predict/mc12.machine.json) has, to first order, a hole
centre error that is linear in its eight variables, derived by hand:

- guide plane through corners g1 (0, 0), g2 (500, 0), g3 (0, 400), g4 (500, 400): the
  tool tip is 600 mm along and 200 mm across the plane's origin, 260 mm above it, so
  dZ = mean(g) + 350 b1 = -0.1 g1 + 0.6 g2 - 0.1 g3 + 0.6 g4 and
  dY = -260 b2 = 0.325 (g1 + g2 - g3 - g4) (b1, b2 the plane slopes, formula 19);
- head supports 400 mm apart, tip 600 mm from the rear one:
  dZ += 1.5 cz_front - 0.5 cz_rear, dY += 1.5 cy_front - 0.5 cy_rear.
"""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.errors import PostprocError
from postproc.predict import bore, tolerance
from postproc.predict.operation import load_operation

SAMPLES = Path(__file__).parents[1] / "samples" / "predict"
T = 0.05  # parallelism tolerance and clearances of the seed's example, mm
SIGMA = T / np.sqrt(12)  # standard deviation of a uniform variable over a 0.05 mm field

COEF_Z = {"g1": -0.1, "g2": 0.6, "g3": -0.1, "g4": 0.6, "cz_front": 1.5, "cz_rear": -0.5}
COEF_Y = {"g1": 0.325, "g2": 0.325, "g3": -0.325, "g4": -0.325, "cy_front": 1.5, "cy_rear": -0.5}


@pytest.fixture(scope="module")
def op():
    return load_operation(SAMPLES / "bore_50H7.operation.json")


def values(**kw):
    names = ["g1", "g2", "g3", "g4", "cy_rear", "cz_rear", "cy_front", "cz_front"]
    return {n: kw.get(n, 0.0) for n in names}


def test_section_points_are_table4_on_the_nominal_hole(op):
    sec = bore.evaluate_section(op, values())
    ang = np.radians(bore.TABLE4_ANGLES_DEG[:8])
    assert_allclose(sec.points_mm[:8, 1], 270 + 25 * np.cos(ang), atol=1e-9)
    assert_allclose(sec.points_mm[:8, 2], 560 + 25 * np.sin(ang), atol=1e-9)
    assert_allclose(sec.points_mm[:, 0], 600.0)
    assert_allclose(sec.error_mm, [0, 0], atol=1e-9)
    assert_allclose(sec.axis_point_mm, [600, 270, 560], atol=1e-9)


@pytest.mark.parametrize(
    ("setting", "expected"),
    [
        ({"g1": T, "g2": T, "g3": T, "g4": T}, [0.0, T]),  # the whole plane raised: pure shift
        ({"cz_rear": 0.01, "cz_front": 0.01}, [0.0, 0.01]),
        ({"cy_rear": -0.02, "cy_front": -0.02}, [-0.02, 0.0]),
        ({"cz_rear": -0.025, "cz_front": 0.025}, [0.0, 0.05]),  # tilt: -c + 2c * 600/400
        ({"g3": T, "g4": T}, [-0.0325, T / 2]),  # roll: -260 * 0.05/400, plane mid-height
        ({"g2": T, "g4": T}, [0.0, 0.06]),  # pitch: 0.05 * 600/500
    ],
)
def test_centre_error_for_hand_computed_settings(op, setting, expected):
    sec = bore.evaluate_section(op, values(**setting))
    # products of the micro-radian tilts and the 600 mm arm stay below 0.1 um
    assert_allclose(sec.error_mm, expected, atol=1e-4)
    assert_allclose(sec.axis_point_mm[1:] - [270, 560], sec.error_mm, atol=1e-6)


def test_worst_case_is_the_sum_of_the_extreme_contributions(op):
    worst = tolerance.worst_case(lambda env: bore.centre_errors(op, env), op.chain.random,
                                 tolerance_mm=[0.1, 0.1], names=["Y", "Z"])
    # The hand values are first order; at a corner the neglected products of tilts
    # (up to 2.25e-4 rad) with the 260-600 mm arms reach 600 * (2.25e-4)**2 / 2 = 1.5e-5 mm.
    second_order = 2e-5
    # Z: 0.6 * 2 * 0.05 + (1.5 + 0.5) * 0.025 = 0.11; Y: 0.325 * 2 * 0.05 + 0.05 = 0.0825
    assert_allclose(worst.max_abs_mm, [0.0825, 0.11], atol=second_order)
    # lowest Z: -0.2 * 0.05 (plane) - 0.05 (clearances) = -0.06
    assert_allclose(worst.min_mm, [-0.0825, -0.06], atol=second_order)
    assert_allclose(worst.max_mm, [0.0825, 0.11], atol=second_order)
    assert not worst.within  # the seed's conclusion: +-0.1 mm cannot be guaranteed
    assert worst.corner[1]["g2"] == T
    assert worst.corner[1]["g1"] == 0.0


def test_monte_carlo_matches_the_linear_model(op):
    n = 4000
    fn = lambda env: bore.centre_errors(op, env)  # noqa: E731
    dist = tolerance.monte_carlo(fn, op.chain.random, n=n, seed=3, tolerance_mm=[0.1, 0.1], names=["Y", "Z"])
    std_y = SIGMA * np.sqrt(sum(c * c for c in COEF_Y.values()))
    std_z = SIGMA * np.sqrt(sum(c * c for c in COEF_Z.values()))
    assert std_z == pytest.approx(1.8 * SIGMA)
    mean_z = sum(c * T / 2 for k, c in COEF_Z.items() if k.startswith("g"))  # = 0.025
    assert dist.mean_mm[1] == pytest.approx(mean_z, abs=4 * std_z / np.sqrt(n))
    assert dist.mean_mm[0] == pytest.approx(0.0, abs=4 * std_y / np.sqrt(n))
    assert_allclose(dist.std_mm, [std_y, std_z], rtol=4 / np.sqrt(2 * n))
    # the draws themselves follow the linear model to second order
    draws = tolerance.sample(op.chain.random, n, np.random.default_rng(3))
    lin_z = sum(c * draws[k] for k, c in COEF_Z.items())
    assert_allclose(dist.samples_mm[:, 1], lin_z, atol=1e-4)
    assert dist.p_within == pytest.approx(np.mean((np.abs(dist.samples_mm) <= 0.1).all(axis=1)))
    assert dist.p_within > 0.99  # rarely outside: the worst corner is a rare combination
    lo, hi = dist.p_within_ci95
    assert lo <= dist.p_within <= hi


def test_monte_carlo_is_reproducible_per_seed(op):
    fn = lambda env: bore.centre_errors(op, env)  # noqa: E731
    kw = {"n": 300, "tolerance_mm": [0.1, 0.1], "names": ["Y", "Z"]}
    a = tolerance.monte_carlo(fn, op.chain.random, seed=7, **kw)
    b = tolerance.monte_carlo(fn, op.chain.random, seed=7, **kw)
    c = tolerance.monte_carlo(fn, op.chain.random, seed=8, **kw)
    assert np.array_equal(a.samples_mm, b.samples_mm)
    assert not np.array_equal(a.samples_mm, c.samples_mm)


def test_circle_centre_of_exact_points():
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    pts = np.column_stack([3 + 25 * np.cos(ang), -7 + 25 * np.sin(ang)])
    assert_allclose(bore.circle_centre(pts), [3, -7], atol=1e-12)


def test_distributions_and_their_bounds():
    assert tolerance.bounds({"normal": [1.0, 0.1]}) == pytest.approx((0.7, 1.3))
    c = tolerance.corners({"a": {"uniform": [0, 1]}, "b": {"uniform": [-2, 2]}})
    assert sorted(zip(c["a"], c["b"], strict=True)) == [(0, -2), (0, 2), (1, -2), (1, 2)]
    with pytest.raises(PostprocError, match="2\\*\\*17"):
        tolerance.corners({f"v{i}": {"uniform": [0, 1]} for i in range(17)})


def test_monte_carlo_in_blocks_gives_the_same_draws(op, monkeypatch):
    fn = lambda env: bore.centre_errors(op, env)  # noqa: E731
    kw = {"n": 50, "seed": 5, "tolerance_mm": [0.1, 0.1], "names": ["Y", "Z"]}
    whole = tolerance.monte_carlo(fn, op.chain.random, **kw)
    monkeypatch.setattr(tolerance, "DRAWS_PER_BLOCK", 7)
    blocks = tolerance.monte_carlo(fn, op.chain.random, **kw)
    assert_allclose(blocks.samples_mm, whole.samples_mm, rtol=0, atol=1e-15)


def test_a_turning_deflection_changes_the_diameter_not_the_centre(tmp_path):
    from postproc.predict.operation import operation_from_dict

    chain = {"format": "postproc chain", "modules": [
        {"name": "head", "elements": [{"fixed": {"translation": [0, 270, 560]}}]},
        {"name": "spindle", "elements": [
            {"rotary": {"axis": "x", "var": "S"}},
            # 10 um of radial tool deflection turning with the spindle, 20 urad of axis tilt
            {"error": {"v": 0.01, "gamma": 2e-5}}]},
    ]}
    op = operation_from_dict({"format": "postproc operation", "kind": "bore", "machine": chain,
                              "diameter_mm": 50, "overhang_mm": 100, "nominal_centre_mm": [270, 560],
                              "tolerance_mm": [0.1, 0.1]}, tmp_path)
    sec = bore.evaluate_section(op, {})
    # tip (100, 25, 0) in the turning frame -> radius 25 + 0.01 + 2e-5 * 100
    assert sec.diameter_mm == pytest.approx(50 + 2 * (0.01 + 2e-5 * 100), abs=1e-9)
    assert_allclose(sec.error_mm, [0, 0], atol=1e-9)
    assert sec.roundness_mm == pytest.approx(0.0, abs=1e-9)


def test_turning_cutting_force_of_table3_shrinks_and_ovalises_the_hole():
    # supports displaced by (A2 cos S, A1 sin S) at the rear and (-A4 cos S, -A3 sin S) at
    # the front: the tip, at 1.5 front - 0.5 rear, moves (-(1.5 A4 + 0.5 A2) cos S,
    # -(1.5 A3 + 0.5 A1) sin S): an ellipse with half-axes 25.00625 - 0.010 and - 0.006
    op = load_operation(SAMPLES / "bore_50H7_rotating_load.operation.json")
    sec = bore.evaluate_section(op, tolerance.nominal(op.chain.random))
    assert sec.diameter_mm == pytest.approx(50.0125 - 0.010 - 0.006, abs=1e-6)
    assert sec.roundness_mm == pytest.approx(0.004, abs=1e-6)
    assert_allclose(sec.error_mm, [0.0, 0.025], atol=1e-6)  # the centre does not move
    assert not (op.params["diameter_limits_mm"][0] <= sec.diameter_mm)
