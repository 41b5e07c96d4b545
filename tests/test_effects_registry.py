"""The effects catalogue (postproc.effects.registry) and the context-linear effects."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import postproc.effects
from postproc.effects import EFFECTS, KINDS, candidate_names, effect_class, get_effect
from postproc.effects.base import ContextLinear, Effect
from postproc.errors import CalibrationError, MissingSetupError


def test_candidates_in_catalogue_order():
    names = candidate_names(["t", "temp", "temp2", "load", "humidity", "dirx"])
    assert names == [
        "backlash:X", "backlash:Y", "backlash:Z", "periodic:X", "periodic:Y", "periodic:Z",
        "thermal:t", "thermal:temp", "thermal:temp2", "expansion:temp", "expansion:temp2", "load:load",
        "loadpos:X", "loadpos:Y", "loadpos:Z", "abbe:tilt", "abbe:X", "abbe:Y", "abbe:Z", "squareness:XY", "squareness:XZ", "squareness:YZ",
        "scale:X", "scale:Y", "scale:Z", "straightness:X", "straightness:Y", "straightness:Z",
        "positioning:X", "positioning:Y", "positioning:Z",
        "lever:XY", "lever:XZ", "lever:YX", "lever:YZ", "lever:ZX", "lever:ZY", "linear:humidity",
    ]
    # without temperature columns the temperature effects are still named (untestable)
    assert "thermal:temp" in candidate_names([])
    assert "expansion:temp" in candidate_names([])


def test_every_name_resolves_to_its_class():
    for name in candidate_names(["temp_bed", "humidity"]) + ["empirical:poly3", "expansion:x", "load:weight"]:
        cls = effect_class(name)
        assert cls.kind == name.split(":")[0]
        assert get_effect(name).name == name
    assert effect_class("thermal:t").__name__ == "ThermalTime"
    assert effect_class("thermal:temp_bed").__name__ == "ThermalTemperature"


def test_unknown_names_say_what_would_do():
    with pytest.raises(CalibrationError, match="unknown effect") as info:
        get_effect("wobble:X")
    assert "kinds: " + ", ".join(KINDS) in info.value.hint
    with pytest.raises(CalibrationError, match="unknown effect") as info:
        get_effect("thermal:humidity")
    assert info.value.hint == "thermal effects are thermal:t (time) or thermal:temp... (a temperature column)"
    with pytest.raises(CalibrationError) as info:
        get_effect("lever:XX")
    assert info.value.hint == "lever targets: XY, XZ, YX, YZ, ZX, ZY"
    for bad in ("backlash", "backlash:", ":X"):
        with pytest.raises(CalibrationError, match="unknown effect"):
            get_effect(bad)


def test_every_kind_is_in_the_package_table():
    # the table in postproc/effects/__init__.py documents the catalogue: every kind is there
    doc = postproc.effects.__doc__
    for kind in KINDS:
        assert f"``{kind}:" in doc, kind
    assert len(EFFECTS) == len(set(EFFECTS))


RNG = np.random.default_rng(21)
N = 40
Q = RNG.uniform(0, 300, (N, 3))
CTX = {"t": RNG.uniform(0, 7200, N), "temp": RNG.uniform(18, 24, N), "load": RNG.uniform(0, 500, N),
       "humidity": RNG.uniform(30, 70, N)}

# name, config, params, the displacement written out by hand, describe(), compensable_reason
CONTEXT_LINEAR = [
    ("thermal:t", {"tau_s": 900.0}, (0.01, -0.02, 0.03),
     lambda c, q: (1 - np.exp(-c["t"] / 900.0))[:, None] * [0.01, -0.02, 0.03],
     "warm-up drift (growth when warm) X +10.00 um Y -20.00 um Z +30.00 um, time constant 15.0 min",
     "compensated at the warm-up time given as --context t=SECONDS"),
    ("thermal:temp", {"reference_C": 20.0}, (1e-3, 2e-3, -1e-3),
     lambda c, q: (c["temp"] - 20.0)[:, None] * [1e-3, 2e-3, -1e-3],
     "thermal growth per °C of temp X +1.00 um/°C Y +2.00 um/°C Z -1.00 um/°C",
     "compensated at the temperature given as --context temp=°C"),
    ("expansion:temp", {"reference_C": 20.0}, (1e-6, 2e-6, -1e-6),
     lambda c, q: (c["temp"] - 20.0)[:, None] * q * [1e-6, 2e-6, -1e-6],
     "thermal expansion per °C of temp X +1.00 ppm/°C Y +2.00 ppm/°C Z -1.00 ppm/°C",
     "compensated at the temperature given as --context temp=°C"),
    ("load:load", {}, (0.002, 0.001, -0.003),
     lambda c, q: c["load"][:, None] * [0.002, 0.001, -0.003],
     "deflection per unit of load X +2.000 um Y +1.000 um Z -3.000 um",
     "compensated at the load given as --context load=VALUE"),
    ("linear:humidity", {"reference": 50.0}, (0.002, 0.001, -0.003),
     lambda c, q: (c["humidity"] - 50.0)[:, None] * [0.002, 0.001, -0.003],
     "shift per unit of humidity X +2.000 um Y +1.000 um Z -3.000 um",
     "compensated at the value given as --context humidity=VALUE"),
]


@pytest.mark.parametrize(("name", "config", "values", "by_hand", "text", "reason"), CONTEXT_LINEAR)
def test_context_linear_effects(name, config, values, by_hand, text, reason):
    cls = effect_class(name)
    assert issubclass(cls, ContextLinear)
    e = get_effect(name, config=config, params=dict(zip(cls.param_names_xyz, values, strict=True)))
    assert e.needs == (name.split(":")[1],)
    assert_allclose(e.displacement(Q, None, CTX), by_hand(CTX, Q), rtol=1e-14, atol=1e-18)
    B = e.basis(Q, np.zeros_like(Q), CTX)
    off_diagonal = ~np.eye(3, dtype=bool)
    assert_array_equal(B[:, off_diagonal], 0.0)  # each parameter moves its own axis only
    assert e.describe() == text
    assert e.compensable_reason == reason
    # a scalar from --context broadcasts like a column
    one = {k: float(v[0]) for k, v in CTX.items()}
    assert_allclose(e.displacement(Q[:1], None, one), by_hand(CTX, Q)[:1], rtol=1e-14, atol=1e-18)
    with pytest.raises(MissingSetupError, match=f"--context {e.needs[0]}=|{e.needs[0]!r}"):
        e.displacement(Q, None, {})


def test_context_linear_classes_are_the_ones_shifting_by_a_context_value():
    linear = {cls.__name__ for cls in EFFECTS if issubclass(cls, ContextLinear)}
    assert linear == {"ThermalTime", "ThermalTemperature", "ThermalExpansion", "Load", "Linear"}
    assert all(issubclass(cls, Effect) for cls in EFFECTS)
