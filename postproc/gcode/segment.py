"""Segmentation and exact arcs: keep the emitted path within tolerance of the corrected ideal path.

- :func:`bisector_centre`, :func:`arc_candidates`: an emitted arc is one exact circle
  (or helix) through its end points as written; its centre lies on their bisector and
  each rounded candidate centre is judged by how far the arc every controller draws from
  it (LinuxCNC's spiral, or one radius and a jump at the end) strays from the corrected
  samples. The emitter (:mod:`postproc.gcode.emitter`) fits the fewest such arcs, or
  chords (:func:`chord_deviation`; :func:`chord_exceeds` spares it where one sample
  settles the answer), through each move's samples. Where the path bows
  from its chord by less than one output step the fitted centre means nothing and the
  nominal centre brought onto the bisector (:func:`bisector_point`) is tried first. No
  arc is written that a controller refuses or reads as a full circle
  (:data:`MIN_ARC_RADIUS_MM`, :data:`MIN_ARC_SWEEP_RAD`). The measures over the samples
  (the centre fit, the chord's deviation, each candidate's arc) run sample by sample in
  plain floats in :mod:`postproc.gcode.fitcore`, compiled with the core.
- :func:`off_every_circle`, :func:`off_every_helix`: a few samples that no arc from S
  to E could pass, whatever its centre, refuse a long try without the fit of a centre.
- :func:`quadrant_breaks`: where an arc reverses an axis (backlash is taken up there).
- :func:`subdivide` splits curves adaptively where the samples are too sparse: a chord
  is accepted when the corrected point at the middle of its parameter interval lies
  within the threshold of the chord's middle. All midpoints of one level go to the
  engine in one vectorised call.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, NotRequired, TypedDict

import numpy as np

from postproc.constants import MM_PER_INCH
from postproc.errors import SolverError
from postproc.gcode import fitcore
from postproc.gcode.fitcore import chord_exceeds as chord_exceeds  # re-exported
from postproc.gcode.geometry import FULL_CIRCLE_MM, TWO_PI, arc_params, arc_points, line_points
from postproc.gcode.interp import Arc

# A point (x, y, z) in machine coordinates; the plane's axes as (first, second, normal).
Point = Sequence[float] | np.ndarray
Axes = tuple[int, int, int]

class ArcSpec(TypedDict):
    """The written form of an exact arc: ``keep`` (the input's own centre words), ``ij``
    (centre offsets ``vals``: ((letter, text), (letter, text))) or ``r`` (``vals``:
    (("R", text),)); ``turns``; ``dev``, ``mismatch``: its measured deviation and radius
    mismatch; ``replace``: set when the move's own arc words are replaced."""

    form: Literal["keep", "ij", "r"]
    turns: int
    vals: NotRequired[tuple[tuple[str, str], ...]]
    dev: NotRequired[float]
    mismatch: NotRequired[float]
    replace: NotRequired[bool]


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

    q0: tuple[float, float, float]
    q1: tuple[float, float, float]
    arc: Arc | None
    r: np.ndarray  # (3,) tool vector
    dirs: np.ndarray  # (3,) approach signs carried into the move
    lineno: int
    rotary: dict[str, float]
    params: tuple[Axes, float, float, float, float] | None = None  # arc_params of an arc (computed once)
    path: str | None = None  # the file of its line, in an expanded program (None: the program's own)

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


# corrected gauge points (N, 3) of curves (N,) at parameters (N,)
Evaluate = Callable[[np.ndarray, np.ndarray], np.ndarray]


def subdivide(curves: list[Curve], s_init: list[np.ndarray], evaluate: Evaluate,
              threshold_mm: float) -> list[tuple[np.ndarray, np.ndarray]]:
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
    knots: list[list[tuple[float, np.ndarray]]] = [[] for _ in curves]
    offs = np.cumsum([0] + [len(s) for s in s_init])
    pend_c: list[np.ndarray] = []
    pend_a: list[np.ndarray] = []
    pend_b: list[np.ndarray] = []
    pend_qa: list[np.ndarray] = []
    pend_qb: list[np.ndarray] = []
    for i, s in enumerate(s_init):
        qi = q[offs[i]:offs[i + 1]]
        knots[i].extend(zip(s.tolist(), qi, strict=True))
        pend_c.append(np.full(len(s) - 1, i))
        pend_a.append(s[:-1])
        pend_b.append(s[1:])
        pend_qa.append(qi[:-1])
        pend_qb.append(qi[1:])
    pc, pa, pb = np.concatenate(pend_c), np.concatenate(pend_a), np.concatenate(pend_b)
    qa, qb = np.vstack(pend_qa), np.vstack(pend_qb)
    depth = 0
    while len(pc):
        depth += 1
        if depth > MAX_SUBDIVISION_DEPTH:
            worst = curves[int(pc[0])]
            raise SolverError(
                f"the correction varies too fast along this move to follow within {threshold_mm:g} mm",
                path=worst.path, lineno=worst.lineno, hint="check the calibration (is it smooth?) or raise --tolerance")
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


# -- exact circles --------------------------------------------------------------------
# Rounded centre candidates tried on each side of the ideal centre (per axis).
CENTRE_LATTICE = 3
# Smallest start or end radius of an emitted arc. LinuxCNC (interp_arc.cc arc_data_ijk)
# refuses "Zero-radius arc" when either radius is below its radius_tolerance,
# RADIUS_TOLERANCE_INCH 0.00005 in a G20 program and RADIUS_TOLERANCE_MM (the same
# length, 0.00005 * 25.4) in a G21 one (interp_internal.hh); NIST RS274NGC's limit (a
# tenth of its 0.002 mm arc tolerance) is smaller. An arc that needs a smaller circle is
# written as lines. The margin (a millionth of the limit, far above the rounding of the
# controller's own arithmetic) keeps a radius that lands on the limit, such as I0.00005
# in a G20 program, on the refused side.
MIN_ARC_RADIUS_MM = 0.00005 * MM_PER_INCH * (1.0 + 1e-6)
# Smallest sweep of an emitted arc (rad). LinuxCNC's motion (posemath pmCircleInit) takes
# the arc's angle from acos of the start and end radius vectors and makes an angle within
# CIRCLE_FUZZ (1e-6 rad) of zero a full circle; Grbl (mc_arc) does the same below
# ARC_ANGULAR_TRAVEL_EPSILON (5e-7 rad), computed in single precision. An arc that flat
# (a short chord on a huge radius, from a centre fitted where the chord is a few output
# steps long) would be cut as a whole circle: it is written as a line instead, which
# departs from it by less than chord * sweep / 8.
MIN_ARC_SWEEP_RAD = 1e-5


# Gauss-Newton steps of bisector_centre stop below this (mm)
CENTRE_SETTLED_MM = fitcore.CENTRE_SETTLED_MM


def bisector_centre(S2: Point, E2: Point, P2: np.ndarray, c0: Point) -> np.ndarray:
    """Centre (2,) on the perpendicular bisector of S2-E2 whose circle through both fits
    the points P2 (k, 2) best (least squares on the radial distance); ``c0``: first guess
    (:func:`postproc.gcode.fitcore.bisector_centre`, Gauss-Newton along the bisector)."""
    us, vs = np.asarray(P2, dtype=float).T.tolist()
    centre = fitcore.bisector_centre((float(S2[0]), float(S2[1])), (float(E2[0]), float(E2[1])), us, vs,
                                     (float(c0[0]), float(c0[1])))
    return np.array(centre)


def bisector_point(S2: np.ndarray, E2: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The point (2,) of the perpendicular bisector of S2-E2 nearest ``c`` (S2 != E2)."""
    M = 0.5 * (S2 + E2)
    D = E2 - S2
    n = np.array([-D[1], D[0]]) / math.hypot(D[0], D[1])
    return M + float((np.asarray(c, dtype=float) - M) @ n) * n


def circle_fit(P2: np.ndarray) -> np.ndarray | None:
    """Least-squares (Kasa) centre (2,) of points P2 (k, 2), or None when they are collinear."""
    m = P2.mean(axis=0)
    x, y = P2[:, 0] - m[0], P2[:, 1] - m[1]
    A = np.column_stack([x, y, np.ones(len(x))])
    b = x * x + y * y
    try:
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(sol).all():
        return None
    return m + 0.5 * sol[:2]


@dataclass(frozen=True, eq=False)
class ArcPiece:
    """A piece of an arc move to be written as one exact arc: from ``S`` to ``E`` (as
    written, machine mm) in the plane ``axes`` (its two axes and its normal), turning
    ``clockwise`` or not by about ``nominal_sweep`` (rad, signed), through the corrected
    samples ``Q`` (k, 3); ``frac`` (k,): where each sample lies along the piece (0 at S,
    1 at E), which resolves the angle's turn for multi-turn arcs."""

    S: Point
    E: Point
    axes: Axes
    clockwise: bool
    nominal_sweep: float
    Q: np.ndarray
    frac: np.ndarray


def arc_candidates(piece: ArcPiece, C: np.ndarray, controller_limits: bool = False,
                   mismatch_limit: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deviation of the corrected samples of ``piece`` from the arcs that controllers draw
    from its S to its E around each candidate centre ``C`` (m, 2, plane coordinates).

    Returns ``(worst (m,), mismatch (m,), turns (m,))``: ``worst`` is the largest
    distance of a sample from the spiral (LinuxCNC's reading: radius from the start
    radius to the end radius) plus the radius mismatch (the most any controller that
    draws on one radius and jumps at the end, Grbl or Fanuc, adds to it); inf where the
    arc would turn the wrong way or the wrong number of turns. ``controller_limits``:
    ``worst`` is also inf where a controller refuses or misreads the arc: a start or end
    radius below :data:`MIN_ARC_RADIUS_MM`, a sweep below :data:`MIN_ARC_SWEEP_RAD`.

    ``mismatch_limit``: the candidates whose radius mismatch exceeds it (which the caller
    refuses anyway) are not measured: their ``worst`` is inf and their ``turns`` 0. The
    others get the values they get among all (see :func:`limited_candidates`)."""
    return _measure(piece, C, math.inf if mismatch_limit is None else mismatch_limit, controller_limits).full()


def _try_of(piece: ArcPiece) -> fitcore.ArcTry:
    """The piece's samples as the columns of floats the measure takes."""
    S, E, Q = piece.S, piece.E, piece.Q
    a1, a2, an = piece.axes
    ends = (float(S[a1]), float(S[a2]), float(S[an]), float(E[a1]), float(E[a2]), float(E[an]))
    full = math.hypot(ends[3] - ends[0], ends[4] - ends[1]) < FULL_CIRCLE_MM
    return fitcore.ArcTry(ends, piece.clockwise, float(piece.nominal_sweep), full, Q[:, a1].tolist(),
                          Q[:, a2].tolist(), Q[:, an].tolist(), np.asarray(piece.frac, dtype=float).tolist())


def controller_limits_of(on: bool) -> tuple[float, float]:
    """The smallest radius and |sweep| of an arc the measure accepts: the controllers'
    limits, or none (0: every radius and sweep passes)."""
    return (MIN_ARC_RADIUS_MM, MIN_ARC_SWEEP_RAD) if on else (0.0, 0.0)


def _measure(piece: ArcPiece, C: np.ndarray, limit: float, controller_limits: bool) -> Measured:
    cx, cy = np.asarray(C, dtype=float).reshape(-1, 2).T.tolist()
    return Measured(_try_of(piece).measure(cx, cy, limit, controller_limits_of(controller_limits), math.inf))


class Measured:
    """The candidates of :func:`limited_candidates` (:class:`postproc.gcode.fitcore.Measured`)
    as arrays: ``mismatch`` (m,) of all; ``sel`` the candidates within the limit and
    ``sel_turns`` their turns; ``idx`` those measured (within the limit, turning the right
    way and, with controller limits, within them), ``worst``, ``turns`` and ``mism``:
    theirs."""

    __slots__ = ("found", "mismatch", "sel", "sel_turns", "idx", "worst", "turns", "mism")

    def __init__(self, found: fitcore.Measured) -> None:
        self.found = found
        self.mismatch = np.array(found.mismatch, dtype=float)
        self.sel = np.array(found.sel, dtype=int)
        self.sel_turns = np.array(found.sel_turns, dtype=int)
        self.idx = np.array(found.idx, dtype=int)
        self.turns = np.array(found.turns, dtype=int)
        self.worst = np.array(found.worst, dtype=float)
        self.mism = np.array(found.mism, dtype=float)

    def full(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(worst (m,), mismatch (m,), turns (m,))`` as :func:`arc_candidates` gives
        them (:func:`full_of`)."""
        return full_of(self.found)


def full_of(found: fitcore.Measured) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(worst (m,), mismatch (m,), turns (m,))`` of all m candidates from what the
    measure found: inf and 0 turns for the candidates beyond the limit, inf for those
    refused."""
    m = len(found.mismatch)
    worst = np.full(m, np.inf)
    turns = np.zeros(m, dtype=int)
    turns[found.sel] = found.sel_turns
    worst[found.idx] = found.worst
    return worst, np.array(found.mismatch, dtype=float), turns


def limited_candidates(piece: ArcPiece, C: np.ndarray, limit: float, controller_limits: bool = False) -> Measured:
    """:func:`arc_candidates` with a mismatch ``limit``, its results as they come (see
    :class:`Measured`): only the candidates within it are measured."""
    return _measure(piece, C, limit, controller_limits)


_EPS = 2.0 ** -52


class _Region:
    """What points P2 (k, 2) tell of the centres C whose circle through S2 (2,) passes
    within a bound of each (see :func:`off_every_circle`): d = P2 - S2, b = |d|^2 / 2,
    ``bnd`` and ``extra`` (the bound and its square's half, with the rounding of d and b),
    ``xmax`` (no such C is farther from S2) and ``gn`` (C lies within ``gn (bnd xmax +
    extra)`` of ``S2 + xc``)."""

    __slots__ = ("d", "b", "bnd", "extra", "xmax", "gn", "xc")

    def __init__(self, d: np.ndarray, b: np.ndarray, bnd: float, extra: float, xmax: float, gn: float,
                 xc: np.ndarray) -> None:
        self.d, self.b, self.bnd, self.extra, self.xmax, self.gn, self.xc = d, b, bnd, extra, xmax, gn, xc


def _region(S2: np.ndarray, P2: np.ndarray, bound: float) -> _Region | None:
    """The :class:`_Region` of the centres, or None where it cannot be bounded."""
    if len(P2) < 4 or not bound >= 0.0:
        return None
    d = P2 - S2
    b = 0.5 * (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    if not np.isfinite(b).all():
        return None
    dmax = math.sqrt(2.0 * float(b.max()))
    # the rounding of d and b: |d - d_exact| <= eps |d|, |b - b_exact| <= 2 eps |d|^2
    bnd = bound + _EPS * dmax
    extra = 0.5 * bnd * bnd + 2.0 * _EPS * dmax * dmax
    i = int(np.argmax(b))
    g1 = d[i]
    j = int(np.argmax(np.abs(d[:, 0] * g1[1] - d[:, 1] * g1[0])))
    g2 = d[j]
    det = float(g1[0] * g2[1] - g1[1] * g2[0])
    if not abs(det) > 1e-4 * (abs(float(g1[0] * g2[1])) + abs(float(g1[1] * g2[0]))):
        return None
    # X = G^-1 (b_ij - e), |e_k| <= bnd |X| + extra
    inv = np.array([[g2[1], -g1[1]], [-g2[0], g1[0]]]) / det
    xc = inv @ np.array([b[i], b[j]])
    gn = math.sqrt(float((inv * inv).sum())) * math.sqrt(2.0) * (1.0 + 1e-9)
    q = gn * bnd
    if not q < 0.5:
        return None
    xmax = (math.hypot(float(xc[0]), float(xc[1])) + gn * extra) / (1.0 - q) * (1.0 + 1e-9)
    return _Region(d, b, bnd, extra, xmax, gn, xc)


def off_every_circle(S2: np.ndarray, P2: np.ndarray, bound: float) -> bool:
    """True when no centre C makes every point of ``P2`` (k, 2) lie within ``bound`` of
    the circle about C through ``S2`` (2,): for every C some ``| |P - C| - |S2 - C| |``
    exceeds ``bound``. False where it cannot tell. Cost O(k), whatever C may be.

    With X = C - S2, d = P - S2 and b = |d|^2 / 2, each point within the bound gives
    ``|b - X.d| <= bound |X| + bound^2 / 2`` (``|P - C|^2 - |S2 - C|^2 = 2 (b - X.d)``). Two
    points in independent directions then bound |X| (``xmax``), and weights ``lam`` (the
    residual of b after its least-squares fit by X.d: the points' departure from every
    circle through S2) give ``|sum lam b| <= xmax |sum lam d| + sum |lam| (bound xmax +
    bound^2 / 2)``: the points are off every circle where the left side exceeds the
    right. The rounding of d and b and of the sums is bounded and counted against it."""
    reg = _region(S2, P2, bound)
    if reg is None:
        return False
    d, b, xmax = reg.d, reg.b, reg.xmax
    try:
        coef = np.linalg.lstsq(d, b, rcond=None)[0]
    except np.linalg.LinAlgError:
        return False
    lam = b - d @ coef
    alam = np.abs(lam)
    l1 = float(alam.sum())
    gam = 2.0 * (len(b) + 2) * _EPS  # the rounding of a sum of k products
    lhs = abs(float(lam @ b)) - gam * float(alam @ np.abs(b))
    sd = lam @ d
    dn = np.hypot(d[:, 0], d[:, 1])
    rhs = xmax * (math.hypot(float(sd[0]), float(sd[1])) + gam * float(alam @ dn)) + l1 * (reg.bnd * xmax + reg.extra)
    return bool(lhs > rhs * (1.0 + 1e-9))


def off_every_helix(piece: ArcPiece, bound: float, budget: float) -> bool:
    """True when no arc a controller draws from S to E of ``piece`` (its samples ``Q``
    and their ``frac``: any few of the piece's), whatever its centre, passes within
    ``budget`` of every sample along the plane's normal, given that every sample lies
    within ``bound`` of the circle about its centre through S (see
    :func:`off_every_circle`). False where it cannot tell. Cost O(k).

    Those centres lie in a small disc (:class:`_Region`); over it each angle about the
    centre (of S, E and every sample) moves by at most asin(disc radius / distance). Where
    no rounding or choice of turns, and no sample's turn, changes across the disc, the
    angle of each sample from S and the sweep have bounds, so has the height the arc
    gives each sample (``S + (E - S) alpha / |sweep|`` along the normal): one sample
    farther than ``budget`` from its bounds shows that no centre of the disc passes."""
    S, E, Q, clockwise = piece.S, piece.E, piece.Q, piece.clockwise
    a1, a2, an = piece.axes
    S2 = np.array([float(S[a1]), float(S[a2])])
    reg = _region(S2, Q[:, [a1, a2]], bound)
    if reg is None:
        return False
    delta = reg.gn * (reg.bnd * reg.xmax + reg.extra) + 1e-9 * (1.0 + reg.xmax)
    cx, cy = float(S2[0] + reg.xc[0]), float(S2[1] + reg.xc[1])
    slop = 1e-9  # rad: the rounding of the angles, far below
    rS = math.hypot(S2[0] - cx, S2[1] - cy)
    rE = math.hypot(float(E[a1]) - cx, float(E[a2]) - cy)
    if not (rS > 2.0 * delta and rE > 2.0 * delta):
        return False
    eta_s = delta / (rS - delta) + slop
    eta_b = eta_s + delta / (rE - delta) + slop  # of the sweep, unless a full circle
    t0 = math.atan2(S2[1] - cy, S2[0] - cx)
    t1 = math.atan2(float(E[a2]) - cy, float(E[a1]) - cx)
    nsw = abs(piece.nominal_sweep)
    if math.hypot(float(E[a1]) - S2[0], float(E[a2]) - S2[1]) < FULL_CIRCLE_MM:
        base, eta_b = TWO_PI, 0.0
    else:
        base = ((t0 - t1) if clockwise else (t1 - t0)) % TWO_PI
        if not eta_b < base < TWO_PI - eta_b:
            return False  # a centre of the disc may make it a full circle
    x = (nsw - base) / TWO_PI
    if abs(x - math.floor(x) - 0.5) <= eta_b / TWO_PI + 1e-12:
        return False  # the number of turns may change across the disc
    asw = base + (max(1, round(x) + 1) - 1) * TWO_PI
    if not asw > eta_b:
        return False
    v1, v2 = Q[:, a1] - cx, Q[:, a2] - cy
    rho = np.hypot(v1, v2)
    near = rho > 2.0 * delta
    # (a sample within the disc's reach: no bound, never sure)
    eta = np.where(near, delta / np.where(near, rho - delta, 1.0), 10.0) + eta_s + slop
    phi = np.arctan2(v2, v1)
    alpha = np.mod((t0 - phi) if clockwise else (phi - t0), TWO_PI)
    target = piece.frac * asw
    alpha += TWO_PI * np.rint((target - alpha) / TWO_PI)
    # the sample's turn is settled where its angle stays less than half a turn from target
    sure = np.abs(alpha - target) < math.pi - eta - piece.frac * eta_b - slop
    lo = np.minimum((alpha - eta) / (asw - eta_b), (alpha - eta) / (asw + eta_b))
    hi = np.maximum((alpha + eta) / (asw - eta_b), (alpha + eta) / (asw + eta_b))
    dz = float(E[an]) - float(S[an])
    z_lo = float(S[an]) + np.minimum(dz * lo, dz * hi)
    z_hi = float(S[an]) + np.maximum(dz * lo, dz * hi)
    q = Q[:, an]
    off = np.maximum(z_lo - q, q - z_hi)
    scale = max(float(np.abs(Q).max()), abs(float(S[an])), abs(float(E[an])), abs(cx), abs(cy))
    return bool((sure & (off > budget + 1e-8 * (1.0 + scale))).any())


def chord_deviation(S: Point, E: Point, Q: np.ndarray) -> float:
    """Largest distance of the points Q (k, 3) from the segment S-E
    (:func:`postproc.gcode.fitcore.chord_deviation`)."""
    xs, ys, zs = np.asarray(Q, dtype=float).T.tolist()
    return fitcore.chord_deviation([float(v) for v in S], [float(v) for v in E], xs, ys, zs)


def quadrant_breaks(t0: float, sweep: float) -> np.ndarray:
    """Parameters s in (0, 1) where an arc from angle t0 sweeping ``sweep`` passes a
    quadrant point (an in-plane axis reverses there)."""
    if sweep == 0.0:
        return np.zeros(0)
    lo, hi = sorted((t0, t0 + sweep))
    k0, k1 = math.ceil(lo / (math.pi / 2)), math.floor(hi / (math.pi / 2))
    # the few quadrant angles in floats (each k * (pi / 2), as np.arange(k0, k1 + 1) * (pi / 2))
    s = [(k * (math.pi / 2) - t0) / sweep for k in range(k0, k1 + 1)]
    return np.array(sorted(v for v in s if 1e-9 < v < 1.0 - 1e-9), dtype=float)
