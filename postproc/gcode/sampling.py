"""The samples of a chunk's planned moves: where the corrected ideal path is evaluated.

A move is cut into pieces along which every axis moves one way (an arc at its quadrant
points); each piece is sampled at least every :data:`SAMPLE_STEP_MM` along it and, on
an arc, every :data:`ARC_CHECK_STEP_RAD` of sweep. Every emitted arc and chord is fitted
to these samples and checked against them (:mod:`postproc.gcode.arcfit`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import final

import numpy as np

from postproc.gcode.geometry import ArcColumns, arc_length, arcs_points
from postproc.gcode.segment import quadrant_breaks
from postproc.gcode.table import Table
from postproc.gcode.vplan import ArcParams, FloatArray, IntArray, PlanMove

# Samples of the corrected ideal path that every emitted arc and chord is fitted to and
# checked against: at most this far apart along a move (half verify's run step) ...
SAMPLE_STEP_MM = 0.25
# ... and this far apart in angle along an arc, with at least this many on each piece.
ARC_CHECK_STEP_RAD = math.pi / 32
ARC_CHECK_MIN_SAMPLES = 5


@final
class _RunLine:
    """What the planner needs of a straight move read in a run of plain lines."""

    __slots__ = ("lineno",)
    arc: None = None
    rotary: dict[str, float] = {}

    def __init__(self, lineno: int) -> None:
        self.lineno = lineno


@final
class _Sampled:
    """The nominal samples of a chunk's planned moves, cut into pieces along which every
    axis moves one way (see :func:`_sample_moves`)."""

    __slots__ = ("s", "nom", "bulge", "dirs", "counts", "piece_move", "pieces_of")

    def __init__(self, s: FloatArray, nom: FloatArray, bulge: FloatArray, dirs: FloatArray, counts: IntArray,
                 piece_move: list[int], pieces_of: list[list[tuple[int, int, int]]]) -> None:
        self.s = s  # parameters of every sample, piece after piece
        self.nom = nom  # their nominal points
        self.bulge = bulge  # how the nominal path bulges from the chord of each sample interval
        self.dirs = dirs  # (pieces, 3) each piece's approach directions
        self.counts = counts  # samples per piece
        self.piece_move = piece_move  # the row of each piece's move
        self.pieces_of = pieces_of  # per move: (piece, first sample, end) of its pieces


@final
class _Layout:
    """How the planned moves are cut into pieces and sampled (see :func:`_sample_moves`):
    per piece its parameter span (``sa``, ``sb``), its number of samples, its move's row
    and its arc (an index into ``arc_rows``, or -1 for a line); per move its pieces
    (piece, first sample, end); ``total`` samples in all."""

    __slots__ = ("sa", "sb", "n", "piece_move", "arc_piece", "arc_rows", "pieces_of", "total")

    def __init__(self, planned: Sequence[tuple[int, PlanMove | _RunLine]], tab: Table) -> None:
        arc_prm, breaks, Q0, Q1 = tab.arc_prm, tab.breaks, tab.q0, tab.q1
        sa_l: list[float] = []
        sb_l: list[float] = []
        n_l: list[int] = []
        piece_move: list[int] = []
        arc_piece: list[int] = []  # per piece: its arc's index in arc_rows, or -1 for a line
        arc_rows: list[tuple[ArcParams, Sequence[float], Sequence[float], Sequence[float]]] = []  # prm, q0, q1, centre
        pieces_of: list[list[tuple[int, int, int]]] = []
        total = 0
        lengths = iter(_line_lengths([i for i, m in planned if m.arc is None], Q0, Q1))
        for i, m in planned:
            own: list[tuple[int, int, int]] = []
            if m.arc is not None:
                prm = arc_prm[i]
                _axes, t0, sweep, _r0, _r1 = prm
                length = arc_length(m.arc, m.q0, m.q1, prm)
                br = breaks.get(i)
                if br is None:
                    br = breaks[i] = quadrant_breaks(t0, sweep)
                cuts = [0.0, *br.tolist(), 1.0]
                k = len(arc_rows)
                arc_rows.append((prm, m.q0, m.q1, m.arc.center))
                for sa, sb in zip(cuts[:-1], cuts[1:], strict=True):
                    n = _arc_piece_samples(sb - sa, length, sweep)
                    own.append((len(n_l), total, total + n))
                    sa_l.append(sa)
                    sb_l.append(sb)
                    n_l.append(n)
                    piece_move.append(i)
                    arc_piece.append(k)
                    total += n
            else:
                length = next(lengths)
                n = max(3, math.ceil(length / SAMPLE_STEP_MM) + 1)
                own.append((len(n_l), total, total + n))
                sa_l.append(0.0)
                sb_l.append(1.0)
                n_l.append(n)
                piece_move.append(i)
                arc_piece.append(-1)
                total += n
            pieces_of.append(own)
        self.sa, self.sb, self.n, self.piece_move, self.arc_piece = sa_l, sb_l, n_l, piece_move, arc_piece
        self.arc_rows, self.pieces_of, self.total = arc_rows, pieces_of, total


def _sample_moves(planned: Sequence[tuple[int, PlanMove | _RunLine]], tab: Table) -> _Sampled:
    """Samples of the planned moves, every one at once: an arc cut at its quadrant points
    (``breaks`` filled where missing), each piece sampled at least every
    SAMPLE_STEP_MM and ARC_CHECK_STEP_RAD (ARC_CHECK_MIN_SAMPLES at least), a line every
    SAMPLE_STEP_MM (3 samples at least). The parameters are np.linspace's and the
    points :func:`~postproc.gcode.geometry.arc_points`' and
    :func:`~postproc.gcode.geometry.line_points`', element by element the same
    operations. An arc piece's directions are the signs of its chord, carried from the
    piece before (from ``d_in``) where an axis stands; a line's are ``D``."""
    Q0, Q1, D, d_in = tab.q0, tab.q1, tab.dirs, tab.d_in
    lay = _Layout(planned, tab)
    sa_l, sb_l, n_l, piece_move, arc_piece = lay.sa, lay.sb, lay.n, lay.piece_move, lay.arc_piece
    arc_rows, pieces_of, total = lay.arc_rows, lay.pieces_of, lay.total
    counts = np.array(n_l, dtype=int)
    P = len(counts)
    first = np.cumsum(counts) - counts
    sa, sb = np.array(sa_l), np.array(sb_l)
    # np.linspace(sa, sb, n): arange(n) * ((sb - sa) / (n - 1)) + sa, its last value sb
    k_in = (np.arange(total) - np.repeat(first, counts)).astype(float)
    s = k_in * np.repeat((sb - sa) / (counts - 1), counts) + np.repeat(sa, counts)
    s[first + counts - 1] = sb
    owner_piece = np.repeat(np.arange(P), counts)
    rows = np.array(piece_move, dtype=int)
    ap = np.array(arc_piece, dtype=int)
    nom = np.empty((total, 3))
    # lines: q0 + (q1 - q0) * s
    line_smp = np.flatnonzero(ap[owner_piece] < 0)
    if len(line_smp):
        r = rows[owner_piece[line_smp]]
        nom[line_smp] = Q0[r] + (Q1[r] - Q0[r]) * s[line_smp, None]
    # the middle of every sample interval within a piece
    inner = np.ones(total, dtype=bool)
    inner[first + counts - 1] = False
    j = np.flatnonzero(inner)
    s_mid = 0.5 * (s[j] + s[j + 1])
    owner_mid = owner_piece[j]
    bulge = np.zeros((len(j), 3))
    arc_smp = np.flatnonzero(ap[owner_piece] >= 0)
    if len(arc_smp):
        axes = np.array([prm[0] for prm, _q0, _q1, _c in arc_rows], dtype=int)
        t0s, sweeps, r0s, r1s = (np.array([prm[f] for prm, _q0, _q1, _c in arc_rows]) for f in (1, 2, 3, 4))
        q0s, q1s, centres = (np.array([row[f] for row in arc_rows], dtype=float) for f in (1, 2, 3))

        def arc_nominal(which: IntArray, at: FloatArray) -> FloatArray:
            return arcs_points(which, at, ArcColumns(axes, t0s, sweeps, r0s, r1s, centres, q0s, q1s))

        arc_mid = np.flatnonzero(ap[owner_mid] >= 0)
        mid = arc_nominal(ap[owner_mid[arc_mid]], s_mid[arc_mid])
        nom[arc_smp] = arc_nominal(ap[owner_piece[arc_smp]], s[arc_smp])
        jm = j[arc_mid]
        bulge[arc_mid] = mid - 0.5 * (nom[jm] + nom[jm + 1])
    # directions: an arc piece's chord signs, an axis that stands carried from the piece
    # before (the first from d_in); a line's own
    last = first + counts - 1
    dd = nom[last] - nom[first]
    sign = np.sign(np.where(np.abs(dd) > 1e-12, dd, 0.0))
    dirs = D[rows]  # a line's own
    if len(arc_smp):
        # per axis, the last piece of the same arc up to each where the axis moves, else d_in
        at = np.arange(P)
        is_arc = ap >= 0
        first_of_arc = is_arc & np.concatenate([[True], ap[1:] != ap[:-1]])
        arc_start = np.maximum.accumulate(np.where(first_of_arc, at, 0))
        for ax in range(3):
            moves = np.maximum.accumulate(np.where(is_arc & (sign[:, ax] != 0), at, -1))
            known = moves >= arc_start
            col = np.where(known, sign[np.maximum(moves, 0), ax], d_in[rows, ax])
            dirs[is_arc, ax] = col[is_arc]
    return _Sampled(s, nom, bulge, dirs, counts, piece_move, pieces_of)


def _line_lengths(rows: list[int], Q0: FloatArray, Q1: FloatArray) -> list[float]:
    """The lengths of the lines ``rows`` (Q0 to Q1), as np.linalg.norm gives each: the
    square root of the squares summed in order, by whole columns."""
    d = Q1[rows] - Q0[rows]
    d2 = d * d
    out: list[float] = np.sqrt((d2[:, 0] + d2[:, 1]) + d2[:, 2]).tolist()
    return out


def _arc_piece_samples(span: float, length: float, sweep: float) -> int:
    """Samples of an arc piece spanning ``span`` of the arc's parameter (``length``,
    ``sweep``: the whole arc's): at least every SAMPLE_STEP_MM and ARC_CHECK_STEP_RAD,
    and ARC_CHECK_MIN_SAMPLES at least."""
    return max(ARC_CHECK_MIN_SAMPLES, math.ceil(span * length / SAMPLE_STEP_MM) + 1,
               math.ceil(span * abs(sweep) / ARC_CHECK_STEP_RAD) + 1)


def _no_bulge(s: FloatArray, nom: FloatArray) -> FloatArray:
    """A straight move's nominal path does not bulge from its chords."""
    return np.zeros((len(s) - 1, 3))
