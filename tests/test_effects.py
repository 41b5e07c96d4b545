import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.calfile import load_calibration, save_calibration
from postproc.effects import candidate_names, compose, effect_from_dict, get_effect
from postproc.effects.composed import ComposedEngine
from postproc.engine.static import StaticEngine
from postproc.errors import CalibrationError, MissingSetupError

RNG = np.random.default_rng(11)
VOLUME = [[0, 0, 0], [300, 300, 300]]


def base_engine():
    G = np.eye(3) + np.array([[80e-6, -50e-6, 30e-6], [0, 60e-6, -40e-6], [0, 0, -20e-6]])
    return StaticEngine(G, [0.02, -0.01, 0.005], VOLUME)


ALL_EFFECTS = [
    get_effect("backlash:X", params={"b_mm": 0.012}),
    get_effect("periodic:Y", config={"pitch_mm": 10.0}, params={"cos_mm": 0.003, "sin_mm": -0.002}),
    get_effect("thermal:t", config={"tau_s": 1800.0}, params={"dx_mm": 0.004, "dz_mm": 0.01}),
    get_effect("thermal:temp", params={"kz_mm_per_C": 0.003}),
    get_effect("load:load", params={"cz_mm_per_unit": -2e-5}),
    get_effect("expansion:temp", params={"ax_per_C": 11.5e-6, "az_per_C": 5e-6}),
    get_effect("abbe:tilt", params={"wx_rad": 2e-5, "wy_rad": -1e-5}),
    get_effect("abbe:Y", params={"wx_rad_per_mm": 5e-8}),
    get_effect("squareness:XY", params={"EC0Y_rad": 3e-5}),
    get_effect("scale:Z", params={"scale": 2e-5}),
    get_effect("straightness:X", config={"center_mm": 150, "half_travel_mm": 150},
               params={"bow_y_mm": 0.004, "s_z_mm": -0.003}),
    get_effect("lever:XZ", params={"EAX_rad_per_mm": 1e-7, "EBX_rad_per_mm": -5e-8}),
    get_effect("linear:humidity", config={"reference": 50}, params={"ax_mm_per_unit": 1e-4}),
]


def full_context(n):
    return {
        "dirx": RNG.choice([-1.0, 1.0], n), "t": RNG.uniform(0, 7200, n),
        "temp": RNG.uniform(19, 23, n), "load": RNG.uniform(0, 500, n), "humidity": RNG.uniform(30, 70, n),
    }


def test_displacement_is_basis_times_params():
    q = RNG.uniform(0, 300, (50, 3))
    r = RNG.uniform(-100, 100, (50, 3))
    ctx = full_context(50)
    for e in ALL_EFFECTS:
        B = e.basis(q, r, ctx)
        assert B.shape == (50, 3, len(e.param_names)), e.name
        assert_allclose(e.displacement(q, r, ctx), B @ e.param_vector(), err_msg=e.name)
        assert np.abs(e.displacement(q, r, ctx)).max() > 0, e.name


def test_backlash_is_half_reversal_along_its_axis():
    e = get_effect("backlash:Y", params={"b_mm": 0.01})
    q = np.zeros((2, 3))
    d = e.displacement(q, None, {"diry": np.array([1.0, -1.0])})
    assert_allclose(d, [[0, 0.005, 0], [0, -0.005, 0]])
    assert e.needs == ("diry",)


def test_dict_round_trip_and_unknown_names():
    for e in ALL_EFFECTS:
        back = effect_from_dict(e.to_dict())
        assert back.name == e.name
        assert back.config == e.config
        assert back.params == e.params
    with pytest.raises(CalibrationError, match="unknown effect"):
        get_effect("wobble:X")
    with pytest.raises(CalibrationError, match="unknown effect"):
        get_effect("backlash:W")
    with pytest.raises(CalibrationError, match="unknown parameter"):
        get_effect("backlash:X", params={"gap": 1})


def test_compose_inverse_round_trip_with_backlash_context():
    eng = compose(base_engine(), [e.to_dict() for e in ALL_EFFECTS])
    n = 500
    p = RNG.uniform(0, 300, (n, 3))
    r = np.array([0, 0, -120.0])
    ctx = full_context(n)
    res = eng.inverse(p, r, ctx)
    assert res.residual_mm.max() < 1e-6
    assert_allclose(eng.forward(res.q, r, ctx), p, atol=1e-6)
    # scalars from --context broadcast like per-point arrays
    ctx_scalar = dict(ctx, t=3600.0, temp=21.0, load=100.0, humidity=55.0)
    res2 = eng.inverse(p, r, ctx_scalar)
    assert_allclose(eng.forward(res2.q, r, ctx_scalar), p, atol=1e-6)
    # the correction differs between approach directions by the backlash
    one = np.array([[100.0, 100, 100]] * 2)
    res3 = eng.inverse(one, r, dict(ctx_scalar, dirx=np.array([1.0, -1.0])))
    assert res3.q[1, 0] - res3.q[0, 0] == pytest.approx(0.012 * eng.base.G_inv[0, 0], abs=1e-6)


