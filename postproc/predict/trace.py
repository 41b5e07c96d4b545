"""The trace of a cutting edge in the workpiece frame and the machined surface (seed 002).

``r_s(t, p) = M_1(t) ... M_m(t) r_e(p)`` (formula 3) is evaluated for a grid of
times and edge parameters in one vectorised call. The machined surface is the part of
the trace that is not "in the air": for a flank cut only short arcs of every
revolution touch the wall. Formula (4) jumps over the rest with a new time scale,

    tau(t, t0) = t + [(t - 0.5 t_m + t0) / t_m] (1/n - t_m),

where ``[.]`` is the integer part (the brackets are lost in the printed formula; as
printed, without them, tau is linear in t and skips nothing), ``t_m`` the time an
edge point spends in the cut and ``t0`` the helix correction of point ``p``. Within
those windows the remaining material is the envelope of the passes: at each place
along the surface the deepest reach of any pass (:func:`envelope`).

Also two misprints of the seed, corrected here: the cutting angle is
``theta = 2 s_z / d`` so ``t_m = theta / (2 pi n) = s_z / (pi d n)`` (the print drops
``d``; as printed it is not a time), and the edge of a boring tool has the factor p.

Times here are in seconds, spindle speeds in rev/min, feeds in mm/min.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from postproc.errors import PostprocError
from postproc.predict import frames
from postproc.predict.chain import Chain, Element, Module
from postproc.predict.tools import ball_edge_parameter

SECONDS_PER_MINUTE = 60.0

# Edge heights traced at once: bounds the memory of the (windows, samples, heights, 4, 4)
# chain matrices to some tens of megabytes.
HEIGHTS_PER_BLOCK = 16

# The wall is reported between the second and the last-but-one pass (the first and last
# have a neighbour on one side only), so at least this many passes are traced.
MIN_WINDOWS = 5

# Smallest vertical range (nm) of the trace-near-the-wall plot, for a wall with no cusps.
MIN_PLOT_RANGE_NM = 1e-6


def cutting_time_scale(t, t0, rev_per_s: float, t_m: float) -> np.ndarray:
    """Seed 002 formula (4) with the integer part: compressed time -> real time.

    Each interval of length ``t_m`` of ``t`` maps onto one cutting window; windows
    are one revolution ``1/n`` apart, the air between them is skipped.
    """
    t = np.asarray(t, dtype=float)
    period = 1.0 / rev_per_s
    return t + np.floor((t - 0.5 * t_m + t0) / t_m) * (period - t_m)


def cutting_time_s(feed_per_edge_mm: float, d_mm: float, rev_per_s: float) -> float:
    """``t_m = s_z / (pi d n)``: time an edge point of a flank-cutting mill is in the cut."""
    return feed_per_edge_mm / (np.pi * d_mm * rev_per_s)


def runout_element(amplitude_rad: float, edge_rpm: float, flutes: int, phase_rad: float = 0.0) -> Element:
    """Seed 002's spindle-runout matrix ``M_f`` as an error element (multiply on the right).

    ``M_f`` is the small-angle rotation about y by ``A sin(omega t)``, with
    ``omega = 2 pi n / z``. Here ``n`` is the speed of the single modelled edge, which
    stands for ``z`` equal flutes turning at ``n / z`` real rev/min (the seed models
    one edge at ``z_c n``); so ``omega`` is once per real spindle revolution.
    """
    omega = 2.0 * np.pi * edge_rpm / flutes / SECONDS_PER_MINUTE
    sine = {"var": "t", "sine": {"amplitude": float(amplitude_rad), "omega": omega, "phase": float(phase_rad)}}
    return Element("error", {"beta": sine, "order": "small"}, "runout")


def with_runout(chain: Chain, amplitude_rad: float, edge_rpm: float, flutes: int, phase_rad: float = 0.0) -> Chain:
    """A copy of ``chain`` with the runout matrix appended after its last module."""
    module = Module("spindle runout", [runout_element(amplitude_rad, edge_rpm, flutes, phase_rad)])
    return Chain([*chain.modules, module], chain.name, dict(chain.random), chain.description, dict(chain.defaults))


def facing_times(
    helix_rad, direction_rad: float, edge_rpm: float, spin: str = "cw", phase_rad: float = 0.0
) -> np.ndarray:
    """First time in [0, 1/n) at which an edge point points along ``direction_rad``.

    The point's angle in the machine frame is ``helix + s 2 pi n t + phase`` with
    ``s = -1`` for a clockwise spindle; ``helix`` is its angle in the tool frame.
    """
    rev_per_s = edge_rpm / SECONDS_PER_MINUTE
    s = -1.0 if spin == "cw" else 1.0
    t = (direction_rad - np.asarray(helix_rad, dtype=float) - phase_rad) / (s * 2.0 * np.pi * rev_per_s)
    return np.mod(t, 1.0 / rev_per_s)


def spindle_of(chain: Chain) -> tuple[str, float]:
    """Direction and constant phase of the chain's (single) spindle element."""
    found = [e for m in chain.modules for e in m.elements if e.kind == "spindle"]
    if len(found) != 1:
        raise PostprocError(
            f"chain {chain.name!r} has {len(found)} spindle elements; a trace needs exactly one",
            hint='add {"spindle": {"axis": "z", "rpm": "rpm"}} to the last module',
        )
    phase = found[0].body.get("phase", 0.0)
    if not isinstance(phase, int | float):
        raise PostprocError("the spindle phase must be a number for a trace")
    return found[0].body.get("direction", "cw"), float(phase)


