"""Static tangential method (seed 000, chapter 2, formula 1).

The physical axes are straight lines in the ideal (tracker) frame with direction
cosines in the columns of a constant 3x3 matrix ``G``::

    p = r_O1 + G q + r            forward (the tool vector is carried, not rotated)
    q = G^-1 (p* - r - r_O1)      inverse, formula (1)

Fitted by least squares over point measurements; six points (two per axis) suffice.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.measurements import Measurements
from postproc.engine.base import (
    Engine,
    FitResult,
    InverseResult,
    check_points,
    check_tool_vectors,
)
from postproc.errors import CalibrationError, MeasurementError

# A design matrix [1, q] whose smallest singular value relative to its largest is below
# this cannot separate the three axes (points on a plane or a line).
MIN_RELATIVE_SINGULAR_VALUE = 1e-9


class StaticEngine(Engine):
    method = "static"
    affine = True

    def __init__(self, G, origin_mm, volume_mm) -> None:
        super().__init__(volume_mm)
        self.G = np.asarray(G, dtype=float)
        self.origin_mm = np.asarray(origin_mm, dtype=float)
        if self.G.shape != (3, 3) or self.origin_mm.shape != (3,):
            raise CalibrationError(
                f"static model needs G (3, 3) and r_O1 (3,), got {self.G.shape} and {self.origin_mm.shape}"
            )
        det = np.linalg.det(self.G)
        if not np.isfinite(det) or abs(det) < 0.5:
            raise CalibrationError(
                f"static model matrix G has determinant {det:.3g}: axes are not independent unit directions",
                hint="G must be close to the identity (columns = measured axis directions)",
            )
        self.G_inv = np.linalg.inv(self.G)

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        return self.origin_mm + q @ self.G.T + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        rr = check_tool_vectors(r, len(p))
        q = (p - rr - self.origin_mm) @ self.G_inv.T
        resid = np.linalg.norm(self.forward(q, rr) - p, axis=1)
        return InverseResult(q, resid, np.zeros(len(p), dtype=int))

    def model_to_dict(self) -> dict:
        return {"G": self.G.tolist(), "r_O1_mm": self.origin_mm.tolist()}

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> StaticEngine:
        return cls(model["G"], model["r_O1_mm"], volume_mm)


def fit_affine(q: np.ndarray, target: np.ndarray, where: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least squares ``target ≈ origin + G q``; returns (G, origin, residuals)."""
    A = np.column_stack([np.ones(len(q)), q])
    s = np.linalg.svd(A, compute_uv=False)
    if len(q) < 4 or s[-1] < MIN_RELATIVE_SINGULAR_VALUE * s[0]:
        raise MeasurementError(
            f"{len(q)} points{where} do not span three axes: the static model needs points "
            "that move each axis (e.g. two points per axis, six in all)",
            hint="measure at least two positions along each of X, Y and Z",
        )
    coef, *_ = np.linalg.lstsq(A, target, rcond=None)
    origin, G = coef[0], coef[1:].T
    return G, origin, target - (origin + q @ G.T)


def fit(measurements, **options) -> FitResult:
    meas = Measurements.concat(list(measurements))
    G, origin, resid = fit_affine(meas.q, meas.m - meas.r)
    volume = np.vstack([meas.q.min(axis=0), meas.q.max(axis=0)])
    engine = StaticEngine(G, origin, volume)
    # Squareness read off G: angle between measured axis directions minus 90 degrees.
    u = G / np.linalg.norm(G, axis=0)
    sq = {
        "XY_urad": float((np.arccos(np.clip(u[:, 0] @ u[:, 1], -1, 1)) - np.pi / 2) * 1e6),
        "XZ_urad": float((np.arccos(np.clip(u[:, 0] @ u[:, 2], -1, 1)) - np.pi / 2) * 1e6),
        "YZ_urad": float((np.arccos(np.clip(u[:, 1] @ u[:, 2], -1, 1)) - np.pi / 2) * 1e6),
    }
    scale_ppm = ((np.linalg.norm(G, axis=0) - 1.0) * 1e6).tolist()
    result = FitResult(engine=engine, residuals_mm=resid)
    result.report = [
        f"static tangential fit on {len(meas)} points",
        f"axis scale errors (ppm): X {scale_ppm[0]:+.1f}  Y {scale_ppm[1]:+.1f}  Z {scale_ppm[2]:+.1f}",
        "out-of-squareness (urad): " + "  ".join(f"{k[:2]} {v:+.1f}" for k, v in sq.items()),
        f"origin r_O1 (mm): {origin[0]:+.4f} {origin[1]:+.4f} {origin[2]:+.4f}",
    ]
    result.info = {"n_points": len(meas), "rms_mm": result.rms_mm, "max_mm": result.max_mm,
                   "sources": [m.path for m in measurements]}
    return result
