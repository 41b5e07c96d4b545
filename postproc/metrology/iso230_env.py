"""What ISO 230-2 asks to be reported beside the figures: the temperatures of the test
and the normal-temperature correction (§4.2), and the expanded uncertainty of the
figures (ISO 230-2:2014 Annex A, ISO/TR 230-9: GUM, coverage factor k = 2).

**Temperature (§4.2).** The reference temperature is 20 °C. The runs file may carry
``temp`` (the air, any name starting ``temp``) and ``material_temp`` (the machine or
its scale). The air temperature belongs to the laser's wavelength compensation and is
already in the reading: it is reported, not applied. With ``material_temp``, the
nominal differential expansion is corrected to 20 °C as interferometer software does:
``x_20 = x - alpha (T_m - 20) P`` (a machine at T_m > 20 °C positions to its expanded
scale; at 20 °C that expansion is not there). Without it the report says that no
correction was made and that the figures hold at the unknown temperature of the test.

**Uncertainty budget** (standard uncertainties, lengths over the measured travel L):

- ``u_DEVICE = U_laser / 2 * L``: the interferometer's calibration, given as an
  expanded (k = 2) uncertainty per metre (``laser_u_um_per_m``);
- ``u_M,MACHINE = alpha * L * U_T / 2``: the machine temperature reading (expanded
  uncertainty ``temp_u_k`` of the thermometer) acting through the expansion
  correction, counted when ``material_temp`` is given (else the temperature is unknown
  and the term is ``alpha * L * TEMP_UNKNOWN_K / sqrt(3)``: a test within ±1 °C of 20);
- ``u_E = alpha_u / sqrt(3) * L * |T_m - 20|``: the expansion coefficient, known to
  ±``alpha_u`` (rectangular);
- ``u_A``: the scatter of the runs, ``s_i / sqrt(n)`` of the mean at the worst target
  (type A); E and M compare two means: ``sqrt(2) u_A``.

Then ``U(E) = U(M) = 2 sqrt(u_DEVICE^2 + u_M,MACHINE^2 + u_E^2 + 2 u_A^2)``; A adds the
uncertainty of 2s; B_i compares the two directions at one target, where device and
temperature cancel: ``U(B) = 2 sqrt(u_A,up^2 + u_A,down^2)``; R = 4s (or 2s+2s+|B|)
carries the uncertainty of an estimator s from n runs, ``s / sqrt(2 (n - 1))``. The
environmental variation error (E_VE, a drift test per ISO 230-3) and the misalignment
of the optics are not in the runs file: they are listed as not included.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Reference temperature of dimensional metrology (ISO 1).
REFERENCE_TEMP_C = 20.0
#: Half-width (K) of the temperature assumed when the runs give none: a test
#: within ±1 °C of 20 °C (ISO 230-2 asks for the test near 20 °C).
TEMP_UNKNOWN_K = 1.0
#: Coverage factor of every expanded uncertainty reported (ISO/TR 230-9, GUM).
K_COVERAGE = 2.0


@dataclass
class UncertaintyInputs:
    """The budget's inputs; every value is stated in the report."""

    alpha_um_per_m_k: float = 11.5  # expansion coefficient of the machine's scale (steel)
    alpha_u_um_per_m_k: float = 2.0  # half-width of its rectangular uncertainty
    laser_u_um_per_m: float = 1.0  # expanded (k = 2) uncertainty of the interferometer, per metre
    temp_u_k: float = 0.2  # expanded (k = 2) uncertainty of the machine temperature reading


def environment(sub) -> dict:
    """The temperature columns of one axis's runs: {name: (mean, min, max)} in °C."""
    return {name: (float(np.mean(v)), float(np.min(v)), float(np.max(v))) for name, v in sub.env.items()}


def material_temperature(sub) -> np.ndarray | None:
    return sub.env.get("material_temp")


def normal_temperature_correction(sub, alpha_um_per_m_k: float) -> np.ndarray:
    """The correction (mm) to add to each deviation: ``-alpha (T_m - 20) P``."""
    t = material_temperature(sub)
    if t is None:
        return np.zeros(len(sub))
    return -alpha_um_per_m_k * 1e-6 * (t - REFERENCE_TEMP_C) * sub.target_mm


