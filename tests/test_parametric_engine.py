import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration, save_calibration
from postproc.calibration.axis_tables import AXES, AxisTables, Squareness
from postproc.constants import SOLVER_TOL_MM
from postproc.engine.parametric import ParametricEngine
from postproc.engine.parametric_orders import SEED_ORDER_POINTS_MM
from postproc.engine.parametric_solvers import newton_inverse_located
from postproc.errors import CalibrationError, SolverError
from postproc.simulate.s500 import SEED_CONTROL_POINTS_MM, synthetic_tables

RNG = np.random.default_rng(5)
TOOL = np.array([0.0, 0.0, -100.0])
CONTROL = np.array(SEED_CONTROL_POINTS_MM, dtype=float)


def machine(seed=0, **options):
    tables, sq = synthetic_tables(seed)
    return ParametricEngine(tables, sq, **options)


def reference_first_order(tables, sq, q, r):
    """Formula (3) written out independently: linear interpolation, numpy cross."""
    rho = np.zeros_like(q)
    eps = np.zeros_like(q)
    for i, ax in enumerate(AXES):
        x, e = tables.position_mm[ax], tables.errors[ax]
        vals = np.column_stack([np.interp(q[:, i], x, e[:, j]) for j in range(6)])
        rho += vals[:, :3]
        eps += vals[:, 3:]
    rho[:, 0] += -sq.EC0Y * q[:, 1] + sq.EB0Z * q[:, 2]
    rho[:, 1] += -sq.EA0Z * q[:, 2]
    return q + r + rho + np.cross(eps, r)


def test_first_order_matches_formula_3_written_out():
    tables, sq = synthetic_tables(1)
    eng = ParametricEngine(tables, sq, interpolation="linear")
    q = RNG.uniform(0, 315, (300, 3))
    r = RNG.uniform(-50, 50, (300, 3))
    assert_allclose(eng.forward(q, r), reference_first_order(tables, sq, q, r), atol=1e-13)


def test_table_rows_are_reproduced_by_both_interpolations():
    tables, sq = synthetic_tables(3)
    for interp in ("pchip", "linear"):
        eng = ParametricEngine(tables, Squareness(), interpolation=interp)
        x = tables.position_mm["Y"]
        q = np.column_stack([np.zeros_like(x), x, np.zeros_like(x)])
        rho, eps = eng.errors_at(q)
        # X and Z tables are zero at 0, so only Y's rows show.
        assert_allclose(np.hstack([rho, eps]), tables.errors["Y"], atol=1e-15)


def test_signs_of_squareness_follow_formats_md():
    tables, _ = synthetic_tables(0)
    zero = AxisTables(tables.position_mm, {a: np.zeros_like(tables.errors[a]) for a in AXES})
    eng = ParametricEngine(zero, Squareness(EC0Y=1e-4, EB0Z=2e-4, EA0Z=3e-4))
    p = eng.forward([[0, 100, 200]])
    # +EB0Z leans Z towards +x, +EC0Y leans Y towards -x, +EA0Z leans Z towards -y.
    assert_allclose(p[0], [-1e-4 * 100 + 2e-4 * 200, 100 - 3e-4 * 200, 200], atol=1e-15)


def test_orders_differ_by_the_expected_powers_of_the_angles():
    tables, sq = synthetic_tables(0)
    q = RNG.uniform(0, 315, (200, 3))
    r = np.array([30.0, -20.0, -150.0])
    gaps = {}
    for k in (1.0, 100.0):
        eng = ParametricEngine(tables.scaled(angle_factor=k), sq)
        p1, p2, pe = (eng.forward_order(q, r, o) for o in ("first", "second", "exact"))
        gaps[k] = (np.abs(pe - p1).max(), np.abs(pe - p2).max())
    # first order misses |eps|^2 |r| / 2; formula (4) (Cayley) only |eps|^3 |r| / 12.
    assert gaps[100.0][0] / gaps[1.0][0] == pytest.approx(100**2, rel=0.05)
    assert gaps[100.0][1] / gaps[1.0][1] == pytest.approx(100**3, rel=0.1)
    assert gaps[1.0][1] < 1e-3 * gaps[1.0][0]


def test_control_points_land_within_a_micrometre_newton():
    eng = machine(0)
    target = CONTROL + TOOL  # the gauge point commanded at the control point, tool 100 mm down
    before = np.linalg.norm(eng.forward(target - TOOL, TOOL) - target, axis=1)
    assert before.min() > 0.08
    assert before.max() < 0.5
    for order in ("first", "second", "exact"):
        e = eng.with_options(order=order)
        res = e.inverse(target, TOOL)
        after = np.linalg.norm(e.forward(res.q, TOOL) - target, axis=1)
        assert after.max() < 1e-3 * 1e-3  # 1 nm: far inside 1 um
        assert_allclose(res.residual_mm, after, atol=1e-15)
        assert res.iterations.max() <= 4


