"""The arc fit's measures over the samples of one try, in plain floats.

The fit (:mod:`postproc.gcode.arcfit`) tries, for each piece of a move, segments over
ranges of its samples; each try measures every sample: its distance from a chord
(:func:`chord_deviation`) and from the arc a controller draws about each rounded
candidate centre (:func:`centre_lattice`, :meth:`ArcTry.measure`), after the fit of the
centre on the bisector of the try's ends (:func:`bisector_centre`). The samples are
columns of floats (lists), one per axis; the loops run over them one sample at a time.

The arithmetic is Python's on floats: ``math.atan2``, the floored ``%``, sums taken in
order, a turn count rounded half to even (:func:`rint`), the centre words rounded as they
are written (:func:`postproc.gcode.numfmt.round_to`, Python's ``round``: the value a
controller reads of the word), and the C library's hypot (:func:`hypot`, GNU libc's
algorithm in plain floats; Python's ``math.hypot`` is another, a last place off it now and
then). The bulk planner measures its arcs with numpy (:mod:`postproc.gcode.vplan`); the
two need not agree in the last place, as each of their decisions is bounded on its own.
The centre fit's Gauss-Newton steps amplify a last place where the centre is ill-defined
(a circle of kilometres through a few millimetres of path): the circle fits the samples
as closely, and the rounded candidates about it are measured as any others, so the arc
written is then another one within the same bounds. That is why the fit's distances keep
one hypot: with ``math.hypot`` in its place, two corpus programs' arcs of 12 and 48 km
radius got centre words a few last digits apart under a uniform scale, whose outputs are
pinned byte for byte.

The R form (:meth:`ArcTry.r_form`) tries rounded radii about the one a centre gives:
each is written as a word, read back, and its centre is the one a controller computes
from it (:func:`r_center`, the package's one formula for it), with the rounding and
formatting of the writers (:func:`postproc.gcode.numfmt.round_to`,
:func:`postproc.gcode.numfmt.fmt`) and ``math.hypot``, as the readers use them.

Compiled at install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled.
It imports nothing of the package but :mod:`postproc.gcode.numfmt`, compiled with it.
"""

from __future__ import annotations

import math
from typing import Final

from postproc.gcode.numfmt import fmt, round_to

TWO_PI: Final = 2.0 * math.pi

_atan2: Final = math.atan2

# rint: adding and taking away 2**52 rounds a float below it to an integer, half to even
_TWO52: Final = 4503599627370496.0
# hypot: glibc's scaling of very large and very small inputs, and the ratio beyond which
# the smaller input does not count
_HYPOT_SCALE: Final = 2.0 ** -600
_HYPOT_LARGE: Final = 2.0 ** 511
_HYPOT_TINY: Final = 2.0 ** -511
_HYPOT_EPS: Final = 2.0 ** -54


def rint(x: float) -> float:
    """The integer nearest ``x``, half to even, as a float; -0.0, inf and nan as they are."""
    if x > 0.0:
        return (x + _TWO52) - _TWO52 if x < _TWO52 else x
    if x < 0.0:
        return -((_TWO52 - x) - _TWO52) if x > -_TWO52 else x
    return x


def hypot(x: float, y: float) -> float:
    """sqrt(x * x + y * y) as the C library computes it (numpy's hypot too): GNU libc's
    algorithm (2.35 and later, without fused multiply-add: C. F. Borges, "An improved
    algorithm for hypot(a, b)", its correction of the square root). Python's math.hypot
    is another algorithm, a last place off it now and then (see the module's docstring)."""
    ax = abs(x)
    ay = abs(y)
    if ax < ay:
        ax, ay = ay, ax
    # (false for a nan)
    if not (ay >= _HYPOT_TINY and ax <= _HYPOT_LARGE):
        return _hypot_scaled(x, y)
    if ay <= ax * _HYPOT_EPS:
        return ax + ay
    return _hypot_kernel(ax, ay)


