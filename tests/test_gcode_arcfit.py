"""The emitter's split-arc fitting pinned on representative moves.

Each case is one piece of corrected samples (the nominal move plus a smooth synthetic
correction that one arc cannot follow within the budget) handed to the emitter's
greedy fit (``arcfit.MoveFit.piece``): the written words of every fitted piece, its arc form,
turns and share of the move are pinned, so that any change of the search or of the
circle fits that alters the output shows here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from postproc.gcode.arcfit import MoveFit
from postproc.gcode.emitter import EmitterMixin
from postproc.gcode.geometry import arc_params, arc_points
from postproc.gcode.interp import Arc, Move
from postproc.gcode.lexer import Word
from postproc.gcode.state import ARC_CCW, ARC_CW, LINE

BUDGET = 0.01 * 0.95


class Fitter(EmitterMixin):
    """The emitter's fitting alone; subdivision: the middle of the interval, corrected."""

    corrected: Callable[[np.ndarray], np.ndarray]

    def subdivision(self, curves, s_init, unit):
        (sa, sb), = s_init
        ss = np.array([sa, 0.5 * (sa + sb), sb])
        return [(ss, self.corrected(ss))]


def build(center, q0, q1, clockwise=False, turns=1, plane=170, n=25, amp=0.05, unit=1.0, r_word=None,
          line=False):
    """A move's samples: ``(mv, plan, s, Q, nom, bulge, corrected)`` as the planner hands them."""
    q0 = tuple(map(float, q0))
    q1 = tuple(map(float, q1))
    words = []
    arc = None
    if not line:
        r_idx = -1
        if r_word is not None:
            words = [Word("R", r_word, 0, len(r_word) + 1, 0)]
            r_idx = 0
        arc = Arc(tuple(map(float, center)), plane, clockwise, turns, (-1, -1), r_idx)
    kind = LINE if line else (ARC_CW if clockwise else ARC_CCW)
    mv = Move(1, kind, q0, q1, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), unit, False, False, words, (-1, -1, -1), -1,
              False, 100.0, {}, arc)
    s = np.linspace(0.0, 1.0, n)
    plan = {"whole": True, "curve": None}
    if arc is None:
        nom = q0 + (np.array(q1) - q0) * s[:, None]
        bulge = np.zeros((n - 1, 3))
    else:
        prm = arc_params(arc, q0, q1)
        nom = arc_points(arc, q0, q1, s, prm)
        mid = arc_points(arc, q0, q1, 0.5 * (s[:-1] + s[1:]), prm)
        bulge = mid - 0.5 * (nom[:-1] + nom[1:])
        plan["nsweep"] = prm[2]
        plan["mismatch"] = abs(prm[4] - prm[3])

    def corrected(ss):
        p = q0 + (np.array(q1) - q0) * ss[:, None] if arc is None else arc_points(arc, q0, q1, ss)
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        return p + amp * np.column_stack([np.sin(y / 3.0 + 0.3), np.cos(x / 4.0), np.sin((x + y) / 5.0 + z)])

    return mv, plan, s, corrected(s), nom, bulge, corrected


CASES = {
    # quarter... three-quarter helix descending 2 mm, CCW in XY
    "helix": dict(center=(50, 50, 0), q0=(60, 50, 20), q1=(50, 40, 18), n=31),
    # a full circle (start == end), CW
    "full_circle": dict(center=(50, 50, 0), q0=(60, 50, 20), q1=(60, 50, 20), clockwise=True, n=41),
    # two turns of a helix
    "two_turn_helix": dict(center=(50, 50, 0), q0=(60, 50, 20), q1=(60, 50, 16), turns=2, n=61),
    # a tiny sweep on a large radius
    "tiny_sweep": dict(center=(0, 0, 0), q0=(500, 0, 10), q1=(500 * math.cos(0.004), 500 * math.sin(0.004), 10),
                       n=9, amp=0.02),
    # a radius near the controllers' smallest (0.00127 mm): written as lines or refused arcs
    "small_radius": dict(center=(20, 20, 5), q0=(20.003, 20, 5), q1=(20, 20.003, 5), n=9, amp=0.0005),
    # a radius below the controllers' smallest: lines
    "below_min_radius": dict(center=(20, 20, 5), q0=(20.001, 20, 5), q1=(19.999, 20, 5.01), n=9, amp=0.004),
    # an R-format arc in G18 (XZ plane)
    "r_word_xz": dict(center=(30, 10, 40), q0=(40, 10, 40), q1=(30, 10, 50), plane=180, r_word="10.", n=21),
    # an inch program (unit 25.4, 5 decimals)
    "inch": dict(center=(100, 100, 0), q0=(125.4, 100, 30), q1=(100, 125.4, 30), unit=25.4, n=21),
    # a line that one chord cannot follow
    "line": dict(center=None, q0=(0, 0, 0), q1=(40, 30, 5), line=True, n=11, amp=0.01),
}

