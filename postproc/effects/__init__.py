"""Physical effects a geometric model may miss, one module per effect.

Names are ``kind:target`` exactly as ``postproc check`` prints them:

==========================  ==============================================  ==============
name                        physical meaning                                needs
==========================  ==============================================  ==============
``backlash:X|Y|Z``          reversal value b, b/2 along approach direction  ``dirx|diry|dirz``
``periodic:X|Y|Z``          lead-screw periodic error at a found pitch      positions
``thermal:t``               warm-up drift, first-order lag in time          ``t``
``thermal:temp...``         growth linear in temperature (about 20 °C)      ``temp...``
``expansion:temp...``       axes expanding with temperature (ppm/°C)         ``temp...``
``load:load``               zero-point migration per unit table load        ``load``
``loadpos:X|Y|Z``           deflection growing with load x axis position    ``load``
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

The catalogue is :mod:`postproc.effects.registry` (a new effect is one module plus one
line there); ``get_effect(name)`` builds one; ``compose(engine, effects_dicts)`` adds
them to a base engine (:mod:`postproc.effects.composed`). Effects whose displacement is
a shift proportional to a context value (thermal, load, linear) share
:class:`~postproc.effects.base.ContextLinear`.
"""

from postproc.effects.base import Effect
from postproc.effects.composed import ComposedEngine, check_config, compose
from postproc.effects.registry import (
           EFFECTS,
           KINDS,
           candidate_names,
           effect_class,
           effect_from_dict,
           get_effect,
)

__all__ = ["EFFECTS", "KINDS", "ComposedEngine", "Effect", "candidate_names", "check_config", "compose",
           "effect_class", "effect_from_dict", "get_effect"]