def _hypot_kernel(ax: float, ay: float) -> float:
    h = math.sqrt(ax * ax + ay * ay)
    if h <= 2.0 * ay:
        delta = h - ay
        t1 = ax * (2.0 * delta - ax)
        t2 = (delta - 2.0 * (ax - ay)) * delta
    else:
        delta = h - ax
        t1 = 2.0 * delta * (ax - 2.0 * ay)
        t2 = (4.0 * delta - ay) * ay + delta * delta
    return h - (t1 + t2) / (2.0 * h)


def _hypot_scaled(x: float, y: float) -> float:
    """:func:`hypot` where an input is not finite, very large or very small."""
    if math.isinf(x) or math.isinf(y):
        return math.inf
    if math.isnan(x) or math.isnan(y):
        return x + y
    x = abs(x)
    y = abs(y)
    ax = y if x < y else x
    ay = x if x < y else y
    if ax > _HYPOT_LARGE:
        if ay <= ax * _HYPOT_EPS:
            return ax + ay
        return _hypot_kernel(ax * _HYPOT_SCALE, ay * _HYPOT_SCALE) / _HYPOT_SCALE
    if ay < _HYPOT_TINY:
        if ax >= ay / _HYPOT_EPS:
            return ax + ay
        return _hypot_kernel(ax / _HYPOT_SCALE, ay / _HYPOT_SCALE) * _HYPOT_SCALE
    if ay <= ax * _HYPOT_EPS:
        return ax + ay
    return _hypot_kernel(ax, ay)


# -- chords -----------------------------------------------------------------------------

def chord_deviation(S: list[float], E: list[float], xs: list[float], ys: list[float], zs: list[float]) -> float:
    """Largest distance of the points (``xs``, ``ys``, ``zs``) from the segment S-E."""
    a0, a1, a2 = S[0], S[1], S[2]
    d0, d1, d2 = E[0] - a0, E[1] - a1, E[2] - a2
    den = d0 * d0 + d1 * d1 + d2 * d2
    worst = 0.0
    nan = False
    for i in range(len(xs)):
        p0, p1, p2 = xs[i] - a0, ys[i] - a1, zs[i] - a2
        if den == 0.0:
            r0, r1, r2 = p0, p1, p2
        else:
            # the parameter of the nearest point of the segment, clipped to [0, 1]
            t = (p0 * d0 + p1 * d1 + p2 * d2) / den
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            r0, r1, r2 = xs[i] - (a0 + t * d0), ys[i] - (a1 + t * d1), zs[i] - (a2 + t * d2)
        sq = r0 * r0 + r1 * r1 + r2 * r2
        if sq > worst:
            worst = sq
        elif sq != sq:
            nan = True
    # the root of the largest sum is the largest root (both correctly rounded)
    return math.nan if nan else math.sqrt(worst)


def chord_exceeds(S: list[float], E: list[float], q: list[float], limit: float) -> bool:
    """True when the point q (3,) lies so far from the segment S-E that
    :func:`chord_deviation` of any points that include q exceeds ``limit``: a cheap
    test that spares the full measure where its answer is known.

    Both this and :func:`chord_deviation` come within a few units in the last place of
    the coordinates' magnitude of q's exact distance from the segment; the margin, a
    billionth of that magnitude, is millions of times more. False also where it cannot
    tell (within the margin, or a value that is not finite)."""
    s0, s1, s2 = S[0], S[1], S[2]
    q0, q1, q2 = q[0], q[1], q[2]
    d0, d1, d2 = E[0] - s0, E[1] - s1, E[2] - s2
    p0, p1, p2 = q0 - s0, q1 - s1, q2 - s2
    den = d0 * d0 + d1 * d1 + d2 * d2
    t = (p0 * d0 + p1 * d1 + p2 * d2) / den if den > 0.0 else 0.0
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    r0, r1, r2 = p0 - t * d0, p1 - t * d1, p2 - t * d2
    # the magnitude: at least the largest coordinate and the segment's length
    scale = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2 + q0 * q0 + q1 * q1 + q2 * q2 + den)
    return math.sqrt(r0 * r0 + r1 * r1 + r2 * r2) > limit + 1e-9 * (1.0 + scale)


