"""Segmentation: keep the emitted path within tolerance of the corrected ideal path.

- :func:`subdivide` splits curves (straight moves under a non-affine correction,
  linearised arcs) adaptively: a chord is accepted when the corrected point at the
  middle of its parameter interval lies within the threshold of the chord's middle.
  All midpoints of one level, over all curves of a chunk, go to the engine in one
  vectorised call.
- :func:`check_arc` decides whether a corrected arc can stay an arc: the arc that
  the controller will draw from the emitted words must pass the controller's radius
  check and lie within tolerance of the corrected ideal path at every sample.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from postproc.constants import ARC_RADIUS_ABS_MM, ARC_RADIUS_REL
from postproc.errors import SolverError
from postproc.gcode.geometry import TWO_PI, arc_params, arc_points, line_points
from postproc.gcode.interp import Arc

# Deepest subdivision: 2**20 pieces of one move means the correction field is not
# smooth at the tolerance's scale (or is broken); refuse rather than emit millions of lines.
MAX_SUBDIVISION_DEPTH = 20
# A chord is accepted when the midpoint deviation is below this fraction of the
# budget: the midpoint is where a smooth curve departs most from its chord, and the
# margin covers curves whose deviation peaks slightly off-centre.
MIDPOINT_SAFETY = 0.5


@dataclass
class Curve:
    """A move to follow: nominal gauge points as a function of s in [0, 1]."""

    q0: tuple
    q1: tuple
    arc: Arc | None
    r: np.ndarray  # (3,) tool vector
    dirs: np.ndarray  # (3,) approach signs carried into the move
    lineno: int
    rotary: dict
    params: tuple | None = None  # arc_params of an arc (computed once)

    def nominal(self, s: np.ndarray) -> np.ndarray:
        if self.arc is None:
            return line_points(self.q0, self.q1, s)
        if self.params is None:
            self.params = arc_params(self.arc, self.q0, self.q1)
        return arc_points(self.arc, self.q0, self.q1, s, self.params)

    def directions(self, s: np.ndarray, nominal: np.ndarray | None = None) -> np.ndarray:
        """Sign of each axis's motion at parameter s (the carried sign where it does not
        move); ``nominal``: ``self.nominal(s)`` when already computed."""
        if self.arc is None:
            d = np.sign(np.asarray(self.q1) - np.asarray(self.q0))
            d = np.where(d == 0, self.dirs, d)
            return np.broadcast_to(d, (len(s), 3))
        h = 1e-6
        here = self.nominal(s) if nominal is None else nominal
        d = np.sign(here - self.nominal(np.clip(s - h, 0.0, 1.0)))
        return np.where(d == 0, self.dirs, d)


Evaluate = Callable[[np.ndarray, list, list], np.ndarray]


def subdivide(curves: list[Curve], s_init: list[np.ndarray], evaluate, threshold_mm: float):
    """Adaptive subdivision of every curve; returns ``[(s (k,), q (k, 3)), ...]``.

    ``evaluate(curve_index (N,), s (N,))`` returns corrected gauge points (N, 3) for
    all requested parameters in one call.
    """
    if not curves:
        return []
    thr = threshold_mm * MIDPOINT_SAFETY
    cid = np.concatenate([np.full(len(s), i) for i, s in enumerate(s_init)])
    ss = np.concatenate(s_init)
    q = evaluate(cid, ss)
    knots: list[list] = [[] for _ in curves]
    offs = np.cumsum([0] + [len(s) for s in s_init])
    pend_c, pend_a, pend_b, qa, qb = [], [], [], [], []
    for i, s in enumerate(s_init):
        qi = q[offs[i]:offs[i + 1]]
        knots[i].extend(zip(s.tolist(), qi, strict=True))
        pend_c.append(np.full(len(s) - 1, i))
        pend_a.append(s[:-1])
        pend_b.append(s[1:])
        qa.append(qi[:-1])
        qb.append(qi[1:])
    pc, pa, pb = np.concatenate(pend_c), np.concatenate(pend_a), np.concatenate(pend_b)
    qa, qb = np.vstack(qa), np.vstack(qb)
    depth = 0
    while len(pc):
        depth += 1
        if depth > MAX_SUBDIVISION_DEPTH:
            worst = curves[int(pc[0])]
            raise SolverError(
                f"the correction varies too fast along this move to follow within {threshold_mm:g} mm",
                lineno=worst.lineno, hint="check the calibration (is it smooth?) or raise --tolerance")
        sm = 0.5 * (pa + pb)
        qm = evaluate(pc, sm)
        dev = np.linalg.norm(qm - 0.5 * (qa + qb), axis=1)
        bad = dev > thr
        for c, s, qq in zip(pc[bad].tolist(), sm[bad].tolist(), qm[bad], strict=True):
            knots[c].append((s, qq))
        pc = np.concatenate([pc[bad], pc[bad]])
        pa, pb = np.concatenate([pa[bad], sm[bad]]), np.concatenate([sm[bad], pb[bad]])
        qa, qb = np.vstack([qa[bad], qm[bad]]), np.vstack([qm[bad], qb[bad]])
    out = []
    for k in knots:
        k.sort(key=lambda t: t[0])
        out.append((np.array([t[0] for t in k]), np.array([t[1] for t in k])))
    return out


def r_center(s1: float, s2: float, e1: float, e2: float, R: float, clockwise: bool):
    """Centre the controller computes for an R-format arc, or None if R is too small."""
    dx, dy = e1 - s1, e2 - s2
    chord = math.hypot(dx, dy)
    if chord == 0.0:
        return None
    half = chord / 2
    if abs(R) < half:
        if half - abs(R) > max(ARC_RADIUS_ABS_MM, ARC_RADIUS_REL * abs(R)):
            return None
        h = 0.0
    else:
        h = math.sqrt(R * R - half * half)
    sign = -1.0 if clockwise else 1.0
    if R < 0:
        sign = -sign
    mx, my = (s1 + e1) / 2, (s2 + e2) / 2
    return mx - sign * h * dy / chord, my + sign * h * dx / chord


def centre_estimate(arc: Arc, s_nom: np.ndarray, q_nom: np.ndarray, q_corr: np.ndarray) -> np.ndarray:
    """Corrected centre: the correction fitted as affine in the plane, evaluated at the centre."""
    (a1, a2, _an), _ = _plane(arc)
    d = q_corr - q_nom
    c = np.asarray(arc.center, dtype=float)
    # coordinates about the centre keep the 3x3 normal equations well conditioned;
    # the fitted constant term is then the correction at the centre
    A = np.column_stack([np.ones(len(q_nom)), q_nom[:, a1] - c[a1], q_nom[:, a2] - c[a2]])
    try:
        coef = np.linalg.solve(A.T @ A, A.T @ d)
    except np.linalg.LinAlgError:
        # an arc so short that its samples do not span the plane: the correction
        # does not vary along it; the centre gets the mean
        return c + d.mean(axis=0)
    return c + coef[0]


def _plane(arc: Arc):
    from postproc.gcode.state import PLANES

    return PLANES[arc.plane]


def arc_deviation(arc: Arc, S, E, s_samples: np.ndarray, q_samples: np.ndarray, nominal_sweep: float,
                  input_mismatch_mm: float = 0.0) -> float:
    """Largest distance from the corrected samples to the arc a controller draws from
    S to E around ``arc.center`` (spiral radius, linear normal axis); inf if the
    arc fails the controller's radius check (or is worse than the input arc, which
    the user's controller accepts) or turns the wrong way."""
    (a1, a2, an), t0, sweep, r0, r1 = arc_params(arc, S, E)
    if abs(r0 - r1) > max(ARC_RADIUS_ABS_MM, ARC_RADIUS_REL * r0, input_mismatch_mm):
        return math.inf
    if abs(sweep - nominal_sweep) > math.pi / 2:
        return math.inf
    c1, c2 = arc.center[a1], arc.center[a2]
    v1 = q_samples[:, a1] - c1
    v2 = q_samples[:, a2] - c2
    phi = np.arctan2(v2, v1)
    sgn = -1.0 if arc.clockwise else 1.0
    alpha = ((phi - t0) * sgn) % TWO_PI
    target = s_samples * abs(sweep)
    alpha = alpha + TWO_PI * np.round((target - alpha) / TWO_PI)
    frac = alpha / abs(sweep)
    rad = r0 + (r1 - r0) * frac
    nrm = S[an] + (E[an] - S[an]) * frac
    dev = np.hypot(np.hypot(v1, v2) - rad, q_samples[:, an] - nrm)
    return float(dev.max())
