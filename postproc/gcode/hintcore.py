"""The bulk planner's arc hint in plain floats: the centre words of an arc as written,
and how far the arc they give can lie from the corrected samples.

The planner fits one circle to each arc's corrected samples (:mod:`postproc.gcode.vplan`)
and keeps it as the arc's :class:`ArcHint`: its centre, radius, deviation and nominal
sweep, and the corrected ends it was fitted between. Where the arc's end points are written,
:func:`centre_words` moves that centre onto the bisector of the written ends, rounds it
to the words' decimals (or takes the nearest rounded centre around it whose start and end
radii agree within half a step) and bounds the arc a controller then draws
(:func:`arc_bound`). The planner asks it for every arc of a chunk with the corrected ends
rounded as words are (:meth:`ArcHint.guess`, its guess of which arcs need a plan of
their own) and the run writer with the ends as written (:meth:`ArcHint.words`); both get
the same answer for the same ends, as there is one computation: the hint keeps its last
question (:data:`Key`) with its answer, and the writer's same question takes it.

The arithmetic is Python's on floats (``math.hypot``, ``math.atan2``, ``round`` through
:func:`postproc.gcode.numfmt.round_to`, the floored ``%``), compiled or not. Compiled at
install by mypyc with the scanner (``setup.py``); runs unchanged uncompiled. Of the
package it imports the formatter
(:mod:`postproc.gcode.numfmt`, compiled with it), the planes' axes
(:data:`postproc.gcode.state.PLANES`) and the least radius and sweep a controller cuts
as meant (:mod:`postproc.gcode.segment`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Final, Protocol

from postproc.gcode.numfmt import fmt, round_to
from postproc.gcode.segment import MIN_ARC_RADIUS_MM, MIN_ARC_SWEEP_RAD
from postproc.gcode.state import PLANES

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from postproc.gcode.moves import Arc
    from postproc.gcode.segment import ArcSpec

# The input's own arc words are kept when their radius mismatch is at most the input's
# own (which its controller accepts) plus this (float noise of the two readings).
KEEP_MISMATCH_SLACK_MM: Final = 1e-9

TWO_PI: Final = 2.0 * math.pi
# Rounded centre candidates tried on each side of the centre moved onto the bisector of
# the written end points (per axis), as the general path does.
LATTICE: Final = 3
# the lattice offsets (per axis, in units of the last decimal), nearest first
ORDER: Final = tuple(sorted(((k1, k2) for k1 in range(-LATTICE, LATTICE + 1) for k2 in range(-LATTICE, LATTICE + 1)),
                            key=lambda k: (k[0] ** 2 + k[1] ** 2, k)))

#: the hint's circle: centre (c1, c2) in the plane's order, radius, deviation of the
#: samples from it, nominal sweep (rad, negative clockwise)
Circle = tuple[float, float, float, float, float]
#: an arc's ends in the plane's order: (s1, s2, sn, e1, e2, en)
Ends = tuple[float, float, float, float, float, float]
#: the centre words' values (``float`` of their text), their radius mismatch and bound
Words = tuple[float, float, float, float]
#: a question to :func:`centre_words`: the written ends, clockwise, the words' decimals,
#: mm per program unit, what they are relative to (b1, b2) and the budget
Key = tuple[Ends, bool, int, float, float, float, float]


def arc_bound(circle: Circle, fitted: Ends, clockwise: bool, written: Ends, c1: float, c2: float
              ) -> tuple[float, float, float, float] | None:
    """How far the arc a controller draws through the ``written`` ends around (c1, c2)
    (radius from the start to the end radius, the normal axis linear) can lie from the
    corrected samples the ``circle`` was fitted to between the ``fitted`` ends: the
    circle's deviation plus how far the drawn arc lies from it anywhere. Returned with the
    start and end radii and the turn from start to end (in the arc's sense, [0, 2 pi)).
    None when it does not turn as the nominal arc does (one turn)."""
    s1, s2, sn, e1, e2, en = written
    hyp = math.hypot
    rs, re = hyp(s1 - c1, s2 - c2), hyp(e1 - c1, e2 - c2)
    th0, th1 = math.atan2(s2 - c2, s1 - c1), math.atan2(e2 - c2, e1 - c1)
    turn = (th0 - th1) % TWO_PI if clockwise else (th1 - th0) % TWO_PI
    sweep = -turn if clockwise else turn
    h1, h2, rho, worst, nsweep = circle
    if sweep == 0.0 or abs(sweep - nsweep) > math.pi / 2:
        return None
    moved = hyp(c1 - h1, c2 - h2)
    u1, u2, un, x1, x2, xn = fitted
    shift = max(hyp(s1 - u1, s2 - u2), hyp(e1 - x1, e2 - x2))
    # in the plane: the samples' distance from the ideal circle, plus how far the
    # written circle (centre c, radius from rs to re) lies from it anywhere
    bound = worst + moved + max(abs(rs - rho), abs(re - rho))
    # along the normal axis: the written ends, and the shift of each sample's angle
    # (centre and ends moved) along the helix
    r_min = min(rs, re, rho)
    if not r_min > 0.0:
        return None
    dfrac = 3.0 * (moved + shift) / (r_min * abs(sweep))
    return bound + max(abs(sn - un), abs(en - xn)) + abs(en - sn) * dfrac, rs, re, turn


def centre_words(circle: Circle, fitted: Ends, clockwise: bool, written: Ends, words: tuple[int, float, float, float],
                 limits: tuple[float, float, float]) -> tuple[float, float, float, float] | None:
    """The centre words of the arc written through the ``written`` ends: ``(w1, w2,
    mismatch, bound)``, the words' values (``float`` of their text), the radius mismatch
    of the centre they give and the bound on the arc's distance from the corrected
    samples (:func:`arc_bound`). ``words``: their decimals, mm per program unit and what
    they are relative to (b1, b2: machine mm); ``limits``: the budget (mm), and the
    least radius and sweep a controller cuts as meant. The centre is the circle's moved
    onto the written ends' bisector and rounded, or the nearest lattice point around it
    whose radii agree within half a step. None when no such centre stays within the
    budget or the arc is below the least radius or sweep."""
    s1, s2, sn, e1, e2, en = written
    d, unit, b1, b2 = words
    budget, min_radius, min_sweep = limits
    dx, dy = e1 - s1, e2 - s2
    hyp = math.hypot
    L = hyp(dx, dy)
    if L == 0.0:
        return None
    m1, m2 = 0.5 * (s1 + e1), 0.5 * (s2 + e2)
    n1, n2 = -dy / L, dx / L
    t = (circle[0] - m1) * n1 + (circle[1] - m2) * n2
    step = 10.0 ** (-d)
    agree = 0.5 * step * unit
    v1 = round_to((m1 + t * n1 - b1) / unit, d)
    v2 = round_to((m2 + t * n2 - b2) / unit, d)
    # the first candidate, round(v + 0 * step, d), is v + 0.0 (v is rounded already)
    w1, w2 = v1 + 0.0, v2 + 0.0
    C1, C2 = b1 + w1 * unit, b2 + w2 * unit
    mism = abs(hyp(s1 - C1, s2 - C2) - hyp(e1 - C1, e2 - C2))
    if not mism <= agree:
        found = False
        for k in range(1, len(ORDER)):
            k1, k2 = ORDER[k]
            w1, w2 = round_to(v1 + k1 * step, d), round_to(v2 + k2 * step, d)
            C1, C2 = b1 + w1 * unit, b2 + w2 * unit
            mism = abs(hyp(s1 - C1, s2 - C2) - hyp(e1 - C1, e2 - C2))
            if mism <= agree:
                found = True
                break
        if not found:
            return None
    got = arc_bound(circle, fitted, clockwise, written, C1, C2)
    if got is None:
        return None
    bound, rs, re, turn = got
    if not bound + mism <= budget:
        return None
    # the controller limits around the centre of the words as written (float of the
    # text: -0.0 reads back 0.0, else the same centre, radii and sweep); the ends differ
    # in the plane (L > 0)
    if w1 == 0.0 or w2 == 0.0:
        w1, w2 = w1 + 0.0, w2 + 0.0
        c1, c2 = b1 + w1 * unit, b2 + w2 * unit
        rs, re = hyp(s1 - c1, s2 - c2), hyp(e1 - c1, e2 - c2)
        t0, t1 = math.atan2(s2 - c2, s1 - c1), math.atan2(e2 - c2, e1 - c1)
        turn = (t0 - t1) % TWO_PI if clockwise else (t1 - t0) % TWO_PI
    if min(rs, re) < min_radius or not turn >= min_sweep:
        return None
    return w1, w2, mism, bound


class ArcMove(Protocol):
    """What :class:`ArcHint` reads of the move it writes (a
    :class:`postproc.gcode.interp.Move`, or the bulk writer's view of a line of a run)."""

    @property
    def arc(self) -> Arc | None: ...
    @property
    def unit(self) -> float: ...
    @property
    def arc_absolute(self) -> object: ...  # (true where the centre words are absolute: G90.1)
    @property
    def shift(self) -> Sequence[float]: ...


class ArcHint:
    """What the bulk planner found for one arc (:mod:`postproc.gcode.vplan`): the circle
    fitted to its corrected samples between its corrected ends, and what the writer asks
    of it (:meth:`words`, :meth:`spec`, :meth:`keep`)."""

    c1: float
    c2: float
    rho: float
    worst: float
    nsweep: float
    mismatch: float
    ends: Ends
    row: int
    edge: bool
    last: tuple[Key, Words | None] | None

    def __init__(self, c1: float, c2: float, rho: float, worst: float, nsweep: float, ends: Sequence[float],
                 row: int, mismatch: float = 0.0) -> None:
        # Python floats (a numpy float would round as numpy does: hintcore's arithmetic is Python's)
        self.c1, self.c2, self.rho, self.worst, self.nsweep = float(c1), float(c2), float(rho), float(worst), float(nsweep)
        self.mismatch = float(mismatch)  # the nominal arc's own end-radius mismatch (mm)
        # the corrected ends the fit used: (s1, s2, sn, e1, e2, en), plane axes first
        self.ends = (float(ends[0]), float(ends[1]), float(ends[2]), float(ends[3]), float(ends[4]),
                           float(ends[5]))
        self.row = row  # the arc's row of the table (its general plan's, when the hint does not do)
        # the planner expects the hint may fail where written (its general plan is made with
        # the chunk): the run writer ends a stretch at this arc
        self.edge = False
        # the last question to centre_words and its answer (:meth:`_answer`)
        self.last = None

    def spec(self, mv: ArcMove, S: Sequence[float], E: Sequence[float], d: int, budget: float) -> ArcSpec | None:
        """The arc words for the move written from S to E (machine mm, as written):
        ``{"form": "ij", "vals": ..., "turns": 1, ...}``, or None where :meth:`words`
        gives none."""
        arc = mv.arc
        if arc is None:
            raise AssertionError("an arc hint asked for a move that is no arc")
        axes, (l1, l2) = PLANES[arc.plane]
        a1, a2 = axes[0], axes[1]
        base = (mv.shift[a1], mv.shift[a2]) if mv.arc_absolute else (S[a1], S[a2])
        w = self.words(S, E, axes, arc.clockwise, d, mv.unit, base, budget)
        if w is None:
            return None
        w1, w2, mism, bound = w
        return {"form": "ij", "vals": ((l1, fmt(w1, d)), (l2, fmt(w2, d))), "turns": 1,
                "dev": bound + mism, "mismatch": mism}

    def words(self, S: Sequence[float], E: Sequence[float], axes: tuple[int, int, int], clockwise: bool, d: int,
              unit: float, base: tuple[float, float], budget: float) -> tuple[float, float, float, float] | None:
        """The centre words of the arc written from S to E (machine mm, as written; ``axes``:
        the plane's two axes and its normal; ``base``: what the centre words are relative
        to, machine mm): ``(w1, w2, mismatch, bound)``, the words' values (``float`` of
        their text, ``d`` decimals), the radius mismatch of the centre they give and the
        bound on the arc's distance from the corrected samples (:meth:`_bound`). The
        centre is the fitted one moved onto the written ends' bisector and rounded, or
        the nearest lattice point around it whose radii agree within half a step. None
        when no such centre stays within ``budget`` or a controller would not cut the
        arc as meant (radius and sweep below :data:`MIN_ARC_RADIUS_MM` and
        :data:`MIN_ARC_SWEEP_RAD`, as :func:`postproc.gcode.segment.arc_candidates`' controller
        limits decide)."""
        a1, a2, an = axes
        return self._answer((float(S[a1]), float(S[a2]), float(S[an]), float(E[a1]), float(E[a2]), float(E[an])),
                            clockwise, d, float(unit), (float(base[0]), float(base[1])), budget)

    def guess(self, arc: Arc, d: int, unit: float, shift: Sequence[float], absolute: object,
              budget: float) -> Words | None:
        """The planner's guess: :meth:`words` for the arc ``arc`` of this hint written
        from its fitted ends rounded as its words round them (``round((q - shift) / unit,
        d) * unit + shift`` on each axis: ``d`` decimals, ``unit`` mm per program unit, the
        machine ``shift`` of each axis; its centre words ``absolute`` or not)."""
        a1, a2, an = PLANES[arc.plane][0]
        u = float(unit)
        h1, h2, hn = float(shift[a1]), float(shift[a2]), float(shift[an])
        f = self.ends
        s1 = round_to((f[0] - h1) / u, d) * u + h1
        s2 = round_to((f[1] - h2) / u, d) * u + h2
        sn = round_to((f[2] - hn) / u, d) * u + hn
        e1 = round_to((f[3] - h1) / u, d) * u + h1
        e2 = round_to((f[4] - h2) / u, d) * u + h2
        en = round_to((f[5] - hn) / u, d) * u + hn
        return self._answer((s1, s2, sn, e1, e2, en), arc.clockwise, d, u, (h1, h2) if absolute else (s1, s2),
                            budget)

    def _answer(self, written: Ends, clockwise: bool, d: int, unit: float, base: tuple[float, float],
                budget: float) -> Words | None:
        """:func:`centre_words` of the arc through the ``written`` ends; the same question
        as the last one (the planner's guess, then the writer, usually ask with the same
        ends) gets the last one's answer."""
        key = (written, clockwise, d, unit, base[0], base[1], budget)
        last = self.last
        if last is not None and last[0] == key:
            return last[1]
        result = centre_words(self.circle(), self.ends, clockwise, written, (d, unit, base[0], base[1]),
                              (budget, MIN_ARC_RADIUS_MM, MIN_ARC_SWEEP_RAD))
        self.last = (key, result)
        return result

    def circle(self) -> Circle:
        """The fitted circle as :func:`centre_words` and :func:`arc_bound` take it."""
        return self.c1, self.c2, self.rho, self.worst, self.nsweep

    def keep(self, mv: ArcMove, S: Sequence[float], E: Sequence[float], centre: Sequence[float] | npt.NDArray[np.float64],
             budget: float) -> ArcSpec | None:
        """``{"form": "keep", "turns": 1}`` when the input's own arc words, around
        ``centre`` from S to E (as written), still pass: their radius mismatch no larger
        than the input's own (:attr:`mismatch`, which its controller accepts) and the arc
        within ``budget`` of the samples; else None."""
        arc = mv.arc
        if arc is None:
            raise AssertionError("an arc hint asked for a move that is no arc")
        (a1, a2, an), _ = PLANES[arc.plane]
        C1, C2 = float(centre[0]), float(centre[1])
        mism = abs(math.hypot(S[a1] - C1, S[a2] - C2) - math.hypot(E[a1] - C1, E[a2] - C2))
        if not mism <= self.mismatch + KEEP_MISMATCH_SLACK_MM:
            return None
        got = self._bound(arc.clockwise, (float(S[a1]), float(S[a2]), float(S[an]), float(E[a1]), float(E[a2]),
                                          float(E[an])), C1, C2)
        if got is None or not got[0] <= budget:
            return None
        return {"form": "keep", "turns": 1}

    def _bound(self, clockwise: bool, written: Ends, C1: float, C2: float
               ) -> tuple[float, float, float, float] | None:
        """How far the arc a controller draws from S to E (``written``: (s1, s2, sn, e1,
        e2, en), the plane coordinates and the normal one of each, as :attr:`ends`) around
        (C1, C2) can lie from the corrected samples, with its start and end radii and
        turn (:func:`postproc.gcode.arc_bound`); None when it does not turn as
        the nominal arc does."""
        return arc_bound(self.circle(), self.ends, clockwise, written, C1, C2)