EXPECTED = {
    "helix": [
        "arc X55.9142 Y58.0985 Z19.5500 ij I-10.1517 J0.0320 P1 0.2",
        "arc X50.0496 Y60.0499 Z19.3097 ij I-5.8742 J-7.8657 P1 0.1333333333333333",
        "arc X44.1585 Y58.0919 Z19.1152 ij I0.0477 J-9.9849 P1 0.13333333333333336",
        "arc X41.9136 Y55.8531 Z18.9689 ij I6.1904 J-8.4522 P1 0.06666666666666665",
        "arc X39.9524 Y49.9580 Z18.6237 ij I7.8992 J-5.9017 P1 0.1333333333333333",
        "arc X50.0438 Y40.0499 Z17.9504 ij I10.0451 J0.1378 P1 0.33333333333333337",
    ],
    "full_circle": [
        "arc X58.1224 Y44.1034 Z20.0194 ij I-9.9033 J-0.1217 P1 0.1",
        "arc X54.5894 Y41.1140 Z20.0495 ij I-7.8118 J5.6499 P1 0.07500000000000001",
        "arc X44.1717 Y41.9116 Z19.9763 ij I-4.5408 J9.1245 P1 0.17500000000000002",
        "arc X40.4781 Y46.8715 Z19.9891 ij I5.8931 J8.2438 P1 0.09999999999999998",
        "arc X41.0719 Y54.5068 Z20.0495 ij I9.1103 J3.1322 P1 0.12500000000000006",
        "arc X44.1585 Y58.0919 Z20.0194 ij I9.2669 J-4.8571 P1 0.07499999999999996",
        "arc X50.0496 Y60.0499 Z19.9542 ij I5.9387 J-8.0266 P1 0.09999999999999998",
        "arc X57.0939 Y57.0646 Z19.9543 ij I-0.0153 J-9.8398 P1 0.125",
        "arc X59.9524 Y49.9620 Z19.9542 ij I-7.3712 J-7.0931 P1 0.125",
    ],
    "two_turn_helix": [
        "arc X56.7193 Y57.4297 Z19.6839 ij I-10.1972 J0.0189 P1 0.06666666666666667",
        "arc X51.0948 Y59.9943 Z19.4945 ij I-6.6983 J-7.2403 P1 0.05",
        "arc X43.3367 Y57.4231 Z19.3161 ij I-1.0084 J-9.9472 P1 0.06666666666666665",
        "arc X40.8394 Y54.0322 Z19.1537 ij I6.9482 J-7.7322 P1 0.033333333333333354",
        "arc X40.1917 Y47.8805 Z18.8879 ij I8.7356 J-4.0297 P1 0.04999999999999999",
        "arc X51.0895 Y40.1038 Z18.4243 ij I9.8246 J2.2435 P1 0.11666666666666664",
        "arc X58.1224 Y44.1034 Z18.2405 ij I-0.9351 J9.8274 P1 0.06666666666666671",
        "arc X59.7547 Y47.8847 Z18.1139 ij I-7.8921 J5.6498 P1 0.033333333333333326",
        "arc X58.0940 Y55.8591 Z17.8122 ij I-10.1939 J2.0372 P1 0.06666666666666671",
        "arc X49.0042 Y59.9926 Z17.5167 ij I-8.0543 J-5.6506 P1 0.08333333333333326",
        "arc X45.0422 Y58.6728 Z17.3512 ij I1.1064 J-9.9282 P1 0.033333333333333326",
        "arc X41.9136 Y55.8531 Z17.1596 ij I5.2887 J-9.0136 P1 0.033333333333333326",
        "arc X40.1721 Y52.0387 Z17.0255 ij I8.0961 J-6.0011 P1 0.033333333333333326",
        "arc X41.9421 Y44.0974 Z16.8262 ij I9.5861 J-2.0313 P1 0.06666666666666676",
        "arc X46.9570 Y40.5228 Z16.6230 ij I8.0297 J5.9600 P1 0.04999999999999993",
        "arc X55.0499 Y41.3586 Z16.2901 ij I3.0814 J9.7623 P1 0.06666666666666665",
        "arc X58.1224 Y44.1034 Z16.1565 ij I-4.7321 J8.3891 P1 0.033333333333333326",
        "arc X59.9524 Y49.9620 Z16.0148 ij I-8.0711 J5.7362 P1 0.050000000000000044",
    ],
    "tiny_sweep": [
        "arc X500.0125 Y2.0157 Z9.9914 ij I-307.5040 J2.0148 P1 1.0",
    ],
    "small_radius": [
        "arc X20.0003 Y20.0031 ij I-0.0029 J0.0001 P1 1.0",
    ],
    "below_min_radius": [
        "line X20.0015 Z5.0117 1.0",
    ],
    "r_word_xz": [
        "arc X38.8865 Y9.9523 Z35.5077 r R9.4896 P1 0.1",
        "arc X35.8542 Y9.9551 Z31.8977 r R9.1955 P1 0.1",
        "arc X31.5407 Y9.9981 Z30.1567 r R11.0469 P1 0.10000000000000003",
        "arc X26.8862 Y10.0451 Z30.4980 r R9.6481 P1 0.09999999999999998",
        "arc X22.9053 Y10.0426 Z32.9774 r R10.2107 P1 0.09999999999999998",
        "arc X20.0072 Y10.0146 Z39.2627 r R9.5525 P1 0.15000000000000002",
        "arc X21.8862 Y10.0346 Z45.9234 r R10.2715 P1 0.15000000000000002",
        "arc X25.4365 Y10.0498 Z48.8841 r R11.0072 P1 0.09999999999999998",
        "arc X29.9764 Y10.0173 Z50.0496 r R9.5265 P1 0.09999999999999998",
    ],
    "inch": [
        "arc X4.88611 Y4.24786 Z1.18276 ij I-1.04642 J-0.01885 P1 0.2",
        "arc X4.74758 Y4.52536 Z1.18306 ij I-0.94557 J-0.29871 P1 0.2",
        "arc X4.45948 Y4.78768 Z1.18307 ij I-0.79028 J-0.57858 P1 0.25",
        "arc X4.16877 Y4.90981 Z1.18241 ij I-0.55314 J-0.90960 P1 0.20000000000000007",
        "arc X3.93513 Y4.93896 Z1.18049 ij I-0.23379 J-0.92295 P1 0.1499999999999999",
    ],
    "line": [
        "line X2.0072 Y1.5088 Z0.2581 0.05",
        "line X4.0096 Y3.0054 Z0.5095 0.05",
        "line X11.9984 Y8.9901 Z1.4945 0.20000000000000004",
        "line X13.9939 Y10.4906 Z1.7536 0.04999999999999999",
        "line X15.9908 Y11.9935 Z2.0097 0.04999999999999999",
        "line X24.0002 Y18.0096 Z2.9908 0.20000000000000007",
        "line X32.0090 Y23.9985 Z4.0049 0.19999999999999996",
        "line X34.0058 Y25.4940 Z4.2457 0.050000000000000044",
        "line X36.0012 Y26.9909 Z4.4902 0.04999999999999993",
        "line X39.9923 Y29.9916 Z5.0015 0.09999999999999998",
    ],
}


def describe(p) -> str:
    get = p.get if isinstance(p, dict) else (lambda k, dflt=None: getattr(p, k, dflt))
    out = [get("kind")] + list(get("added")) + [f"{a}:{b}:{t}" for a, b, t in get("edits")]
    spec = get("spec")
    if spec is not None:
        out += [spec["form"]] + [letter + v for letter, v in spec.get("vals", ())] + [f"P{spec['turns']}"]
    out.append(repr(get("ds")))
    return " ".join(out)


@pytest.mark.parametrize("name", list(CASES))
def test_fitted_pieces_are_pinned(name):
    kw = CASES[name]
    mv, plan, s, Q, nom, bulge, corrected = build(**kw)
    d = 5 if kw.get("unit") == 25.4 else 4
    fitter = Fitter()
    fitter.corrected = corrected
    qe = [round(float(v), d) for v in Q[0]]
    pieces = MoveFit(fitter, mv, plan, d, BUDGET).piece(s, Q, nom, bulge, qe, True)
    assert [describe(p) for p in pieces] == EXPECTED[name]
    # every arc written stays within the budget at the samples it covers
    assert all(p.spec is None or p.spec.get("dev", 0.0) <= BUDGET for p in pieces)