def window_times(t_face, rev_per_s: float, width_s: float, windows: int, samples: int) -> np.ndarray:
    """Real times (windows, samples, P) of the cutting windows, through formula (4).

    The compressed time runs evenly over ``windows * width``; formula (4) with
    ``t0 = width - t_face`` centres window ``k`` on ``t_face + k / n``.
    """
    t_face = np.asarray(t_face, dtype=float)
    t0 = width_s - t_face
    frac = (np.arange(samples) + 0.5) / samples
    k = np.arange(windows)[:, None, None]
    compressed = 0.5 * width_s - t0 + (k + frac[None, :, None]) * width_s
    return cutting_time_scale(compressed, t0, rev_per_s, width_s)


def trace_points(chain: Chain, edge, env: Mapping[str, np.ndarray]) -> np.ndarray:
    """``r_s = M(t) r_e(p)`` for an environment whose arrays broadcast to ``S`` (last axis P).

    ``edge`` (P, 3) are the edge points in the tool frame; returns ``S + (3,)``.
    """
    return frames.apply(chain.matrix(env), np.asarray(edge, dtype=float))


def envelope(u, depth, u_query) -> np.ndarray:
    """Deepest reach at ``u_query`` over passes: rows of ``u``/``depth`` (K, M) are curves.

    Each curve is interpolated in ``u`` over its own range only; a place that no pass
    reaches gets ``-inf``. This is the numerical removal of the air parts: whatever
    another pass cuts deeper is not part of the surface.
    """
    u = np.asarray(u, dtype=float)
    depth = np.asarray(depth, dtype=float)
    uq = np.asarray(u_query, dtype=float)
    best = np.full(uq.shape, -np.inf)
    for uk, dk in zip(u, depth, strict=True):
        order = np.argsort(uk)
        us, ds = uk[order], dk[order]
        inside = (uq >= us[0]) & (uq <= us[-1])
        best = np.where(inside, np.maximum(best, np.interp(uq, us, ds)), best)
    return best


@dataclass
class FlankSurface:
    """Material left on a flank-milled wall: ``excess_mm[j, i]`` at ``u_mm[i]``, height ``p_mm[j]``.

    ``excess`` is measured from the nominal wall (cutter radius from the commanded
    path) into the stock: 0 where the tool reached the nominal wall, positive where
    material is left (cusps), negative where it cut too deep.
    """

    u_mm: np.ndarray
    p_mm: np.ndarray
    excess_mm: np.ndarray
    feed_per_edge_mm: float
    t_m_s: float

    @property
    def cusp_mm(self) -> np.ndarray:
        """Peak-to-valley along the feed at each height."""
        return np.max(self.excess_mm, axis=1) - np.min(self.excess_mm, axis=1)

    @property
    def form_mm(self) -> float:
        """Peak-to-valley over the whole wall."""
        return float(np.max(self.excess_mm) - np.min(self.excess_mm))


