"""The fit's measures as they were written before their overhead was cut:
:func:`postproc.gcode.segment.bisector_centre` and
:func:`~postproc.gcode.segment.arc_candidates` (with its limited form and the samples'
deviation). Kept here, unchanged, as the reference ``tests/test_gcode_fit_exact.py``
holds the present ones to: bit for bit, but for the centre fit, which now takes its sums
in order where numpy's went through BLAS (it fits the points as closely).

Also the R form's candidates as the writer chose them in Python (:func:`r_candidates`,
with :func:`r_center` as geometry had it), the reference ``tests/test_fitcore.py``
holds :meth:`postproc.gcode.fitcore.ArcTry.r_form` to, bit for bit.

Angles are the C library's ``atan2`` (:func:`_arctan2`), as numpy's ``arctan2`` gave them
where these measures were written: where the CPU has AVX-512, numpy takes its own
vectorised ``arctan2`` instead, which differs from the C library's in the last bit of
about 2 % of the angles, and the reference would then move with the machine."""

from __future__ import annotations

import math

import numpy as np

from postproc.constants import ARC_RADIUS_ABS_MM, ARC_RADIUS_REL
from postproc.gcode import emit
from postproc.gcode.geometry import FULL_CIRCLE_MM, TWO_PI
from postproc.gcode.segment import (
    CENTRE_LATTICE,
    CENTRE_SETTLED_MM,
    MIN_ARC_RADIUS_MM,
    MIN_ARC_SWEEP_RAD,
    controller_limits_of,
    full_of,
)

_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


