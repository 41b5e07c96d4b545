"""Fitting a planned move's corrected samples with the fewest exact arcs or lines.

The writer (:mod:`postproc.gcode.emitter`) hands each piece of a move's plan
(:class:`postproc.gcode.vplan.Plan`: corrected samples between reversals) to a
:class:`MoveFit`, which cuts it greedily: from each start, the farthest sample that one
exact arc (arc moves; its centre on the bisector of the written end points, rounded
among candidates whose radii agree) or one chord reaches within the budget.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol, final

import numpy as np

from postproc.gcode import emit, fitcore
from postproc.gcode.geometry import FULL_CIRCLE_MM, R_TOLERANCE, TWO_PI
from postproc.gcode.moves import Arc, Move
from postproc.gcode.segment import (
    CENTRE_LATTICE,
    ArcPiece,
    ArcSpec,
    Point,
    bisector_centre,
    bisector_point,
    circle_fit,
    controller_limits_of,
    full_of,
    off_every_circle,
    off_every_helix,
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
    and the middles of their intervals interleaved (the chord's middle moved by the
    nominal path's bulge there), as lists of floats for the measures of
    :mod:`postproc.gcode.fitcore` (``cols``: by axis, ``sl``: their parameters), and as
    arrays made at the first try that needs them (:meth:`points`, :meth:`params`,
    :meth:`plane_points`: the coordinates of the plane ``plane``, arc moves); the
    corrections of an arc's samples (``dq``: corrected minus nominal, by axis); ``free``:
    the move an inserted line writes."""

    __slots__ = ("mv", "s", "Q", "plane", "dq", "cols", "sl", "_free", "_Qs", "_ss", "_P2")

    def __init__(self, mv: Move, s: np.ndarray, Q: np.ndarray, nom: np.ndarray, bulge: np.ndarray) -> None:
        self.mv = mv
        self.s = s
        self.Q = Q
        self.cols, self.sl = fitcore.interleave(Q.T.tolist(), s.tolist(), bulge.T.tolist())
        self.plane: tuple[int, int] | None = None
        self.dq: list[list[float]] = []
        if mv.arc is not None:
            (a1, a2, _an), _ = PLANES[mv.arc.plane]
            self.plane = (a1, a2)
            self.dq = (Q - nom).T.tolist()
        self._free: Move | None = None
        self._Qs: np.ndarray | None = None
        self._ss: np.ndarray | None = None
        self._P2: np.ndarray | None = None

    @property
    def free(self) -> Move:
        """The move without its words (made at the first inserted line)."""
        if self._free is None:
            self._free = _free_move(self.mv)
        return self._free

    def offset(self, a: int, b: int) -> list[float]:
        """The mean correction over samples a..b of an arc: corrected minus nominal."""
        return [fitcore.mean_between(col, a, b) for col in self.dq]

    def column(self, axis: int, lo: int, hi: int) -> list[float]:
        """Coordinate ``axis`` of the interleaved samples lo..hi - 1."""
        return self.cols[axis][lo:hi]

    def points(self, lo: int, hi: int) -> np.ndarray:
        """The interleaved samples lo..hi - 1, (hi - lo, 3), one row a sample."""
        if self._Qs is None:
            self._Qs = np.array(self.cols).T.copy()
        return self._Qs[lo:hi]

    def params(self, lo: int, hi: int) -> np.ndarray:
        """The parameters of the interleaved samples lo..hi - 1."""
        if self._ss is None:
            self._ss = np.array(self.sl)
        return self._ss[lo:hi]

    def plane_points(self, lo: int, hi: int) -> np.ndarray:
        """The plane coordinates of the interleaved samples lo..hi - 1 of an arc, (hi - lo,
        2), one row a sample."""
        if self._P2 is None:
            assert self.plane is not None
            a1, a2 = self.plane
            self._P2 = np.array([self.cols[a1], self.cols[a2]]).T.copy()
        return self._P2[lo:hi]


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


_NO_ARC = Arc((0.0, 0.0, 0.0), 170, False, 1, (-1, -1), -1)


