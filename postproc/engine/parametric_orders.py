"""First against second order (seed 000, Tables 3 and 4), for ``postproc orders``.

For commanded points q and a tool vector r: |delta| of formula (3), the bounds
|delta+| and |delta-| of formula (4), and their relative differences in percent;
then the same with every angular error multiplied by k (the seed's scaling factor),
to show where the second-order terms start to matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.engine.base import check_points, check_tool_vectors
from postproc.engine.parametric import ParametricEngine

#: Seed 000, Tables 3 and 4: the six points (X/Y/Z, mm) where the orders were compared.
SEED_ORDER_POINTS_MM = (
    (60, 50, 50), (120, 170, 190), (180, 130, 200), (140, 140, 110), (200, 200, 140), (80, 110, 120),
)


@dataclass
class OrdersComparison:
    """|delta| values in mm (N,) and relative differences in percent (N,), for one k."""

    k: float
    delta_plus_mm: np.ndarray
    delta_minus_mm: np.ndarray
    delta_first_mm: np.ndarray

    @property
    def rel_plus_pct(self) -> np.ndarray:
        return np.abs(self.delta_plus_mm - self.delta_first_mm) / self.delta_first_mm * 100

    @property
    def rel_minus_pct(self) -> np.ndarray:
        return np.abs(self.delta_minus_mm - self.delta_first_mm) / self.delta_first_mm * 100

    def rows(self) -> list[dict]:
        return [
            {"delta_plus_um": float(a * 1000), "delta_minus_um": float(b * 1000), "delta_um": float(c * 1000),
             "rel_plus_pct": float(d), "rel_minus_pct": float(e)}
            for a, b, c, d, e in zip(self.delta_plus_mm, self.delta_minus_mm, self.delta_first_mm,
                                     self.rel_plus_pct, self.rel_minus_pct, strict=True)
        ]


def compare_orders(engine, q, r=None, k: float = 1.0) -> OrdersComparison:
    """Seed 000 Table 3 (k = 1) or Table 4 (k = 1000) quantities at commanded points q."""
    q = check_points(q, "q")
    r = check_tool_vectors(r, len(q))
    eng = engine
    if k != 1.0:
        eng = ParametricEngine(engine.tables.scaled(angle_factor=k), engine.squareness, engine.volume_mm,
                               interpolation=engine.interpolation, extrapolate=engine.extrapolate)
    plus, minus, first = (np.linalg.norm(v, axis=1) for v in eng.second_order_bounds(q, r))
    return OrdersComparison(float(k), plus, minus, first)
