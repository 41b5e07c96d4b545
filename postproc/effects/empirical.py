"""Empirical correction: a smooth residual field with no physics behind it.

The last resort when ``check`` finds a residual above the noise that no effect of the
catalogue explains (a tool-length error, sag, a lever-arm coupling ...): a polynomial
field over the measured volume, fitted like any effect and named as empirical so that
no report pretends to know its cause. ``empirical:poly2|poly3|poly4`` is the total
degree; terms of degree 2 and up only (the affine part belongs to the base model and
the frame registration). Each component (x, y, z) has its own coefficients on products
of Legendre polynomials of the positions scaled to [-1, 1] over the measured extent
(``config``: ``center_{x,y,z}_mm``, ``half_{x,y,z}_mm``); outside that extent the field is
held at its value on the boundary (clamped), never extrapolated.

Never offered as a candidate effect: ``check`` offers it (with its cross-validated
figure and extent) only when its verdict is "unexplained".
"""

from __future__ import annotations

from itertools import product

import numpy as np

from postproc.effects.base import AXES, Effect
from postproc.errors import CalibrationError

DEGREES = {"poly2": 2, "poly3": 3, "poly4": 4}
# Half extents below this (mm) are floored: one position along an axis gives no shape.
MIN_HALF_MM = 1e-3


def _legendre(u: np.ndarray, n: int) -> np.ndarray:
    return np.polynomial.legendre.legval(u, [0] * n + [1])


def exponents(degree: int) -> list[tuple[int, int, int]]:
    return [(i, j, k) for i, j, k in product(range(degree + 1), repeat=3) if 2 <= i + j + k <= degree]


class Empirical(Effect):
    kind = "empirical"
    targets = tuple(DEGREES)
    candidate = False
    meaning = "empirical smooth residual field (no physical model): corrects what no known effect explains"

    @property
    def degree(self) -> int:
        return DEGREES[self.target]

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(f"{c}_{i}{j}{k}_mm" for c in "xyz" for i, j, k in exponents(self.degree))

    def describe(self, params=None) -> str:
        p = self.param_vector() if params is None else np.array([params[k] for k in self.param_names])
        ext = self.extent()
        where = "" if ext is None else " over X {:.0f}..{:.0f} Y {:.0f}..{:.0f} Z {:.0f}..{:.0f} mm".format(
            *ext.T.ravel())
        return (f"empirical field of degree {self.degree} ({len(p)} coefficients, largest "
                f"{np.max(np.abs(p)) * 1000 if len(p) else 0:.2f} um){where}")

    def extent(self) -> np.ndarray | None:
        try:
            c = np.array([self.config[f"center_{a}_mm"] for a in "xyz"])
            h = np.array([self.config[f"half_{a}_mm"] for a in "xyz"])
        except KeyError:
            return None
        return np.vstack([c - h, c + h])

    def basis(self, q, r, ctx) -> np.ndarray:
        ext = self.extent()
        if ext is None:
            raise CalibrationError(f"effect {self.name} has no extent (center_x_mm ... half_z_mm) in its config")
        c, h = ext.mean(axis=0), np.maximum(0.5 * (ext[1] - ext[0]), MIN_HALF_MM)
        u = np.clip((np.asarray(q, dtype=float) - c) / h, -1.0, 1.0)
        terms = exponents(self.degree)
        cols = np.column_stack([_legendre(u[:, 0], i) * _legendre(u[:, 1], j) * _legendre(u[:, 2], k)
                                for i, j, k in terms])
        n, m = len(q), len(terms)
        B = np.zeros((n, 3, 3 * m))
        for comp in range(3):
            B[:, comp, comp * m:(comp + 1) * m] = cols
        return B

    def prepare(self, q, r, ctx, resid) -> Empirical:
        q = np.asarray(q, dtype=float)
        lo, hi = q.min(axis=0), q.max(axis=0)
        cfg = {}
        for j, a in enumerate(AXES):
            cfg[f"center_{a.lower()}_mm"] = float(0.5 * (lo[j] + hi[j]))
            cfg[f"half_{a.lower()}_mm"] = float(max(0.5 * (hi[j] - lo[j]), MIN_HALF_MM))
        return self.copy(config=cfg)
