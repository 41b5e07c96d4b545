"""Synthetic measurements with hidden effects: a base engine + effects + Gaussian noise.

Used by the diagnostics tests and benchmarks to show that `check` finds what was hidden.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.measurements import Measurements
from postproc.diagnose.data import Dataset
from postproc.diagnose.models import static_design
from postproc.effects import get_effect
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine

SIGMA_MM = 0.002
VOLUME = [[0.0, 0.0, 0.0], [300.0, 300.0, 300.0]]
TOOLS = np.array([[0, 0, -60.0], [0, 0, -180.0], [50, 0, -110.0], [0, -50, -110.0]])


def static_machine(seed: int = 5) -> StaticEngine:
    rng = np.random.default_rng(seed)
    return StaticEngine(np.eye(3) + 1.5e-4 * rng.standard_normal((3, 3)), [0.01, -0.02, 0.005], VOLUME)


def identity_machine() -> IdentityEngine:
    return IdentityEngine(VOLUME)


def sample_points(rng, n_points: int, shots: int):
    q = rng.uniform(0, 300, (n_points, 3))
    r = TOOLS[rng.integers(0, len(TOOLS), n_points)]
    d = rng.choice([-1.0, 1.0], (n_points, 3))
    ctx = {"t": np.sort(rng.uniform(0, 4 * 3600, n_points)), "temp": rng.uniform(18.5, 23.5, n_points),
           "load": rng.uniform(0, 800, n_points), "humidity": rng.uniform(30, 70, n_points)}
    idx = np.repeat(np.arange(n_points), shots)
    ctx = {k: v[idx] for k, v in ctx.items()}
    ctx.update(dirx=d[idx, 0], diry=d[idx, 1], dirz=d[idx, 2])
    return q[idx], r[idx], ctx


def visible_rms(effect, q, r, ctx, base: str) -> float:
    """RMS of the part of the displacement the base model cannot absorb."""
    d = effect.displacement(q, r, ctx)
    if base == "static":
        A = static_design(Dataset(q=q, m=q, r=r))
        y = d.reshape(-1)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        d = (y - A @ coef).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def hidden(spec: dict, q, r, ctx, size_sigmas: float, base: str):
    """The effect ``spec`` (name, config, param direction) scaled so its visible RMS is
    ``size_sigmas`` times the noise sigma."""
    e = get_effect(spec["name"], config=spec.get("config"), params=spec["params"])
    k = size_sigmas * SIGMA_MM / visible_rms(e, q, r, ctx, base)
    return e.copy(params={n: v * k for n, v in e.params.items()})


def make_data(specs: list[tuple[dict, float]], *, base: str = "static", seed: int = 1, n_points: int = 70,
              shots: int = 3, path: str = "synthetic.csv"):
    """Measurements of ``base`` plus the effects (spec, size in sigmas), and the effects used."""
    rng = np.random.default_rng(seed)
    q, r, ctx = sample_points(rng, n_points, shots)
    engine = static_machine() if base == "static" else identity_machine()
    effects = [hidden(s, q, r, ctx, size, base) for s, size in specs]
    m = engine.forward(q, r) + sum((e.displacement(q, r, ctx) for e in effects), np.zeros_like(q))
    m = m + rng.normal(0.0, SIGMA_MM, m.shape)
    direction = np.column_stack([ctx["dirx"], ctx["diry"], ctx["dirz"]])
    context = {k: v for k, v in ctx.items() if not k.startswith("dir")}
    meas = Measurements(q=q, m=m, r=r, direction=direction, context=context, path=path,
                        linenos=np.arange(len(q)) + 4)
    return meas, effects


# One spec per effect: the direction of its parameters (scaled by ``hidden``).
SPECS = {
    "backlash:X": {"name": "backlash:X", "params": {"b_mm": 1.0}},
    "backlash:Z": {"name": "backlash:Z", "params": {"b_mm": 1.0}},
    "periodic:Y": {"name": "periodic:Y", "config": {"pitch_mm": 7.7}, "params": {"cos_mm": 0.8, "sin_mm": 0.6}},
    "thermal:t": {"name": "thermal:t", "config": {"tau_s": 2700.0}, "params": {"dx_mm": 0.4, "dz_mm": 1.0}},
    "thermal:temp": {"name": "thermal:temp", "params": {"kx_mm_per_C": 0.3, "kz_mm_per_C": 1.0}},
    "expansion:temp": {"name": "expansion:temp", "params": {"ax_per_C": 1.0, "ay_per_C": 0.8, "az_per_C": 0.3}},
    "load:load": {"name": "load:load", "params": {"cy_mm_per_unit": 0.3, "cz_mm_per_unit": -1.0}},
    "abbe:tilt": {"name": "abbe:tilt", "params": {"wx_rad": 1.0, "wy_rad": -0.6}},
    "abbe:X": {"name": "abbe:X", "params": {"wy_rad_per_mm": 1.0, "wz_rad_per_mm": 0.5}},
    "straightness:X": {"name": "straightness:X", "config": {"center_mm": 150.0, "half_travel_mm": 150.0},
                       "params": {"bow_y_mm": 1.0, "s_z_mm": -0.7}},
    "positioning:Y": {"name": "positioning:Y", "config": {"center_mm": 150.0, "half_travel_mm": 150.0},
                      "params": {"bow_mm": 1.0, "s_mm": 0.6}},
    "lever:XZ": {"name": "lever:XZ", "params": {"EAX_rad_per_mm": 1.0, "EBX_rad_per_mm": -0.5}},
    "linear:humidity": {"name": "linear:humidity", "config": {"reference": 50.0},
                        "params": {"ay_mm_per_unit": 1.0}},
    "squareness:XY": {"name": "squareness:XY", "params": {"EC0Y_rad": 1.0}},
    "scale:Z": {"name": "scale:Z", "params": {"scale": 1.0}},
}
#: effects the static model already holds: hidden in data of an identity-calibrated machine
NEEDS_IDENTITY_BASE = {"squareness:XY", "scale:Z"}
