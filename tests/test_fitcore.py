"""postproc.gcode.fitcore, the fit's measures in plain floats: its hypot is the C
library's bit for bit, its rint rounds half to even, its centre lattice holds the words as
they are written (each reads back as its value), the compiled module (where it is
compiled) gives the floats its source gives, and a measure that stops early keeps the
answers the fit takes from it."""

from __future__ import annotations

import importlib.util
import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import bisector_cases

from postproc.gcode import arcfit, emit, fitcore, geometry, segment
from postproc.gcode.segment import CENTRE_LATTICE, controller_limits_of

_SOURCE = fitcore.__file__ if fitcore.__file__.endswith(".py") else fitcore.__file__.split(".")[0] + ".py"


def _source_module():
    """fitcore loaded from its .py (the same module where it is not compiled)."""
    spec = importlib.util.spec_from_file_location("fitcore_source", _SOURCE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _bits(values) -> list[int]:
    return np.asarray(values, dtype=float).view(np.uint64).tolist()


def _pairs(seed: int, n: int = 20000):
    rng = np.random.default_rng(seed)
    out = []
    for scale in (1e-300, 1e-160, 1e-3, 1.0, 1e3, 1e160, 1e300):
        x = rng.normal(size=n) * scale
        y = rng.normal(size=n) * scale * rng.uniform(0, 2, n) ** 3
        y[: n // 20] = x[: n // 20] * 10.0 ** rng.uniform(-20, 0, n // 20)  # widely varying
        out.append((x, np.where(np.isfinite(y), y, 1.0)))
    special = [0.0, -0.0, 5e-324, -5e-324, 1e-310, math.inf, -math.inf, math.nan, 1.7e308, 1.0, 3.0]
    sx, sy = np.meshgrid(special, special)
    out.append((sx.ravel(), sy.ravel()))
    return out


@pytest.mark.parametrize("seed", range(2))
def test_hypot_is_the_c_librarys_bit_for_bit(seed):
    # (numpy's hypot is the C library's)
    for x, y in _pairs(seed):
        ours = [fitcore.hypot(a, b) for a, b in zip(x.tolist(), y.tolist(), strict=True)]
        with np.errstate(over="ignore"):  # the largest overflow to inf (as ours do)
            assert _bits(ours) == _bits(np.hypot(x, y))


def test_rint_rounds_half_to_even_as_np_rint():
    rng = np.random.default_rng(5)
    x = np.concatenate([rng.normal(size=20000) * 10.0 ** rng.uniform(-3, 17, 20000),
                        np.arange(-10, 10) + 0.5, [0.0, -0.0, 2.0 ** 52, -(2.0 ** 52), 2.0 ** 52 - 0.5,
                                                    -(2.0 ** 52) + 0.5, 2.0 ** 51 + 0.5, math.inf, -math.inf,
                                                    math.nan, 0.49999999999999994, -0.49999999999999994]])
    assert _bits([fitcore.rint(v) for v in x.tolist()]) == _bits(np.rint(x))


@pytest.mark.parametrize("d", [0, 3, 4, 5, 6])
def test_centre_lattice_holds_the_words_as_written(d):
    # each word is its value rounded to d decimals as Python rounds (the value a
    # controller reads of its text), the lattice steps of one last digit about the rounded
    # centre, each centre the one its words mean
    rng = np.random.default_rng(d)
    step = 10.0 ** (-d)
    for _ in range(300):
        centre = rng.uniform(-500, 500, 2)
        base = rng.uniform(-500, 500, 2) * (rng.random() < 0.5)
        unit = 25.4 if rng.random() < 0.3 else 1.0
        v = [round(float((centre[a] - base[a]) / unit), d) for a in range(2)]
        x1 = [round(v[0] + k * step, d) for k in range(-3, 4)]
        x2 = [round(v[1] + k * step, d) for k in range(-3, 4)]
        w1, w2, c1, c2 = fitcore.centre_lattice((float(centre[0]), float(centre[1])),
                                                (float(base[0]), float(base[1])), unit, d, 3)
        assert _bits(w1) == _bits([a for a in x1 for _b in x2])
        assert _bits(w2) == _bits([b for _a in x1 for b in x2])
        assert _bits(c1) == _bits([float(base[0]) + a * unit for a in w1])
        assert _bits(c2) == _bits([float(base[1]) + b * unit for b in w2])
        assert all(float(emit.fmt(w, d)) == w for w in w1 + w2)  # the text reads back as the value


def _chord_reference(S, E, Q):
    """The chord's deviation as numpy measured it (the products through BLAS)."""
    a = np.asarray(S, dtype=float)
    ab = np.asarray(E, dtype=float) - a
    den = float(ab @ ab)
    if den == 0.0:
        d = Q - a
    else:
        t = np.minimum(np.maximum(((Q - a) @ ab) / den, 0.0), 1.0)
        d = Q - (a + t[:, None] * ab)
    return math.sqrt(float(np.add.reduce(d * d, axis=1).max()))


def test_chord_deviation_agrees_with_numpys_to_the_rounding():
    rng = np.random.default_rng(7)
    for i in range(3000):
        S = rng.uniform(-500, 500, 3)
        E = S + rng.normal(0, 10.0 ** rng.uniform(-3, 3), 3) * (i % 7 != 0)
        k = int(rng.integers(1, 60))
        Q = S + np.sort(rng.uniform(-0.1, 1.1, k))[:, None] * (E - S) + rng.normal(0, 10.0 ** rng.uniform(-6, 0), (k, 3))
        ours = fitcore.chord_deviation(S.tolist(), E.tolist(), *Q.T.tolist())
        scale = float(np.abs(np.vstack([Q, S, E])).max())
        assert abs(ours - _chord_reference(S, E, Q)) <= 1e-14 * scale


def _arc_try(mod, rng, k):
    """A try of a random arc (some of several turns) through k samples strayed from it,
    and the rounded candidate centres around its centre."""
    r = 10.0 ** rng.uniform(-2, 2)
    c = rng.uniform(-200, 200, 2)
    t0 = rng.uniform(-math.pi, math.pi)
    cw = bool(rng.integers(0, 2))
    sweep = rng.uniform(0.1, 4 * math.pi) * (-1.0 if cw else 1.0)
    frac = np.linspace(0.0, 1.0, k)
    th = t0 + sweep * frac
    z0, dz = rng.uniform(-50, 50), rng.normal(0, 5)
    noise = 10.0 ** rng.uniform(-5, -2)
    u = c[0] + r * np.cos(th) + rng.normal(0, noise, k)
    v = c[1] + r * np.sin(th) + rng.normal(0, noise, k)
    w = z0 + dz * frac + rng.normal(0, noise, k)
    ends = (round(u[0], 4), round(v[0], 4), round(w[0], 4), round(u[-1], 4), round(v[-1], 4), round(w[-1], 4))
    tr = mod.ArcTry(ends, cw, sweep, False, u.tolist(), v.tolist(), w.tolist(), frac.tolist())
    step = 10.0 ** -int(rng.integers(3, 5))
    cands = mod.centre_lattice((float(c[0]), float(c[1])), (0.0, 0.0), 1.0, int(round(-math.log10(step))), 3)
    return tr, cands[2], cands[3], 0.5 * step, noise


def _found(m):
    return (m.mismatch, m.sel, m.sel_turns, m.idx, m.turns, m.mism, m.worst)


def test_the_compiled_module_gives_the_floats_of_its_source():
    src = _source_module()
    rng = np.random.default_rng(11)
    for x, y in _pairs(3, 500):
        xs, ys = x.tolist(), y.tolist()
        assert _bits([fitcore.hypot(a, b) for a, b in zip(xs, ys, strict=True)]) == \
            _bits([src.hypot(a, b) for a, b in zip(xs, ys, strict=True)])
        assert _bits([fitcore.rint(a * 1e3) for a in xs if math.isfinite(a * 1e3)]) == \
            _bits([src.rint(a * 1e3) for a in xs if math.isfinite(a * 1e3)])
    for _ in range(200):
        S, E = rng.uniform(-100, 100, 3).tolist(), rng.uniform(-100, 100, 3).tolist()
        Q = rng.uniform(-100, 100, (int(rng.integers(1, 30)), 3)).T.tolist()
        assert _bits([fitcore.chord_deviation(S, E, *Q)]) == _bits([src.chord_deviation(S, E, *Q)])
        q = [row[0] for row in Q]
        assert fitcore.chord_exceeds(S, E, q, 1.0) == src.chord_exceeds(S, E, q, 1.0)
    for d in range(9):
        for _ in range(20):
            centre, base = tuple(rng.uniform(-500, 500, 2).tolist()), tuple(rng.uniform(-500, 500, 2).tolist())
            for unit in (1.0, 25.4):
                assert [_bits(a) for a in fitcore.centre_lattice(centre, base, unit, d, 3)] == \
                    [_bits(b) for b in src.centre_lattice(centre, base, unit, d, 3)]
    ss = np.sort(rng.uniform(0, 1, 50)).tolist()
    assert _bits(fitcore.fractions(ss, 3, 40)) == _bits(src.fractions(ss, 3, 40))
    for _ in range(200):
        k = int(rng.integers(2, 80))
        state = rng.bit_generator.state
        tr, cx, cy, agree, noise = _arc_try(fitcore, rng, k)
        rng.bit_generator.state = state
        tr_src, *_ = _arc_try(src, rng, k)
        for limit, stop, least in ((agree, math.inf, False), (math.inf, math.inf, False), (agree, 3 * noise, True)):
            ours = _found(tr.measure(cx, cy, limit, (1e-6, 1e-5), stop, least))
            theirs = _found(tr_src.measure(cx, cy, limit, (1e-6, 1e-5), stop, least))
            assert [_bits(a) for a in ours] == [_bits(b) for b in theirs]


def test_a_measure_that_stops_keeps_what_the_fit_takes_from_it():
    """With a stop (the budget) the candidates within it are measured in full, the others
    are above it; with ``least`` the least worst and those equal to it are measured in
    full and the others are above it."""
    rng = np.random.default_rng(13)
    cut = 0
    for _ in range(300):
        tr, cx, cy, agree, noise = _arc_try(fitcore, rng, int(rng.integers(2, 120)))
        budget = noise * rng.uniform(0.5, 6)
        full = tr.measure(cx, cy, agree, (0.0, 0.0), math.inf)
        for least in (False, True):
            part = tr.measure(cx, cy, agree, (0.0, 0.0), budget, least)
            assert (part.idx, part.turns, part.mism) == (full.idx, full.turns, full.mism)
            passing = [w for w in full.worst if w <= budget]
            best = min(passing, default=math.inf)
            bound = min(best, budget) if least else budget
            for w_full, w_part in zip(full.worst, part.worst, strict=True):
                if w_full <= bound:
                    assert w_part == w_full
                else:
                    assert bound < w_part <= w_full
                    cut += w_part < w_full
            if least and passing:
                kept = [w for w in part.worst if w <= budget]
                assert min(kept) == best
                assert kept.count(best) == passing.count(best)
    assert cut > 100


def _bisector_cases(rng, n: int):
    """conftest.bisector_cases as fitcore takes them: (S2, E2, us, vs, c0) in floats."""
    for S2, E2, P2, c0 in bisector_cases(rng, n):
        yield tuple(S2.tolist()), tuple(E2.tolist()), P2[:, 0].tolist(), P2[:, 1].tolist(), tuple(c0.tolist())


def test_the_compiled_centre_fit_gives_the_floats_of_its_source():
    src = _source_module()
    rng = np.random.default_rng(17)
    settled = 0
    for S2, E2, us, vs, c0 in _bisector_cases(rng, 3000):
        ours = fitcore.bisector_centre(S2, E2, us, vs, c0)
        theirs = src.bisector_centre(S2, E2, us, vs, c0)
        assert _bits(ours) == _bits(theirs), (S2, E2, c0)
        settled += math.isfinite(ours[0]) and S2 != E2
    assert settled > 2000


def test_the_centre_fit_finds_the_circle_through_the_ends():
    """On the samples of an exact circle through S2 and E2 the centre is the circle's to
    the rounding, from a first guess near it on its side of the chord (a step across the
    chord is halved: the guess says which side)."""
    rng = np.random.default_rng(19)
    for _ in range(500):
        R = 10.0 ** rng.uniform(-1, 3)
        c = rng.uniform(-300, 300, 2)
        t0 = rng.uniform(-math.pi, math.pi)
        sweep = rng.uniform(0.2, 2.6) if rng.random() < 0.5 else rng.uniform(3.7, 6.0)
        th = t0 + sweep * np.linspace(0.0, 1.0, int(rng.integers(3, 60)))
        us, vs = (c[0] + R * np.cos(th)).tolist(), (c[1] + R * np.sin(th)).tolist()
        c0 = (c + rng.normal(0, 0.02 * R, 2)).tolist()
        found = fitcore.bisector_centre((us[0], vs[0]), (us[-1], vs[-1]), us, vs, (c0[0], c0[1]))
        assert math.hypot(found[0] - c[0], found[1] - c[1]) <= 1e-9 * (R + 300.0)


def test_mean_between_is_numpys_mean_of_rows_bit_for_bit():
    """The mean correction of an arc's samples (arcfit's offset) as numpy took it, the rows
    of a (k, 3) array summed one after another; the compiled module's the same."""
    src = _source_module()
    rng = np.random.default_rng(23)
    for _ in range(2000):
        k = int(rng.integers(1, 200))
        dq = rng.normal(0, 1, (k, 3)) * 10.0 ** rng.uniform(-9, 3, (k, 1))
        a = int(rng.integers(0, k))
        b = int(rng.integers(a, k))
        want = np.add.reduce(dq[a:b + 1], axis=0) / (b + 1 - a)
        cols = dq.T.tolist()
        ours = [fitcore.mean_between(col, a, b) for col in cols]
        assert _bits(ours) == _bits(want)
        assert _bits(ours) == _bits([src.mean_between(col, a, b) for col in cols])


# -- R-form arcs ----------------------------------------------------------------------------

def _numfmt_source():
    """numfmt loaded from its .py (the same module where it is not compiled)."""
    from postproc.gcode import numfmt  # noqa: PLC0415

    path = numfmt.__file__ if numfmt.__file__.endswith(".py") else numfmt.__file__.split(".")[0] + ".py"
    spec = importlib.util.spec_from_file_location("numfmt_source", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _r_try(mod, rng):
    """A try of a random arc of under a turn (some near half a turn, some short, a few with
    one end point for both), its ends rounded as an R arc's words are, through k samples
    strayed from it: ``(tr, centre, nsw, d, unit, budget)``, ``centre`` near the arc's."""
    d = int(rng.choice([1, 2, 3, 3, 4, 4, 5]))
    unit = 25.4 if rng.random() < 0.3 else 1.0
    r = 10.0 ** rng.uniform(-1.5, 2.5)
    c = rng.uniform(-300, 300, 2)
    t0 = rng.uniform(-math.pi, math.pi)
    cw = bool(rng.integers(0, 2))
    kind = rng.random()
    if kind < 0.2:
        sweep = math.pi + rng.normal(0, 10.0 ** rng.uniform(-6, -1))
    elif kind < 0.4:
        sweep = rng.uniform(1e-4, 0.3)
    else:
        sweep = rng.uniform(0.01, 2 * math.pi - 0.01)
    nsw = -sweep if cw else sweep
    k = int(rng.integers(2, 40))
    frac = np.linspace(0.0, 1.0, k)
    th = t0 + nsw * frac
    noise = 10.0 ** rng.uniform(-6, -2)
    u = c[0] + r * np.cos(th) + rng.normal(0, noise, k)
    v = c[1] + r * np.sin(th) + rng.normal(0, noise, k)
    w = rng.uniform(-50, 50) + rng.normal(0, 1) * frac
    step = 10.0 ** -d * unit
    ends = [float(np.round(x / step) * step) for x in (u[0], v[0], w[0], u[-1], v[-1], w[-1])]
    if rng.random() < 0.03:
        ends[3], ends[4] = ends[0], ends[1]
    tr = mod.ArcTry(tuple(ends), cw, nsw, False, u.tolist(), v.tolist(), w.tolist(), frac.tolist())
    centre = c + rng.normal(0, 10.0 ** rng.uniform(-7, -2) * r, 2)
    budget = math.inf if rng.random() < 0.05 else (noise + step) * rng.uniform(0.5, 6)
    return tr, (float(centre[0]), float(centre[1])), nsw, d, unit, budget


_R_TOL = geometry.R_TOLERANCE
_LIMITS = controller_limits_of(True)


def _r_spec(tr, centre, nsw, d, unit, budget):
    """The writer's R form of the try (MoveFit._r_candidates) for these values."""
    fit = SimpleNamespace(d=d, mv=SimpleNamespace(unit=unit), budget=budget)
    return arcfit.MoveFit._r_candidates(fit, tr, centre, nsw)


def test_the_r_form_chooses_the_candidates_and_the_arc_the_writer_chose():
    """ArcTry.r_candidates and r_form (and MoveFit._r_candidates on them) give the R
    words, centres and choice of the Python loop they replace (tests/fit_reference.py),
    bit for bit."""
    import fit_reference as ref  # noqa: PLC0415  (the tests' own reference, a sibling module)

    rng = np.random.default_rng(29)
    chosen = negative = none = 0
    for _ in range(4000):
        tr, centre, nsw, d, unit, budget = _r_try(fitcore, rng)
        texts, cx, cy, spec = ref.r_candidates(tr, centre, nsw, d, unit, budget)
        ours = tr.r_candidates(centre, nsw, unit, d, CENTRE_LATTICE, _R_TOL)
        assert ours[0] == texts
        assert _bits(ours[1]) == _bits(cx)
        assert _bits(ours[2]) == _bits(cy)
        found = _r_spec(tr, centre, nsw, d, unit, budget)
        if spec is None:
            assert found is None
            none += 1
            continue
        assert found == spec
        assert _bits([found["dev"], found["mismatch"]]) == _bits([spec["dev"], spec["mismatch"]])
        chosen += 1
        negative += spec["vals"][0][1].startswith("-")
    assert min(chosen, none, 2 * negative) > 1000, (chosen, none, negative)


def test_the_compiled_r_form_gives_what_its_source_gives():
    """r_center, r_radii (Python's round), r_candidates (numfmt's %.*f) and r_form: the
    compiled module's results are its source's, bit for bit."""
    src = _source_module()
    rng = np.random.default_rng(31)
    for _ in range(20000):
        s1, s2, e1, e2 = (rng.uniform(-500, 500, 4) * 10.0 ** rng.uniform(-4, 0)).tolist()
        if rng.random() < 0.02:
            e1, e2 = s1, s2
        half = 0.5 * math.hypot(e1 - s1, e2 - s2)
        R = half * (1.0 + float(rng.choice([0.0, -1e-3, -1e-2, 1e-9, 1e-3, 1.0, 50.0]))) * float(rng.choice([1, -1]))
        cw = bool(rng.integers(0, 2))
        ours = fitcore.r_center(s1, s2, e1, e2, R, cw, *_R_TOL)
        theirs = src.r_center(s1, s2, e1, e2, R, cw, *_R_TOL)
        assert (ours is None) == (theirs is None)
        if ours is not None:
            assert _bits(ours) == _bits(theirs)
    for _ in range(20000):
        rho, half = (10.0 ** rng.uniform(-4, 4, 2)).tolist()
        unit = 25.4 if rng.random() < 0.3 else 1.0
        d = int(rng.integers(0, 7))
        assert _bits(fitcore.r_radii(rho, half, unit, d, 3)) == _bits(src.r_radii(rho, half, unit, d, 3))
    for _ in range(3000):
        state = rng.bit_generator.state
        tr, centre, nsw, d, unit, budget = _r_try(fitcore, rng)
        rng.bit_generator.state = state
        tr_src, *_ = _r_try(src, rng)
        ours = tr.r_candidates(centre, nsw, unit, d, CENTRE_LATTICE, _R_TOL)
        theirs = tr_src.r_candidates(centre, nsw, unit, d, CENTRE_LATTICE, _R_TOL)
        assert ours[0] == theirs[0]
        assert [_bits(a) for a in ours[1:]] == [_bits(b) for b in theirs[1:]]
        ours = tr.r_form(centre, nsw, unit, d, CENTRE_LATTICE, _R_TOL, budget, _LIMITS)
        theirs = tr_src.r_form(centre, nsw, unit, d, CENTRE_LATTICE, _R_TOL, budget, _LIMITS)
        assert (ours is None) == (theirs is None)
        if ours is not None:
            assert ours[0] == theirs[0]
            assert _bits(ours[1:]) == _bits(theirs[1:])


def test_round_and_fixed_point_text_are_pythons_compiled():
    """The rounding (``round(x, d)``, through r_radii) and the text (numfmt.fmt, ``%.*f``)
    of the compiled modules are Python's own over many values, halves of the last decimal
    among them."""
    src = _numfmt_source()
    from postproc.gcode import numfmt  # noqa: PLC0415

    rng = np.random.default_rng(37)
    for d in range(8):
        x = np.concatenate([rng.normal(0, 1, 3000) * 10.0 ** rng.uniform(-3, 6, 3000),
                            (rng.integers(-10 ** 6, 10 ** 6, 3000) + 0.5) / 10.0 ** d]).tolist()
        assert [numfmt.fmt(v, d) for v in x] == [src.fmt(v, d) for v in x] == [_py_fmt(v, d) for v in x]
        for v in x:
            # r_radii's first values: rho (here |v|) rounded and the steps below it
            r0 = round(abs(v), d)
            want = sorted({round(r0 + k * 10.0 ** -d, d) for k in range(-3, 4)}
                          | {round(math.ceil(0.5 / 10.0 ** -d) * 10.0 ** -d + k * 10.0 ** -d, d) for k in (0, 1, 2)})
            assert _bits(fitcore.r_radii(abs(v), 0.5, 1.0, d, 3)) == _bits(want)


def _py_fmt(v: float, d: int) -> str:
    text = "%.*f" % (d, v)  # noqa: UP031
    return text[1:] if text[0] == "-" and not text.strip("-0.") else text


def test_geometrys_r_center_is_the_one_formula():
    """geometry.r_center (the interpreter's, the readers' and the writer's) is fitcore's
    with the controllers' tolerances, as it was (numpy scalars and bools taken too)."""
    import fit_reference as ref  # noqa: PLC0415

    rng = np.random.default_rng(41)
    for i in range(20000):
        s1, s2, e1, e2 = rng.uniform(-500, 500, 4).tolist()
        if i % 50 == 0:
            e1, e2 = s1, s2
        half = 0.5 * math.hypot(e1 - s1, e2 - s2)
        R = half * (1.0 + float(rng.choice([0.0, -1e-3, -1e-5, -1e-7, 1e-3, 3.0]))) * float(rng.choice([1, -1]))
        cw = bool(rng.integers(0, 2))
        args = (s1, s2, e1, e2, R, cw)
        if i % 3 == 0:
            args = (*np.array(args[:5]), np.bool_(cw))
        want = ref.r_center(*args)
        got = geometry.r_center(*args)
        assert (got is None) == (want is None)
        if got is not None:
            assert _bits(got) == _bits(want)
    # every reader and the writer call this one (segment has none of its own); the bulk
    # reader's arcs (plainscan.run_arcs) call fitcore's with geometry's tolerances
    from postproc.gcode import emitter, fitcore, interp_motion, plainscan

    assert emitter.r_center is interp_motion.r_center is geometry.r_center
    assert plainscan.r_center is fitcore.r_center
    assert not hasattr(segment, "r_center")


def test_interleave_is_the_samples_numpy_interleaved():
    """The samples and the middles of their intervals (moved by the bulge) as arcfit built
    them with numpy, bit for bit; the compiled module's the same."""
    src = _source_module()
    rng = np.random.default_rng(43)
    for _ in range(2000):
        n = int(rng.integers(1, 40))
        Q = rng.uniform(-500, 500, (n, 3)) * 10.0 ** rng.uniform(-3, 0)
        s = np.sort(rng.uniform(0, 1, n))
        bulge = rng.normal(0, 10.0 ** rng.uniform(-9, -1), (max(n - 1, 0) + int(rng.integers(0, 2)), 3))
        Qs = np.empty((2 * n - 1, 3))
        Qs[0::2] = Q
        Qs[1::2] = 0.5 * (Q[:-1] + Q[1:]) + bulge[:n - 1]
        ss = np.empty(2 * n - 1)
        ss[0::2] = s
        ss[1::2] = 0.5 * (s[:-1] + s[1:])
        args = (Q.T.tolist(), s.tolist(), bulge.T.tolist() if len(bulge) else [[], [], []])
        cols, sl = fitcore.interleave(*args)
        assert [_bits(c) for c in cols] == [_bits(c) for c in Qs.T]
        assert _bits(sl) == _bits(ss)
        cols_src, sl_src = src.interleave(*args)
        assert [_bits(c) for c in cols_src] == [_bits(c) for c in cols]
        assert _bits(sl_src) == _bits(sl)