# -- centres ----------------------------------------------------------------------------

def centre_lattice(ideal: tuple[float, float], base: tuple[float, float], unit: float, d: int,
                   reach: int) -> tuple[list[float], list[float], list[float], list[float]]:
    """The rounded centre words (``d`` decimals, program units) nearest ``ideal`` (plane
    mm) and the ``reach`` steps on each side of them on both axes, as they are written
    from ``base`` (mm; the words are offsets from it), and the centres they mean:
    ``(w1, w2, c1, c2)``, the second axis's step varying fastest."""
    step = 10.0 ** (-d)
    v1 = round_to((ideal[0] - base[0]) / unit, d)
    v2 = round_to((ideal[1] - base[1]) / unit, d)
    # each axis's words and centres (one rounding per step), then every pair of them
    x1 = [round_to(v1 + k * step, d) for k in range(-reach, reach + 1)]
    x2 = [round_to(v2 + k * step, d) for k in range(-reach, reach + 1)]
    y1 = [base[0] + x * unit for x in x1]
    y2 = [base[1] + x * unit for x in x2]
    w1: list[float] = []
    w2: list[float] = []
    c1: list[float] = []
    c2: list[float] = []
    for i in range(len(x1)):
        w1.extend([x1[i]] * len(x2))
        w2.extend(x2)
        c1.extend([y1[i]] * len(y2))
        c2.extend(y2)
    return w1, w2, c1, c2


# Gauss-Newton steps of bisector_centre stop below this (mm): far below the finest
# output step (1e-4 mm, 1e-5 inch).
CENTRE_SETTLED_MM: Final = 1e-9
# the most Gauss-Newton steps bisector_centre takes
_CENTRE_STEPS: Final = 12
# the distance given a sample on the centre (or one that is not finite): its term of the
# Jacobian stays finite
_ON_CENTRE: Final = 1e-300


def bisector_centre(S2: tuple[float, float], E2: tuple[float, float], us: list[float], vs: list[float],
                    c0: tuple[float, float]) -> tuple[float, float]:
    """Centre on the perpendicular bisector of S2-E2 whose circle through both fits the
    points (``us``, ``vs``) best (least squares on the radial distance); ``c0``: first
    guess, returned as it is where S2 and E2 are one point.

    Gauss-Newton on the one free parameter, the signed distance ``t`` of the centre from
    the chord's midpoint along the bisector; every step one pass over the points. The sums
    are taken in order (see the module's docstring)."""
    s0, s1 = S2
    e0, e1 = E2
    m0, m1 = 0.5 * (s0 + e0), 0.5 * (s1 + e1)
    d0, d1 = e0 - s0, e1 - s1
    L = math.hypot(d0, d1)
    if L == 0.0:
        return c0
    n0, n1 = -d1 / L, d0 / L
    h = 0.5 * L
    t = (c0[0] - m0) * n0 + (c0[1] - m1) * n1
    k = len(us)
    for _ in range(_CENTRE_STEPS):
        c_0 = m0 + t * n0
        c_1 = m1 + t * n1
        rho = math.hypot(h, t)
        q = t / rho
        # minus the Jacobian, -J = (v . n) / dist + t / rho: the step is the same as with J
        den = 0.0
        num = 0.0
        for i in range(k):
            v0 = us[i] - c_0
            v1 = vs[i] - c_1
            dist = hypot(v0, v1)
            if not dist > 0.0:
                dist = _ON_CENTRE
            mj = (v0 * n0 + v1 * n1) / dist + q
            den += mj * mj
            num += mj * (dist - rho)
        if den <= 0.0:
            break
        dt = num / den
        # a step across the chord would flip the arc to the other side: halve it
        if (t + dt) * t < 0.0 and abs(t) > 0.0:
            dt = -0.5 * t
        t += dt
        # settled far below any output step: the steps after the third or fourth are
        # rounding noise (about 1e-12 mm on a radius of a few mm), iterating on only makes
        # t wander within it. (On a radius of kilometres the noise stays above it, and all
        # the steps are taken.)
        if abs(dt) <= CENTRE_SETTLED_MM:
            break
    return m0 + t * n0, m1 + t * n1