def flank_surface(
    chain: Chain,
    cutter,
    *,
    rpm: float,
    feed_mm_min: float,
    heights_mm,
    windows: int = 40,
    samples: int = 201,
    margin: float = 4.0,
    wall_direction_rad: float = -np.pi / 2,
    context: Mapping[str, float] | None = None,
    env_fn: Callable[[np.ndarray], dict] | None = None,
) -> FlankSurface:
    """Wall left by a flank cut with feed along +x, the wall on the side ``wall_direction``.

    ``chain`` must take ``X`` (mm), ``t`` (s) and ``rpm`` (the modelled single edge's
    speed, ``flutes * rpm``); ``Y``, ``Z`` default to 0. The cut is sampled in
    ``windows`` cutting windows of ``margin * t_m`` each (formula 4) and the surface
    is the envelope of the passes at every height.
    """
    if rpm <= 0 or feed_mm_min <= 0:
        raise PostprocError(f"spindle speed and feed must be positive, got {rpm} rpm, {feed_mm_min} mm/min")
    if windows < MIN_WINDOWS or samples < 3 or margin < 1.0:
        raise PostprocError(
            f"need at least {MIN_WINDOWS} windows, 3 samples per window and margin >= 1, "
            f"got {windows}, {samples}, {margin}"
        )
    edge_rpm = rpm * cutter.flutes
    rev_per_s = edge_rpm / SECONDS_PER_MINUTE
    fz = feed_mm_min / edge_rpm
    t_m = cutting_time_s(fz, cutter.d_mm, rev_per_s)
    p = np.asarray(heights_mm, dtype=float)
    edge = cutter.edge(p)
    spin, phase = spindle_of(chain)
    t_face = facing_times(cutter.helix_angle_rad(p), wall_direction_rad, edge_rpm, spin, phase)
    normal = np.array([np.cos(wall_direction_rad), np.sin(wall_direction_rad), 0.0])
    base = {"Y": 0.0, "Z": 0.0, **(context or {}), "rpm": edge_rpm}
    radius = np.linalg.norm(edge[:, :2], axis=1)
    uq = None
    excess = np.empty((len(p), 0))
    rows = []
    # Heights are processed in blocks so the (K, M, block, 4, 4) matrices stay small.
    for start in range(0, len(p), HEIGHTS_PER_BLOCK):
        sl = slice(start, start + HEIGHTS_PER_BLOCK)
        t = window_times(t_face[sl], rev_per_s, margin * t_m, windows, samples)  # (K, M, b)
        env = {**base, "t": t, "X": feed_mm_min / SECONDS_PER_MINUTE * t}
        if env_fn is not None:
            env.update(env_fn(t))
        pts = trace_points(chain, edge[sl], env)  # (K, M, b, 3)
        u = pts[..., 0]
        depth = pts @ normal
        if uq is None:
            # Places between the centres of the second and the last-but-one pass are
            # cut by every neighbour that can reach them.
            u_lo = float(np.max(u[1].mean(axis=0)))
            u_hi = u_lo + (windows - 3) * fz
            uq = np.linspace(u_lo, u_hi, max(200 * (windows - 3), 200))
        for j in range(u.shape[2]):
            rows.append(radius[start + j] - envelope(u[:, :, j], depth[:, :, j], uq))
    if uq is None:
        raise PostprocError("no heights to sample: heights_mm is empty")
    excess = np.stack(rows)
    return FlankSurface(uq, p, excess, fz, t_m)


def plot_flank(surfaces: Mapping[str, FlankSurface], ax=None):
    """Colour maps of the material left on the wall, one panel per surface -> axes."""
    import matplotlib.pyplot as plt

    names = list(surfaces)
    if ax is None:
        _, ax = plt.subplots(3, len(names), figsize=(5.5 * len(names), 10), squeeze=False)
    for col, name in enumerate(names):
        s = surfaces[name]
        scale, unit = (1e6, "nm") if s.form_mm < 1e-4 else (1e3, "µm")
        u_um = (s.u_mm - s.u_mm[0]) * 1e3
        mesh = ax[0, col].pcolormesh(u_um, s.p_mm, s.excess_mm * scale, shading="auto", cmap="viridis")
        ax[0, col].set_title(f"{name}: material left ({unit})")
        ax[0, col].set_xlabel("along the feed (µm)")
        ax[0, col].set_ylabel("height on the cutter p (mm)")
        ax[0, col].figure.colorbar(mesh, ax=ax[0, col])
        near = u_um <= 5 * s.feed_per_edge_mm * 1e3
        for j in np.linspace(0, len(s.p_mm) - 1, 3).astype(int)[1:]:
            ax[1, col].plot(u_um[near], s.excess_mm[j, near] * scale, label=f"p = {s.p_mm[j]:.2f} mm")
        ax[1, col].set_xlabel("along the feed (µm)")
        ax[1, col].set_ylabel(f"material left ({unit})")
        ax[1, col].set_title(f"along the feed (5 feeds of {s.feed_per_edge_mm * 1e3:.2f} µm)")
        ax[1, col].legend(fontsize=8)
        ax[2, col].plot(s.p_mm, s.excess_mm.max(axis=1) * scale, label="highest (cusp tops)")
        ax[2, col].plot(s.p_mm, s.excess_mm.min(axis=1) * scale, label="lowest")
        ax[2, col].set_xlabel("height on the cutter p (mm)")
        ax[2, col].set_ylabel(f"material left ({unit})")
        ax[2, col].set_title("across the height of the wall")
        ax[2, col].legend(fontsize=8)
    ax[0, 0].figure.tight_layout()
    return ax


