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

from postproc.errors import PostprocError
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

    def sensor_sweep(self, b_step_deg: float = 0.1, z_rows=None) -> SensorData:
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
        out: list[int] = []
        j = 0  # the pocket K_fb was learnt on (the first pocket learns it)
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


def zigzag_sensor_csv(shell: Shell, pocket: int = 0, step_deg: float = 0.02, rows: int = 4) -> str:
    """The ideal back-wall signal along a zig-zag over one pocket, in path order (for deadband)."""
    b0 = shell.b0(pocket)
    up = np.arange(shell.grid_b_deg, shell.pocket_b_deg - shell.grid_b_deg + 1e-9, step_deg)
    lines = ["# ideal back-wall signal along a zig-zag finish path (path order)", "# units: length=mm",
             "t,B,Z,V"]
    t = 0.0
    for k in range(rows):
        z = shell.z0_mm + shell.grid_z_mm * (k + 1)
        for bl in (up if k % 2 == 0 else up[::-1]):
            b = b0 + bl
            lines.append(f"{t:.3f},{b:.4f},{z:.3f},{float(shell.wall_v(b, z)):.6f}")
            t += 0.01
    return "\n".join(lines) + "\n"


def write_sample_set(directory, *, seed: int = 3, finished: int = 4) -> list:
    """Write a campaign's files; the first ``finished`` pockets are already machined.

    The machined pockets follow the self-tuning (with K_dist) exactly as
    ``postproc mirror pockets`` decides it, so the plan is a consistent history.
    """
    from pathlib import Path

    from postproc.calfile import atomic_write_text
    from postproc.mirror.feedback import Band, pocket_corrections, read_plan, self_tune
    from postproc.mirror.kdist import fit_kdist, kdist_comments
    from postproc.mirror.maps import format_map

    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    shell = Shell(seed=seed)
    written = []

    def put(name: str, text: str) -> None:
        atomic_write_text(d / name, text)
        written.append(d / name)

    sensor = shell.sensor_sweep()
    put("backwall_sensor.csv", sensor_csv(sensor))
    res = fit_kdist(sensor, cutter_radius_mm=shell.cutter_radius_mm, diameter_mm=shell.diameter_mm,
                    segment_deg=2.0)
    put("kdist.csv", format_map(res.kmap, comments=kdist_comments(res, "backwall_sensor.csv")))
    put("pocket.nc", pocket_program(shell))
    put("shell_static.json", shell_calibration_text())
    put("shell_identity.json", shell_calibration_text(identity=True))
    put("zigzag_sensor.csv", zigzag_sensor_csv(shell))
    band = Band(shell.t_ref_mm, shell.t_ref_mm - 0.02, shell.t_ref_mm + 0.02)
    b, z = shell.local_grid()
    p = np.column_stack([np.zeros_like(b), np.full_like(b, -5.0), z])
    rows = [("", "")] * shell.n_pockets
    for _ in range(3 * shell.n_pockets):
        put("plan.csv", plan_csv(shell, rows))
        pockets = read_plan(d)
        last = self_tune(pockets, band, shell.allowance_mm)[-1]
        i = [pk.name for pk in pockets].index(last.pocket.name)
        if not last.next or i >= finished:
            break
        semi, fin = pocket_corrections(last, {pk.name: pk for pk in pockets}, band=band,
                                       allowance=shell.allowance_mm, apply_axis="Y", sign=1.0, kdist=res.kmap)
        kind = "semi" if fin is None else "finish"
        corr = semi if fin is None else fin
        if corr is None:
            raise PostprocError(f"pocket {last.pocket.name}: the self-tuning gave no {kind} correction")
        thk = shell.machine(i, b, z, corr.delta(p, {"B": b})[:, 1])
        name = f"{last.pocket.name}_{kind}.csv"
        put(name, thickness_csv(thk, f"pocket {last.pocket.name} after the {kind} pass"))
        rows[i] = (name, rows[i][1]) if fin is None else (rows[i][0], name)
    return sorted(set(written))


def shell_calibration_text(identity: bool = False) -> str:
    """A small static calibration of the shell machine (X unused, Y spindle, Z vertical).

    Y scale +20 um/m, Z leaning 30 urad towards +Y, 5 um offset in Y: enough to see
    the geometric correction added to the mirror maps. ``identity``: no geometric
    correction over the same volume (the maps alone).
    """
    import json

    from postproc.calfile import calibration_to_dict
    from postproc.engine.identity import IdentityEngine
    from postproc.engine.static import StaticEngine

    volume = [[-10.0, -60.0, -10.0], [10.0, 10.0, 400.0]]
    if identity:
        data = calibration_to_dict(IdentityEngine(volume), name="shell-identity",
                                   fit={"source": "no geometric correction"})
        return json.dumps(data, indent=2) + "\n"
    g = np.eye(3)
    g[1, 1] += 20e-6
    g[1, 2] = 30e-6
    eng = StaticEngine(g, [0.0, 0.005, 0.0], volume)
    data = calibration_to_dict(eng, name="shell-static", fit={"source": "synthetic shell machine"})
    return json.dumps(data, indent=2) + "\n"
