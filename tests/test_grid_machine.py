"""A small smooth non-linear machine for the tangential-method tests and benchmarks.

Seed-000 magnitudes over a 315 mm cube: uncorrected errors of 0.1-0.45 mm, about half
of them linear (scale, squareness, offset), the rest curved axes, angular errors
acting on the lever of the axes above them (couplings q1*q3, q2*q3) and a small
periodic lead-screw error. ``p = q + r + rho(q) + eps(q) x r``.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.measurements import Measurements

SIDE_MM = 315.0
#: Seed 000, Table 1 control points.
TABLE1_POINTS = np.array([
    [230, 230, 230], [110, 170, 185], [170, 125, 200], [198, 196, 140], [130, 140, 106],
    [50, 50, 50], [133, 198, 176], [80, 112, 118], [162, 168, 210], [108, 136, 168],
], dtype=float)


class TangentTestMachine:
    """Smooth test machine; ``screw`` = (amplitude mm, pitch mm) of a periodic X/Y error.

    ``scale`` multiplies every error but the periodic one.
    """

    def __init__(self, screw=(0.001, 16.0), scale: float = 2.0) -> None:
        self.screw = screw
        self.scale = scale

    def errors(self, q):
        q = np.asarray(q, dtype=float)
        x, y, z = (q[:, j] / SIDE_MM for j in range(3))
        # Linear part: offset, scale and squareness (what the static method removes).
        lin = np.array([0.045, -0.030, 0.020]) + q @ (np.array([
            [420e-6, -260e-6, 180e-6],
            [0.0, 330e-6, -240e-6],
            [0.0, 0.0, 280e-6],
        ]).T)
        # Curved axes: positioning and straightness, as smooth functions of one axis.
        curved = np.column_stack([
            0.060 * np.sin(np.pi * x) + 0.035 * y**2 - 0.030 * np.sin(1.5 * np.pi * z),
            0.050 * x**2 - 0.055 * np.sin(np.pi * y) + 0.030 * z**3,
            -0.045 * np.sin(np.pi * x) + 0.040 * y**2 - 0.040 * np.sin(np.pi * z),
        ])
        # Angular errors of X and Y acting on the lever of the axes above them.
        eps_x = np.column_stack([120e-6 * np.sin(np.pi * x), -150e-6 * x**2, 80e-6 * x])
        eps_y = np.column_stack([-130e-6 * y**2, 90e-6 * np.sin(np.pi * y), -60e-6 * y])
        lever_x = np.column_stack([np.zeros_like(x), q[:, 1], q[:, 2] + 150.0])
        lever_y = np.column_stack([np.zeros_like(x), np.zeros_like(x), q[:, 2] + 150.0])
        coupled = np.cross(eps_x, lever_x) + np.cross(eps_y, lever_y)
        amp, pitch = self.screw
        periodic = amp * np.column_stack([
            np.sin(2 * np.pi * q[:, 0] / pitch), np.sin(2 * np.pi * q[:, 1] / pitch + 1.0), np.zeros_like(x)
        ])
        eps = eps_x + eps_y + np.column_stack([np.zeros_like(x), 50e-6 * z, -40e-6 * z])
        return self.scale * (lin + curved + coupled) + periodic, self.scale * eps

    def forward(self, q, r=None, context=None):
        q = np.asarray(q, dtype=float)
        r = np.zeros_like(q) if r is None else np.broadcast_to(np.asarray(r, dtype=float), q.shape)
        rho, eps = self.errors(q)
        return q + r + rho + np.cross(eps, r)


def grid_measurements(machine, step=15.0, side=SIDE_MM, tool=(0.0, 0.0, 0.0), sigma=0.002,
                      shots=1, seed=0) -> Measurements:
    """Tracker points on a regular lattice 0..side with the given step (``shots`` per node)."""
    ax = np.arange(0.0, side + 1e-9, step)
    q = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    q = np.repeat(q, shots, axis=0)
    r = np.tile(np.asarray(tool, dtype=float), (len(q), 1))
    rng = np.random.default_rng(seed)
    m = machine.forward(q, r) + rng.normal(0.0, sigma, q.shape)
    return Measurements(q=q, m=m, r=r, path="grid.csv")


def six_point_measurements(machine, side=SIDE_MM, tool=(0.0, 0.0, 0.0), sigma=0.002, seed=0) -> Measurements:
    """The seed's static set: two points per axis."""
    a = side - 15.0
    q = np.array([[15, 15, 15], [a, 15, 15], [15, 15, 15], [15, a, 15], [15, 15, 15], [15, 15, a]], float)
    r = np.tile(np.asarray(tool, dtype=float), (len(q), 1))
    rng = np.random.default_rng(seed)
    return Measurements(q=q, m=machine.forward(q, r) + rng.normal(0.0, sigma, q.shape), r=r, path="six.csv")


def test_machine_has_seed_magnitudes():
    m = TangentTestMachine()
    err = np.linalg.norm(m.forward(TABLE1_POINTS) - TABLE1_POINTS, axis=1)
    assert err.min() > 0.1
    assert err.max() < 0.5