def plot_trace_near_wall(
    chain: Chain,
    cutter,
    *,
    rpm: float,
    feed_mm_min: float,
    height_mm: float = 0.0,
    revolutions: int = 6,
    span: float = 6.0,
    wall_direction_rad: float = -np.pi / 2,
    context: Mapping[str, float] | None = None,
    ax=None,
):
    """The trace of one edge point near the wall: each pass's arc, the part formula (4)
    keeps (coloured) and the air it skips (grey), with the resulting wall -> axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(8, 4.5))
    edge_rpm = rpm * cutter.flutes
    rev_per_s = edge_rpm / SECONDS_PER_MINUTE
    fz = feed_mm_min / edge_rpm
    t_m = cutting_time_s(fz, cutter.d_mm, rev_per_s)
    p = np.array([float(height_mm)])
    spin, phase = spindle_of(chain)
    t_face = facing_times(cutter.helix_angle_rad(p), wall_direction_rad, edge_rpm, spin, phase)
    wide = window_times(t_face, rev_per_s, span * t_m, revolutions, 801)  # (K, M, 1)
    env = {"Y": 0.0, "Z": 0.0, **(context or {}), "rpm": edge_rpm}
    env.update({"t": wide, "X": feed_mm_min / SECONDS_PER_MINUTE * wide})
    pts = trace_points(chain, cutter.edge(p), env)[..., 0, :]  # (K, M, 3)
    normal = np.array([np.cos(wall_direction_rad), np.sin(wall_direction_rad), 0.0])
    radius = float(np.linalg.norm(cutter.edge(p)[0, :2]))
    u_um = (pts[..., 0] - pts[0, :, 0].mean()) * 1e3
    left_nm = (radius - pts @ normal) * 1e6
    frac = (np.arange(801) + 0.5) / 801 - 0.5  # position inside the wide window
    kept = np.abs(frac * span) <= 0.5
    for k in range(revolutions):
        ax.plot(u_um[k], left_nm[k], color="0.75", lw=1, label="air (skipped)" if k == 0 else None)
        ax.plot(u_um[k, kept], left_nm[k, kept], color="tab:blue", lw=2,
                label="cutting window t_m (formula 4)" if k == 0 else None)
    uq = np.linspace(u_um[1].mean(), u_um[-2].mean(), 2000)
    wall = -envelope(u_um, -left_nm, uq)
    ax.plot(uq, wall, "k--", lw=1, label="wall left (envelope)")
    ax.set_ylim(-0.02, 4 * max(float(np.max(wall)), MIN_PLOT_RANGE_NM))
    ax.set_xlabel("along the feed (µm)")
    ax.set_ylabel("distance from the nominal wall (nm)")
    ax.set_title(f"edge point p = {height_mm:g} mm near the wall: one arc per pass, "
                 f"feed {fz * 1e3:.3g} µm, t_m = {t_m * 1e9:.1f} ns")
    ax.legend(fontsize=8, loc="upper right")
    ax.figure.tight_layout()
    return ax


def raster_section(
    chain: Chain,
    cutter,
    *,
    rpm: float,
    stepover_mm: float,
    passes: int,
    samples: int = 2001,
    context: Mapping[str, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Floor left by parallel ball-end passes ``stepover`` apart along y, in the section x = X.

    The chain must take ``Y`` (the pass position), ``t`` (s) and ``rpm``; pass k runs at
    ``Y = k * stepover``. In each pass the edge points cross the section when they face
    +y or -y; those points (k, both sides, every p) are the section curves, and the floor
    is their lowest envelope. Returns ``(y_mm, height_mm)`` between the first and the last
    pass, the height measured from the tool tip's nominal level (z = 0 at Z = 0).
    """
    if cutter.kind != "ball":
        raise PostprocError(f"a raster section needs a ball-end cutter, got {cutter.kind!r}")
    if passes < 2 or stepover_mm <= 0 or samples < 3:
        raise PostprocError(f"need at least 2 passes, a positive stepover and 3 samples, got "
                            f"{passes}, {stepover_mm}, {samples}")
    edge_rpm = rpm * cutter.flutes
    p = cutter.d_mm / 2 * ball_edge_parameter(np.linspace(0.0, np.pi / 2, samples))
    edge = cutter.edge(p)
    spin, phase = spindle_of(chain)
    ys = np.arange(passes) * stepover_mm
    curves = []
    for side in (np.pi / 2, -np.pi / 2):
        t = facing_times(cutter.helix_angle_rad(p), side, edge_rpm, spin, phase)
        env = {"X": 0.0, "Z": 0.0, **(context or {}), "rpm": edge_rpm, "Y": ys[:, None], "t": t[None, :]}
        curves.append(trace_points(chain, edge, env))  # (passes, P, 3)
    pts = np.concatenate(curves)
    u = np.linspace(ys[0], ys[-1], max(400 * (passes - 1), 200) + 1)
    return u, -envelope(pts[..., 1], -pts[..., 2], u)