def uncertainty(res, inputs: UncertaintyInputs, temp_c: float | None) -> dict:
    """Expanded uncertainties (k = 2, mm) of the axis figures of ``res`` (an AxisResult)."""
    travel_m = float(res.target_mm[-1] - res.target_mm[0]) / 1000.0
    alpha = inputs.alpha_um_per_m_k * 1e-6
    u_device = inputs.laser_u_um_per_m / K_COVERAGE * travel_m * 1e-3
    if temp_c is None:
        u_temp = alpha * travel_m * 1e3 * TEMP_UNKNOWN_K / math.sqrt(3)
        u_alpha = 0.0
    else:
        u_temp = alpha * travel_m * 1e3 * inputs.temp_u_k / K_COVERAGE
        u_alpha = inputs.alpha_u_um_per_m_k * 1e-6 / math.sqrt(3) * travel_m * 1e3 * abs(temp_c - REFERENCE_TEMP_C)
    dirs = res.directions
    s = {d: (res.s_up if d > 0 else res.s_down) for d in dirs}
    n = {d: (res.n_up if d > 0 else res.n_down) for d in dirs}
    u_a = {d: s[d] / np.sqrt(n[d]) for d in dirs}
    u_a_max = max(float(u_a[d].max()) for d in dirs)
    systematic = math.sqrt(u_device**2 + u_temp**2 + u_alpha**2 + 2 * u_a_max**2)
    u_s = {d: s[d] / np.sqrt(2 * np.maximum(n[d] - 1, 1)) for d in dirs}
    out = {"k": K_COVERAGE, "u_device_mm": u_device, "u_temperature_mm": u_temp, "u_expansion_mm": u_alpha,
           "u_scatter_mm": u_a_max}
    for d in dirs:
        tag = "up" if d > 0 else "down"
        out[f"E_{tag}"] = K_COVERAGE * systematic
        out[f"R_{tag}"] = K_COVERAGE * 4 * float(u_s[d].max())
        out[f"A_{tag}"] = K_COVERAGE * math.sqrt(systematic**2 + (2 * float(u_s[d].max()))**2)
    if len(dirs) == 2:
        i = int(np.argmax(np.abs(res.reversal)))
        u_b = math.sqrt(u_a[1][i] ** 2 + u_a[-1][i] ** 2)
        u_s_max = max(float(u_s[1].max()), float(u_s[-1].max()))
        out.update({"E": K_COVERAGE * systematic, "M": K_COVERAGE * systematic, "B": K_COVERAGE * u_b,
                    "R": K_COVERAGE * math.sqrt(2 * (2 * u_s_max) ** 2 + u_b**2),
                    "A": K_COVERAGE * math.sqrt(systematic**2 + (2 * u_s_max) ** 2)})
    return out


def report_lines(res, inputs: UncertaintyInputs, corrected: bool) -> list[str]:
    """The §4.2 temperature lines and the uncertainty lines of one axis (values in um)."""
    out = []
    env = res.environment
    if env:
        parts = [f"{name} {m:.2f} °C ({lo:.2f}..{hi:.2f})" for name, (m, lo, hi) in env.items()]
        out.append("temperature (ISO 230-2 §4.2): " + ", ".join(parts))
    else:
        out.append("temperature (ISO 230-2 §4.2): not in the runs file (no temp or material_temp column): "
                   "not reported, and no normal-temperature correction was made; the figures hold at the "
                   "unknown temperature of the test")
    if "material_temp" in env:
        t = env["material_temp"][0]
        corr = -inputs.alpha_um_per_m_k * (t - REFERENCE_TEMP_C) * float(res.target_mm[-1]) * 1e-3
        if corrected:
            out.append(f"normal-temperature correction applied: x - alpha (T_m - 20) P with alpha "
                       f"{inputs.alpha_um_per_m_k:g} um/(m K), T_m the material_temp of each reading "
                       f"({corr:+.2f} um at {res.target_mm[-1]:g} mm)")
        else:
            out.append(f"normal-temperature correction not applied (--no-temperature-correction): it would be "
                       f"{corr:+.2f} um at {res.target_mm[-1]:g} mm")
    elif env:
        out.append("normal-temperature correction not made: no material_temp column (the air temperature "
                   "is the laser's wavelength compensation, already in the readings)")
    u = {k: v * 1000 if k not in ("k",) else v for k, v in res.uncertainty.items()}
    figs = [k for k in ("A", "E", "M", "R", "B", "A_up", "E_up", "R_up", "A_down", "E_down", "R_down") if k in u]
    out.append(f"expanded uncertainty (ISO/TR 230-9, k = {u['k']:g}): "
               + ", ".join(f"U({k.replace('_up', '+').replace('_down', '-')}) {u[k]:.2f}" for k in figs))
    temp_note = ("temperature reading" if "material_temp" in env else
                 f"unknown temperature (±{TEMP_UNKNOWN_K:g} K)")
    out.append(f"  budget: u_device {u['u_device_mm']:.2f} (laser {inputs.laser_u_um_per_m:g} um/m, k=2), "
               f"u_temperature {u['u_temperature_mm']:.2f} ({temp_note}, alpha {inputs.alpha_um_per_m_k:g} "
               f"um/(m K)), u_expansion {u['u_expansion_mm']:.2f} (alpha ± {inputs.alpha_u_um_per_m_k:g}), "
               f"u_scatter {u['u_scatter_mm']:.2f} (s/sqrt(n)); not included: environmental variation "
               "error E_VE (drift test), misalignment of the optics")
    return out