def test_newton_round_trip_on_random_points_with_varied_tools():
    eng = machine(2, order="exact")
    q_true = RNG.uniform(0, 315, (2000, 3))
    r = RNG.uniform(-60, 60, (2000, 3))
    p = eng.forward(q_true, r)
    res = eng.inverse(p, r)
    assert res.residual_mm.max() <= SOLVER_TOL_MM
    assert_allclose(res.q, q_true, atol=1e-6)


def test_astatic_error_is_measured_at_seed_parameters():
    eng = machine(0, solver="astatic")
    assert (eng.astatic.grid_step_mm, eng.astatic.gain, eng.astatic.time_step) == (2.0, 1.5, 0.1)
    target = CONTROL + TOOL
    res = eng.inverse(target, TOOL)
    after = np.linalg.norm(eng.forward(res.q, TOOL) - target, axis=1)
    before = np.linalg.norm(eng.forward(target - TOOL, TOOL) - target, axis=1)
    assert_allclose(res.residual_mm, after)
    # It is an approximate method: errors of micrometres to tens of micrometres, well
    # below the uncorrected error but far above the converged solver.
    assert after.sum() < 0.25 * before.sum()
    assert after.max() > 100 * SOLVER_TOL_MM
    assert np.all(res.iterations > 1)


def test_astatic_error_shrinks_with_the_grid_step():
    # Seed 000, chapter 4: a finer partition of the workspace makes KMTPP more accurate.
    eng = machine(1, solver="astatic")
    p = RNG.uniform(0, 315, (300, 3)) + TOOL
    med = [np.median(eng.with_options(astatic={"grid_step_mm": u}).inverse(p, TOOL).residual_mm)
           for u in (1.0, 5.0)]
    assert med[0] < 0.5 * med[1]


def test_astatic_is_exact_on_an_affine_machine():
    tables, _ = synthetic_tables(0)
    zero = AxisTables(tables.position_mm, {a: np.zeros_like(tables.errors[a]) for a in AXES})
    eng = ParametricEngine(zero, Squareness(EC0Y=2e-4, EB0Z=-1e-4, EA0Z=3e-4), solver="astatic")
    p = RNG.uniform(10, 300, (100, 3)) + TOOL
    res = eng.inverse(p, TOOL)
    assert res.residual_mm.max() < 1e-9


def test_newton_failure_names_the_point():
    eng = machine(0)
    p = CONTROL + TOOL
    with pytest.raises(SolverError, match=r"point #\d+ \(target") as info:
        newton_inverse_located(eng, p, np.tile(TOOL, (len(p), 1)), max_iter=0)
    assert 0 <= info.value.point_index < len(p)


def test_outside_the_tables_clamp_and_linear_are_well_defined():
    tables, sq = synthetic_tables(0)
    clamp = ParametricEngine(tables, sq)
    linear = ParametricEngine(tables, sq, extrapolate="linear")
    edge = np.array([[315.0, 100, 100]])
    out = np.array([[325.0, 100, 100]])
    rho_e, eps_e = clamp.errors_at(edge)
    rho_o, eps_o = clamp.errors_at(out)
    assert_allclose(rho_o, rho_e, atol=1e-15)
    assert_allclose(eps_o, eps_e, atol=1e-18)
    drho, deps = linear.error_derivatives(edge - [1e-9, 0, 0])
    rho_l, eps_l = linear.errors_at(out)
    assert_allclose(rho_l, rho_e + 10 * drho[:, :, 0], atol=1e-12)
    assert_allclose(eps_l, eps_e + 10 * deps[:, :, 0], atol=1e-15)
    for eng in (clamp, linear):
        p = np.array([[330.0, -12.0, 340.0]]) + TOOL
        res = eng.inverse(p, TOOL)
        assert res.residual_mm.max() <= SOLVER_TOL_MM
        assert not eng.inside(res.q).any()


def test_second_order_bounds_reproduce_the_seed_finding():
    tables, sq = synthetic_tables(0)
    pts = np.array(SEED_ORDER_POINTS_MM, dtype=float)

    def relative_differences(k):
        eng = ParametricEngine(tables.scaled(angle_factor=k), sq)
        plus, minus, first = (np.linalg.norm(v, axis=1) for v in eng.second_order_bounds(pts, TOOL))
        return np.abs(plus - first) / first * 100, np.abs(minus - first) / first * 100

    real = relative_differences(1.0)
    scaled = relative_differences(1000.0)
    assert max(a.max() for a in real) < 1e-4  # percent: ~1e-5 %, as Table 3
    assert max(a.max() for a in real) > 1e-7  # ... but not zero: the terms are there
    assert max(a.max() for a in scaled) > 1.0  # percent: Table 4's "over 1 %"


