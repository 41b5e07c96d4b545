"""A small smooth non-linear machine for the tangential-method tests and benchmarks.

Seed-000 magnitudes over a 315 mm cube: uncorrected errors of 0.1-0.45 mm, about half
of them linear (scale, squareness, offset), the rest curved axes, angular errors
acting on the lever of the axes above them (couplings q1*q3, q2*q3) and a small
periodic lead-screw error. ``p = q + r + rho(q) + eps(q) x r``.
"""

from __future__ import annotations

import numpy as np
from conftest import (
    TABLE1_POINTS,
    TangentTestMachine,
)


def test_machine_has_seed_magnitudes():
    m = TangentTestMachine()
    err = np.linalg.norm(m.forward(TABLE1_POINTS) - TABLE1_POINTS, axis=1)
    assert err.min() > 0.1
    assert err.max() < 0.5
