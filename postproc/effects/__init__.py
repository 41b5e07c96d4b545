"""Physical effects a geometric model may miss, one module per effect.

Names are ``kind:target`` exactly as ``postproc check`` prints them:

==========================  ==============================================  ==============
name                        physical meaning                                needs
==========================  ==============================================  ==============
``backlash:X|Y|Z``          reversal error, b/2 against approach direction  ``dirx|diry|dirz``
``periodic:X|Y|Z``          lead-screw periodic error at a found pitch      positions
``thermal:t``               warm-up drift, first-order lag in time          ``t``
``thermal:temp...``         growth linear in temperature (about 20 °C)      ``temp...``
``expansion:temp...``       axes expanding with temperature (ppm/°C)         ``temp...``
``load:load``               zero-point migration per unit table load        ``load``
``abbe:tilt|X|Y|Z``         angular error acting through the tool vector    varied ``r``
``squareness:XY|XZ|YZ``     out-of-squareness (if the model lacks it)       positions
``scale:X|Y|Z``             linear positioning error (if lacking)           positions
``straightness:X|Y|Z``      bow and S-shape of an axis's straightness       positions
``positioning:X|Y|Z``       bow and S-shape of the positioning error        positions
``lever:AB``                angle of A growing with A, over B's travel      positions
``linear:<column>``         shift linear in any other context column        ``<column>``
``empirical:poly2|3|4``     smooth residual field, no physics (last resort)  positions
==========================  ==============================================  ==============

``empirical`` is never a candidate: ``check`` offers it only when no effect explains
the residual.

``get_effect(name)`` builds one; ``compose(engine, effects_dicts)`` adds them to a
base engine (:mod:`postproc.effects.composed`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from postproc.effects.abbe import Abbe
from postproc.effects.backlash import Backlash
from postproc.effects.base import AXES, DIR_COLUMNS, Effect
from postproc.effects.empirical import DEGREES as EMPIRICAL_DEGREES
from postproc.effects.empirical import Empirical
from postproc.effects.lever import Lever
from postproc.effects.linear import Linear
from postproc.effects.load import Load
from postproc.effects.periodic import Periodic
from postproc.effects.scale import Scale
from postproc.effects.squareness import PAIRS, Squareness
from postproc.effects.straightness import Positioning, Straightness
from postproc.effects.thermal import ThermalExpansion, ThermalTemperature, ThermalTime
from postproc.errors import CalibrationError

__all__ = ["Effect", "get_effect", "effect_from_dict", "check_config", "compose", "candidate_names", "KINDS"]

LEVER_PAIRS = tuple(a + b for a in AXES for b in AXES if a != b)

#: kind -> (class or chooser, valid targets or None for "a context column")
KINDS = {
    "backlash": (Backlash, tuple(AXES)),
    "periodic": (Periodic, tuple(AXES)),
    "thermal": (None, None),
    "expansion": (ThermalExpansion, None),
    "load": (Load, None),
    "abbe": (Abbe, ("tilt", *AXES)),
    "squareness": (Squareness, tuple(PAIRS)),
    "scale": (Scale, tuple(AXES)),
    "straightness": (Straightness, tuple(AXES)),
    "positioning": (Positioning, tuple(AXES)),
    "lever": (Lever, LEVER_PAIRS),
    "linear": (Linear, None),
    "empirical": (Empirical, tuple(EMPIRICAL_DEGREES)),
}

# Context columns with an effect of their own, never offered as linear:<column>.
_OWN_COLUMNS = {"t", "load", *DIR_COLUMNS}


def get_effect(name: str, config: Mapping | None = None, params: Mapping | None = None) -> Effect:
    """The effect named ``kind:target`` (e.g. ``backlash:X``), with zero parameters unless given."""
    kind, sep, target = str(name).partition(":")
    if not sep or kind not in KINDS or not target:
        raise CalibrationError(
            f"unknown effect {name!r}",
            hint="effects are named kind:target, e.g. backlash:X, periodic:Y, thermal:t, "
                 f"load:load, linear:humidity; kinds: {', '.join(KINDS)}",
        )
    cls, targets = KINDS[kind]
    if kind == "thermal":
        if target == "t":
            cls = ThermalTime
        elif target.startswith("temp"):
            cls = ThermalTemperature
        else:
            raise CalibrationError(f"unknown effect {name!r}",
                                   hint="thermal effects are thermal:t (time) or thermal:temp... (a temperature column)")
    elif targets is not None and target not in targets:
        raise CalibrationError(f"unknown effect {name!r}", hint=f"{kind} targets: {', '.join(targets)}")
    return cls(target, config=config, params=params)


def effect_from_dict(data) -> Effect:
    if not isinstance(data, Mapping) or "name" not in data:
        raise CalibrationError(f"an effect must be an object with a \"name\", got {data!r}")
    for key in ("config", "params"):
        if data.get(key) is not None and not isinstance(data[key], Mapping):
            raise CalibrationError(f"effect {data['name']}: {key!r} must be an object")
    return get_effect(data["name"], config=data.get("config"), params=data.get("params"))


def candidate_names(context_columns: Iterable[str]) -> list[str]:
    """Every effect name worth trying on data with these context columns.

    Effects whose column is absent are included too: ``check`` reports them untestable.
    """
    cols = list(context_columns)
    names = [f"backlash:{a}" for a in AXES]
    names += [f"periodic:{a}" for a in AXES]
    names += ["thermal:t"]
    temps = [c for c in cols if c.startswith("temp")]
    names += [f"thermal:{c}" for c in temps] or ["thermal:temp"]
    names += [f"expansion:{c}" for c in temps] or ["expansion:temp"]
    names += ["load:load"]
    names += ["abbe:tilt"] + [f"abbe:{a}" for a in AXES]
    names += [f"squareness:{p}" for p in PAIRS]
    names += [f"scale:{a}" for a in AXES]
    names += [f"straightness:{a}" for a in AXES]
    names += [f"positioning:{a}" for a in AXES]
    names += [f"lever:{p}" for p in LEVER_PAIRS]
    names += [f"linear:{c}" for c in cols if c not in _OWN_COLUMNS and not c.startswith("temp")]
    return names


#: Value of every context column the effect needs when its config is checked (a valid
#: approach direction, time, temperature and load alike): only the config is under test.
CHECK_CONTEXT_VALUE = 1.0

_CONFIG_HINT = ("an effect's config holds the settings its fit found (pitch_mm, tau_s, center_mm, "
                "half_travel_mm, reference...); refit with 'postproc fit --effect NAME' or correct the file")


def check_config(effect: Effect, volume_mm=None) -> None:
    """Evaluate ``effect`` once, at the corners and centre of ``volume_mm``, so that a
    config it cannot work with (a ``periodic`` without ``pitch_mm``, ``tau_s <= 0`` ...)
    is refused when a calibration or machine is loaded, not when it is first used.

    Raises CalibrationError naming the effect (the caller adds the file).
    """
    vol = np.asarray(volume_mm if volume_mm is not None else np.zeros((2, 3)), dtype=float)
    if vol.shape != (2, 3) or not np.all(np.isfinite(vol)):
        vol = np.zeros((2, 3))
    q = np.vstack([vol, vol.mean(axis=0)])
    ctx = {c: np.full(len(q), CHECK_CONTEXT_VALUE) for c in effect.needs}
    try:
        B = np.asarray(effect.basis(q, np.zeros_like(q), ctx), dtype=float)
    except CalibrationError as exc:
        name = effect.name
        msg = exc.message if name in exc.message else f"effect {name}: {exc.message}"
        raise CalibrationError(msg, hint=exc.hint or _CONFIG_HINT) from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as exc:
        raise CalibrationError(f"effect {effect.name}: config {effect.config} cannot be used "
                               f"({type(exc).__name__}: {exc})", hint=_CONFIG_HINT) from None
    if B.shape != (len(q), 3, len(effect.param_names)) or not np.all(np.isfinite(B)):
        raise CalibrationError(f"effect {effect.name}: config {effect.config} does not give a finite "
                               "displacement in the calibrated volume", hint=_CONFIG_HINT)


def compose(engine, effects_dicts):
    """Wrap ``engine`` so that forward adds the effects' displacements (see composed.py).

    Each effect is built and its config checked (:func:`check_config`) here, so a wrong
    one is reported on loading.
    """
    from postproc.effects.composed import ComposedEngine

    effects = [e if isinstance(e, Effect) else effect_from_dict(e) for e in (effects_dicts or [])]
    if not effects:
        return engine
    for e in effects:
        check_config(e, getattr(engine, "volume_mm", None))
    return ComposedEngine(engine, effects)