def test_calibration_file_keeps_order_solver_and_settings(tmp_path):
    eng = machine(1, order="exact", solver="astatic", extrapolate="linear",
                  astatic={"grid_step_mm": 5.0, "gain": 1.0, "time_step": 0.2})
    path = tmp_path / "p.json"
    save_calibration(path, eng, name="p")
    back = load_calibration(path).engine
    assert (back.order, back.solver, back.extrapolate) == ("exact", "astatic", "linear")
    assert back.astatic == eng.astatic
    q = RNG.uniform(0, 315, (20, 3))
    assert_allclose(back.forward(q, TOOL), eng.forward(q, TOOL), atol=1e-13)


def test_bad_settings_are_refused():
    tables, sq = synthetic_tables(0)
    with pytest.raises(CalibrationError, match="order 'third'"):
        ParametricEngine(tables, sq, order="third")
    with pytest.raises(CalibrationError, match="K\\*l < 2"):
        ParametricEngine(tables, sq, astatic={"gain": 30.0, "time_step": 0.1})
    with pytest.raises(CalibrationError, match="beyond the table ranges"):
        ParametricEngine(tables, sq, [[0, 0, 0], [400, 315, 315]])


def test_newton_converges_with_linear_interpolation_too():
    eng = machine(4, interpolation="linear")
    p = RNG.uniform(0, 315, (3000, 3)) + TOOL
    res = eng.inverse(p, TOOL)
    assert res.residual_mm.max() <= SOLVER_TOL_MM
    assert res.iterations.max() <= 4


def test_singular_tables_raise_a_solver_error_not_a_crash():
    tables, sq = synthetic_tables(0)
    errors = dict(tables.errors)
    errors["X"] = np.zeros_like(errors["X"])
    errors["X"][:, 0] = -tables.position_mm["X"]  # EX of X cancels the X motion: dF/dX = 0
    eng = ParametricEngine(AxisTables(tables.position_mm, errors), sq, interpolation="linear")
    p = np.array([[100.0, 100.0, 100.0]]) + TOOL
    with pytest.raises(SolverError, match="singular at point #0"):
        eng.inverse(p, TOOL)
    with pytest.raises(SolverError, match="astatic iteration did not converge for point #0"):
        eng.inverse(p, TOOL, solver="astatic")
    # Nearly singular (the angular slopes keep dF/dX at ~1e-5): no convergence, reported.
    errors["X"][:, 3:] = tables.errors["X"][:, 3:]
    eng = ParametricEngine(AxisTables(tables.position_mm, errors), sq, interpolation="linear")
    with pytest.raises(SolverError, match="point #0"):
        eng.inverse(p, TOOL)


def test_astatic_iteration_count_follows_the_control_law():
    """On an error-free machine the law q_m <- q_m - dt K (q_m - q_d) shrinks the distance
    from the origin by (1 - K dt) per step; it stops once within u on every axis, then
    takes the final formula (2) step."""
    import math

    from postproc.calibration.axis_tables import AxisTables

    positions = {a: np.array([0.0, 315.0]) for a in "XYZ"}
    zeros = {a: np.zeros((2, 6)) for a in "XYZ"}
    eng = ParametricEngine(AxisTables(positions, zeros), Squareness(), [[0, 0, 0], [315, 315, 315]],
                           solver="astatic")
    u, K, dt = eng.astatic.grid_step_mm, eng.astatic.gain, eng.astatic.time_step
    p = np.array([[200.0, 100.0, 50.0], [20.0, 30.0, 300.0], [150.0, 250.0, 10.0]])
    res = eng.inverse(p, np.zeros((3, 3)))
    expect = [math.ceil(math.log(u / d) / math.log(1.0 - K * dt)) + 1 for d in p.max(axis=1)]
    assert res.iterations.tolist() == expect
    assert_allclose(res.q, p, atol=1e-9)


@pytest.mark.parametrize("n", [2, 3, 5, 40])
def test_numpy_pchip_is_scipys_interpolant(n):
    from scipy.interpolate import PchipInterpolator

    from postproc.engine.pchip import Pchip

    rng = np.random.default_rng(n)
    x = np.unique(rng.uniform(0.0, 300.0, n))
    y = rng.normal(size=(len(x), 6))
    y[:, 0] = np.cumsum(np.abs(y[:, 0]))  # monotone
    y[: min(3, len(x)), 2] = 0.0  # a flat stretch
    ref = PchipInterpolator(x, y, axis=0, extrapolate=True)
    t = np.linspace(x[0] - 20.0, x[-1] + 20.0, 1001)
    ours = Pchip(x, y)
    np.testing.assert_allclose(ours(t), ref(t), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ours.derivative(t), ref.derivative()(t), rtol=1e-12, atol=1e-12)
