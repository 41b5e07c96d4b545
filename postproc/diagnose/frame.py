"""Registration of the measurement frame: a 6-DOF nuisance, not an effect of the machine.

A tracker set up anew stands in a slightly different place: its frame is the ideal
frame moved by a small rigid motion, translation ``t`` and rotation ``w`` (about the
frame's origin). To first order in ``w`` (tens of urad: the second-order term is
``|w|^2 |p|``, below 1e-6 um over a metre) the measured point is::

    m = p + t + w x p

with ``p`` the functional point in the ideal frame, here its commanded position
``q + r`` (the machine's own errors change ``w x p`` by ``|w| * error``, far below any
noise). Linear in the six parameters ``(tx, ty, tz, wx, wy, wz)``. The registration
is fitted with the base and the effects and reported with its size; it is never
stored in a calibration (it belongs to the measurement, not to the machine).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PARAM_NAMES = ("frame_tx_mm", "frame_ty_mm", "frame_tz_mm", "frame_wx_rad", "frame_wy_rad", "frame_wz_rad")


def frame_basis(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(N, 3, 6): displacement = basis @ (tx, ty, tz, wx, wy, wz)."""
    p = np.asarray(q, dtype=float) + np.asarray(r, dtype=float)
    n = len(p)
    B = np.zeros((n, 3, 6))
    for j in range(3):
        B[:, j, j] = 1.0
    # w x p = (wy pz - wz py, wz px - wx pz, wx py - wy px)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    B[:, 0, 4], B[:, 0, 5] = z, -y
    B[:, 1, 5], B[:, 1, 3] = x, -z
    B[:, 2, 3], B[:, 2, 4] = y, -x
    return B


@dataclass
class FrameFit:
    """A fitted registration: ``params`` (6,) as PARAM_NAMES, ``u_k2`` their k=2 uncertainty."""

    params: np.ndarray
    u_k2: np.ndarray | None = None
    absorbed: bool = False  # the base model holds a rigid motion itself (static)

    def displacement(self, q, r) -> np.ndarray:
        return frame_basis(q, r) @ self.params

    def size_mm(self, volume_mm) -> float:
        """Largest displacement of the registration over the corners of ``volume_mm``."""
        vol = np.asarray(volume_mm, dtype=float)
        corners = np.array([[vol[i, 0], vol[j, 1], vol[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return float(np.max(np.linalg.norm(self.displacement(corners, np.zeros_like(corners)), axis=1)))

    def to_json(self, volume_mm=None) -> dict[str, object]:
        out: dict[str, object] = {
            "translation_mm": [float(v) for v in self.params[:3]],
            "rotation_rad": [float(v) for v in self.params[3:]],
            "about": "the origin of the measurement frame",
        }
        if self.u_k2 is not None:
            out["translation_u_k2_mm"] = [float(v) for v in self.u_k2[:3]]
            out["rotation_u_k2_rad"] = [float(v) for v in self.u_k2[3:]]
        if volume_mm is not None:
            out["size_mm"] = self.size_mm(volume_mm)
        return out

    def describe(self, volume_mm=None) -> str:
        t, w = self.params[:3] * 1000, self.params[3:] * 1e6
        u = self.u_k2
        tu = f" (+- {max(u[:3]) * 1000:.2f} um, k=2)" if u is not None else ""
        wu = f" (+- {max(u[3:]) * 1e6:.2f} urad, k=2)" if u is not None else ""
        size = f"; moves points in the volume by up to {self.size_mm(volume_mm) * 1000:.2f} um" \
            if volume_mm is not None else ""
        return (f"translation x {t[0]:+.2f} y {t[1]:+.2f} z {t[2]:+.2f} um{tu}, "
                f"rotation x {w[0]:+.2f} y {w[1]:+.2f} z {w[2]:+.2f} urad{wu}{size}")
