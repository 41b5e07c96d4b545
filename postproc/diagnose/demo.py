"""The walkthrough data set: a machine with one hidden effect, for the README.

``python -m postproc.diagnose.demo samples`` writes ``samples/walkthrough_points.csv``:
a static machine (S500-like scale and squareness errors, seed 000 magnitudes) with
12 um of lost motion on X (the axis lags its approach direction by 6 um, so the ISO
230-2 reversal value b = B = x_up - x_down is -12 um), measured at 80 random points, 3 shots each (tracker noise
sigma 1.5 um per axis), approach directions, time and temperature recorded. Fixed
seed: the file is the same on every run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from postproc.calfile import atomic_write_text
from postproc.calibration.measurements import Measurements, format_measurements
from postproc.effects import get_effect
from postproc.engine.static import StaticEngine

SEED = 2024
SIGMA_MM = 0.0015
# lost motion: the axis stops 6 um short on either side, B = x_up - x_down = -12 um
BACKLASH_X_MM = -0.012
N_POINTS = 80
SHOTS = 3
VOLUME_MM = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]


def walkthrough_machine() -> tuple[StaticEngine, list]:
    G = np.eye(3) + np.array([[180e-6, -230e-6, 140e-6], [0.0, -120e-6, 95e-6], [0.0, 0.0, 60e-6]])
    base = StaticEngine(G, [0.012, -0.008, 0.004], VOLUME_MM)
    return base, [get_effect("backlash:X", params={"b_mm": BACKLASH_X_MM})]


def walkthrough_points(seed: int = SEED) -> Measurements:
    rng = np.random.default_rng(seed)
    base, effects = walkthrough_machine()
    q = np.round(rng.uniform(10, 305, (N_POINTS, 3)), 3)
    direction = rng.choice([-1.0, 1.0], (N_POINTS, 3))
    t = np.sort(rng.uniform(0, 3 * 3600, N_POINTS)).round(0)
    temp = (20.2 + 0.4 * rng.standard_normal(N_POINTS)).round(2)
    idx = np.repeat(np.arange(N_POINTS), SHOTS)
    q, direction, t, temp = q[idx], direction[idx], t[idx], temp[idx]
    r = np.tile([0.0, 0.0, -100.0], (len(q), 1))
    ctx = {"dirx": direction[:, 0], "diry": direction[:, 1], "dirz": direction[:, 2], "t": t, "temp": temp}
    m = base.forward(q, r) + sum(e.displacement(q, r, ctx) for e in effects)
    m = m + rng.normal(0.0, SIGMA_MM, m.shape)
    return Measurements(q=q, m=m, r=r, direction=direction, context={"t": t, "temp": temp})


def write(directory) -> Path:
    path = Path(directory) / "walkthrough_points.csv"
    comments = [
        "walkthrough data: static machine + hidden 12 um lost motion on X, tracker sigma 1.5 um,",
        f"80 points x 3 shots; regenerate with: python -m postproc.diagnose.demo {directory}",
    ]
    atomic_write_text(path, format_measurements(walkthrough_points(), comments=comments))
    return path


if __name__ == "__main__":
    write(sys.argv[1] if len(sys.argv) > 1 else "samples")
