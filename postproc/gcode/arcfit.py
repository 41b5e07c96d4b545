"""Fitting a planned move's corrected samples with the fewest exact arcs or lines.

The writer (:mod:`postproc.gcode.emitter`) hands each piece of a move's plan
(:class:`postproc.gcode.vplan.Plan`: corrected samples between reversals) to a
:class:`MoveFit`, which cuts it greedily: from each start, the farthest sample that one
exact arc (arc moves; its centre on the bisector of the written end points, rounded
among candidates whose radii agree) or one chord reaches within the budget.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol, final

import numpy as np

from postproc.gcode import emit
from postproc.gcode.geometry import TWO_PI
from postproc.gcode.moves import Arc, Move
from postproc.gcode.segment import (
    CENTRE_LATTICE,
    ArcPiece,
    ArcSpec,
    Point,
    arc_candidates,
    bisector_centre,
    bisector_point,
    chord_deviation,
    chord_exceeds,
    circle_fit,
    limited_candidates,
    off_every_circle,
    off_every_helix,
    r_center,
)
from postproc.gcode.state import LINE, PLANES
from postproc.gcode.vplan import Plan

# A piece that one segment cannot follow is first tried in 2 .. EQUAL_SHARES equal shares
# (each one try) to bracket the farthest sample one segment reaches, before the search
# from the next sample outwards. Where the first half fits, the second is tried at once:
# two segments are then the fewest, with no search.
EQUAL_SHARES = 4

Edit = tuple[int, int, str]  # replace line[start:end] by the text

# An arc's try over more samples than this (samples and middles) first checks a few of
# them (SPREAD over the whole and SPREAD over its first turn) against every arc from its
# start to its end, whatever its centre (MoveFit._off_every_arc): a try far beyond the
# farthest sample one arc reaches is refused at the cost of those few, not of all its
# samples.
OFF_EVERY_ARC_FROM = 256
SPREAD = 64


class _Piece:
    """One written segment of a planned move: an exact arc (``spec``) or a line to ``qe``
    (the emitted position after it), the word edits of the move's own line or the words
    of an inserted line, and ``ds``, its share of the move's parameter."""

    __slots__ = ("kind", "qe", "edits", "added", "ds", "spec", "takeup")

    def __init__(self, kind: str, qe: list[float], edits: list[Edit], added: list[str], ds: float,
                 spec: ArcSpec | None = None, takeup: bool = False) -> None:
        self.kind = kind  # "arc" | "line"
        self.qe = qe
        self.edits = edits
        self.added = added
        self.ds = ds
        self.spec = spec
        self.takeup = takeup


class _Samples:
    """A piece's corrected samples prepared once for all the tries of its fit: the samples
    and the middles of their intervals interleaved (``Qs`` (2n - 1, 3), the chord's middle
    moved by the nominal path's bulge there; ``ss`` their parameters), their plane
    coordinates (``P2``) and the corrections (``dq``: corrected minus nominal)."""

    __slots__ = ("s", "Q", "Qs", "ss", "P2", "dq", "free")

    def __init__(self, mv: Move, s: np.ndarray, Q: np.ndarray, nom: np.ndarray, bulge: np.ndarray) -> None:
        n = len(Q)
        self.s = s
        self.Q = Q
        Qs = np.empty((2 * n - 1, 3))
        Qs[0::2] = Q
        Qs[1::2] = 0.5 * (Q[:-1] + Q[1:]) + bulge[:n - 1]
        ss = np.empty(2 * n - 1)
        ss[0::2] = s
        ss[1::2] = 0.5 * (s[:-1] + s[1:])
        self.Qs = Qs
        self.ss = ss
        self.dq = Q - nom
        self.P2: np.ndarray | None = None
        if mv.arc is not None:
            (a1, a2, _an), _ = PLANES[mv.arc.plane]
            self.P2 = Qs[:, [a1, a2]]
        self.free = _free_move(mv)

    def offset(self, a: int, b: int) -> np.ndarray:
        """The mean correction over samples a..b: corrected minus nominal."""
        # as ndarray.mean: the sum divided by the count
        mean: np.ndarray = np.add.reduce(self.dq[a:b + 1], axis=0) / (b + 1 - a)
        return mean


