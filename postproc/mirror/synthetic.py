"""A synthetic waffle shell: what the tests and the samples measure.

A cylindrical shell of diameter D with a row of pockets along the table angle B.
The thickness left by a pass of pocket i at pocket-local ``(b, z)`` is

    T = T_ref + allowance + pattern(b, z) + drift * i + E_dist(B0_i + b, Z0 + z)
        - K_applied(b, z) + noise

- ``pattern``: the within-pocket error (group I factors of the seed), the same in
  every pocket;
- ``drift * i``: a pocket-to-pocket drift (group II, e.g. thermal);
- ``E_dist``: the error of the tilted back wall, formula (1) of the seed evaluated on
  the true wall slope; the wall is ``V = c (B - B_mid)^2 + g Z`` (an out-of-round
  shell), so its tilt changes from pocket to pocket;
- ``K_applied``: the correction the program applied (cut deeper by K);
- ``noise``: ultrasonic gauge noise (Gaussian, fixed seed).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.mirror.feedback import PLAN_MAGIC, ThicknessMap
from postproc.mirror.kdist import SensorData


@dataclass
class Shell:
    diameter_mm: float = 2000.0
    cutter_radius_mm: float = 10.0
    t_ref_mm: float = 2.0
    allowance_mm: float = 0.3
    n_pockets: int = 12
    pitch_deg: float = 6.0  # pocket to pocket along B
    first_b0_deg: float = 3.0
    z0_mm: float = 100.0
    pocket_b_deg: float = 4.0  # pocket extent in B (local 0..pocket_b_deg)
    pocket_z_mm: float = 60.0
    wall_c_mm_per_deg2: float = 6.0e-4  # V = c (B - B_mid)^2 + g Z
    wall_g: float = 1.0e-3
    pattern_mm: float = 0.04
    drift_mm: float = 0.008  # per pocket
    noise_mm: float = 0.0005
    sensor_noise_mm: float = 0.001
    grid_b_deg: float = 0.25  # thickness gauge / program grid in b
    grid_z_mm: float = 5.0
    seed: int = 3
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    # -- geometry -------------------------------------------------------------------
    @property
    def b_mid(self) -> float:
        return self.first_b0_deg + 0.5 * ((self.n_pockets - 1) * self.pitch_deg + self.pocket_b_deg)

    def b0(self, i: int) -> float:
        return self.first_b0_deg + i * self.pitch_deg

    def local_grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Gauge and program nodes inside a pocket: (b, z) local, one cutter radius from the ribs."""
        b = np.arange(self.grid_b_deg, self.pocket_b_deg - 0.5 * self.grid_b_deg, self.grid_b_deg)
        z = np.arange(self.grid_z_mm, self.pocket_z_mm - 0.5 * self.grid_z_mm, self.grid_z_mm)
        bb, zz = np.meshgrid(b, z)
        return bb.ravel(), zz.ravel()

    # -- truth ----------------------------------------------------------------------
    def wall_v(self, b_deg, z_mm) -> np.ndarray:
        return self.wall_c_mm_per_deg2 * (np.asarray(b_deg) - self.b_mid) ** 2 + self.wall_g * np.asarray(z_mm)

    def e_dist(self, b_deg, z_mm) -> np.ndarray:
        """Formula (1) on the true slope dV/dB (mm/deg) of the wall."""
        dv_db = 2.0 * self.wall_c_mm_per_deg2 * (np.asarray(b_deg) - self.b_mid) + 0.0 * np.asarray(z_mm)
        return self.cutter_radius_mm * 360.0 / (np.pi * self.diameter_mm) * dv_db

    def pattern(self, b, z) -> np.ndarray:
        b, z = np.asarray(b), np.asarray(z)
        return self.pattern_mm * (np.sin(np.pi * b / self.pocket_b_deg) * (0.5 + z / self.pocket_z_mm) - 0.6)

    def error_without_correction(self, i: int, b, z) -> np.ndarray:
        return self.pattern(b, z) + self.drift_mm * i + self.e_dist(self.b0(i) + np.asarray(b), self.z0_mm + np.asarray(z))

    def machine(self, i: int, b, z, k_applied_mm, *, allowance: bool = False) -> ThicknessMap:
        """Thickness map of pocket i after a pass that applied K (local b, z nodes)."""
        b, z = np.asarray(b, dtype=float), np.asarray(z, dtype=float)
        t = (self.t_ref_mm + (self.allowance_mm if allowance else 0.0) + self.error_without_correction(i, b, z)
             - np.asarray(k_applied_mm) + self.rng.normal(0.0, self.noise_mm, b.shape))
        return ThicknessMap(self.b0(i) + b, self.z0_mm + z, t)

    def sensor_sweep(self, b_step_deg: float = 0.05, z_rows=None) -> SensorData:
        """Pre-measurement of the back wall over the belt of pockets, rows of constant Z."""
        lo = self.first_b0_deg
        hi = self.b0(self.n_pockets - 1) + self.pocket_b_deg
        b = np.arange(lo, hi + 0.5 * b_step_deg, b_step_deg)
        zs = np.arange(0.0, self.pocket_z_mm + 1e-9, 2 * self.grid_z_mm) if z_rows is None else np.asarray(z_rows)
        bb, zz = np.meshgrid(b, self.z0_mm + zs)
        bb, zz = bb.ravel(), zz.ravel()
        v = self.wall_v(bb, zz) + self.rng.normal(0.0, self.sensor_noise_mm, bb.shape)
        return SensorData(bb, zz, v)

    def expected_relearns(self, band_half_mm: float, with_kdist: bool) -> list[int]:
        """Pockets (0-based) that get a semi-finish pass, from the noise-free truth.

        With K_dist the finish error of pocket i, corrected by K_fb of pocket j, is the
        drift ``drift (i - j)``; without it the change of E_dist between the pockets adds.
        """
        b, z = self.local_grid()
        out, j = [], None
        relearn = True
        for i in range(self.n_pockets):
            if relearn:
                out.append(i)
                j = i
            err = self.drift_mm * (i - j) + (0.0 if with_kdist else
                                              self.e_dist(self.b0(i) + b, self.z0_mm + z)
                                              - self.e_dist(self.b0(j) + b, self.z0_mm + z))
            relearn = bool(np.max(np.abs(err)) > band_half_mm)
        return out


