"""Campaigns measured on the virtual machine, as a metrologist would measure them.

For the tests and benchmarks of ``postproc check``: eight campaign shapes (random
points, a raster with dir=0 rows, three planes, ISO-like lines, body diagonals, three
tool vectors, a sparse set, a campaign with logged temperature and load), measured on
a virtual machine (:mod:`postproc.simulate`) with heavy-tailed tracker noise (Student t,
4 degrees of freedom, at the machine's tracker sigma) and in a tracker frame of its own
(a small rigid motion, set up anew for each campaign).

The clean machine is the S500-like machine without its 10 mm lead-screw terms (the
interferometer tables at a 5 mm step cannot hold them, so with them every campaign would
carry a real, unmodelled periodic error); its calibration is the parametric model fitted
from its own simulated interferometer tables, as a user would make it. Hidden effects
are added to the machine as effect records (:func:`machine_with`), or as arbitrary
displacement functions (local bumps, couplings) by the caller on the measured points.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from postproc.calibration.measurements import Measurements

#: The campaign shapes, in the order the benchmarks list them.
SHAPES = ("random", "raster", "planes", "lines", "diagonals", "tools", "sparse", "logged")
# Student-t degrees of freedom of the tracker noise: heavy tails (kurtosis infinite at 4),
# as a tracker's occasional bad shot, without making every campaign an outlier hunt.
NOISE_DF = 4.0
# Tracker frame set-up: translation (mm) and rotation (rad) standard deviation per axis.
FRAME_TRANSLATION_MM = 0.010
FRAME_ROTATION_RAD = 15e-6
# Duration of a campaign (s): long enough for a warm-up to show.
CAMPAIGN_S = 3 * 3600.0
# Time between shots at most (s): repeats of a point are shots within a minute.
SHOT_S = 30.0
# Interferometer table step of the calibration (mm), as the walkthrough measures it.
TABLES_STEP_MM = 5.0

_CACHE: dict = {}


def clean_machine():
    """The S500-like machine without its lead-screw terms (:mod:`postproc.simulate.s500`)."""
    from postproc.calibration.axis_tables import COLUMNS, AxisTables
    from postproc.simulate.machine import Machine, MachineGeometry
    from postproc.simulate.s500 import (
        _TERMS,
        NOISE,
        ORIGIN_OFFSET_MM,
        SQUARENESS,
        TABLE_STEP_MM,
        TRAVEL_MM,
    )
    from postproc.simulate.s500 import _column as column

    s = np.linspace(0.0, TRAVEL_MM, int(round(TRAVEL_MM / TABLE_STEP_MM)) + 1)
    pos, err = {}, {}
    for axis, cols in _TERMS.items():
        values = np.column_stack([column(s, (*cols[c][:5], 0.0)) for c in COLUMNS])
        if axis == "X":
            values[:, :3] += ORIGIN_OFFSET_MM
        pos[axis], err[axis] = s, values
    geometry = MachineGeometry(AxisTables(pos, err), SQUARENESS, [[0.0] * 3, [TRAVEL_MM] * 3])
    return Machine(geometry=geometry, noise=NOISE, name="s500-clean")


def machine_with(effects: list[dict]):
    """The clean machine with effect records (name, config, params) added."""
    from postproc.simulate.machine import Machine

    base = clean_machine()
    return Machine(base.geometry, effects=list(effects), noise=base.noise, name="s500-hidden")


def tables_calibration():
    """The parametric calibration fitted from the clean machine's interferometer tables
    (5 mm step, the machine's interferometer noise), made once per process."""
    if "tables" not in _CACHE:
        from postproc.calfile import calibration_from_dict, calibration_to_dict
        from postproc.calibration.tables import write_tables
        from postproc.metrology.tables_fit import fit_tables
        from postproc.simulate.tables import simulate_tables

        tabs, sq = simulate_tables(clean_machine(), TABLES_STEP_MM, np.random.default_rng(7))
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "vm_tables.csv"
            write_tables(path, Path(d) / "vm_tables_squareness.csv", tabs, sq)
            res = fit_tables([path])
        data = calibration_to_dict(res.engine, name="vm_tables", fit=res.info)
        _CACHE["tables"] = calibration_from_dict(data, path="vm_tables.json")
    return _CACHE["tables"]


def write_tables_calibration(path) -> Path:
    """:func:`tables_calibration` written as a calibration file at ``path``."""
    from postproc.calfile import save_calibration

    cal = tables_calibration()
    save_calibration(str(path), cal.engine, name="vm_tables", effects=cal.effects, fit=cal.fit)
    return Path(path)


def _both(q: np.ndarray, repeats: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows of each point approached + then - on every axis, ``repeats`` shots each."""
    signs = np.repeat([1.0, -1.0], repeats)
    qq = np.repeat(q, len(signs), axis=0)
    d = np.tile(signs, len(q))
    return qq, np.repeat(d[:, None], 3, axis=1)


def serpentine(step: float, zs, travel: float = 315.0) -> tuple[np.ndarray, np.ndarray]:
    """A serpentine raster of a cube of ``travel`` (mm) at the heights ``zs``: the points in
    the order visited, and the approach direction of each axis as a file records it (0 for
    an axis that did not move)."""
    axis = np.arange(0.0, travel + 1e-9, step)
    rows = []
    for k, z in enumerate(zs):
        ys = axis if k % 2 == 0 else axis[::-1]
        for i, y in enumerate(ys):
            xs = axis if i % 2 == 0 else axis[::-1]
            rows += [(x, y, z) for x in xs]
    q = np.array(rows)
    return q, np.sign(np.diff(np.vstack([q[:1] - 1.0, q]), axis=0))


def _raster(step: float, zs, travel: float = 315.0) -> tuple[np.ndarray, np.ndarray]:
    """Serpentine raster, two shots a point; dir 0 for axes that did not move (their state is carried)."""
    q, recorded = serpentine(step, zs, travel)
    q, recorded = np.repeat(q, 2, axis=0), np.repeat(recorded, 2, axis=0)
    recorded[1::2] = 0.0  # the second shot: no axis moved
    return q, recorded


def plan(shape: str, rng: np.random.Generator, n: int | None = None):
    """(q, r, recorded direction) of a campaign of ``shape`` over the 315 mm cube."""
    lo, hi = 0.0, 315.0
    tool = np.array([0.0, 0.0, -100.0])
    if shape == "random":
        q, d = _both(rng.uniform(lo, hi, (n or 60, 3)), 2)
    elif shape == "raster":
        q, d = _raster(45.0, (0.0, 157.5, 315.0))
    elif shape == "planes":
        k = (n or 75) // 3
        pts = []
        for j in range(3):
            p = rng.uniform(lo, hi, (k, 3))
            p[:, j] = 157.5
            pts.append(p)
        q, d = _both(np.vstack(pts), 2)
    elif shape == "lines":
        pts = []
        for j in range(3):
            for off in (80.0, 235.0):
                s = np.linspace(lo + 5, hi - 5, n or 21) + rng.uniform(-3, 3, n or 21)
                p = np.full((len(s), 3), off)
                p[:, j] = s
                pts.append(p)
        q, d = _both(np.vstack(pts), 2)
    elif shape == "diagonals":
        s = np.linspace(0.03, 0.97, n or 20)[:, None]
        corners = [((0, 0, 0), (1, 1, 1)), ((1, 0, 0), (0, 1, 1)), ((0, 1, 0), (1, 0, 1)), ((0, 0, 1), (1, 1, 0))]
        pts = [lo + (hi - lo) * (np.array(a) + s * (np.array(b) - np.array(a))) for a, b in corners]
        q, d = _both(np.vstack(pts) + rng.uniform(-2, 2, (len(s) * 4, 3)), 2)
    elif shape == "tools":
        tools = np.array([[0, 0, -60.0], [0, 0, -160.0], [60, 0, -110.0]])
        centres = rng.uniform(lo, hi, (n or 40, 3))
        q = np.repeat(np.repeat(centres, 3, axis=0), 2, axis=0)
        r = np.repeat(np.tile(tools, (len(centres), 1)), 2, axis=0)
        return q, r, np.ones_like(q)
    elif shape == "sparse":
        q = np.repeat(rng.uniform(lo, hi, (n or 25, 3)), 3, axis=0)
        d = np.ones_like(q)
    elif shape == "logged":
        q, d = _both(rng.uniform(lo, hi, (n or 80, 3)), 2)
    else:
        raise ValueError(f"unknown campaign shape {shape!r}: one of {', '.join(SHAPES)}")
    return q, np.tile(tool, (len(q), 1)), d


def carried(recorded: np.ndarray) -> np.ndarray:
    """The approach state the machine is in: dir 0 carries the last move's (formats.md)."""
    state = recorded.copy()
    for i in range(1, len(state)):
        state[i] = np.where(recorded[i] != 0, recorded[i], state[i - 1])
    return state


def campaign(shape: str, seed: int, *, machine=None, n: int | None = None, context=None, frame: bool = True,
             noise_df: float | None = NOISE_DF, path: str | None = None, extra=None,
             visit_sigma_mm: float = 0.0, moved: tuple[float, float, float] | None = None) -> Measurements:
    """One campaign of ``shape`` measured on ``machine`` (default: the clean one).

    ``context``: extra columns, name -> function(t, rng) -> (N,) values, or a pair (true
    values the machine sees through its effects, values as logged in the file: empty
    cells as NaN, sample and hold); "logged" campaigns add a
    temperature (20 deg C +- a slow wander and sensor noise) and a stepped load
    column of their own. ``noise_df``: Student-t degrees of freedom of the tracker
    noise (None: Gaussian). ``frame``: the tracker's own frame (a rigid motion).
    ``extra(q, r, ctx) -> (N, 3)``: a displacement outside the effect catalogue (a local
    bump, a coupling) added to the machine's. ``visit_sigma_mm``: the machine's
    repeatability, a random offset per visit of a point (shared by its shots).
    ``moved``: (fraction, translation mm, rotation rad): the tracker knocked or set up
    again after that fraction of the rows: from there on its frame is moved once more by a
    rigid motion, of the given size along a random direction.
    """
    rng = np.random.default_rng(seed)
    mach = machine if machine is not None else clean_machine()
    q, r, recorded = plan(shape, rng, n)
    t = np.arange(len(q)) * min(SHOT_S, CAMPAIGN_S / len(q))
    ctx = {"t": t}
    if shape == "logged":
        ctx["temp"] = 20.0 + 0.3 * np.sin(2 * np.pi * t / CAMPAIGN_S + rng.uniform(0, 6)) + rng.normal(0, 0.02, len(t))
        ctx["load"] = np.repeat([0.0, 200.0, 400.0], -(-len(t) // 3))[:len(t)][rng.permutation(len(t))]
    logged = {}
    for name, fn in (context or {}).items():
        v = fn(t, rng)
        true, log = v if isinstance(v, tuple) else (v, v)
        ctx[name], logged[name] = np.asarray(true, dtype=float), np.asarray(log, dtype=float)
    state = carried(recorded)
    full = {**ctx, "dirx": state[:, 0], "diry": state[:, 1], "dirz": state[:, 2]}
    ctx.update(logged)  # the file holds what was logged; the machine saw the true values
    m = mach.forward(q, r, full)
    if extra is not None:
        m = m + extra(q, r, full)
    if visit_sigma_mm:
        new_visit = np.any(q[1:] != q[:-1], axis=1) | np.any((recorded[1:] != 0) & (recorded[1:] != recorded[:-1]), axis=1)
        visit = np.cumsum(np.r_[True, new_visit]) - 1
        m = m + rng.normal(0.0, visit_sigma_mm, (visit[-1] + 1, 3))[visit]
    sigma = mach.noise.tracker_mm
    if noise_df is None:
        m = m + rng.normal(0.0, sigma, m.shape)
    else:
        m = m + sigma * rng.standard_t(noise_df, m.shape) / np.sqrt(noise_df / (noise_df - 2.0))
    if frame:
        from postproc.rotation import rotate

        w = rng.normal(0.0, FRAME_ROTATION_RAD, 3)
        m = rotate(np.tile(w, (len(m), 1)), m) + rng.normal(0.0, FRAME_TRANSLATION_MM, 3)
    if moved is not None:
        from postproc.rotation import rotate

        fraction, shift_mm, turn_rad = moved
        k = int(round(fraction * len(m)))
        d_t, d_w = rng.normal(size=3), rng.normal(size=3)
        d_t *= shift_mm / np.linalg.norm(d_t)
        d_w *= turn_rad / np.linalg.norm(d_w)
        m[k:] = rotate(np.tile(d_w, (len(m) - k, 1)), m[k:]) + d_t
    return Measurements(q=q, m=m, r=r, direction=recorded, context=ctx, path=path or f"{shape}_{seed}.csv",
                        linenos=np.arange(len(q)) + 4, has_tool_columns=True)


def ram_sag(tip_sag_mm: float, axis: int = 1, *, overhang_mm: float = 100.0, travel_mm: float = 315.0,
            load_column: str | None = None, load_max: float = 1.0):
    """A ram (a cantilever along ``axis``) that sags under a weight at its tip, as a
    displacement function for :func:`campaign`'s ``extra``.

    The ram's free length is ``e = q[axis] + overhang_mm``; a tip weight ``P`` bends it by
    ``P e^3 / (3 E I)`` downwards (-Z) and turns its end by ``P e^2 / (2 E I)``, which acts
    through the tool vector (the ram's end carries the tool). ``tip_sag_mm`` is the sag at
    the full extension (and, with ``load_column``, at the load ``load_max``): with a load
    column the weight is the load (a head or a workpiece hung on the ram), without it the
    ram's own head, the same in every row. Beam theory, not an effect of the catalogue.
    """
    from postproc.rotation import rotate

    full = travel_mm + overhang_mm
    k = tip_sag_mm / full**3  # P / (3 E I) at the full weight

    def f(q, r, ctx):
        weight = np.ones(len(q)) if load_column is None else np.asarray(ctx[load_column], dtype=float) / load_max
        e = q[:, axis] + overhang_mm
        out = np.zeros_like(q)
        out[:, 2] = -k * weight * e**3
        slope = -3.0 * k * weight * e**2  # dz/de: the end turns nose down
        w = np.zeros_like(q)
        bend = 1 - axis if axis < 2 else 0  # about X for a ram along Y, about Y for one along X
        w[:, bend] = slope if axis == 1 else -slope
        return out + rotate(w, r) - r
    return f


def check_campaign(meas: Measurements, cal=None, **options):
    """``check --fixed`` of a campaign against the tables calibration (default)."""
    from postproc.diagnose.check import run_check

    cal = cal if cal is not None else tables_calibration()
    options.setdefault("fixed", True)
    return run_check(cal, [meas], [meas.path], **options)
