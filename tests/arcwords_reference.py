"""The per-arc centre-word decision as it was written before it became one method:
``ArcHint.spec`` (the rounded centre on the written ends' bisector, its deviation bound)
followed by the emitter's controller-limit check. Kept here, unchanged, as the reference
``tests/test_gcode_arcwords.py`` holds :meth:`postproc.gcode.vplan.ArcHint.spec` and
:meth:`~postproc.gcode.vplan.ArcHint.words` to, bit for bit."""

import math

from postproc.gcode import emit
from postproc.gcode.hintcore import ORDER as _ORDER
from postproc.gcode.segment import MIN_ARC_RADIUS_MM, MIN_ARC_SWEEP_RAD
from postproc.gcode.state import PLANES
from postproc.gcode.vplan import TWO_PI


def within_controller_limits(S, E, centre, axes, clockwise):
    """Whether controllers cut the arc from S to E around ``centre`` as that arc: both
    radii at least MIN_ARC_RADIUS_MM and, unless S and E coincide in the plane, a sweep
    of at least MIN_ARC_SWEEP_RAD."""
    a1, a2, _an = axes
    c1, c2 = float(centre[0]), float(centre[1])
    if min(math.hypot(S[a1] - c1, S[a2] - c2), math.hypot(E[a1] - c1, E[a2] - c2)) < MIN_ARC_RADIUS_MM:
        return False
    if S[a1] == E[a1] and S[a2] == E[a2]:
        return True
    t0, t1 = math.atan2(S[a2] - c2, S[a1] - c1), math.atan2(E[a2] - c2, E[a1] - c1)
    sweep = (t0 - t1) % TWO_PI if clockwise else (t1 - t0) % TWO_PI
    return sweep >= MIN_ARC_SWEEP_RAD


def _bound(hint, clockwise, S, E, C1, C2, axes):
    a1, a2, an = axes
    hyp = math.hypot
    s1, s2, e1, e2 = S[a1], S[a2], E[a1], E[a2]
    rs, re = hyp(s1 - C1, s2 - C2), hyp(e1 - C1, e2 - C2)
    th0, th1 = math.atan2(s2 - C2, s1 - C1), math.atan2(e2 - C2, e1 - C1)
    sweep = -((th0 - th1) % TWO_PI) if clockwise else (th1 - th0) % TWO_PI
    if sweep == 0.0 or abs(sweep - hint.nsweep) > math.pi / 2:
        return None
    moved = hyp(C1 - hint.c1, C2 - hint.c2)
    u1, u2, un, w1, w2, wn = hint.ends
    shift = max(hyp(s1 - u1, s2 - u2), hyp(e1 - w1, e2 - w2))
    bound = hint.worst + moved + max(abs(rs - hint.rho), abs(re - hint.rho))
    r_min = min(rs, re, hint.rho)
    if not r_min > 0.0:
        return None
    dfrac = 3.0 * (moved + shift) / (r_min * abs(sweep))
    return bound + max(abs(S[an] - un), abs(E[an] - wn)) + abs(E[an] - S[an]) * dfrac


def spec(hint, mv, S, E, d, budget):
    """The old ``ArcHint.spec``: the words' texts and bound, or None."""
    arc = mv.arc
    (a1, a2, an), (l1, l2) = PLANES[arc.plane]
    s1, s2, e1, e2 = S[a1], S[a2], E[a1], E[a2]
    dx, dy = e1 - s1, e2 - s2
    L = math.hypot(dx, dy)
    if L == 0.0:
        return None
    m1, m2 = 0.5 * (s1 + e1), 0.5 * (s2 + e2)
    n1, n2 = -dy / L, dx / L
    t = (hint.c1 - m1) * n1 + (hint.c2 - m2) * n2
    p1, p2 = m1 + t * n1, m2 + t * n2
    unit = mv.unit
    if mv.arc_absolute:
        b1, b2 = mv.shift[a1], mv.shift[a2]
    else:
        b1, b2 = s1, s2
    step = 10.0 ** (-d)
    agree = 0.5 * step * unit
    v1 = round((p1 - b1) / unit, d)
    v2 = round((p2 - b2) / unit, d)
    hyp = math.hypot
    best = None
    for k1, k2 in _ORDER:
        w1, w2 = round(v1 + k1 * step, d), round(v2 + k2 * step, d)
        C1, C2 = b1 + w1 * unit, b2 + w2 * unit
        mism = abs(hyp(s1 - C1, s2 - C2) - hyp(e1 - C1, e2 - C2))
        if mism <= agree:
            best = (emit.fmt(w1, d), emit.fmt(w2, d), C1, C2, mism)
            break
    if best is None:
        return None
    t1, t2, C1, C2, mism = best
    bound = _bound(hint, arc.clockwise, S, E, C1, C2, (a1, a2, an))
    if bound is None or not bound + mism <= budget:
        return None
    return {"form": "ij", "vals": ((l1, t1), (l2, t2)), "turns": 1, "dev": bound + mism, "mismatch": mism}


def is_sound(mv, spec_, S, E):
    """The emitter's old ``_hint_is_sound``: the controller-limit check of a spec."""
    arc = mv.arc
    (a1, a2, an), _ = PLANES[arc.plane]
    base = (mv.shift[a1], mv.shift[a2]) if mv.arc_absolute else (S[a1], S[a2])
    (_l1, t1), (_l2, t2) = spec_["vals"]
    centre = (base[0] + float(t1) * mv.unit, base[1] + float(t2) * mv.unit)
    return within_controller_limits(S, E, centre, (a1, a2, an), arc.clockwise)


def decision(hint, mv, S, E, d, budget):
    """The old decision: the spec when it passes the controller-limit check, else None."""
    s = spec(hint, mv, S, E, d, budget)
    return s if s is not None and is_sound(mv, s, S, E) else None