class _Writer(Protocol):
    """What a fit uses of the writer (:class:`postproc.gcode.emitter.EmitterMixin`): the
    words of a move, its input's own arc centre, the engine's subdivision of a curve."""

    def axis_words(self, mv: Move, target: Point, qe: list[float], d: int,
                    present_only: bool = False) -> tuple[list[Edit], list[str]]: ...

    def axis_words_free(self, mv: Move, q: Point, qe: list[float], d: int) -> tuple[list[Edit], list[str]]: ...

    def input_centre(self, mv: Move, S: Point, E: Point) -> np.ndarray | None: ...

    def subdivision(self, curves: list, s_init: list[np.ndarray], unit: float
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
        lo, hi = 2 * a, 2 * b + 1  # the try's samples and middles
        cols = smp.cols
        # sample b as floats (its row of Q): the words' arithmetic on floats, not numpy scalars
        target = [cols[0][hi - 1], cols[1][hi - 1], cols[2][hi - 1]]
        if last:
            edits, added = self.w.axis_words(mv, target, qn, d)
        else:
            edits, added = self.w.axis_words(smp.free, target, qn, d)
        ds = smp.sl[hi - 1] - smp.sl[lo]
        # the chord's deviation is measured only where needed: the middle sample alone
        # often shows it above the limit it is compared with
        m = (lo + hi) // 2
        mid = [smp.cols[0][m], smp.cols[1][m], smp.cols[2][m]]
        chord: float | None = None
        if mv.arc is not None and smp.plane is not None:
            step_mm = 10.0 ** (-d) * mv.unit
            if fitcore.chord_exceeds(cur, qn, mid, step_mm):
                flat = False
            else:
                chord = self._chord(smp, lo, hi, cur, qn)
                flat = chord <= step_mm
            spec = self._exact_arc(smp, lo, hi, cur, qn, smp.offset(a, b), flat, last and not edits)
            if spec is not None:
                return _Piece("arc", qn, edits, added, ds, spec)
        if chord is None:
            if fitcore.chord_exceeds(cur, qn, mid, budget):
                return None
            chord = self._chord(smp, lo, hi, cur, qn)
        if chord <= budget:
            return _Piece("line", qn, edits, added, ds)
        return None

    @staticmethod
    def _chord(smp: _Samples, lo: int, hi: int, S: list[float], E: list[float]) -> float:
        """The largest distance of the samples lo..hi - 1 from the chord S-E."""
        return fitcore.chord_deviation(S, E, smp.column(0, lo, hi), smp.column(1, lo, hi), smp.column(2, lo, hi))

    def _refine(self, sa: float, sb: float, qb: np.ndarray, cur: list[float], last: bool) -> list[_Piece]:
        """Lines following the corrected curve between samples ``sa`` and ``sb`` (the
        controller at ``cur``; ``qb``: the corrected point at ``sb``), as fine as the
        engine's own subdivision needs."""
        mv, d = self.mv, self.d
        (ss, qq), = self.w.subdivision([self.plan["curve"]], [np.array([sa, sb])], mv.unit)
        qq = np.array(qq, dtype=float) if self.to_view is None else self.to_view(qq)
        qq[-1] = qb
        out = []
        for j in range(1, len(ss)):
            qn = list(cur)
            if last and j == len(ss) - 1:
                edits, added = self.w.axis_words(mv, qq[j], qn, d)
            else:
                edits, added = self.w.axis_words_free(mv, qq[j], qn, d)
            out.append(_Piece("line", qn, edits, added, float(ss[j] - ss[j - 1])))
            cur = qn
        return out

    def _exact_arc(self, smp: _Samples, lo: int, hi: int, S_: list[float], E_: list[float], offset: list[float],
                   flat: bool, may_keep: bool) -> ArcSpec | None:
        """The arc from S to E (both as written) that stays within ``budget`` of the
        corrected samples lo..hi - 1 of ``smp`` (``offset``: their mean correction, which
        moves the nominal centre to the first guess; ``flat``: their largest distance
        from the chord S-E is at most one output step): its centre on the bisector of S
        and E, the written centre (I/J/K, or R where the input used R) chosen among
        rounded candidates so that the start and end radii agree to half the output
        resolution. None if none passes.

        ``may_keep``: the piece is the whole move and its end words are unchanged: the
        input's own centre words are kept when their arc still passes (identity keeps
        every input arc as it is)."""
        mv, arc, plan, budget = self.mv, self.arc, self.plan, self.budget
        (a1, a2, an), _letters = PLANES[arc.plane]
        span = smp.sl[hi - 1] - smp.sl[lo]
        if span <= 0.0 or smp.plane is None:
            return None
        nsw = span * plan["nsweep"]
        keep = bool(may_keep and span >= 1.0 and plan.get("whole"))
        if hi - lo > OFF_EVERY_ARC_FROM:
            # a few of the samples checked first (where each lies along the try, for them
            # as for all: the same division)
            sp = smp.params(lo, hi)
            if self._off_every_arc(np.array(S_), np.array(E_), smp.points(lo, hi), (sp - sp[0]) / span, nsw, keep):
                return None
        frac = fitcore.fractions(smp.sl, lo, hi)
        ends = (S_[a1], S_[a2], S_[an], E_[a1], E_[a2], E_[an])
        full = math.hypot(E_[a1] - S_[a1], E_[a2] - S_[a2]) < FULL_CIRCLE_MM
        tr = fitcore.ArcTry(ends, arc.clockwise, nsw, full, smp.column(a1, lo, hi), smp.column(a2, lo, hi),
                            smp.column(an, lo, hi), frac)
        if keep:
            ctrl = self.w.input_centre(mv, S_, E_)
            if ctrl is not None:
                worst, mism, turns = _one(tr, float(ctrl[0]), float(ctrl[1]), False)
                # the input's own reading: the spiral its controller draws (no penalty for
                # the input's own radius mismatch)
                if mism <= plan["mismatch"] + 1e-9 and worst - mism <= budget and turns == arc.turns:
                    return {"form": "keep", "turns": turns}
        S2, E2 = (S_[a1], S_[a2]), (E_[a1], E_[a2])
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
            centres.append(bisector_centre(S2, E2, smp.plane_points(lo, hi), (cx, cy)))
        else:
            centre = circle_fit(smp.plane_points(lo, hi))
            centres.append(np.array([cx, cy]) if centre is None or not np.isfinite(centre).all() else centre)
        for centre in centres:
            spec = self._arc_about(tr, S_, (float(centre[0]), float(centre[1])), nsw)
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

    def _arc_about(self, tr: fitcore.ArcTry, S: list[float], centre: tuple[float, float],
                   nsw: float) -> ArcSpec | None:
        """The written arc of the try ``tr`` from S whose centre is the rounded candidate
        nearest ``centre`` that passes (see :meth:`_exact_arc`), or None."""
        mv, arc, d, budget = self.mv, self.arc, self.d, self.budget
        (a1, a2, _an), (l1, l2) = PLANES[arc.plane]
        unit = mv.unit
        agree = 0.5 * 10.0 ** (-d) * unit
        if arc.r_idx >= 0 and abs(nsw) < TWO_PI - 1e-6:
            spec = self._r_candidates(tr, centre, nsw)
            if spec is not None:
                return spec
        base = (float(mv.shift[a1]), float(mv.shift[a2])) if mv.arc_absolute else (S[a1], S[a2])
        V1, V2, C1, C2 = fitcore.centre_lattice(centre, base, unit, d, CENTRE_LATTICE)
        # candidates whose radii disagree are refused unmeasured; a measure stops once it
        # shows its candidate beyond the budget
        limits = controller_limits_of(True)
        if budget < math.inf:
            # the measured candidates within the budget (those within the mismatch limit,
            # not refused); the first of the order below is the best of them when no other
            # ties with it, and is taken when its written centre is the one measured (the
            # measures stop also above the best so far: only the best's worst is needed)
            meas = tr.measure(C1, C2, agree, limits, budget, least=True)
            passing = [w for w in meas.worst if w <= budget]
            if not passing:
                return None
            best = min(passing)
            if passing.count(best) == 1:
                k = meas.worst.index(best)
                j = meas.idx[k]
                # (the words' text reads back as the lattice's value: it is the centre measured)
                return {"form": "ij", "vals": ((l1, emit.fmt(V1[j], d)), (l2, emit.fmt(V2[j], d))),
                        "turns": meas.turns[k], "dev": best, "mismatch": meas.mism[k]}
        # the order of all those within the budget
        worst, mism, turns = full_of(tr.measure(C1, C2, agree, limits, budget))
        ok = (mism <= agree) & (worst <= budget)
        if not ok.any():
            return None
        # the best candidate that passes (never one that fails: its radii disagree or it
        # leaves the budget); the first of equals
        j = int(np.argmin(np.where(ok, worst, np.inf)))
        return {"form": "ij", "vals": ((l1, emit.fmt(V1[j], d)), (l2, emit.fmt(V2[j], d))), "turns": int(turns[j]),
                "dev": float(worst[j]), "mismatch": float(mism[j])}

    def _r_candidates(self, tr: fitcore.ArcTry, centre: tuple[float, float], nsw: float) -> ArcSpec | None:
        """The written R-form arc of the try ``tr`` nearest ``centre`` that passes (see
        :meth:`_exact_arc`), or None: of the rounded radii about the centre's, every one's
        arc measured, the first of the smallest deviations among one-turn arcs
        (:meth:`postproc.gcode.fitcore.ArcTry.r_form`)."""
        found = tr.r_form(centre, nsw, self.mv.unit, self.d, CENTRE_LATTICE, R_TOLERANCE, self.budget,
                          controller_limits_of(True))
        if found is None:
            return None
        text, dev, mismatch = found
        return {"form": "r", "vals": (("R", text),), "turns": 1, "dev": dev, "mismatch": mismatch}


def _one(tr: fitcore.ArcTry, cx: float, cy: float, controller_limits: bool) -> tuple[float, float, int]:
    """``(worst, mismatch, turns)`` of the arc of the try ``tr`` about one centre, as
    :func:`postproc.gcode.segment.arc_candidates` gives them."""
    meas = tr.measure([cx], [cy], math.inf, controller_limits_of(controller_limits), math.inf)
    return meas.worst[0] if meas.idx else math.inf, meas.mismatch[0], meas.sel_turns[0]
