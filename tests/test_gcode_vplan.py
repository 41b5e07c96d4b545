"""Moves settled in bulk (one engine call per chunk) are written as the general planner
writes them: straight moves byte for byte; arcs as exact circles within --tolerance of
the corrected ideal path, with the centre moved by no more than the bound allows."""

import warnings

import numpy as np
import pytest
from conftest import PARAMETRIC, TOL, emitted_arcs, ideal_vs_emitted

from postproc.calfile import load_calibration
from postproc.effects import compose
from postproc.engine.static import StaticEngine
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text


def _lines_program(seed: int, n: int = 400) -> str:
    """Straight moves of every length (0.01 to 60 mm), some of them plain runs, some not."""
    rng = np.random.default_rng(seed)
    out = ["G21 G90 G17\n", "G0 X150 Y150 Z120\n", "G1 Z100 F500\n"]
    x, y, z = 150.0, 150.0, 100.0
    for i in range(n):
        step = rng.choice([0.01, 0.3, 2.0, 15.0, 60.0])
        x = float(np.clip(x + rng.uniform(-step, step), 20, 290))
        y = float(np.clip(y + rng.uniform(-step, step), 20, 290))
        if i % 7 == 0:
            z = float(np.clip(z + rng.uniform(-3, 3), 60, 140))
            out.append(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f} (plunge)\n")  # not a plain line: the interpreter reads it
        elif i % 11 == 0:
            out.append(f"G0 X{x:.3f} Y{y:.3f}\n")
        else:
            out.append(f"X{x:.4f} Y{y:.4f}\n")
    out.append("M2\n")
    return "".join(out)


@pytest.fixture(scope="module")
def parametric():
    return load_calibration(PARAMETRIC).engine


@pytest.mark.parametrize("seed", [1, 2])
def test_straight_moves_settled_in_bulk_are_written_as_the_general_planner_writes_them(parametric, seed):
    text = _lines_program(seed)
    outs = [correct_text(text, parametric, Setup(), CorrectOptions(bulk_plan=bp, bulk_lane=bl, chunk_lines=97))
            for bp, bl in ((True, True), (True, False), (False, False))]
    assert outs[0][0] == outs[1][0] == outs[2][0]
    # the long moves are split (the calibration is not affine), the short ones are not
    assert outs[0][1].lines_inserted > 0
    assert ideal_vs_emitted(text, outs[0][0], parametric, Setup()) <= TOL


def _arcs_program(seed: int) -> str:
    """Arcs of every kind the bulk planner takes: small and large radius, short chords,
    helices, both directions, absolute and incremental centres."""
    rng = np.random.default_rng(seed)
    out = ["G21 G90 G17\n", "G0 X150 Y150 Z100\n", "G1 Z90 F500\n"]
    x, y = 150.0, 150.0
    z = 90.0
    for _ in range(60):
        r = float(rng.choice([0.05, 0.5, 4.0, 40.0, 700.0]))
        a0 = rng.uniform(0, 2 * np.pi)
        sweep = float(rng.choice([0.02, 0.3, 1.5, 3.0])) if r < 700 else 0.006
        cw = bool(rng.integers(2))
        cx, cy = x - r * np.cos(a0), y - r * np.sin(a0)
        a1 = a0 - sweep if cw else a0 + sweep
        ex, ey = cx + r * np.cos(a1), cy + r * np.sin(a1)
        if not (20 < ex < 290 and 20 < ey < 290):
            continue
        dz = float(rng.choice([0.0, 0.0, 0.5]))
        z = float(np.clip(z - dz, 60, 140))
        out.append(f"G{2 if cw else 3} X{ex:.4f} Y{ey:.4f}{f' Z{z:.4f}' if dz else ''} "
                   f"I{cx - x:.4f} J{cy - y:.4f}\n")
        x, y = float(f"{ex:.4f}"), float(f"{ey:.4f}")
    out.append("M2\n")
    return "".join(out)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_arcs_settled_in_bulk_are_exact_and_within_tolerance(parametric, seed):
    text = _arcs_program(seed)
    out, rep = correct_text(text, parametric, Setup(), CorrectOptions())
    general, _ = correct_text(text, parametric, Setup(), CorrectOptions(bulk_plan=False))
    for unit, r0, r1, lineno in emitted_arcs(out, Setup()):
        assert abs(r1 - r0) <= 0.5e-4 * unit + 1e-9, out.splitlines()[lineno - 1]
    assert ideal_vs_emitted(text, out, parametric, Setup()) <= TOL
    # the same lines and arcs as the general planner writes, the centres within a few
    # units of the last decimal
    a, b = emit.split_header(out)[1].splitlines(), emit.split_header(general)[1].splitlines()
    assert len(a) == len(b)
    assert rep.arcs_kept > 0



@pytest.mark.parametrize("seed", [1, 3])
def test_an_arc_is_written_alike_whatever_the_chunk_it_is_planned_with(parametric, seed):
    # each arc's centre fit stops on its own step, not on the chunk's
    text = _arcs_program(seed)
    outs = {c: correct_text(text, parametric, Setup(), CorrectOptions(chunk_lines=c)) for c in (5, 64, 20_000)}
    ref = outs[20_000]
    assert ref[1].arcs_kept > 0
    for out, rep in outs.values():
        assert out == ref[0]
        assert rep.arcs_kept == ref[1].arcs_kept
        assert rep.lines_inserted == ref[1].lines_inserted


