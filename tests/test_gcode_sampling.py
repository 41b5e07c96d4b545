"""The planner's samples of a chunk's moves, made at once (``sampling._sample_moves``),
against the per-piece computation they replace: np.linspace per piece, arc_points and
line_points, the interval middles' bulge and the carried directions, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from postproc.gcode.geometry import arc_params, arc_points, line_points
from postproc.gcode.interp import Arc, Move
from postproc.gcode.moves import kind_of
from postproc.gcode.sampling import (
    ARC_CHECK_MIN_SAMPLES,
    ARC_CHECK_STEP_RAD,
    SAMPLE_STEP_MM,
    _sample_moves,
)
from postproc.gcode.segment import quadrant_breaks
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE
from postproc.gcode.table import Table


def _move(i, q0, q1, arc=None):
    kind = LINE if arc is None else (ARC_CW if arc.clockwise else ARC_CCW)
    return Move(i + 1, kind, tuple(q0), tuple(q1), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1.0, False, False, [],
                (-1, -1, -1), -1, False, 100.0, {}, arc)


def _reference(planned, arc_prm, Q0, Q1, D, d_in):
    """The per-piece sampling: [(row, s, nominal, dirs, bulge), ...] piece after piece."""
    out = []
    for i, m in planned:
        if m.arc is not None:
            prm = arc_prm[i]
            (_a1, _a2, an), t0, sweep, r0, r1 = prm
            length = math.hypot(abs(sweep) * 0.5 * (r0 + r1), m.q1[an] - m.q0[an])
            cuts = [0.0, *quadrant_breaks(t0, sweep).tolist(), 1.0]
            carried = d_in[i]
            for sa, sb in zip(cuts[:-1], cuts[1:], strict=True):
                n = max(ARC_CHECK_MIN_SAMPLES, math.ceil((sb - sa) * length / SAMPLE_STEP_MM) + 1,
                        math.ceil((sb - sa) * abs(sweep) / ARC_CHECK_STEP_RAD) + 1)
                s = np.linspace(sa, sb, n)
                nom = arc_points(m.arc, m.q0, m.q1, s, prm)
                dd = nom[-1] - nom[0]
                dr = np.sign(np.where(np.abs(dd) > 1e-12, dd, 0.0))
                dr = np.where(dr == 0, carried, dr)
                carried = dr
                mid = arc_points(m.arc, m.q0, m.q1, 0.5 * (s[:-1] + s[1:]), prm)
                out.append((i, s, nom, dr, mid - 0.5 * (nom[:-1] + nom[1:])))
        else:
            length = float(np.linalg.norm(Q1[i] - Q0[i]))
            n = max(3, math.ceil(length / SAMPLE_STEP_MM) + 1)
            s = np.linspace(0.0, 1.0, n)
            out.append((i, s, line_points(Q0[i], Q1[i], s), D[i], np.zeros((n - 1, 3))))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_samples_made_at_once_are_the_per_piece_ones(seed):
    rng = np.random.default_rng(seed)
    planned, arc_prm = [], {}
    M = 40
    Q0 = rng.uniform(0.0, 300.0, (M, 3))
    Q1 = Q0 + rng.normal(0.0, 20.0, (M, 3))
    D = rng.choice([-1.0, 0.0, 1.0], (M, 3))
    d_in = rng.choice([-1.0, 0.0, 1.0], (M, 3))
    for i in range(M):
        if rng.random() < 0.3:
            planned.append((i, _move(i, Q0[i], Q1[i])))
            continue
        plane = [170, 180, 190][int(rng.integers(3))]
        q0, q1 = Q0[i].copy(), Q1[i].copy()
        if rng.random() < 0.4:  # a flat or standing axis: directions carried
            q1[int(rng.integers(3))] = q0[int(rng.integers(3))]
        centre = tuple((0.5 * (q0 + q1) + rng.normal(0.0, 5.0, 3)).tolist())
        turns = 1 + int(rng.random() < 0.15)
        arc = Arc(centre, plane, bool(rng.random() < 0.5), turns, (-1, -1), -1)
        mv = _move(i, q0, q1, arc)
        planned.append((i, mv))
        arc_prm[i] = arc_params(arc, mv.q0, mv.q1)
    kind = np.array([kind_of(m.role, m.kind) for _i, m in planned], dtype=np.int8)
    tab = Table(Q1, np.arange(1, M + 1), np.zeros((M, 3)), [{}] * M, planned, kind)
    tab.q0, tab.dirs, tab.d_in, tab.arc_prm = Q0, D, d_in, arc_prm
    smp = _sample_moves(planned, tab)
    ref = _reference(planned, arc_prm, Q0, Q1, D, d_in)
    assert len(smp.counts) == len(ref)
    assert [row for row, *_ in ref] == smp.piece_move
    pieces = [pc for own in smp.pieces_of for pc in own]
    assert [p for p, _a, _b in pieces] == list(range(len(ref)))
    for (p, a, b), (_row, s, nom, dr, bulge) in zip(pieces, ref, strict=True):
        # bit for bit: the uint64 views agree
        assert smp.s[a:b].view(np.uint64).tolist() == s.view(np.uint64).tolist()
        assert smp.nom[a:b].view(np.uint64).tolist() == nom.view(np.uint64).tolist()
        assert smp.bulge[a - p:b - p - 1].view(np.uint64).tolist() == bulge.view(np.uint64).tolist()
        assert smp.dirs[p].tolist() == np.asarray(dr, dtype=float).tolist()
