"""The centre words of an arc the bulk planner settled: one decision, held to the old one.

:meth:`ArcHint.words` (the run writer's call, XY plane) and :meth:`ArcHint.spec` (the
general emitter's, any plane) make the decision that was once ``ArcHint.spec`` followed
by the emitter's controller-limit check, kept as it was in ``arcwords_reference``. On
many generated arcs (seeded) in the three planes, near every threshold the decision has
(smallest radius and sweep, whole turns, ends that coincide in the plane, a bound about
the budget, values that are not finite): the same words, bounds and refusals.
"""

import math

import numpy as np
import pytest
from arcwords_reference import decision  # noqa: I001  (the tests' own reference, a sibling module)

from postproc.gcode import emit, vplan
from postproc.gcode.interp import Arc
from postproc.gcode.segment import MIN_ARC_SWEEP_RAD
from postproc.gcode.state import PLANES


class _View:
    __slots__ = ("arc", "unit", "arc_absolute", "shift")

    def __init__(self, arc, unit, arc_absolute, shift):
        self.arc, self.unit, self.arc_absolute, self.shift = arc, unit, arc_absolute, shift


def _case(rng, kind):
    """One arc as the run writer sees it: the hint, the ends as written, the setup."""
    unit = float(rng.choice([1.0, 25.4]))
    d = int(rng.choice([3, 4])) if unit == 1.0 else int(rng.choice([4, 5]))
    absolute = bool(rng.integers(2))
    cw = bool(rng.integers(2))
    budget = 0.95 * float(rng.choice([0.001, 0.005, 0.01]))
    step = 10.0 ** -d * unit
    r = float(rng.choice([0.002, 0.05, 0.5, 4.0, 40.0, 700.0]))
    if kind == "small":  # about the controllers' smallest radius
        r = vplan.MIN_ARC_RADIUS_MM * float(rng.uniform(0.9, 1.6))
    cx, cy = rng.uniform(-300, 300, 2)
    a0 = float(rng.uniform(-math.pi, math.pi))
    sw = float(rng.choice([1e-4, 0.02, 0.3, 1.5, 3.0, 6.0]))
    if r > 100:
        sw = min(sw, 0.01)
    if kind == "sweep":  # about the smallest sweep (on a large radius: a chord of a few steps), or a whole turn
        if rng.integers(2):
            r, sw = 700.0, MIN_ARC_SWEEP_RAD * float(rng.uniform(0.5, 2.0))
        else:
            sw = 2 * math.pi - float(rng.uniform(0, 1e-5))
    a1 = a0 - sw if cw else a0 + sw
    z0 = float(rng.uniform(-50, 50))
    z1 = z0 + float(rng.choice([0.0, 0.0, rng.uniform(-2, 2)]))
    # written ends: the corrected ends rounded to the words' decimals
    S = [round((cx + r * math.cos(a0)) / unit, d) * unit, round((cy + r * math.sin(a0)) / unit, d) * unit,
         round(z0 / unit, d) * unit]
    E = [round((cx + r * math.cos(a1)) / unit, d) * unit, round((cy + r * math.sin(a1)) / unit, d) * unit,
         round(z1 / unit, d) * unit]
    if kind == "flat":  # the ends coincide in the plane
        E[0], E[1] = S[0], S[1]
    # the hint: the fitted centre near the true one moved onto the bisector of the ends
    # (as the planner fits it), the corrected ends near the written ones
    L = math.hypot(E[0] - S[0], E[1] - S[1])
    if L > 0:
        m1, m2 = 0.5 * (S[0] + E[0]), 0.5 * (S[1] + E[1])
        n1, n2 = -(E[1] - S[1]) / L, (E[0] - S[0]) / L
        t = (cx - m1) * n1 + (cy - m2) * n2
        cx, cy = m1 + t * n1, m2 + t * n2
    noise = float(rng.choice([0.0, 1e-6, 1e-4, step]))
    c1, c2 = cx + rng.normal(0, noise + 1e-12), cy + rng.normal(0, noise + 1e-12)
    rho = math.hypot(S[0] - c1, S[1] - c2)
    worst = float(rng.uniform(0, budget))
    if kind == "budget":  # the bound about the budget
        worst = budget - float(rng.uniform(0, 2 * step))
    ends = tuple(float(v + rng.normal(0, step / 3)) for v in (*S, *E))
    nsweep = -sw if cw else sw
    mismatch = float(rng.choice([0.0, 1e-5, step]))
    hint = vplan.ArcHint(c1, c2, rho, worst, nsweep, ends, -1, mismatch)
    if kind == "nan":
        S[int(rng.integers(3))] = math.nan
    shift = (float(rng.choice([0.0, -0.0, 12.5])), float(rng.choice([0.0, 7.25])), 100.0)
    base = (shift[0], shift[1]) if absolute else (S[0], S[1])
    # the input's own centre words (for the arcs kept): the nominal centre as read
    gi, gj = round((cx - base[0]) / unit, d), round((cy - base[1]) / unit, d)
    keep = kind == "keep"
    return hint, S, E, cw, d, unit, absolute, shift, base, budget, keep, (gi, gj)


