"""Cutting edges as radius vectors ``r_e(p)`` in the tool frame (seed 002).

The tool frame has z along the tool axis, from the tip towards the shank, and its
origin at the tip on the axis. Each function takes the free parameter ``p`` (array)
and returns points (..., 3) in mm.

- cylindrical end mill (formula 2): ``(d/2 cos 2pi p/p_e, d/2 sin 2pi p/p_e, p)``,
  ``p = 0..L_c``;
- conical end mill: the radius grows linearly from ``d/2`` at the tip to ``D/2``
  at ``p = L_c``;
- ball end mill: ``(sqrt(p (d - p)) cos 2pi p/p_e, sqrt(p (d - p)) sin .., p)``,
  ``p = 0..d/2`` (a sphere of diameter d centred at ``z = d/2``);
- boring tool: the main edge from its tip along the unit direction
  ``(-cos l sin f, sin l, -cos l cos f)`` (lead angle ``l``, plan angle ``f``),
  ``p = 0..L_e``. The seed prints the direction without the factor ``p``; a point
  at distance ``p`` along the edge is ``tip + p * direction``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.errors import PostprocError

# Relative slack on the ball parameter's upper end d/2, so that d/2 computed as
# d/2 * (1 - cos(pi/2)) (6e-17 off) is still accepted.
BALL_PARAMETER_SLACK = 1e-12


def _positive(value: float, name: str) -> float:
    if not np.isfinite(value) or value <= 0:
        raise PostprocError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def _helix(radius, p, pitch_mm: float) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    phase = 2.0 * np.pi * p / pitch_mm if np.isfinite(pitch_mm) else np.zeros_like(p)
    return np.stack(np.broadcast_arrays(radius * np.cos(phase), radius * np.sin(phase), p), axis=-1)


def cylindrical_edge(p, d_mm: float, pitch_mm: float = np.inf) -> np.ndarray:
    """Seed 002 formula (2): edge of a cylindrical mill of diameter d, helix pitch p_e."""
    return _helix(_positive(d_mm, "cutter diameter") / 2.0, p, pitch_mm)


def conical_edge(p, d_mm: float, D_mm: float, length_mm: float, pitch_mm: float = np.inf) -> np.ndarray:
    """Edge of a conical mill: tip diameter d, diameter D at the end of the cutting length."""
    d = _positive(d_mm, "tip diameter")
    length = _positive(length_mm, "cutting length")
    radius = (D_mm - d) / (2.0 * length) * np.asarray(p, dtype=float) + d / 2.0
    return _helix(radius, p, pitch_mm)


def ball_edge(p, d_mm: float, pitch_mm: float = np.inf) -> np.ndarray:
    """Edge of a ball-end mill of diameter d; ``p`` is the height above the tip, 0..d/2."""
    d = _positive(d_mm, "ball diameter")
    p = np.asarray(p, dtype=float)
    if np.any(p < 0) or np.any(p > d / 2.0 * (1.0 + BALL_PARAMETER_SLACK)):
        raise PostprocError(f"ball edge parameter must lie in 0..d/2 = {d / 2.0}")
    radius = np.sqrt(np.clip(p * (d - p), 0.0, None))
    return _helix(radius, p, pitch_mm)


def ball_edge_parameter(angle_rad) -> np.ndarray:
    """``p`` for an edge point at polar angle ``angle`` from the tip (p = d/2 (1 - cos a))/(d/2).

    Multiply by ``d/2``: sampling the angle evenly gives evenly spaced points on the
    sphere, which plain ``p`` spacing does not near the tip.
    """
    return 1.0 - np.cos(np.asarray(angle_rad, dtype=float))


def boring_edge(p, lead_rad: float, plan_rad: float, tip=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Main edge of a boring tool: ``tip + p (-cos l sin f, sin l, -cos l cos f)``."""
    direction = np.array(
        [-np.cos(lead_rad) * np.sin(plan_rad), np.sin(lead_rad), -np.cos(lead_rad) * np.cos(plan_rad)]
    )
    p = np.asarray(p, dtype=float)
    return np.asarray(tip, dtype=float) + p[..., None] * direction


@dataclass(frozen=True)
class Cutter:
    """A milling cutter: its kind, sizes (mm) and number of flutes."""

    kind: str  # "cylindrical" | "conical" | "ball"
    d_mm: float
    pitch_mm: float = np.inf
    length_mm: float = 0.0
    D_mm: float = 0.0
    flutes: int = 1

    def __post_init__(self) -> None:
        if self.kind not in ("cylindrical", "conical", "ball"):
            raise PostprocError(f"cutter kind must be cylindrical, conical or ball, got {self.kind!r}")
        if int(self.flutes) < 1:
            raise PostprocError(f"flutes must be at least 1, got {self.flutes}")

    def edge(self, p) -> np.ndarray:
        if self.kind == "cylindrical":
            return cylindrical_edge(p, self.d_mm, self.pitch_mm)
        if self.kind == "conical":
            return conical_edge(p, self.d_mm, self.D_mm, self.length_mm, self.pitch_mm)
        return ball_edge(p, self.d_mm, self.pitch_mm)

    def helix_angle_rad(self, p) -> np.ndarray:
        """Angular position of the edge point ``p`` in the tool frame (2 pi p / p_e)."""
        p = np.asarray(p, dtype=float)
        return 2.0 * np.pi * p / self.pitch_mm if np.isfinite(self.pitch_mm) else np.zeros_like(p)
