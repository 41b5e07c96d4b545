"""Thermal drift: the machine grows as it warms up, or with its temperature.

``thermal:t`` (needs ``t``, seconds since the start of the warm-up): a first-order
lag towards a steady state. Each axis's zero point migrates by ``d`` (``dx_mm``,
``dy_mm``, ``dz_mm``, the growth once warm) with time constant ``tau_s``::

    displacement = (dx, dy, dz) * (1 - exp(-t / tau))

``tau`` is a non-linear setting found by a 1-D search (log-spaced, least squares on
the residual); with ``tau`` much longer than the campaign the drift is linear in t.

``thermal:temp`` (or any column named ``temp...``, needs it): linear in temperature
about the ISO 1 reference temperature of 20 °C::

    displacement = (kx, ky, kz) * (T - 20)          k in mm per °C

Compensable in a program only at a known state: ``--context t=SECONDS`` (time since
the warm-up started when the program runs) or ``--context temp=°C``.
"""

from __future__ import annotations

import numpy as np

from postproc.effects.base import ContextLinear, lstsq_with_offset
from postproc.errors import CalibrationError

# Time constants searched, as fractions of the time span of the data: from a lag that
# is over after the first few percent of the campaign (it looks like a step) to one
# several times longer than the campaign (it looks linear).
TAU_MIN_SPAN_FRACTION = 0.02
TAU_MAX_SPAN_FRACTION = 5.0
# Number of log-spaced time constants tried: adjacent ones differ by ~12 %, finer
# than the time constant is ever determined by noisy data.
TAU_GRID_POINTS = 48

# ISO 1: the standard reference temperature for geometrical measurements.
REFERENCE_TEMPERATURE_C = 20.0


class ThermalTime(ContextLinear):
    kind = "thermal"
    meaning = "warm-up drift: zero points migrate along a first-order lag in time"
    targets = ("t",)
    target_meaning = "t (time)"
    param_names_xyz = ("dx_mm", "dy_mm", "dz_mm")
    given_as = ("the warm-up time", "SECONDS")

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        tau = self.config.get("tau_s", float("nan"))
        return ("warm-up drift (growth when warm) "
                + " ".join(f"{a} {p[k] * 1000:+.2f} um" for a, k in zip("XYZ", self.param_names, strict=True))
                + f", time constant {tau / 60:.1f} min")

    def value(self, v: np.ndarray, q: np.ndarray) -> np.ndarray:
        tau = float(self.config.get("tau_s", 0.0))
        if tau <= 0:
            raise CalibrationError(f"effect {self.name} has no tau_s > 0 in its config")
        return 1.0 - np.exp(-np.clip(v, 0.0, None) / tau)

    def prepare(self, q, r, ctx, resid) -> ThermalTime:
        t = np.asarray(ctx["t"], dtype=float)
        span = max(float(np.max(t)), float(np.ptp(t)))
        taus = np.geomspace(TAU_MIN_SPAN_FRACTION * span, TAU_MAX_SPAN_FRACTION * span, TAU_GRID_POINTS)
        best, best_sse = taus[0], np.inf
        for tau in taus:
            B = self.copy(config={"tau_s": float(tau)}).basis(q, r, ctx)
            _, sse = lstsq_with_offset(B, resid)
            if sse < best_sse:
                best, best_sse = tau, sse
        return self.copy(config={"tau_s": float(best)})


class ThermalTemperature(ContextLinear):
    kind = "thermal"
    meaning = "thermal growth linear in temperature (about 20 °C)"
    target_prefix = "temp"
    target_meaning = "temp... (a temperature column)"
    param_names_xyz = ("kx_mm_per_C", "ky_mm_per_C", "kz_mm_per_C")
    reference_key, reference_default = "reference_C", REFERENCE_TEMPERATURE_C
    given_as = ("the temperature", "°C")
    describe_head, describe_unit, describe_format = "thermal growth per °C of", "um/°C", "+.2f"


class ThermalExpansion(ContextLinear):
    """Thermal expansion of the axes with temperature (``expansion:temp``): each axis's
    positioning error grows with its position from the axis zero and with the
    temperature's departure from 20 °C (ISO 230-3's nominal differential expansion
    of scale and part)::

        displacement_j = a_j * (T - 20) * q_j          a in mm/mm per °C (reported in ppm/°C)

    Needs the temperature column; compensable at ``--context temp=°C``.
    """

    kind = "expansion"
    meaning = "thermal expansion of the axes: positioning error growing with position and temperature"
    param_names_xyz = ("ax_per_C", "ay_per_C", "az_per_C")
    reference_key, reference_default = "reference_C", REFERENCE_TEMPERATURE_C
    given_as = ("the temperature", "°C")
    describe_head, describe_unit, describe_format = "thermal expansion per °C of", "ppm/°C", "+.2f"
    describe_scale = 1e6

    @classmethod
    def candidates(cls, columns: list[str]) -> list[str]:
        return [f"expansion:{c}" for c in columns if c.startswith("temp")] or ["expansion:temp"]

    def value(self, v: np.ndarray, q: np.ndarray) -> np.ndarray:
        return (v - self.reference)[:, None] * q