# -- an arc's turn ---------------------------------------------------------------------

# Start and end closer than this in the plane make a full circle (I/J/K arcs).
FULL_CIRCLE_MM: Final = 1e-9


def arc_sweep(centre: tuple[float, float], start: tuple[float, float], end: tuple[float, float], clockwise: bool,
              turns: int) -> tuple[float, float, float, float]:
    """``(theta0, sweep, r0, r1)`` of an arc about ``centre`` from ``start`` to ``end``
    (plane coordinates): the start angle, the signed sweep (negative clockwise; a full
    turn where the ends coincide, and ``turns - 1`` more), and the start and end radii
    (Python's ``math.atan2``, ``math.hypot`` and floored ``%``, as
    :func:`postproc.gcode.geometry.arc_params` gives them)."""
    c1, c2 = centre
    s1, s2 = start
    e1, e2 = end
    t0 = math.atan2(s2 - c2, s1 - c1)
    t1 = math.atan2(e2 - c2, e1 - c1)
    r0 = math.hypot(s1 - c1, s2 - c2)
    r1 = math.hypot(e1 - c1, e2 - c2)
    if clockwise:
        sweep = -((t0 - t1) % TWO_PI)
    else:
        sweep = (t1 - t0) % TWO_PI
    if abs(sweep) < 1e-12 or math.hypot(e1 - s1, e2 - s2) < FULL_CIRCLE_MM:
        sweep = -TWO_PI if clockwise else TWO_PI
    extra = (turns - 1) * TWO_PI
    sweep += -extra if clockwise else extra
    return t0, sweep, r0, r1


# -- R-form arcs ------------------------------------------------------------------------

def r_center(s1: float, s2: float, e1: float, e2: float, R: float, clockwise: bool, abs_tol: float,
             rel_tol: float) -> tuple[float, float] | None:
    """Centre the controller computes for an R-format arc from (s1, s2) to (e1, e2) in
    its plane (a negative R takes the longer way round), or None where the ends coincide
    or R is short of half the chord by more than the controllers' tolerance: ``abs_tol``
    (mm) or ``rel_tol`` of |R|, the larger."""
    dx, dy = e1 - s1, e2 - s2
    chord = math.hypot(dx, dy)
    if chord == 0.0:
        return None
    half = chord / 2
    if abs(R) < half:
        if half - abs(R) > max(abs_tol, rel_tol * abs(R)):
            return None
        h = 0.0
    else:
        h = math.sqrt(R * R - half * half)
    sign = -1.0 if clockwise else 1.0
    if R < 0:
        sign = -sign
    mx, my = (s1 + e1) / 2, (s2 + e2) / 2
    return mx - sign * h * dy / chord, my + sign * h * dx / chord


def r_radii(rho: float, half: float, unit: float, d: int, reach: int) -> list[float]:
    """The radii (``d`` decimals, program units; ``unit``: mm per program unit) an R-form
    arc tries, in increasing order: ``rho`` (mm) rounded and ``reach`` steps on each side
    of it, and the three smallest steps above ``half`` (mm, half the chord)."""
    step = 10.0 ** (-d)
    r0 = round_to(rho / unit, d)
    vals = {round_to(r0 + k * step, d) for k in range(-reach, reach + 1)}
    vals |= {round_to(math.ceil(half / unit / step) * step + k * step, d) for k in (0, 1, 2)}
    return sorted(vals)


# -- arcs about candidate centres -----------------------------------------------------------

