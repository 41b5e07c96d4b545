"""Simulated point measurements (laser tracker) on a virtual machine.

Point sets: :func:`grid_points`, :func:`random_points`, :func:`static_set`.
Context: :func:`measurement_plan` expands a point set over tool vectors, load values,
approach directions and repeated shots, and gives each row its time and temperature.
:func:`simulate_points` runs commanded points through the machine and adds the
tracker noise; the result is a :class:`Measurements` exactly as read from a file.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from postproc.calibration.measurements import Measurements
from postproc.engine.base import check_points, check_tool_vectors
from postproc.errors import PostprocError
from postproc.simulate.machine import Machine

# A grid keeps the far end of an axis when the last step falls short of it by less
# than this: text round-off of the volume must not drop a whole plane of points.
_GRID_END_SLACK_MM = 1e-9

#: Default temperature (deg C) when a temperature column is asked for without a profile.
REFERENCE_TEMP_C = 20.0
# Bounds of a temperature profile: no machine shop is a thousand degrees from freezing, and
# a warm-up that takes longer than 30 years is no warm-up.
MAX_TEMP_C = 1000.0
MAX_TIME_CONSTANT_S = 1e9
# Rows of one simulated campaign: a real one has hundreds to tens of thousands; a million
# rows is ~100 MB of CSV and a few hundred MB while they are made.
MAX_ROWS = 1_000_000


def check_rows(rows: float, what: str, hint: str) -> None:
    """Refuse a campaign of more than :data:`MAX_ROWS` rows (``rows`` may be inf)."""
    if not rows <= MAX_ROWS:
        raise SimulationError(f"{what} makes {rows:.4g} rows: more than {MAX_ROWS:,}", hint=hint)


class SimulationError(PostprocError):
    """A simulation request that cannot be carried out as given."""


def _volume(volume_mm) -> np.ndarray:
    vol = np.asarray(volume_mm, dtype=float)
    if vol.shape != (2, 3) or np.any(vol[0] > vol[1]):
        raise SimulationError(f"volume must be [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {vol.tolist()}")
    return vol


def grid_points(volume_mm, step_mm: float | Sequence[float]) -> np.ndarray:
    """Lattice (N, 3) from the low corner with ``step_mm`` (one or three values), X fastest."""
    vol = _volume(volume_mm)
    steps = np.broadcast_to(np.asarray(step_mm, dtype=float), (3,))
    if np.any(steps <= 0):
        raise SimulationError(f"grid step must be positive, got {steps.tolist()}",
                              hint="give --grid STEP in mm, e.g. --grid 45")
    with np.errstate(over="ignore"):  # a step of 1e-320 mm: inf points, refused below
        counts = np.floor((vol[1] - vol[0]) / steps + _GRID_END_SLACK_MM) + 1
    check_rows(float(np.prod(counts)), f"a grid step of {', '.join(f'{v:g}' for v in steps)} mm",
               "give a larger --grid step")
    axes = [vol[0, j] + steps[j] * np.arange(int(counts[j])) for j in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


def random_points(volume_mm, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniformly distributed in the volume."""
    vol = _volume(volume_mm)
    if n < 1:
        raise SimulationError(f"number of random points must be at least 1, got {n}")
    check_rows(n, f"--random {n}", "ask for fewer --random points")
    return rng.uniform(vol[0], vol[1], (n, 3))


def static_set(volume_mm) -> np.ndarray:
    """The static method's six points: two per axis, from the low corner to each axis end."""
    vol = _volume(volume_mm)
    lo = vol[0]
    rows = []
    for j in range(3):
        end = lo.copy()
        end[j] = vol[1, j]
        rows += [lo.copy(), end]
    return np.array(rows)