def _spread(n: int, nsw: float) -> np.ndarray:
    """Indices of a few of n samples along an arc sweeping ``nsw``: SPREAD evenly over all
    and SPREAD over its first turn (samples one turn apart may lie at one angle)."""
    first = min(n, math.ceil(n * TWO_PI / abs(nsw))) if abs(nsw) > TWO_PI else n
    idx = np.concatenate([np.linspace(0, n - 1, SPREAD), np.linspace(0, first - 1, SPREAD)])
    out: np.ndarray = np.unique(idx.round().astype(int))
    return out


def _free_move(mv: Move) -> Move:
    """``mv`` without its words: the move an inserted line writes."""
    return Move(mv.lineno, LINE, mv.q0, mv.q1, mv.r, mv.shift, mv.unit, mv.incremental, mv.arc_absolute,
                [], (-1, -1, -1), -1, mv.inverse_time, mv.feed, mv.rotary, frame=mv.frame)


# Offsets of the rounded centre candidates tried around the ideal one, per number of decimals.
_LATTICES: dict[int, np.ndarray] = {}


def _lattice(d: int) -> np.ndarray:
    grid = _LATTICES.get(d)
    if grid is None:
        ks = np.arange(-CENTRE_LATTICE, CENTRE_LATTICE + 1) * 10.0 ** (-d)
        grid = _LATTICES[d] = np.stack(np.meshgrid(ks, ks, indexing="ij"), axis=-1).reshape(-1, 2)
    return grid


_NO_ARC = Arc((0.0, 0.0, 0.0), 170, False, 1, (-1, -1), -1)


class _Writer(Protocol):
    """What a fit uses of the writer (:class:`postproc.gcode.emitter.EmitterMixin`): the
    words of a move, its input's own arc centre, the engine's subdivision of a curve."""

    def _axis_words(self, mv: Move, target: Point, qe: list[float], d: int,
                    present_only: bool = False) -> tuple[list[Edit], list[str]]: ...

    def _axis_words_free(self, mv: Move, q: Point, qe: list[float], d: int) -> tuple[list[Edit], list[str]]: ...

    def _input_centre(self, mv: Move, S: Point, E: Point) -> np.ndarray | None: ...

    def _subdivide(self, curves: list, s_init: list[np.ndarray], unit: float
                   ) -> list[tuple[np.ndarray, np.ndarray]]: ...