class Measured:
    """What :meth:`ArcTry.measure` finds of m candidate centres: ``mismatch`` (m) of all;
    ``sel`` the candidates within the limit and ``sel_turns`` their turns; ``idx`` those
    measured (within the limit, turning the right way and within the controller's
    limits), ``worst``, ``turns`` and ``mism``: theirs."""

    mismatch: list[float]
    sel: list[int]
    sel_turns: list[int]
    idx: list[int]
    worst: list[float]
    turns: list[int]
    mism: list[float]

    def __init__(self) -> None:
        self.mismatch = []
        self.sel = []
        self.sel_turns = []
        self.idx = []
        self.worst = []
        self.turns = []
        self.mism = []


def _least_one_turn(found: Measured) -> tuple[int, float]:
    """The first (in the candidates' order) of those that turn once with the least worst,
    and that worst (a candidate refused counts as inf, one beyond the limit as no turn):
    ``(-1, inf)`` where none turns once."""
    m = len(found.mismatch)
    turns = [0] * m
    for k in range(len(found.sel)):
        turns[found.sel[k]] = found.sel_turns[k]
    worst = [math.inf] * m
    for k in range(len(found.idx)):
        worst[found.idx[k]] = found.worst[k]
    best = -1
    least = math.inf
    for j in range(m):
        if turns[j] == 1 and (best < 0 or worst[j] < least):
            best = j
            least = worst[j]
    return best, least