def parse_temp_profile(text: str) -> tuple[float, float, float | None]:
    """``"20"`` constant, ``"20:23"`` linear ramp over the run, ``"20:23:1800"`` warm-up
    approaching 23 from 20 with a 1800 s time constant. Returns (start, end, tau_s)."""
    parts = [p.strip() for p in text.split(":")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if not all(math.isfinite(v) for v in values) or any(abs(v) > MAX_TEMP_C for v in values[:2]) or (
            len(values) == 3 and not 0 < values[2] <= MAX_TIME_CONSTANT_S):
        raise SimulationError(f"temperature profile {text!r}: temperatures must be finite numbers within "
                              f"{MAX_TEMP_C:g} deg C and the time constant finite, above 0 s and at most "
                              f"{MAX_TIME_CONSTANT_S:g} s", hint="e.g. --temp-profile 20:23:1800 (deg C, deg C, seconds)")
    if not 1 <= len(values) <= 3 or (len(values) == 3 and values[2] <= 0):
        raise SimulationError(f"temperature profile {text!r}: expected T, T0:T1 or T0:T1:TAU_S",
                              hint="e.g. --temp-profile 20:23:1800 (deg C, deg C, seconds)")
    if len(values) == 1:
        return values[0], values[0], None
    return values[0], values[1], values[2] if len(values) == 3 else None


@dataclass
class Plan:
    """Rows of a measurement campaign: commanded q, tool r, approach directions, context."""

    q: np.ndarray
    r: np.ndarray
    direction: np.ndarray
    context: dict[str, np.ndarray] = field(default_factory=dict)

    def context_full(self) -> dict[str, np.ndarray]:
        ctx = dict(self.context)
        for j, name in enumerate(("dirx", "diry", "dirz")):
            ctx[name] = self.direction[:, j]
        return ctx


def measurement_plan(
    points,
    *,
    tool_vectors: Sequence[Sequence[float]] | None = None,
    approach: str = "positive",
    repeats: int = 1,
    time_span_s: float | None = None,
    temp_profile: str | tuple | None = None,
    load_values: Sequence[float] | None = None,
    context: dict[str, float] | None = None,
) -> Plan:
    """Expand ``points`` into the rows of a campaign, in the order they are measured.

    Order: for each load value, for each tool vector, for each point, for each approach
    ("positive": every axis arrives moving +; "both": + then -), ``repeats`` shots.
    ``t`` runs evenly from 0 to ``time_span_s`` over the rows (written when a time span
    is given); ``temp`` follows ``temp_profile`` over that time; ``load`` is written when
    load values are given; ``context`` adds constant columns.
    """
    q0 = check_points(points, "points")
    if approach not in ("positive", "both"):
        raise SimulationError(f"approach {approach!r}: use 'positive' or 'both'")
    if repeats < 1:
        raise SimulationError(f"repeats must be at least 1, got {repeats}")
    tools = np.asarray(tool_vectors if tool_vectors else [(0.0, 0.0, 0.0)], dtype=float).reshape(-1, 3)
    loads = list(load_values) if load_values else [None]
    signs = [1.0] if approach == "positive" else [1.0, -1.0]
    per_point = len(signs) * repeats
    check_rows(float(len(q0)) * per_point * len(tools) * len(loads),
               f"{len(q0)} points x {repeats} repeats x {len(signs)} approaches x {len(tools)} tool vectors x "
               f"{len(loads)} loads", "give fewer --repeats, tool vectors, loads or points")
    qs, rs, dirs, load_col = [], [], [], []
    for load in loads:
        for tool in tools:
            qs.append(np.repeat(q0, per_point, axis=0))
            rs.append(np.broadcast_to(tool, (len(q0) * per_point, 3)))
            sign = np.tile(np.repeat(signs, repeats), len(q0))
            dirs.append(np.repeat(sign[:, None], 3, axis=1))
            load_col.append(np.full(len(q0) * per_point, 0.0 if load is None else float(load)))
    q = np.vstack(qs)
    n = len(q)
    ctx: dict[str, np.ndarray] = {}
    t = np.linspace(0.0, float(time_span_s or 0.0), n) if n > 1 else np.zeros(n)
    if time_span_s is not None:
        ctx["t"] = t
    if temp_profile is not None:
        start, end, tau = parse_temp_profile(temp_profile) if isinstance(temp_profile, str) else temp_profile
        if tau is None:
            frac = t / t[-1] if n > 1 and t[-1] > 0 else np.zeros(n)
            ctx["temp"] = start + (end - start) * frac
        else:
            ctx["temp"] = end + (start - end) * np.exp(-t / tau)
    if load_values:
        ctx["load"] = np.concatenate(load_col)
    for name, value in (context or {}).items():
        ctx[name] = np.full(n, float(value))
    return Plan(q=q, r=np.vstack(rs).copy(), direction=np.vstack(dirs), context=ctx)


def simulate_points(machine: Machine, q, r=None, ctx: dict | None = None,
                    rng: np.random.Generator | None = None, *, direction=None,
                    noise: bool = True) -> Measurements:
    """Measure commanded points ``q`` on ``machine``: m = forward(q, r, ctx) + tracker noise.

    ``ctx`` may hold ``dirx, diry, dirz`` (they become the file's dir columns) and any
    other per-row or scalar context. ``rng`` seeds the noise (default: seed 0).
    """
    q = check_points(q, "q")
    rr = check_tool_vectors(r, len(q))
    ctx = dict(ctx or {})
    dir_names = ("dirx", "diry", "dirz")
    if direction is None and any(k in ctx for k in dir_names):
        direction = np.column_stack([np.broadcast_to(np.asarray(ctx.get(k, 0.0), float), (len(q),))
                                     for k in dir_names])
    if direction is not None:
        direction = np.broadcast_to(np.asarray(direction, dtype=float), (len(q), 3)).copy()
        for j, name in enumerate(dir_names):
            ctx[name] = direction[:, j]
    m = machine.forward(q, rr, ctx)
    if noise and machine.noise.tracker_mm > 0:
        rng = rng if rng is not None else np.random.default_rng(0)
        m = m + rng.normal(0.0, machine.noise.tracker_mm, m.shape)
    context = {k: np.broadcast_to(np.asarray(v, dtype=float), (len(q),)).copy()
               for k, v in ctx.items() if k not in dir_names}
    return Measurements(q=q, m=m, r=rr, direction=direction, context=context,
                        path="", meta={}, has_tool_columns=True)


def simulate_plan(machine: Machine, plan: Plan, rng: np.random.Generator | None = None,
                  *, noise: bool = True) -> Measurements:
    """:func:`simulate_points` over the rows of a :func:`measurement_plan`."""
    return simulate_points(machine, plan.q, plan.r, plan.context, rng, direction=plan.direction,
                           noise=noise)