def _in_plane(case, plane):
    """The XY case moved to ``plane``: its first, second and normal coordinates on the
    plane's axes."""
    hint, S, E, cw, d, unit, absolute, shift, base, budget, keep, g = case
    axes, _letters = PLANES[plane]

    def place(p):
        out = [0.0, 0.0, 0.0]
        for k, a in enumerate(axes):
            out[a] = p[k]
        return out

    return hint, place(S), place(E), cw, d, unit, absolute, place(shift), base, budget, keep, g, axes


def _reference(case, plane=170):
    """The old per-arc decision: (I, J) values of the words written and the spec, or None."""
    hint, S, E, cw, d, unit, absolute, shift, base, budget, keep, (gi, gj), axes = _in_plane(case, plane)
    view = _View(Arc((0.0, 0.0, 0.0), plane, cw, 1, (-1, -1), -1), unit, absolute, shift)
    if keep:
        c = (base[0] + gi * unit, base[1] + gj * unit)
        return None if hint.keep(view, S, E, c, budget) is None else (gi, gj)
    spec = decision(hint, view, S, E, d, budget)
    if spec is None:
        return None
    (_l1, t1), (_l2, t2) = spec["vals"]
    assert (t1, t2) == (emit.fmt(float(t1), d), emit.fmt(float(t2), d))
    return float(t1), float(t2), spec


KINDS = ["plain"] * 6 + ["small", "sweep", "flat", "budget", "nan", "keep"]


def _cases(seed, n):
    rng = np.random.default_rng(seed)
    return [_case(rng, KINDS[i % len(KINDS)]) for i in range(n)]


def _same(a, b):
    """Equal decisions: both None, or the same word values (bit for bit but the sign of zero,
    which the words' text does not keep)."""
    if a is None or b is None:
        return a is None and b is None
    return a[0] == b[0] and a[1] == b[1]


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_words_is_the_old_spec_and_controller_check(seed):
    taken = refused = 0
    for case in _cases(seed, 1200):
        hint, S, E, cw, d, unit, _absolute, _shift, base, budget, keep, _g = case
        if keep:
            continue
        ref = _reference(case)
        got = hint.words(S, E, (0, 1, 2), cw, d, unit, base, budget)
        assert _same(got, ref), (case, got, ref)
        if got is not None:
            assert emit.fmt(got[0], d) == emit.fmt(ref[0], d)
            assert emit.fmt(got[1], d) == emit.fmt(ref[1], d)
            assert got[2] == ref[2]["mismatch"]
            assert got[2] + got[3] == ref[2]["dev"]
        taken += ref is not None
        refused += ref is None
    assert taken > 200
    assert refused > 200


@pytest.mark.parametrize("plane", [170, 180, 190])
def test_spec_is_the_old_spec_and_controller_check_in_every_plane(plane):
    taken = 0
    for case in _cases(20 + plane, 600):
        if case[10]:  # keep
            continue
        ref = _reference(case, plane)
        hint, S, E, cw, d, unit, absolute, shift, _base, budget, _keep, _g, _axes = _in_plane(case, plane)
        view = _View(Arc((0.0, 0.0, 0.0), plane, cw, 1, (-1, -1), -1), unit, absolute, shift)
        got = hint.spec(view, S, E, d, budget)
        if ref is None:
            assert got is None, (case, got)
            continue
        assert got == ref[2], (case, got, ref)
        taken += 1
    assert taken > 100


def test_plane_of_the_run_writer_is_xy():
    # the run writer reads axes 0 and 1 as the plane, 2 as its normal
    assert PLANES[170][0] == (0, 1, 2)


def _bits(v):
    """A result of ArcHint.words, bit for bit (the sign of zero included)."""
    return None if v is None else tuple(math.copysign(1.0, x) * abs(x) if x == x else "nan" for x in v) + tuple(
        math.copysign(1.0, x) for x in v)