class ArcTry:
    """The samples of a try of an exact arc: from S to E (``ends``: the plane's first,
    second and normal coordinate of S, then of E), turning ``clockwise`` or not by about
    ``nsw`` (rad, signed), through the samples ``us``, ``vs`` (plane), ``ws`` (normal) at
    ``frac`` along it (0 at S, 1 at E: it resolves the angle's turn for multi-turn arcs);
    ``full``: S and E are one point (the arc a full circle)."""

    s1: float
    s2: float
    sn: float
    e1: float
    e2: float
    en: float
    clockwise: bool
    nsw: float
    full: bool
    us: list[float]
    vs: list[float]
    ws: list[float]
    frac: list[float]

    def __init__(self, ends: tuple[float, float, float, float, float, float], clockwise: bool, nsw: float,
                 full: bool, us: list[float], vs: list[float], ws: list[float], frac: list[float]) -> None:
        self.s1, self.s2, self.sn, self.e1, self.e2, self.en = ends
        self.clockwise = clockwise
        self.nsw = nsw
        self.full = full
        self.us, self.vs, self.ws, self.frac = us, vs, ws, frac

    def measure(self, cx: list[float], cy: list[float], limit: float, limits: tuple[float, float],
                stop: float, least: bool = False) -> Measured:
        """The arcs a controller draws from S to E about each candidate centre (``cx``,
        ``cy``): their radius mismatch, and for those within ``limit`` (every one where
        it is inf) their turns and, unless they turn the wrong way or the wrong number of
        turns or fall below ``limits`` (smallest radius, smallest |sweep|), ``worst``:
        the largest distance of a sample from the spiral (LinuxCNC's reading: the radius
        goes from the start radius to the end radius) plus the mismatch (the most any
        controller that draws on one radius and jumps at the end adds to it).

        ``stop``: a candidate's measure stops at a sample that makes its worst exceed
        it (that worst, above ``stop``, is then a lower bound of the full one).
        ``least``: only the least worst matters, and whether another ties with it: the
        measures stop also once above the least worst so far (every candidate whose worst
        is the least is measured in full; the others, above it, may be lower bounds)."""
        out = Measured()
        s1, s2, e1, e2 = self.s1, self.s2, self.e1, self.e2
        clockwise, nominal = self.clockwise, self.nsw
        nsw = abs(nominal)
        full_sweep = -TWO_PI if clockwise else TWO_PI
        half_pi = math.pi / 2
        min_r, min_sweep = limits
        every = limit == math.inf
        arcs: list[tuple[float, float, float, float]] = []  # of the candidates measured
        for j in range(len(cx)):
            x, y = cx[j], cy[j]
            dx0, dy0, dx1, dy1 = s1 - x, s2 - y, e1 - x, e2 - y
            r0, r1 = hypot(dx0, dy0), hypot(dx1, dy1)
            mism = abs(r1 - r0)
            out.mismatch.append(mism)
            if not (every or mism <= limit):
                continue
            t0, t1 = _atan2(dy0, dx0), _atan2(dy1, dx1)
            base = -((t0 - t1) % TWO_PI) if clockwise else (t1 - t0) % TWO_PI
            if self.full or -1e-12 < base < 1e-12:
                base = full_sweep
            tr = round((nsw - (base if base > 0.0 else -base)) / TWO_PI) + 1
            if tr < 1:
                tr = 1
            sweep = base + (1.0 if base > 0.0 else -1.0) * (tr - 1) * TWO_PI
            asw = sweep if sweep > 0.0 else -sweep
            out.sel.append(j)
            out.sel_turns.append(tr)
            off = sweep - nominal
            if off > half_pi or -off > half_pi or r0 < min_r or r1 < min_r or asw < min_sweep:
                continue
            out.idx.append(j)
            out.turns.append(tr)
            out.mism.append(mism)
            arcs.append((t0, asw, r0, r1 - r0))
        # the deviations: where only the least matters, the middle candidate first (the
        # one nearest the centre the candidates surround), then the others in order
        n = len(arcs)
        first = n // 2 if least else 0
        out.worst = [0.0] * n
        hint = -1  # the sample farthest from the arc measured last, measured first
        for m in range(-1, n):
            if m == first:
                continue
            k = first if m < 0 else m
            if k >= n:
                break
            j = out.idx[k]
            mism = out.mism[k]
            dev, hint = self._deviation(arcs[k], cx[j], cy[j], mism, stop, hint)
            worst = dev + mism
            out.worst[k] = worst
            if least and worst < stop:
                stop = worst
        return out

    def _deviation(self, arc: tuple[float, float, float, float], cx: float, cy: float, mism: float,
                   stop: float, first: int) -> tuple[float, int]:
        """Largest distance of the samples from the spiral about (cx, cy) from its start
        angle sweeping |sweep|, its radius from r0 to r0 + dr (``arc``), and the sample
        where it is; sample ``first`` (the middle one if out of range) is measured first.
        The measure stops where ``that + mism`` exceeds ``stop``. (The largest of the
        distances does not depend on their order.)"""
        t0, asw, r0, dr = arc
        us, vs, ws, frac = self.us, self.vs, self.ws, self.frac
        sn = self.sn
        dn = self.en - sn
        clockwise = self.clockwise
        k = len(us)
        if not 0 <= first < k:
            first = k // 2
        worst = 0.0
        at = first
        nan = False
        for n in range(-1, k):
            if n == first:
                continue
            i = first if n < 0 else n
            v1 = us[i] - cx
            v2 = vs[i] - cy
            phi = _atan2(v2, v1)
            # the angle from the start the way the arc turns, then the turns that bring it
            # nearest the sample's share of the sweep (rint inline: alpha is never -0.0,
            # so the sign of a zero turn does not count)
            alpha = (t0 - phi) % TWO_PI if clockwise else (phi - t0) % TWO_PI
            turn = (frac[i] * asw - alpha) / TWO_PI
            if -_TWO52 < turn < _TWO52:
                turn = (turn + _TWO52) - _TWO52 if turn >= 0.0 else -((_TWO52 - turn) - _TWO52)
            else:
                turn = rint(turn)
            alpha = alpha + turn * TWO_PI
            f = alpha / asw
            dev = hypot(hypot(v1, v2) - (r0 + dr * f), ws[i] - (sn + dn * f))
            if dev > worst:
                worst = dev
                at = i
                if dev + mism > stop:
                    break
            elif dev != dev:
                nan = True
        return (math.nan if nan else worst), at


    def r_candidates(self, centre: tuple[float, float], nsw: float, unit: float, d: int, reach: int,
                     tol: tuple[float, float]) -> tuple[list[str], list[float], list[float]]:
        """The R words (``d`` decimals) of the arc of the try about radii near that of
        ``centre`` (:func:`r_radii`; ``reach`` steps on each side; negative where |nsw| is
        over half a turn), each longer than half the chord once read back (every
        controller finds its centre without its own tolerance), and the centres a
        controller finds from them (:func:`r_center`, ``tol``: its tolerances):
        ``(texts, cx, cy)``, empty where S and E are one point."""
        s1, s2, e1, e2 = self.s1, self.s2, self.e1, self.e2
        clockwise = self.clockwise
        texts: list[str] = []
        cx: list[float] = []
        cy: list[float] = []
        half = 0.5 * math.hypot(e1 - s1, e2 - s2)
        if half == 0.0:
            return texts, cx, cy
        c0, c1 = centre
        rho = 0.5 * (math.hypot(s1 - c0, s2 - c1) + math.hypot(e1 - c0, e2 - c1))
        sign = -1.0 if abs(nsw) > math.pi else 1.0
        abs_tol, rel_tol = tol
        for val in r_radii(rho, half, unit, d, reach):
            text = fmt(sign * val, d)
            R = float(text) * unit
            if abs(R) <= half:
                continue
            c = r_center(s1, s2, e1, e2, R, clockwise, abs_tol, rel_tol)
            if c is not None:
                texts.append(text)
                cx.append(c[0])
                cy.append(c[1])
        return texts, cx, cy

    def r_form(self, centre: tuple[float, float], nsw: float, unit: float, d: int, reach: int,
               tol: tuple[float, float], budget: float, limits: tuple[float, float]) -> tuple[str, float, float] | None:
        """The R word of the try's arc nearest ``centre`` that passes (see
        :meth:`r_candidates`): every candidate's arc measured (``limits``: the
        controllers', see :meth:`measure`; a measure stops once beyond ``budget``), the
        first in the order of the radii of those turning once with the least worst, if
        within ``budget``: ``(text, worst, mismatch)``, or None."""
        texts, cx, cy = self.r_candidates(centre, nsw, unit, d, reach, tol)
        if not texts:
            return None
        found = self.measure(cx, cy, math.inf, limits, budget)
        best, least = _least_one_turn(found)
        if best < 0 or not least <= budget:
            return None
        return texts[best], least, found.mismatch[best]