@pytest.mark.parametrize("seed", [1, 2])
def test_the_run_writer_writes_alike_in_stretches_of_any_length(parametric, monkeypatch, seed):
    # the run writer takes a run in stretches (ending at arcs whose hints are expected to
    # fail, or after MAX_STRETCH lines): the words added and the positions carry over
    from postproc.gcode import bulk

    text = _arcs_program(seed) + _lines_program(seed, 200).replace("G21 G90 G17\n", "").replace("M2\n", "")
    text = text.replace("M2\n", "") + "M2\n"
    ref = correct_text(text, parametric, Setup(), CorrectOptions())
    for stretch in (1, 3, 50):
        monkeypatch.setattr(bulk, "MAX_STRETCH", stretch)
        out, rep = correct_text(text, parametric, Setup(), CorrectOptions())
        assert out == ref[0]
        assert rep == ref[1]

def test_direction_dependent_calibration_takes_the_general_path():
    base = StaticEngine(np.eye(3), [0, 0, 0], [[0] * 3, [315] * 3])
    eng = compose(base, [{"name": "backlash:X", "params": {"b_mm": -0.012}}])
    assert eng.direction_dependent
    assert not base.direction_dependent
    text = "G21 G90 G17\nG0 X100 Y100 Z50\nG1 X120 F500\nX110\nG2 X100 Y110 I0 J10\nM2\n"
    a = correct_text(text, eng, Setup(), CorrectOptions())
    b = correct_text(text, eng, Setup(), CorrectOptions(bulk_plan=False, bulk_lane=False))
    assert a[0] == b[0]
    assert a[1].takeups > 0


def test_line_curvature_bound_holds_along_random_moves(parametric):
    """The engine's bound on the correction's second derivative along a move holds for
    the finite-difference second derivative of its inverse, and so the bound on the
    chord deviation holds for the densely sampled corrected move."""
    rng = np.random.default_rng(11)
    n = 300
    q0 = rng.uniform(20, 295, (n, 3))
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    length = rng.choice([0.5, 2.0, 8.0], n)
    q1 = np.clip(q0 + u * length[:, None], 5, 310)
    r = np.zeros((n, 3))
    r[:, 2] = rng.choice([0.0, -100.0], n)
    K = parametric.line_curvature_bound(q0, q1, np.linalg.norm(r, axis=1), 1.0)
    assert np.isfinite(K).all()
    s = np.linspace(0, 1, 41)
    pts = q0[:, None, :] + (q1 - q0)[:, None, :] * s[None, :, None]
    rr = np.repeat(r, len(s), axis=0)
    delta = np.asarray(parametric.correction(pts.reshape(-1, 3) + rr, rr).q).reshape(n, len(s), 3)
    L = np.linalg.norm(q1 - q0, axis=1)
    h = L / (len(s) - 1)
    second = np.linalg.norm(delta[:, 2:] - 2 * delta[:, 1:-1] + delta[:, :-2], axis=2) / (h[:, None] ** 2)
    assert (second.max(axis=1) <= K).all()
    # the chord deviation of the corrected move stays within K L^2 / 8
    chord = delta[:, :1] + (delta[:, -1:] - delta[:, :1]) * s[None, :, None]
    dev = np.linalg.norm(delta - chord, axis=2).max(axis=1)
    assert (dev <= K * L * L / 8 + 1e-12).all()
    # and the bound is not vacuous: within a factor 30 of the largest seen
    assert np.median(K / np.maximum(second.max(axis=1), 1e-12)) < 30


def test_no_bound_outside_the_tables_or_for_effects(parametric):
    q = np.array([[100.0, 100.0, 100.0]])
    assert np.isinf(parametric.line_curvature_bound(q, q + [0, 0, 300.0], np.zeros(1), 1.0)).all()
    base = StaticEngine(np.eye(3), [0, 0, 0], [[0] * 3, [315] * 3])
    assert (base.line_curvature_bound(q, q + 1, np.zeros(1)) == 0).all()
    eng = compose(base, [{"name": "periodic:X", "config": {"pitch_mm": 5.0},
                          "params": {"cos_mm": 0.004, "sin_mm": -0.003}}])
    assert np.isinf(eng.line_curvature_bound(q, q + 1, np.zeros(1))).all()


@pytest.mark.parametrize("seed", [3, 6])
def test_arcs_whose_words_do_not_change_keep_their_own_centre_words(seed):
    """Under a correction too small to change an end word the input arc stays as written,
    as the general planner keeps it (its own radius mismatch included)."""
    from postproc.engine.identity import IdentityEngine

    text = _arcs_program(seed)
    eng = IdentityEngine([[-1e4] * 3, [1e4] * 3])
    bulk, rep = correct_text(text, eng, Setup(), CorrectOptions())
    general, _ = correct_text(text, eng, Setup(), CorrectOptions(bulk_plan=False))
    assert emit.split_header(bulk)[1] == text
    assert bulk == general
    assert rep.arcs_kept == text.count("\nG2 ") + text.count("\nG3 ")


@pytest.mark.parametrize("extrapolate", ["clamp", "linear"])
def test_a_move_of_no_length_outside_the_tables_is_planned_without_a_floating_point_warning(parametric, extrapolate):
    # outside the tables the curvature bound is inf: inf * 0 (the move's length) made a
    # RuntimeWarning (invalid value) in the planner; the output is that of the move before
    q = np.array([[400.0, 10.0, 10.0]])
    assert np.isinf(parametric.line_curvature_bound(q, q, np.zeros(1))).all()
    text = "G90 G21\nG1 X400 Y10 Z10 F100\nG1 X400 Y10 Z10\nG1 X401\nM2\n"
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, start={"X": 10.0, "Y": 10.0, "Z": 10.0})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, rep = correct_text(text, parametric, setup, CorrectOptions(extrapolate=extrapolate))
    body = emit.split_header(out)[1].splitlines()
    end = max(i for i, line in enumerate(body) if line.endswith(" F100"))  # the end of G1 X400 Y10 Z10
    assert body[end + 1] + " F100" == body[end]
    assert rep.extrapolated_points > 0
