"""Points along moves: straight lines and (helical, multi-turn, spiral) arcs.

An arc is parametrised by ``s`` in [0, 1]: angle ``theta0 + s * sweep`` around the
centre in the plane, radius from the start radius to the end radius (a controller
draws this spiral when they differ slightly), and the normal axis linear in ``s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np

from postproc.constants import ARC_RADIUS_ABS_MM, ARC_RADIUS_REL
from postproc.gcode import fitcore
from postproc.gcode.moves import Arc
from postproc.gcode.state import PLANES

TWO_PI = 2.0 * math.pi
FULL_CIRCLE_MM = fitcore.FULL_CIRCLE_MM  # start and end closer than this make a full circle (I/J/K arcs)


#: ``arc_params`` of an arc: (plane axes, start angle, sweep, start radius, end radius)
ArcParams: TypeAlias = tuple[tuple[int, int, int], float, float, float, float]


def arc_params(arc: Arc, q0, q1) -> ArcParams:
    """``((a1, a2, an), theta0, sweep, r0, r1)`` of an arc from q0 to q1 (signed sweep;
    :func:`postproc.gcode.fitcore.arc_sweep`)."""
    (a1, a2, an), _ = PLANES[arc.plane]
    c = arc.center
    # (plain floats, a bool and an int: the compiled formula takes no numpy scalar)
    t0, sweep, r0, r1 = fitcore.arc_sweep((float(c[a1]), float(c[a2])), (float(q0[a1]), float(q0[a2])),
                                          (float(q1[a1]), float(q1[a2])), bool(arc.clockwise), int(arc.turns))
    return (a1, a2, an), t0, sweep, r0, r1


def arc_points(arc: Arc, q0, q1, s: np.ndarray, params=None) -> np.ndarray:
    """Nominal points (k, 3) at parameters ``s`` along the arc (``params``: its
    :func:`arc_params`, when already known)."""
    (a1, a2, an), t0, sweep, r0, r1 = params or arc_params(arc, q0, q1)
    s = np.asarray(s, dtype=float)
    th = t0 + s * sweep
    rad = r0 + (r1 - r0) * s
    out = np.empty((len(s), 3))
    out[:, a1] = arc.center[a1] + rad * np.cos(th)
    out[:, a2] = arc.center[a2] + rad * np.sin(th)
    out[:, an] = q0[an] + (q1[an] - q0[an]) * s
    return out


def arc_length(arc: Arc, q0, q1, params=None) -> float:
    """Length of the arc (``params``: its :func:`arc_params`, when already known)."""
    (a1, a2, an), _t0, sweep, r0, r1 = params or arc_params(arc, q0, q1)
    planar = abs(sweep) * 0.5 * (r0 + r1)
    return math.hypot(planar, q1[an] - q0[an])


@dataclass(frozen=True, eq=False)
class ArcColumns:
    """Many arcs at once, as columns (k arcs): ``axes`` (k, 3) the plane axes and the
    normal axis, ``t0``, ``sweep``, ``r0``, ``r1`` (k,) as :func:`arc_params` gives them,
    ``centre``, ``q0``, ``q1`` (k, 3)."""

    axes: np.ndarray
    t0: np.ndarray
    sweep: np.ndarray
    r0: np.ndarray
    r1: np.ndarray
    centre: np.ndarray
    q0: np.ndarray
    q1: np.ndarray


def arcs_points(owner: np.ndarray, s: np.ndarray, arcs: ArcColumns) -> np.ndarray:
    """Points (len(s), 3) of many arcs at once: sample j on arc ``owner[j]`` at parameter
    ``s[j]``. Element by element the operations of :func:`arc_points`, so each point is
    the one it gives."""
    th = arcs.t0[owner] + s * arcs.sweep[owner]
    rad = arcs.r0[owner] + (arcs.r1 - arcs.r0)[owner] * s
    out = np.empty((len(s), 3))
    centre, q0, q1 = arcs.centre, arcs.q0, arcs.q1
    if len(arcs.axes) and (arcs.axes == arcs.axes[0]).all():  # every arc in one plane: by columns
        b1, b2, bn = arcs.axes[0].tolist()
        out[:, b1] = centre[owner, b1] + rad * np.cos(th)
        out[:, b2] = centre[owner, b2] + rad * np.sin(th)
        out[:, bn] = q0[owner, bn] + (q1 - q0)[owner, bn] * s
        return out
    idx = np.arange(len(s))
    ax = arcs.axes[owner]
    a1, a2, an = ax[:, 0], ax[:, 1], ax[:, 2]
    out[idx, a1] = centre[owner, a1] + rad * np.cos(th)
    out[idx, a2] = centre[owner, a2] + rad * np.sin(th)
    out[idx, an] = q0[owner, an] + (q1 - q0)[owner, an] * s
    return out


def line_points(q0, q1, s: np.ndarray) -> np.ndarray:
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    s = np.asarray(s, dtype=float)[:, None]
    return q0 + (q1 - q0) * s


def arc_chord_steps(arc: Arc, q0, q1, tol_mm: float, params: ArcParams | None = None) -> int:
    """Number of equal chords whose sagitta is below ``tol_mm`` (``params``: the arc's
    :func:`arc_params`, when already known)."""
    (_, _, _), _t0, sweep, r0, r1 = params or arc_params(arc, q0, q1)
    r = max(r0, r1)
    if r <= tol_mm:
        return max(1, math.ceil(abs(sweep) / (math.pi / 2)))
    dtheta = 2.0 * math.acos(max(-1.0, 1.0 - tol_mm / r))
    return max(1, math.ceil(abs(sweep) / dtheta))


# how far R may fall short of half the chord (mm, and a share of |R|, the larger) before
# a controller refuses an R-format arc; within it the centre is on the chord
R_TOLERANCE = (ARC_RADIUS_ABS_MM, ARC_RADIUS_REL)


def r_center(s1: float, s2: float, e1: float, e2: float, R: float, clockwise: bool) -> tuple[float, float] | None:
    """Centre the controller computes for an R-format arc from (s1, s2) to (e1, e2) in
    its plane (a negative R takes the longer way round), or None where the ends coincide
    or R is short of half the chord by more than :data:`R_TOLERANCE`
    (:func:`postproc.gcode.fitcore.r_center`)."""
    return fitcore.r_center(s1, s2, e1, e2, R, bool(clockwise), *R_TOLERANCE)