def interleave(cols: list[list[float]], ss: list[float],
               bulge: list[list[float]]) -> tuple[list[list[float]], list[float]]:
    """The n samples (``cols``: n coordinates an axis, at the parameters ``ss``) and the
    middles of their intervals, interleaved (2n - 1 an axis): a middle is the mean of its
    ends (``0.5 * (a + b)``) moved by its ``bulge`` (its first n - 1 an axis), its
    parameter the mean of theirs."""
    n = len(ss)
    out: list[list[float]] = []
    for axis in range(len(cols)):
        col = cols[axis]
        bc = bulge[axis]
        row = [col[0]] * (2 * n - 1)
        for i in range(n - 1):
            row[2 * i + 1] = 0.5 * (col[i] + col[i + 1]) + bc[i]
            row[2 * i + 2] = col[i + 1]
        out.append(row)
    sl = [ss[0]] * (2 * n - 1)
    for i in range(n - 1):
        sl[2 * i + 1] = 0.5 * (ss[i] + ss[i + 1])
        sl[2 * i + 2] = ss[i + 1]
    return out, sl


def mean_between(col: list[float], a: int, b: int) -> float:
    """The mean of ``col[a:b + 1]``: the sum in order divided by the count."""
    total = col[a]
    for i in range(a + 1, b + 1):
        total += col[i]
    return total / (b + 1 - a)


def fractions(ss: list[float], lo: int, hi: int) -> list[float]:
    """Where each of the parameters ``ss[lo:hi]`` lies between the first and the last (0
    to 1)."""
    s0 = ss[lo]
    span = ss[hi - 1] - s0
    return [(ss[i] - s0) / span for i in range(lo, hi)]