@pytest.mark.parametrize("seed", [31, 32])
def test_words_many_is_words_bit_for_bit_in_every_plane_and_leaves_the_same_answer_for_the_writer(seed, monkeypatch):
    # the planner's guess asks every arc of a chunk at once (vplan.words_many); each answer
    # must be the per-arc ArcHint.words bit for bit, and the writer asking again with the
    # same ends must get it from the hint without computing it
    rng = np.random.default_rng(seed)
    cases = []
    for plane in (170, 180, 190):
        for case in _cases(seed * 7 + plane, 700):
            hint, S, E, cw, d, unit, _absolute, _shift, base, budget, _keep, _g, axes = _in_plane(case, plane)
            if rng.integers(8) == 0:  # the fitted centre a step off: the lattice around another candidate
                hint.c1 += float(rng.normal(0, 10.0 ** -d * unit))
            # Python floats, as the planner and the writer ask (round of a numpy float is numpy's)
            hint = vplan.ArcHint(float(hint.c1), float(hint.c2), float(hint.rho), float(hint.worst),
                                 float(hint.nsweep), tuple(float(v) for v in hint.ends), -1, float(hint.mismatch))
            cases.append((hint, [float(v) for v in S], [float(v) for v in E], axes, cw, d, unit,
                          (float(base[0]), float(base[1])), budget))
    refs = [vplan.ArcHint(h.c1, h.c2, h.rho, h.worst, h.nsweep, h.ends, -1, h.mismatch).words(*rest)
            for h, *rest in cases]
    got: dict[int, object] = {}
    for budget in {c[8] for c in cases}:  # words_many takes one budget for all
        idx = [k for k, c in enumerate(cases) if c[8] == budget]
        mine = [cases[k] for k in idx]
        answers = vplan.words_many([c[0] for c in mine], vplan.WrittenArcs(
            np.array([c[1] for c in mine]), np.array([c[2] for c in mine]), np.array([c[3] for c in mine]),
            [c[4] for c in mine], [c[5] for c in mine], np.array([c[6] for c in mine]),
            np.array([c[7] for c in mine])), budget)
        got.update(zip(idx, answers, strict=True))
    lattice = zero = taken = 0
    for k, (c, ref) in enumerate(zip(cases, refs, strict=True)):
        g = got[k]
        assert _bits(g) == _bits(ref), (c, g, ref)
        taken += g is not None
        if g is not None:
            h, S, E, (a1, a2, _an), _cw, d, unit, base, _b = c
            L = math.hypot(E[a1] - S[a1], E[a2] - S[a2])
            m1, m2 = 0.5 * (S[a1] + E[a1]), 0.5 * (S[a2] + E[a2])
            n1, n2 = -(E[a2] - S[a2]) / L, (E[a1] - S[a1]) / L
            t = (h.c1 - m1) * n1 + (h.c2 - m2) * n2
            lattice += g[0] != round((m1 + t * n1 - base[0]) / unit, d) + 0.0
            zero += g[0] == 0.0 or g[1] == 0.0
    assert taken > 300
    assert lattice > 20  # centres found in the lattice, not at the first candidate
    assert zero > 5

    # the writer's question, same ends: the hint's stored answer, nothing computed again
    # (a NaN end is never the same key: not equal to itself)
    def computed(*_a):
        raise AssertionError("asked again")

    monkeypatch.setattr(vplan.ArcHint, "_words", computed)
    for c, ref in zip(cases, refs, strict=True):
        if not all(map(math.isfinite, c[1] + c[2])):
            continue
        h, S, E, axes, cw, d, unit, base, budget = c
        assert _bits(h.words(S, E, tuple(axes), cw, d, unit, tuple(base), budget)) == _bits(ref)


def test_round_many_is_pythons_round_near_every_half():
    rng = np.random.default_rng(5)
    for d in range(0, 7):
        k = np.round(rng.normal(size=4000) * 10.0 ** rng.integers(0, 7, size=4000))
        ties = (k + 0.5) / 10.0 ** d
        x = np.concatenate([rng.normal(size=4000) * 300, ties, np.nextafter(ties, np.inf), np.nextafter(ties, -np.inf),
                            -ties, [0.0, -0.0, -1e-9, math.inf, -math.inf, math.nan, 1e300, 2.0 ** 60 + 0.5]])
        got = vplan.round_many(x, [d] * len(x))
        ref = [round(v, d) for v in x.tolist()]
        assert [_bits((v,)) for v in got.tolist()] == [_bits((v,)) for v in ref]
    rows = rng.normal(size=(50, 9)) * 40
    dd = rng.integers(0, 6, size=50)
    assert vplan.round_many(rows, dd).tolist() == [[round(v, int(e)) for v in r] for r, e in zip(rows.tolist(), dd, strict=True)]
