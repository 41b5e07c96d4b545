"""The fit's cheap shortcuts give the answers of the full measures they spare."""

from __future__ import annotations

import math

import numpy as np
import pytest

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