def test_compose_refuses_thermal_without_context():
    eng = compose(base_engine(), [ALL_EFFECTS[2].to_dict()])
    p = RNG.uniform(0, 300, (5, 3))
    with pytest.raises(MissingSetupError, match="thermal:t") as exc:
        eng.inverse(p, None, {"dirx": np.ones(5)})
    assert "--context t=" in str(exc.value)
    with pytest.raises(MissingSetupError, match="--context t="):
        eng.check_context({"dirx"})
    eng.check_context({"t"})


def test_calibration_file_carries_effects(tmp_path):
    eng = base_engine()
    effs = [ALL_EFFECTS[0].to_dict(), ALL_EFFECTS[1].to_dict()]
    path = tmp_path / "cal.json"
    save_calibration(path, eng, effects=effs)
    cal = load_calibration(path)
    assert isinstance(cal.engine, ComposedEngine)
    assert cal.method == "static"
    q = RNG.uniform(0, 300, (20, 3))
    ctx = {"dirx": RNG.choice([-1.0, 1.0], 20)}
    expected = eng.forward(q) + ALL_EFFECTS[0].displacement(q, None, ctx) + ALL_EFFECTS[1].displacement(q)
    assert_allclose(cal.engine.forward(q, None, ctx), expected, atol=1e-12)
    # a composed engine saves as its base model plus its effects
    path2 = tmp_path / "again.json"
    save_calibration(path2, cal.engine, effects=cal.engine.effects_dicts())
    assert_allclose(load_calibration(path2).engine.forward(q, None, ctx), expected, atol=1e-12)


def test_candidates_cover_context_columns():
    names = candidate_names(["t", "temp_spindle", "load", "dirx", "humidity"])
    assert "thermal:temp_spindle" in names
    assert "linear:humidity" in names
    assert "linear:t" not in names
    assert "linear:dirx" not in names
    for n in names:
        assert get_effect(n).name == n


def test_untestable_reasons_name_what_is_missing():
    q = RNG.uniform(0, 300, (40, 3))
    r = np.zeros((40, 3))
    bl = get_effect("backlash:X")
    assert "no dirx column" in bl.untestable_reason(q, r, {})
    assert "does not vary" in bl.untestable_reason(q, r, {"dirx": np.ones(40)})
    one_sided = np.ones(40)
    one_sided[:2] = -1
    assert "2 from -" in bl.untestable_reason(q, r, {"dirx": one_sided})
    assert bl.untestable_reason(q, r, {"dirx": np.where(np.arange(40) % 2, 1.0, -1.0)}) is None
    assert "tool vectors vary by only" in get_effect("abbe:tilt").untestable_reason(q, r, {})
    assert "distinct Y positions" in get_effect("periodic:Y").untestable_reason(
        np.repeat(q[:5], 8, axis=0), r, {})


def test_too_little_variation_is_untestable():
    q = RNG.uniform(0, 300, (30, 3))
    load = np.zeros(30)
    load[:2] = 500.0
    why = get_effect("load:load").untestable_reason(q, None, {"load": load})
    assert "varies in only 2 row(s)" in why
    load[:5] = 500.0
    assert get_effect("load:load").untestable_reason(q, None, {"load": load}) is None


def test_periodic_is_a_wave_of_its_pitch_along_its_axis():
    """Against the formula, not against data made by the effect itself."""
    e = get_effect("periodic:Y", config={"pitch_mm": 10.0}, params={"cos_mm": 0.003, "sin_mm": -0.002})
    q = RNG.uniform(0, 300, (40, 3))
    y = q[:, 1]
    expect = np.zeros((40, 3))
    expect[:, 1] = 0.003 * np.cos(2 * np.pi * y / 10.0) - 0.002 * np.sin(2 * np.pi * y / 10.0)
    assert_allclose(e.displacement(q, None, {}), expect, atol=1e-15)


def test_periodic_pitch_and_amplitude_from_an_independent_lead_screw_wave():
    q = RNG.uniform(0, 300, (400, 3))
    resid = np.zeros((400, 3))
    resid[:, 0] = 0.0025 * np.sin(2 * np.pi * q[:, 0] / 10.0 + 0.4) + RNG.normal(0, 2e-4, 400)
    e = get_effect("periodic:X").prepare(q, None, {}, resid)
    assert e.config["pitch_mm"] == pytest.approx(10.0, rel=2e-3)
    B = e.basis(q, None, {})[:, 0, :]
    coef, *_ = np.linalg.lstsq(B, resid[:, 0], rcond=None)
    assert np.hypot(*coef) == pytest.approx(0.0025, rel=0.05)


