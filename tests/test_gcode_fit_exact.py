"""The fit's cheap shortcuts give the answers of the full measures they spare."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import bisector_cases

from postproc.gcode.segment import chord_deviation, chord_exceeds


def _chord_cases(seed: int, n: int = 400):
    rng = np.random.default_rng(seed)
    for i in range(n):
        scale = 10.0 ** rng.uniform(-3, 3)
        S = rng.uniform(-500, 500, 3)
        E = S + rng.normal(0, scale, 3) * (i % 7 != 0)  # every seventh: S == E
        k = int(rng.integers(1, 40))
        s = np.sort(rng.uniform(0, 1, k))
        Q = S + s[:, None] * (E - S) + rng.normal(0, 10.0 ** rng.uniform(-6, 0), (k, 3))
        yield S.tolist(), E.tolist(), Q


@pytest.mark.parametrize("seed", range(4))
def test_chord_exceeds_never_contradicts_chord_deviation(seed):
    told = 0
    for S, E, Q in _chord_cases(seed):
        full = chord_deviation(S, E, Q)
        for j in (0, len(Q) // 2, len(Q) - 1):
            q = Q[j].tolist()
            exact = chord_deviation(S, E, Q[j:j + 1])
            for limit in (0.0, 0.5 * exact, exact * (1 - 1e-6), exact, exact * (1 + 1e-12), 2 * exact, 1e-4):
                if chord_exceeds(S, E, q, limit):
                    told += 1
                    assert full > limit
                    assert not full <= limit
    assert told > 1000  # the test spares the measure in most cases far from the limit


def test_chord_exceeds_is_false_where_it_cannot_tell():
    S, E = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]
    assert not chord_exceeds(S, E, [0.5, math.nan, 0.0], 0.1)
    assert not chord_exceeds(S, E, [0.5, math.inf, 0.0], 0.1)
    assert not chord_exceeds(S, [math.inf, 0.0, 0.0], [0.5, 1.0, 0.0], 0.1)
    # at the limit itself, within the margin
    assert not chord_exceeds(S, E, [0.5, 0.1, 0.0], 0.1)
    assert chord_exceeds(S, E, [0.5, 0.1 + 1e-6, 0.0], 0.1)
    # beyond the ends the distance is to the nearer end; a point on the segment is at 0
    assert chord_exceeds(S, E, [2.0, 0.0, 0.0], 0.99)
    assert not chord_exceeds(S, E, [0.3, 0.0, 0.0], 0.0)
    # S == E: the distance from the point
    assert chord_exceeds(S, S, [0.0, 0.0, 0.2], 0.1)


# -- the measures rewritten with less overhead, against their old text (fit_reference) ---------

def _arc_cases(seed: int, n: int = 300):
    """Random arcs (some helical, multi-turn, tiny or flat) with samples strayed from them,
    and rounded candidate centres around the true one: S, E, C (m, 2), axes, clockwise,
    nominal sweep, Q (k, 3), frac (k,)."""
    rng = np.random.default_rng(seed)
    planes = [(0, 1, 2), (2, 0, 1), (1, 2, 0)]
    for i in range(n):
        axes = planes[i % 3]
        a1, a2, an = axes
        R = 10.0 ** rng.uniform(-4.5, 3)
        cw = bool(i % 2)
        turns = 1 + (i % 11 == 0)
        sweep = rng.uniform(1e-6, 2 * math.pi) * (turns if i % 11 == 0 else 1) * (-1 if cw else 1)
        c = rng.uniform(-200, 200, 2)
        k = int(rng.integers(2, 60))
        s = np.linspace(0.0, 1.0, k)
        th0 = rng.uniform(-math.pi, math.pi)
        th = th0 + s * sweep
        Q = np.empty((k, 3))
        Q[:, a1] = c[0] + R * np.cos(th)
        Q[:, a2] = c[1] + R * np.sin(th)
        Q[:, an] = rng.uniform(-50, 50) + s * rng.normal(0, 5) * (i % 4 == 0)
        Q += rng.normal(0, 10.0 ** rng.uniform(-7, -2), Q.shape)
        S, E = Q[0].round(4), Q[-1].round(4)
        if i % 29 == 0:
            E = S.copy()
        step = 10.0 ** -int(rng.integers(3, 6))
        ks = np.arange(-3, 4) * step
        C = (c.round(4) + np.stack(np.meshgrid(ks, ks, indexing="ij"), axis=-1).reshape(-1, 2)).round(5)
        if i % 7 == 0:
            C = C[:int(rng.integers(0, 4))]
        yield S, E, C, axes, cw, sweep, Q, s, 0.5 * step


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", range(3))
def test_arc_candidates_are_the_old_ones_bit_for_bit(seed):
    import fit_reference as ref  # noqa: PLC0415  (the tests' own reference, a sibling module)

    from postproc.gcode.segment import ArcPiece, arc_candidates, limited_candidates

    measured = 0
    for S, E, C, axes, cw, sweep, Q, frac, agree in _arc_cases(seed):
        for limits in (False, True):
            for limit in (None, agree, 10 * agree, math.inf):
                old = ref.arc_candidates(S, E, C, axes, cw, sweep, Q, frac, limits, limit)
                new = arc_candidates(ArcPiece(S, E, axes, cw, sweep, Q, frac), C, limits, limit)
                assert all(_same(a, b) for a, b in zip(old, new, strict=True))
                if limit is not None:
                    meas = limited_candidates(ArcPiece(S, E, axes, cw, sweep, Q, frac), C, limit, limits)
                    assert all(_same(a, b) for a, b in zip(old, meas.full(), strict=True))
                    assert _same(meas.worst, old[0][meas.idx])
                    assert _same(meas.turns, old[2][meas.idx])
                    assert _same(meas.mism, old[1][meas.idx])
                    assert np.isinf(np.delete(old[0], meas.idx)).all()
                    measured += len(meas.idx)
    assert measured > 1000


@pytest.mark.parametrize("seed", range(3))
def test_bisector_centre_fits_as_the_old_one_did(seed):
    """The centre fit runs in plain floats (postproc.gcode.fitcore.bisector_centre): its
    sums are taken in order where numpy's went through BLAS, so a centre may differ from
    the old one in the last place, which the Gauss-Newton steps amplify where the centre
    is ill-defined (a circle of kilometres through a few millimetres of path). Most
    centres are the old ones bit for bit; every one fits the points as closely as the old
    one (the points' RMS distance from its circle through S2 and E2 within 0.5 %, or
    within the rounding at the centre's magnitude); the layout of the samples does not
    count."""
    import fit_reference as ref  # noqa: PLC0415  (the tests' own reference, a sibling module)

    from postproc.gcode.segment import bisector_centre

    rng = np.random.default_rng(seed)
    same = 0
    for i, (S2, E2, P2, c0) in enumerate(bisector_cases(rng, 2000)):
        # the samples as the fit holds them (plane columns taken from (k, 3) rows, which
        # numpy lays out by column), by row, and a strided view
        rows = np.c_[P2, np.zeros(len(P2))]
        strided = np.repeat(P2, 2, axis=1)[:, ::2]
        found = [bisector_centre(S2, E2, P, c0) for P in (rows[:, [0, 1]], np.ascontiguousarray(P2),
                                                             np.asfortranarray(P2), strided)]
        assert all(_same(found[0], f) for f in found[1:])
        old = ref.bisector_centre(S2, E2, np.ascontiguousarray(P2), c0)
        if _same(old, found[0]):
            same += 1
            continue
        rms_old, rms_new = _rms_off_circle(S2, P2, old), _rms_off_circle(S2, P2, found[0])
        rounding = 1e-12 * max(1.0, float(np.abs(old).max()), float(np.abs(found[0]).max()))
        assert abs(rms_new - rms_old) <= 5e-3 * rms_old + rounding, (i, old, found[0], rms_old, rms_new)
    assert same > 1700


def _rms_off_circle(S2: np.ndarray, P2: np.ndarray, c: np.ndarray) -> float:
    """RMS distance of the points P2 (k, 2) from the circle about c through S2 (nan: nan)."""
    rho = math.hypot(S2[0] - c[0], S2[1] - c[1])
    return float(np.sqrt(np.mean((np.hypot(P2[:, 0] - c[0], P2[:, 1] - c[1]) - rho) ** 2)))


def test_a_changed_word_moves_the_tracked_position_to_the_value_written():
    # the emitter's tracked position is what the controller reads: the value of the word's
    # text. numpy's round of a numpy float (multiply, rint, divide) is a step off it where the
    # scaled value lies near a half, as 1.1683000257725 to 12 decimals does: text
    # 1.168300025773, numpy 1.168300025772. In G91 the next word would carry that step.
    from types import SimpleNamespace

    from postproc.gcode.emitter import EmitterMixin

    v = 1.1683000257725
    assert round(np.float64(v), 12) != float(f"{v:.12f}")
    for incremental in (False, True):
        mv = SimpleNamespace(unit=1.0, shift=(0.0, 0.0, 0.0), incremental=incremental, axis_idx=(0, -1, -1), frame=None,
                             words=[("X", "0.000000000001", 1, 15, 0)])
        qe = [0.0, 5.0, 7.0]
        target = np.array([v, 5.0, 7.0])  # numpy floats, as a fitted piece's sample is
        edits, added = EmitterMixin.axis_words(None, mv, target, qe, 12, present_only=True)
        assert edits == [(1, 15, "1.168300025773")]
        assert added == []
        assert qe[0] == 1.168300025773