# -- files ------------------------------------------------------------------------------


def sensor_csv(data: SensorData) -> str:
    lines = ["# back-wall sensor sweep (copying head), rows of constant Z", "# units: length=mm", "B,Z,V"]
    lines += [f"{b:.4f},{z:.3f},{v:.5f}" for b, z, v in zip(data.b_deg, data.z_mm, data.v_mm, strict=True)]
    return "\n".join(lines) + "\n"


def thickness_csv(thk: ThicknessMap, what: str) -> str:
    lines = [f"# ultrasonic thickness map: {what}", "# units: length=mm", "B,Z,T"]
    lines += [f"{b:.4f},{z:.3f},{t:.5f}" for b, z, t in zip(thk.b_deg, thk.z_mm, thk.t_mm, strict=True)]
    return "\n".join(lines) + "\n"


def plan_csv(shell: Shell, rows: list[tuple[str, str]]) -> str:
    """Plan lines for every pocket; ``rows[i] = (semi_file, finish_file)`` ("" if none)."""
    lines = [f"# {PLAN_MAGIC}", "# units: length=mm", "pocket,B0,Z0,semi,finish"]
    for i in range(shell.n_pockets):
        semi, fin = rows[i] if i < len(rows) else ("", "")
        lines.append(f"P{i + 1:02d},{shell.b0(i):.4f},{shell.z0_mm:.3f},{semi},{fin}")
    return "\n".join(lines) + "\n"


def pocket_program(shell: Shell, y_bottom_mm: float = -5.0, feed: float = 600.0) -> str:
    """Finish pass of one pocket in local coordinates: zig-zag rows along B at constant Z.

    Every gauge node is a block end point (a reference point of the path), so the
    correction map is applied at the same nodes it was measured at.
    """
    b, z = shell.local_grid()
    bs = np.unique(b)
    zs = np.unique(z)
    out = ["%", "(waffle pocket finish pass: rotary table B, vertical Z, spindle along Y)",
           "(pocket-local coordinates: run with a work offset B0, Z0 per pocket)",
           "G21 G90 G94", f"G0 X0.0000 Y{y_bottom_mm - 20:.4f} B{bs[0]:.4f} Z{zs[0]:.4f}",
           f"G1 Y{y_bottom_mm:.4f} F{feed:.0f}"]
    for k, zv in enumerate(zs):
        row = bs if k % 2 == 0 else bs[::-1]
        if k:
            out.append(f"G1 Z{zv:.4f}")
        for bv in row[1:]:
            out.append(f"G1 B{bv:.4f}")
    out += [f"G0 Y{y_bottom_mm - 20:.4f}", "M30", "%"]
    return "\n".join(out) + "\n"