def _arctan2(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.arctan2`` element by element with the C library's ``atan2`` (math.atan2)."""
    return np.asarray(_ATAN2(y, x), dtype=float)


def bisector_centre(S2, E2, P2, c0):
    """Centre (2,) on the perpendicular bisector of S2-E2 whose circle through both fits
    the points P2 (k, 2) best (least squares on the radial distance); ``c0``: first guess.

    Gauss-Newton on the one free parameter, the signed distance ``t`` of the centre
    from the chord's midpoint along the bisector."""
    M = 0.5 * (S2 + E2)
    D = E2 - S2
    L = math.hypot(D[0], D[1])
    if L == 0.0:
        return np.asarray(c0, dtype=float)
    n = np.array([-D[1], D[0]]) / L
    h = 0.5 * L
    t = float((np.asarray(c0, dtype=float) - M) @ n)
    m0, m1 = float(M[0]), float(M[1])
    n0, n1 = float(n[0]), float(n[1])
    c = np.empty(2)
    for _ in range(12):
        # the centre M + t n, element by element as numpy computes it
        c[0] = m0 + t * n0
        c[1] = m1 + t * n1
        v = P2 - c
        dist = np.hypot(v[:, 0], v[:, 1])
        dist = np.where(dist > 0, dist, 1e-300)
        rho = math.hypot(h, t)
        res = dist - rho
        # minus the Jacobian, -J = (v . n) / dist + t / rho: negating a rounded result is
        # exact, so the step is the same as with J itself
        mJ = (v @ n) / dist + t / rho
        den = float(mJ @ mJ)
        if den <= 0.0:
            break
        dt = float(mJ @ res) / den
        # a step across the chord would flip the arc to the other side: halve it
        if (t + dt) * t < 0 and abs(t) > 0:
            dt = -0.5 * t
        t += dt
        # settled far below any output step: the steps after the third or fourth are
        # rounding noise (about 1e-12 mm on a radius of a few mm), iterating on only makes
        # t wander within it. (On a radius of kilometres the noise stays above it, and all
        # the steps are taken.)
        if abs(dt) <= CENTRE_SETTLED_MM:
            break
    return M + t * n


def arc_candidates(S, E, C, axes, clockwise, nominal_sweep,
                   Q, frac_nominal, controller_limits = False,
                   mismatch_limit = None):
    """Deviation of the corrected samples ``Q`` (k, 3) from the arcs that controllers draw
    from S to E around each candidate centre ``C`` (m, 2, plane coordinates).

    Returns ``(worst (m,), mismatch (m,), turns (m,))``: ``worst`` is the largest
    distance of a sample from the spiral (LinuxCNC's reading: radius from the start
    radius to the end radius) plus the radius mismatch (the most any controller that
    draws on one radius and jumps at the end, Grbl or Fanuc, adds to it); inf where the
    arc would turn the wrong way or the wrong number of turns. ``frac_nominal`` (k,):
    where each sample lies along the piece (0 at S, 1 at E), which resolves the
    angle's turn for multi-turn arcs. ``controller_limits``: ``worst`` is also inf where
    a controller refuses or misreads the arc: a start or end radius below
    :data:`MIN_ARC_RADIUS_MM`, a sweep below :data:`MIN_ARC_SWEEP_RAD`.

    ``mismatch_limit``: the candidates whose radius mismatch exceeds it (which the caller
    refuses anyway) are not measured: their ``worst`` is inf and their ``turns`` 0. The
    others get the values they get among all (see :func:`_limited_candidates`)."""
    a1, a2, an = axes
    s1, s2, e1, e2 = S[a1], S[a2], E[a1], E[a2]
    # start (row 0) and end (row 1) about every candidate, in contiguous arrays
    dx = np.array([[s1], [e1]]) - C[:, 0]
    dy = np.array([[s2], [e2]]) - C[:, 1]
    rad = np.hypot(dx, dy)
    r0, r1 = rad[0], rad[1]
    mismatch = np.abs(r1 - r0)
    if mismatch_limit is not None:
        return _limited_candidates(S, E, C, dx, dy, rad, mismatch, mismatch_limit, axes, clockwise, nominal_sweep,
                                   Q, frac_nominal, controller_limits)
    ang = _arctan2(dy, dx)
    t0, t1 = ang[0], ang[1]
    if clockwise:
        base = -np.mod(t0 - t1, TWO_PI)
    else:
        base = np.mod(t1 - t0, TWO_PI)
    chord = math.hypot(e1 - s1, e2 - s2)
    full = (np.abs(base) < 1e-12) | (chord < FULL_CIRCLE_MM)
    base = np.where(full, -TWO_PI if clockwise else TWO_PI, base)
    # np.rint: np.round with no decimals, without its wrapper
    turns = np.maximum(1, np.rint((abs(nominal_sweep) - np.abs(base)) / TWO_PI) + 1).astype(int)
    sweep = base + np.sign(base) * (turns - 1) * TWO_PI
    bad = np.abs(sweep - nominal_sweep) > math.pi / 2
    if controller_limits:
        bad |= (np.minimum(r0, r1) < MIN_ARC_RADIUS_MM) | (np.abs(sweep) < MIN_ARC_SWEEP_RAD)
    dev = _deviation(S, E, C, t0, sweep, r0, r1, axes, clockwise, Q, frac_nominal)
    return np.where(bad, np.inf, dev + mismatch), mismatch, turns


def _limited_candidates(S, E, C, dx, dy, rad,
                        mismatch, limit, axes, clockwise, nominal_sweep,
                        Q, frac_nominal,
                        controller_limits):
    """:func:`arc_candidates` with a mismatch limit: the few candidates within it are
    taken one by one in plain floats (their mismatch is finite, so are all their values),
    with the same operations as numpy's element by element (``%`` is np.mod's floored
    remainder, ``round`` np.rint's half to even, ``copysign`` np.sign of a nonzero
    sweep); their angles come from numpy's arctan2 as among all, and the samples are
    measured with numpy."""
    m = len(C)
    worst = np.full(m, np.inf)
    turns = np.zeros(m, dtype=int)
    sel = np.flatnonzero(mismatch <= limit)
    if len(sel) == 0:
        return worst, mismatch, turns
    a1, a2, _an = axes
    s1, s2, e1, e2 = S[a1], S[a2], E[a1], E[a2]
    ang = _arctan2(dy[:, sel], dx[:, sel])
    full_chord = math.hypot(e1 - s1, e2 - s2) < FULL_CIRCLE_MM
    full_sweep = -TWO_PI if clockwise else TWO_PI
    nsw = abs(nominal_sweep)
    idx, t0k, swk, r0k, r1k = [], [], [], [], []
    for i, t0, t1, r0, r1 in zip(sel.tolist(), ang[0].tolist(), ang[1].tolist(), rad[0, sel].tolist(),
                                 rad[1, sel].tolist(), strict=True):
        base = -((t0 - t1) % TWO_PI) if clockwise else (t1 - t0) % TWO_PI
        if abs(base) < 1e-12 or full_chord:
            base = full_sweep
        tr = max(1, round((nsw - abs(base)) / TWO_PI) + 1)
        turns[i] = tr
        sweep = base + math.copysign(1.0, base) * (tr - 1) * TWO_PI
        if abs(sweep - nominal_sweep) > math.pi / 2:
            continue
        if controller_limits and (min(r0, r1) < MIN_ARC_RADIUS_MM or abs(sweep) < MIN_ARC_SWEEP_RAD):
            continue
        idx.append(i)
        t0k.append(t0)
        swk.append(sweep)
        r0k.append(r0)
        r1k.append(r1)
    if idx:
        worst[idx] = _deviation(S, E, C[idx], np.array(t0k), np.array(swk), np.array(r0k), np.array(r1k), axes,
                                clockwise, Q, frac_nominal) + mismatch[idx]
    return worst, mismatch, turns


def _deviation(S, E, C, t0, sweep, r0,
               r1, axes, clockwise, Q, frac_nominal):
    """Largest distance (m,) of the samples Q (k, 3) from the spiral a controller draws
    around each centre C (m, 2) from angle ``t0`` sweeping ``sweep``, radius ``r0`` to
    ``r1`` (see :func:`arc_candidates`)."""
    a1, a2, an = axes
    v1 = Q[:, a1] - C[:, 0:1]
    v2 = Q[:, a2] - C[:, 1:2]
    asw = np.abs(sweep)[:, None]
    # the angle from the start the way the arc turns ((phi - t0) * -1 is t0 - phi exactly);
    # the arithmetic in place (the same operations, fewer temporary arrays)
    phi = _arctan2(v2, v1)
    if clockwise:
        alpha = np.subtract(t0[:, None], phi, out=phi)
    else:
        alpha = np.subtract(phi, t0[:, None], out=phi)
    np.mod(alpha, TWO_PI, out=alpha)
    turn = frac_nominal * asw  # the target angle, then the turns to add
    np.subtract(turn, alpha, out=turn)
    np.divide(turn, TWO_PI, out=turn)
    np.rint(turn, out=turn)
    np.multiply(turn, TWO_PI, out=turn)
    np.add(alpha, turn, out=alpha)
    frac = np.divide(alpha, asw, out=alpha)
    rad = (r1 - r0)[:, None] * frac
    np.add(r0[:, None], rad, out=rad)
    nrm = (E[an] - S[an]) * frac
    np.add(S[an], nrm, out=nrm)
    np.subtract(Q[:, an], nrm, out=nrm)
    radial = np.hypot(v1, v2, out=v1)
    np.subtract(radial, rad, out=radial)
    dev = np.hypot(radial, nrm, out=radial).max(axis=1)
    return dev


def r_center(s1, s2, e1, e2, R, clockwise):
    """Centre the controller computes for an R-format arc from (s1, s2) to (e1, e2) in
    its plane (a negative R takes the longer way round), or None where the ends coincide
    or R is short of half the chord by more than the controllers' tolerance."""
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


def r_candidates(tr, centre, nsw, d, unit, budget):
    """The R-form arc of the try ``tr`` (a fitcore.ArcTry) nearest ``centre`` that passes,
    as the writer's fit (MoveFit._r_candidates) chose it: ``(texts, cx, cy, spec)``, the
    candidates' words and centres and the spec (None where none passes)."""
    clockwise = tr.clockwise
    s1, s2, e1, e2 = tr.s1, tr.s2, tr.e1, tr.e2
    step = 10.0 ** (-d)
    half = 0.5 * math.hypot(e1 - s1, e2 - s2)
    if half == 0.0:
        return [], [], [], None
    rho = 0.5 * (math.hypot(s1 - centre[0], s2 - centre[1]) + math.hypot(e1 - centre[0], e2 - centre[1]))
    sign = -1.0 if abs(nsw) > math.pi else 1.0
    r0 = round(rho / unit, d)
    vals = {round(r0 + k * step, d) for k in range(-CENTRE_LATTICE, CENTRE_LATTICE + 1)}
    vals |= {round(math.ceil(half / unit / step) * step + k * step, d) for k in (0, 1, 2)}
    texts, cx, cy = [], [], []
    for val in sorted(vals):
        text = emit.fmt(sign * val, d)
        R = float(text) * unit
        if abs(R) <= half:
            continue  # every controller must find a centre without its own tolerance
        c = r_center(s1, s2, e1, e2, R, clockwise)
        if c is not None:
            texts.append(text)
            cx.append(c[0])
            cy.append(c[1])
    if not texts:
        return texts, cx, cy, None
    meas = tr.measure(cx, cy, math.inf, controller_limits_of(True), budget)
    w, _m, t = full_of(meas)
    best = -1
    for j, (wj, tj) in enumerate(zip(w.tolist(), t.tolist(), strict=True)):
        if tj == 1 and (best < 0 or wj < w[best]):
            best = j
    if best < 0 or not w[best] <= budget:
        return texts, cx, cy, None
    return texts, cx, cy, {"form": "r", "vals": (("R", texts[best]),), "turns": 1, "dev": float(w[best]),
                           "mismatch": meas.mismatch[best]}