@final
class MoveFit:
    """The fit of one planned move: the move, its plan, the output's decimals and the
    budget, and the writer whose words and subdivision it uses."""

    __slots__ = ("w", "mv", "plan", "d", "budget", "arc", "to_view")

    def __init__(self, writer: _Writer, mv: Move, plan: Plan, d: int, budget: float,
                 to_view: Callable[[np.ndarray], np.ndarray] | None = None) -> None:
        self.w = writer
        self.mv = mv
        self.plan = plan
        self.d = d  # decimals of the words written
        self.budget = budget  # share of --tolerance a segment may use at the samples
        self.arc = mv.arc or _NO_ARC  # the move's arc (a line's is never read)
        # a framed arc's: machine points (n, 3) into the coordinates the move and its plan
        # are in (postproc.gcode.framed.FrameView.points), for what the engine's subdivision
        # of the plan's curve gives
        self.to_view = to_view

    def piece(self, s: np.ndarray, Q: np.ndarray, nom: np.ndarray, bulge: np.ndarray, qe: list[float],
              final: bool) -> list[_Piece]:
        """Greedy fit of one piece's samples: from each start, the farthest sample that one
        exact arc (or, failing that, one chord) reaches within the budget, or the two
        halves of what is left when each fits in one segment."""
        n = len(Q)
        a = 0
        cur = list(qe)
        out: list[_Piece] = []
        smp = _Samples(self.mv, s, Q, nom, bulge)

        def attempt_from(a0: int, b: int, cur0: list[float]) -> _Piece | None:
            return self._segment(smp, a0, b, cur0, final)

        def attempt(b: int) -> _Piece | None:
            return attempt_from(a, b, cur)

        while a < n - 1:
            seg = attempt(n - 1)
            if seg is not None:
                out.append(seg)
                break
            # equal shares of what is left (a move cut in two or three is the common case):
            # the longest share one segment reaches brackets the farthest sample it
            # reaches, which a bisection between that share and the next longer finds
            hi = n - 1
            b = a
            for k in range(2, EQUAL_SHARES + 1):
                b = a + math.ceil((n - 1 - a) / k)
                if b <= a + 1:
                    break
                seg = attempt(b)
                if seg is not None:
                    break
                hi = b
            if seg is not None:
                if k == 2:
                    # one segment did not reach the end, so two are the fewest: when the
                    # second half fits too, the piece is cut in the middle (the search
                    # for the farthest sample would give two as well)
                    rest = attempt_from(b, n - 1, seg.qe)
                    if rest is not None:
                        out += [seg, rest]
                        break
                lo, seg = self._farthest(attempt, b, hi, seg)
                out.append(seg)
                cur = seg.qe
                a = lo
                continue
            lo_seg = attempt(a + 1)
            if lo_seg is None:
                # the samples are too sparse here: follow the curve by subdivision
                segs = self._refine(s[a], s[a + 1], Q[a + 1], cur, final and a + 1 == n - 1)
                out.extend(segs)
                cur = segs[-1].qe
                a += 1
                continue
            lo, hi = a + 1, n - 1
            step = 2
            while a + step < hi:
                sg = attempt(a + step)
                if sg is None:
                    hi = a + step
                    break
                lo, lo_seg = a + step, sg
                step *= 2
            lo, lo_seg = self._farthest(attempt, lo, hi, lo_seg)
            if lo == a + 1:
                # only the next sample is reached: check the path between them with the
                # engine itself (a jump or a solver's scatter there is refused)
                segs = self._refine(s[a], s[a + 1], Q[a + 1], cur, final and a + 1 == n - 1)
                if len(segs) > 1 or lo_seg.kind == "line":
                    out.extend(segs)
                    cur = segs[-1].qe
                    a += 1
                    continue
            out.append(lo_seg)
            cur = lo_seg.qe
            a = lo
        return out

    @staticmethod
    def _farthest(attempt: Callable[[int], _Piece | None], lo: int, hi: int, lo_seg: _Piece) -> tuple[int, _Piece]:
        """Bisection for the farthest sample one segment (``attempt(sample)``, None where
        it fails) reaches, between ``lo`` (reached, by ``lo_seg``) and ``hi`` (not
        reached): ``(sample, its segment)``."""
        while hi - lo > 1:
            mid = (lo + hi) // 2
            sg = attempt(mid)
            if sg is None:
                hi = mid
            else:
                lo, lo_seg = mid, sg
        return lo, lo_seg

    def _segment(self, smp: _Samples, a: int, b: int, cur: list[float], final: bool) -> _Piece | None:
        """One segment from sample ``a`` (the controller at ``cur``) to sample ``b``: an
        exact arc (arc moves) or a chord within ``budget`` of the samples and the middles
        of their intervals, or None."""
        mv, d, budget = self.mv, self.d, self.budget
        last = final and b == len(smp.Q) - 1
        qn = list(cur)
        if last:
            edits, added = self.w._axis_words(mv, smp.Q[b], qn, d)
        else:
            edits, added = self.w._axis_words(smp.free, smp.Q[b], qn, d)
        ds = float(smp.s[b] - smp.s[a])
        Qs = smp.Qs[2 * a:2 * b + 1]
        # the chord's deviation is measured only where needed: the middle sample alone
        # often shows it above the limit it is compared with
        mid = Qs[len(Qs) // 2].tolist()
        chord: float | None = None
        if mv.arc is not None and smp.P2 is not None:
            step_mm = 10.0 ** (-d) * mv.unit
            if chord_exceeds(cur, qn, mid, step_mm):
                flat = False
            else:
                chord = chord_deviation(cur, qn, Qs)
                flat = chord <= step_mm
            spec = self._exact_arc(cur, qn, Qs, smp.P2[2 * a:2 * b + 1], smp.offset(a, b), smp.ss[2 * a:2 * b + 1],
                                   flat, last and not edits)
            if spec is not None:
                return _Piece("arc", qn, edits, added, ds, spec)
        if chord is None:
            if chord_exceeds(cur, qn, mid, budget):
                return None
            chord = chord_deviation(cur, qn, Qs)
        if chord <= budget:
            return _Piece("line", qn, edits, added, ds)
        return None

    def _refine(self, sa: float, sb: float, qb: np.ndarray, cur: list[float], last: bool) -> list[_Piece]:
        """Lines following the corrected curve between samples ``sa`` and ``sb`` (the
        controller at ``cur``; ``qb``: the corrected point at ``sb``), as fine as the
        engine's own subdivision needs."""
        mv, d = self.mv, self.d
        (ss, qq), = self.w._subdivide([self.plan["curve"]], [np.array([sa, sb])], mv.unit)
        qq = np.array(qq, dtype=float) if self.to_view is None else self.to_view(qq)
        qq[-1] = qb
        out = []
        for j in range(1, len(ss)):
            qn = list(cur)
            if last and j == len(ss) - 1:
                edits, added = self.w._axis_words(mv, qq[j], qn, d)
            else:
                edits, added = self.w._axis_words_free(mv, qq[j], qn, d)
            out.append(_Piece("line", qn, edits, added, float(ss[j] - ss[j - 1])))
            cur = qn
        return out

    def _exact_arc(self, S_: Sequence[float], E_: Sequence[float], Qp: np.ndarray, P2: np.ndarray,
                   offset: np.ndarray, sp: np.ndarray, flat: bool, may_keep: bool) -> ArcSpec | None:
        """The arc from S to E (both as written) that stays within ``budget`` of the
        corrected samples ``Qp`` (``P2``: their plane coordinates; ``offset``: their mean
        correction, which moves the nominal centre to the first guess; ``flat``: their
        largest distance from the chord S-E is at most one output step): its centre on the
        bisector of S and E, the written centre (I/J/K, or R where the input used R)
        chosen among rounded candidates so that the start and end radii agree to half the
        output resolution. None if none passes.

        ``may_keep``: the piece is the whole move and its end words are unchanged: the
        input's own centre words are kept when their arc still passes (identity keeps
        every input arc as it is)."""
        mv, arc, plan, budget = self.mv, self.arc, self.plan, self.budget
        (a1, a2, an), _letters = PLANES[arc.plane]
        S = np.asarray(S_, dtype=float)
        E = np.asarray(E_, dtype=float)
        span = float(sp[-1] - sp[0])
        if span <= 0.0:
            return None
        nsw = span * plan["nsweep"]
        frac = (sp - sp[0]) / span
        keep = bool(may_keep and span >= 1.0 and plan.get("whole"))
        if len(Qp) > OFF_EVERY_ARC_FROM and self._off_every_arc(S, E, Qp, frac, nsw, keep):
            return None
        if keep:
            ctrl = self.w._input_centre(mv, S, E)
            if ctrl is not None:
                worst, mism, turns = arc_candidates(ArcPiece(S, E, (a1, a2, an), arc.clockwise, nsw, Qp, frac), ctrl[None, :])
                # the input's own reading: the spiral its controller draws (no penalty for
                # the input's own radius mismatch)
                if mism[0] <= plan["mismatch"] + 1e-9 and worst[0] - mism[0] <= budget and turns[0] == arc.turns:
                    return {"form": "keep", "turns": int(turns[0])}
        S2, E2 = (float(S[a1]), float(S[a2])), (float(E[a1]), float(E[a2]))
        cx, cy = arc.center[a1] + offset[a1], arc.center[a2] + offset[a2]
        centres = []
        if math.hypot(E2[0] - S2[0], E2[1] - S2[1]) > 0.0:
            if flat:
                # the path bows from the line S-E by less than one output step: a circle
                # fitted to it is set by the rounding of S and E, not by the path (a centre
                # kilometres off, or a circle a few steps wide, where the chord is a few
                # steps long). The nominal circle, moved with the correction and its centre
                # brought onto the bisector, is tried first.
                centres.append(bisector_point(np.array(S2), np.array(E2), np.array([cx, cy])))
            centres.append(bisector_centre(S2, E2, P2, (cx, cy)))
        else:
            centre = circle_fit(P2)
            centres.append(np.array([cx, cy]) if centre is None or not np.isfinite(centre).all() else centre)
        for centre in centres:
            spec = self._arc_about(S, E, centre, nsw, Qp, frac)
            if spec is not None:
                return spec
        return None

    def _off_every_arc(self, S: np.ndarray, E: np.ndarray, Qp: np.ndarray, frac: np.ndarray, nsw: float,
                       keep: bool) -> bool:
        """True when no arc from S sweeping about ``nsw`` (half a turn or more), whatever
        its centre, can pass (see :meth:`_exact_arc`): a few of the samples ``Qp``
        (:func:`_spread`) are off every circle through S by more than a passing arc allows
        (:func:`postproc.gcode.segment.off_every_circle`), or, near such a circle, one of
        them is off every arc from S to E along the plane's normal by more than the budget
        (:func:`postproc.gcode.segment.off_every_helix`). False where neither is shown.

        An arc that passes is within the budget of every sample, and its radius goes from
        its start radius r0 to r0 + dr along the sample's angle from S, at most half a
        turn from its share of the sweep: each sample lies within ``budget + |dr| (1 +
        pi / |sweep|)`` of the circle about its centre through S. Its |sweep| is within a
        quarter turn of |nsw| (else it turns the wrong number of times), and |dr| (its
        radius mismatch) within what each written form allows: half the output step
        (centre words), the budget (R, under a turn), the input's own mismatch (kept
        words). The margin, a hundred-millionth of the coordinates' magnitude, covers
        the rounding of the measure of any centre within a million times that magnitude."""
        budget, arc = self.budget, self.arc
        if not (budget < math.inf and abs(nsw) >= math.pi):
            return False
        (a1, a2, an), _ = PLANES[arc.plane]
        mism = 0.5 * 10.0 ** (-self.d) * self.mv.unit
        if arc.r_idx >= 0 and abs(nsw) < TWO_PI - 1e-6:
            mism = max(mism, budget)
        if keep:
            mism = max(mism, self.plan["mismatch"] + 1e-9)
        few = _spread(len(Qp), nsw)
        P2 = Qp[few][:, [a1, a2]]
        S2 = np.array([float(S[a1]), float(S[a2])])
        scale = max(float(np.abs(P2).max()), abs(S2[0]), abs(S2[1]))
        radial = mism * (1.0 + math.pi / (abs(nsw) - 0.5 * math.pi))
        bound = (budget + radial) * (1.0 + 1e-9) + 1e-8 * (1.0 + scale)
        if off_every_circle(S2, P2, bound):
            return True
        piece = ArcPiece(S, E, (a1, a2, an), arc.clockwise, nsw, Qp[few], frac[few])
        return off_every_helix(piece, bound, budget)

    def _arc_about(self, S: np.ndarray, E: np.ndarray, centre: np.ndarray, nsw: float, Qp: np.ndarray,
                   frac: np.ndarray) -> ArcSpec | None:
        """The written arc from S to E whose centre is the rounded candidate nearest
        ``centre`` (2,) that passes (see :meth:`_exact_arc`), or None."""
        mv, arc, d, budget = self.mv, self.arc, self.d, self.budget
        (a1, a2, an), (l1, l2) = PLANES[arc.plane]
        axes = (a1, a2, an)
        unit = mv.unit
        step = 10.0 ** (-d)
        agree = 0.5 * step * unit
        if arc.r_idx >= 0 and abs(nsw) < TWO_PI - 1e-6:
            spec = self._r_candidates(S, E, centre, nsw, Qp, frac)
            if spec is not None:
                return spec
        b1, b2 = (float(mv.shift[a1]), float(mv.shift[a2])) if mv.arc_absolute else (float(S[a1]), float(S[a2]))
        base = np.array([b1, b2])
        v0 = np.array([(float(centre[0]) - b1) / unit, (float(centre[1]) - b2) / unit]).round(d)
        V = (v0 + _lattice(d)).round(d)  # ndarray.round: np.round without its wrapper
        C = base[None, :] + V * unit
        # candidates whose radii disagree are refused unmeasured (their worst is inf)
        meas = limited_candidates(ArcPiece(S, E, axes, arc.clockwise, nsw, Qp, frac), C, agree, controller_limits=True)
        if budget < math.inf:
            # the measured candidates within the budget (those within the mismatch limit,
            # not refused); the first of the order below is the best of them when no other
            # ties with it, and is taken when its written centre is the one measured
            worst_l = meas.worst.tolist()
            passing = [w for w in worst_l if w <= budget]
            if not passing:
                return None
            best = min(passing)
            if passing.count(best) == 1:
                k = worst_l.index(best)
                j = int(meas.idx[k])
                texts = (emit.fmt(float(V[j, 0]), d), emit.fmt(float(V[j, 1]), d))
                if float(texts[0]) == V[j, 0] and float(texts[1]) == V[j, 1]:
                    return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(meas.turns[k]),
                            "dev": best, "mismatch": float(meas.mism[k])}
        worst, mism, turns = meas.full()
        ok = (mism <= agree) & (worst <= budget)
        if not ok.any():
            return None
        order = np.argsort(np.where(ok, worst, np.inf))
        # the three best candidates that pass (never one that fails: its radii disagree or
        # it leaves the budget)
        for j in order[:min(3, int(ok.sum()))].tolist():
            texts = (emit.fmt(float(V[j, 0]), d), emit.fmt(float(V[j, 1]), d))
            if float(texts[0]) == V[j, 0] and float(texts[1]) == V[j, 1]:
                # the written centre is the candidate measured (numpy's rounding agreed)
                return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(turns[j]),
                        "dev": float(worst[j]), "mismatch": float(mism[j])}
            ctrl = base + np.array([float(texts[0]), float(texts[1])]) * unit
            w, m, t = arc_candidates(ArcPiece(S, E, axes, arc.clockwise, nsw, Qp, frac), ctrl[None, :],
                                     controller_limits=True)
            if m[0] <= agree and w[0] <= budget:
                return {"form": "ij", "vals": ((l1, texts[0]), (l2, texts[1])), "turns": int(t[0]),
                        "dev": float(w[0]), "mismatch": float(m[0])}
        return None

    def _r_candidates(self, S: np.ndarray, E: np.ndarray, centre: np.ndarray, nsw: float, Qp: np.ndarray,
                      frac: np.ndarray) -> ArcSpec | None:
        """The written R-form arc from S to E nearest ``centre`` that passes (see
        :meth:`_exact_arc`), or None."""
        d, unit, budget, clockwise = self.d, self.mv.unit, self.budget, self.arc.clockwise
        axes = PLANES[self.arc.plane][0]
        a1, a2, an = axes
        step = 10.0 ** (-d)
        half = 0.5 * math.hypot(E[a1] - S[a1], E[a2] - S[a2])
        if half == 0.0:
            return None
        rho = 0.5 * (math.hypot(S[a1] - centre[0], S[a2] - centre[1])
                     + math.hypot(E[a1] - centre[0], E[a2] - centre[1]))
        sign = -1.0 if abs(nsw) > math.pi else 1.0
        r0 = round(rho / unit, d)
        vals = {round(r0 + k * step, d) for k in range(-CENTRE_LATTICE, CENTRE_LATTICE + 1)}
        vals |= {round(math.ceil(half / unit / step) * step + k * step, d) for k in (0, 1, 2)}
        texts, centres = [], []
        for val in sorted(vals):
            text = emit.fmt(sign * val, d)
            R = float(text) * unit
            if abs(R) <= half:
                continue  # every controller must find a centre without its own tolerance
            c = r_center(S[a1], S[a2], E[a1], E[a2], R, clockwise)
            if c is not None:
                texts.append(text)
                centres.append(c)
        if not centres:
            return None
        # every radius's arc measured at once (each row as on its own), the best in the
        # order of the radii: the first of the smallest deviations among one-turn arcs
        w, m, t = arc_candidates(ArcPiece(S, E, axes, clockwise, nsw, Qp, frac), np.array(centres), controller_limits=True)
        best = -1
        for j, (wj, tj) in enumerate(zip(w.tolist(), t.tolist(), strict=True)):
            if tj == 1 and (best < 0 or wj < w[best]):
                best = j
        if best < 0 or not w[best] <= budget:
            return None
        return {"form": "r", "vals": (("R", texts[best]),), "turns": 1, "dev": float(w[best]),
                "mismatch": float(m[best])}
