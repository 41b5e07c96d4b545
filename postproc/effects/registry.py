"""The catalogue of effects: which class serves each name ``kind:target``.

:data:`EFFECTS` lists every effect class, in the order ``check`` tries them; each class
says its ``kind`` and which targets it takes (:meth:`Effect.accepts`), and which names
are worth trying on given data (:meth:`Effect.candidates`). A new effect is one module
plus one line here; everything else (names, candidates, the ``unknown effect`` hint)
is read from this list.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from postproc.effects.abbe import Abbe
from postproc.effects.backlash import Backlash
from postproc.effects.base import Effect
from postproc.effects.empirical import Empirical
from postproc.effects.lever import Lever
from postproc.effects.linear import Linear
from postproc.effects.load import Load
from postproc.effects.loadpos import LoadPosition
from postproc.effects.periodic import Periodic
from postproc.effects.scale import Scale
from postproc.effects.squareness import Squareness
from postproc.effects.straightness import Positioning, Straightness
from postproc.effects.thermal import ThermalExpansion, ThermalTemperature, ThermalTime
from postproc.errors import CalibrationError

#: every effect class, in the order ``check`` tries their candidates
EFFECTS: tuple[type[Effect], ...] = (
    Backlash,
    Periodic,
    ThermalTime,
    ThermalTemperature,
    ThermalExpansion,
    Load,
    LoadPosition,
    Abbe,
    Squareness,
    Scale,
    Straightness,
    Positioning,
    Lever,
    Linear,
    Empirical,
)

#: the kinds, in catalogue order
KINDS: tuple[str, ...] = tuple(dict.fromkeys(cls.kind for cls in EFFECTS))


def _target_hint(kind: str, classes: list[type[Effect]]) -> str:
    if len(classes) > 1:
        return f"{kind} effects are " + " or ".join(f"{kind}:{c.target_meaning}" for c in classes)
    return f"{kind} targets: {', '.join(classes[0].targets or ())}"


def effect_class(name: str) -> type[Effect]:
    """The class of the effect named ``kind:target`` (e.g. ``backlash:X``)."""
    kind, sep, target = str(name).partition(":")
    classes = [cls for cls in EFFECTS if cls.kind == kind]
    if not sep or not classes or not target:
        raise CalibrationError(
            f"unknown effect {name!r}",
            hint="effects are named kind:target, e.g. backlash:X, periodic:Y, thermal:t, "
                 f"load:load, linear:humidity; kinds: {', '.join(KINDS)}",
        )
    for cls in classes:
        if cls.accepts(target):
            return cls
    raise CalibrationError(f"unknown effect {name!r}", hint=_target_hint(kind, classes))


def get_effect(name: str, config: Mapping | None = None, params: Mapping | None = None) -> Effect:
    """The effect named ``kind:target`` (e.g. ``backlash:X``), with zero parameters unless given."""
    return effect_class(name)(str(name).partition(":")[2], config=config, params=params)


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
    return [name for cls in EFFECTS for name in cls.candidates(cols)]