def test_geometric_effects_follow_their_documented_formulas():
    """Each against the formula in docs/diagnostics.md, written out independently."""
    q = RNG.uniform(0, 300, (30, 3))
    r = RNG.uniform(-100, 100, (30, 3))
    x, y, z = q.T
    w = np.array([2e-5, -1e-5, 3e-5])

    scale = get_effect("scale:X", params={"scale": 2e-5}).displacement(q, r, {})
    assert_allclose(scale, np.column_stack([2e-5 * x, 0 * x, 0 * x]), atol=1e-15)

    tilt = get_effect("abbe:tilt", params={"wx_rad": w[0], "wy_rad": w[1], "wz_rad": w[2]})
    assert_allclose(tilt.displacement(q, r, {}), np.cross(w, r), atol=1e-15)
    abbe_y = get_effect("abbe:Y", params={"wx_rad_per_mm": w[0], "wy_rad_per_mm": w[1], "wz_rad_per_mm": w[2]})
    assert_allclose(abbe_y.displacement(q, r, {}), np.cross(y[:, None] * w, r), atol=1e-15)

    lever = get_effect("lever:XZ", params={"EAX_rad_per_mm": 1e-7, "EBX_rad_per_mm": -5e-8})
    omega = x[:, None] * np.array([1e-7, -5e-8, 0.0])
    assert_allclose(lever.displacement(q, r, {}), np.cross(omega, z[:, None] * [0.0, 0.0, 1.0]), atol=1e-15)

    st = get_effect("straightness:X", config={"center_mm": 150.0, "half_travel_mm": 150.0},
                    params={"bow_y_mm": 0.004, "s_y_mm": -0.002, "bow_z_mm": 0.001, "s_z_mm": 0.003})
    u = (x - 150.0) / 150.0
    expect = np.column_stack([0 * x, 0.004 * u**2 - 0.002 * u**3, 0.001 * u**2 + 0.003 * u**3])
    assert_allclose(st.displacement(q, r, {}), expect, atol=1e-15)


def test_squareness_effects_use_the_parametric_model_signs():
    """squareness:XY/XZ/YZ add what the 21-parameter model's EC0Y/EB0Z/EA0Z add."""
    from postproc.calibration.axis_tables import AxisTables, Squareness
    from postproc.engine.parametric import ParametricEngine

    positions = {a: np.array([0.0, 300.0]) for a in "XYZ"}
    zeros = {a: np.zeros((2, 6)) for a in "XYZ"}
    sq = Squareness(EC0Y=3e-5, EB0Z=-2e-5, EA0Z=4e-5)
    q = RNG.uniform(0, 300, (20, 3))
    flat = ParametricEngine(AxisTables(positions, zeros), Squareness(), VOLUME)
    square = ParametricEngine(AxisTables(positions, zeros), sq, VOLUME)
    expect = square.forward(q) - flat.forward(q)
    got = sum(get_effect(f"squareness:{pair}", params={name: getattr(sq, name[:4])}).displacement(q, None, {})
              for pair, name in (("XY", "EC0Y_rad"), ("XZ", "EB0Z_rad"), ("YZ", "EA0Z_rad")))
    assert_allclose(got, expect, atol=1e-12)


def test_context_and_positioning_effects_follow_their_documented_formulas():
    q = RNG.uniform(0, 300, (30, 3))
    x, y, z = q.T
    temp, load, hum = RNG.uniform(18, 24, 30), RNG.uniform(0, 500, 30), RNG.uniform(30, 70, 30)
    ones = np.ones((30, 3))

    d = get_effect("thermal:temp", params={"kx_mm_per_C": 0.002, "ky_mm_per_C": -0.001, "kz_mm_per_C": 0.003})
    assert_allclose(d.displacement(q, None, {"temp": temp}),
                    (temp - 20.0)[:, None] * np.array([0.002, -0.001, 0.003]) * ones, atol=1e-15)

    d = get_effect("expansion:temp", params={"ax_per_C": 11.5e-6, "ay_per_C": 0.0, "az_per_C": 5e-6})
    assert_allclose(d.displacement(q, None, {"temp": temp}),
                    (temp - 20.0)[:, None] * np.column_stack([11.5e-6 * x, 0 * y, 5e-6 * z]), atol=1e-15)

    d = get_effect("load:load", params={"cz_mm_per_unit": -2e-5})
    assert_allclose(d.displacement(q, None, {"load": load}), np.column_stack([0 * x, 0 * x, -2e-5 * load]),
                    atol=1e-15)

    d = get_effect("linear:humidity", config={"reference": 50.0}, params={"ax_mm_per_unit": 1e-4})
    assert_allclose(d.displacement(q, None, {"humidity": hum}),
                    np.column_stack([1e-4 * (hum - 50.0), 0 * x, 0 * x]), atol=1e-15)

    d = get_effect("positioning:Y", config={"center_mm": 150.0, "half_travel_mm": 150.0},
                   params={"bow_mm": 0.004, "s_mm": -0.002})
    u = (y - 150.0) / 150.0
    assert_allclose(d.displacement(q, None, {}), np.column_stack([0 * x, 0.004 * u**2 - 0.002 * u**3, 0 * x]),
                    atol=1e-15)
