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

from postproc.gcode import emit, hintcore, vplan
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
        r = hintcore.MIN_ARC_RADIUS_MM * float(rng.uniform(0.9, 1.6))
    # Python floats throughout, as the planner and the writers ask (a numpy float rounds as numpy does)
    cx, cy = (float(v) for v in rng.uniform(-300, 300, 2))
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
    c1, c2 = cx + float(rng.normal(0, noise + 1e-12)), cy + float(rng.normal(0, noise + 1e-12))
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
def test_the_planners_guess_is_the_writers_answer_in_every_plane(seed, monkeypatch):
    # the planner asks every arc's hint for words at its corrected ends rounded as words
    # are (Planner._hints_failing_rounded); the arcs it finds failing are those whose
    # words are None there, and the writer asking again with the same ends gets the
    # hint's answer without computing it
    from types import SimpleNamespace

    from postproc.gcode.planner import Planner

    rng = np.random.default_rng(seed)
    groups: dict[tuple[int, float], list] = {}
    for plane in (170, 180, 190):
        for case in _cases(seed * 7 + plane, 700):
            hint, _S, _E, cw, d, unit, absolute, shift, _base, budget, _keep, _g, axes = _in_plane(case, plane)
            if rng.integers(8) == 0:  # the fitted centre a step off: the lattice around another candidate
                hint.c1 += float(rng.normal(0, 10.0 ** -d * unit))
            if not all(map(math.isfinite, hint.ends)):
                continue
            hint = vplan.ArcHint(float(hint.c1), float(hint.c2), float(hint.rho), float(hint.worst),
                                 float(hint.nsweep), tuple(float(v) for v in hint.ends), -1, float(hint.mismatch))
            view = _View(Arc((0.0, 0.0, 0.0), plane, cw, 1, (-1, -1), -1), unit, absolute, tuple(shift))
            groups.setdefault((d, budget), []).append((view, hint))
    failing = answered = 0
    for (d, budget), arcs in groups.items():
        # the writer's question: the corrected ends rounded to d decimals, machine axes
        asked = []
        for view, hint in arcs:
            axes = PLANES[view.arc.plane][0]
            S, E = [0.0] * 3, [0.0] * 3
            for k, a in enumerate(axes):
                S[a] = round((hint.ends[k] - view.shift[a]) / view.unit, d) * view.unit + view.shift[a]
                E[a] = round((hint.ends[3 + k] - view.shift[a]) / view.unit, d) * view.unit + view.shift[a]
            base = (view.shift[axes[0]], view.shift[axes[1]]) if view.arc_absolute else (S[axes[0]], S[axes[1]])
            fresh = vplan.ArcHint(hint.c1, hint.c2, hint.rho, hint.worst, hint.nsweep, hint.ends, -1, hint.mismatch)
            asked.append((S, E, axes, view.arc.clockwise, d, view.unit, base, budget,
                          fresh.words(S, E, axes, view.arc.clockwise, d, view.unit, base, budget)))
        planner = SimpleNamespace(opt=SimpleNamespace(decimals=d))
        got = Planner._hints_failing_rounded(planner, [(k, view, hint) for k, (view, hint) in enumerate(arcs)],
                                             budget)
        assert got == {k for k, q in enumerate(asked) if q[-1] is None}
        failing += len(got)
        answered += len(arcs) - len(got)
        for (_view, hint), (*args, ref) in zip(arcs, asked, strict=True):
            kept = hint.last  # the guess's question and answer
            assert _bits(hint.words(*args)) == _bits(ref)
            assert hint.last is kept  # the same question: the guess's answer, not asked again
    assert failing > 100
    assert answered > 300


def test_the_hint_takes_what_moves_carry():
    # compiled, the hint checks the types it reads: a move's shift may be a list, a tuple
    # or an array, its unit an int or a numpy float, its G90.1 flag numpy's bool, the
    # written ends lists or arrays of ints or numpy floats: the answers are the plain floats'
    from types import SimpleNamespace

    hint = vplan.ArcHint(np.float64(0.0), 0.0, 1.0, 0.0, 1.5707963, np.array([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]), 3)
    arc = Arc((0.0, 0.0, 0.0), 170, False, 1, (-1, -1), -1)
    plain = SimpleNamespace(arc=arc, unit=1.0, arc_absolute=False, shift=(0.0, 0.0, 0.0))
    want = (hint.spec(plain, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 4, 1e-3),
            hint.keep(plain, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], (0.0, 0.0), 1e-3),
            hint.guess(arc, 4, 1.0, (0.0, 0.0, 0.0), False, 1e-3))
    assert want[0] is not None
    assert want[1] is not None
    for unit, flag, shift, S, E, centre in [
        (1, np.bool_(False), [0, 0, 0], [1, 0, 0], [0, 1, 0], np.zeros(2)),
        (np.float64(1.0), np.bool_(False), np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]),
         [0.0, 0.0]),
    ]:
        mv = SimpleNamespace(arc=arc, unit=unit, arc_absolute=flag, shift=shift)
        got = (hint.spec(mv, S, E, 4, 1e-3), hint.keep(mv, S, E, centre, 1e-3),
               hint.guess(arc, 4, unit, shift, flag, 1e-3))
        assert got == want


def test_an_arcs_turn_takes_numpy_scalars():
    # geometry.arc_params hands the compiled formula plain floats, a bool and an int,
    # whatever a move carries (a framed arc's centre is an array, numpy's bool a flag)
    from postproc.gcode.geometry import arc_params

    arc = Arc((0.5, -0.25, 0.0), 170, True, 2, (-1, -1), -1)
    want = arc_params(arc, (1.5, -0.25, 0.0), (0.5, 0.75, 1.0))
    odd = Arc(np.array([0.5, -0.25, 0.0]), 170, np.bool_(True), np.int64(2), (-1, -1), -1)
    assert arc_params(odd, np.array([1.5, -0.25, 0.0]), (np.float64(0.5), np.float64(0.75), 1)) == want
