"""Canned cycles: the moves the controller makes (LinuxCNC's rs274 as the oracle), kept
cycles corrected at the hole (X/Y at the bottom, R and Z along the tool axis), and
--cycles expand writing them as G0/G1 moves."""

import numpy as np
import pytest
from oracle import requires_rs274, run_rs274  # noqa: I001  (the tests' own helper, a sibling module)

from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import SafetyError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter, plain_moves
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

BIG = [[-1e5] * 3, [1e5] * 3]
ZERO = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
needs_rs274 = requires_rs274

PROGRAMS = {
    "g81_g98": "G21 G90 G17\nG0 X0 Y0 Z10\nG98 G81 X5 Y6 Z-3 R2 F100\nX7\nY9\nG80\nM2\n",
    "g83_peck": "G21 G90 G17\nG0 X0 Y0 Z10\nG98 G83 X5 Y6 Z-3 R2 Q1.2 F100\nX7\nG80\nM2\n",
    "g73_g99": "G21 G90 G17\nG0 X0 Y0 Z10\nG99 G73 X5 Y6 Z-3 R2 Q1.2 F100\nX8 Y1\nG80\nM2\n",
    "g82_dwell": "G21 G90 G17\nG0 X0 Y0 Z1\nG98 G82 X5 Y6 Z-3 R2 P0.5 F100\nG80\nM2\n",
    "g85_g89": "G21 G90 G17\nG0 X0 Y0 Z10\nG99 G85 X5 Y6 Z-3 R2 F100\nG89 X9 Z-2 R2 P0.2\nG80\nM2\n",
    "g91_repeats": "G21 G90 G17\nG0 X0 Y0 Z10\nG91 G99 G81 X1 Y0.5 Z-4 R-1 L3 F100\nG90 G80\nM2\n",
    "inch": "G20 G90 G17\nG0 X0 Y0 Z1\nG98 G83 X0.5 Y0.25 Z-0.3 R0.1 Q0.12 F10\nG80\nM2\n",
}


def rs274_motions(text, tmp_path):
    res = run_rs274(text)
    moves = []
    for m in res.motions:
        kind = m.kind
        p = tuple(m.end[:3])
        if not moves or moves[-1][1] != p:  # rs274 also prints moves of zero length
            moves.append((kind, p))
    return moves, res.error


def our_motions(text, setup=ZERO):
    it = Interpreter(setup, "p.ngc", dialect="linuxcnc")
    unit = 1.0
    out = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        unit = 25.4 if "G20" in line else unit
        mv = it.feed_line(n, line)
        if mv is None:
            continue
        for m in plain_moves(mv):
            kind = "STRAIGHT_TRAVERSE" if m.kind == 0 else "STRAIGHT_FEED"
            out.append((kind, tuple(v / unit for v in m.q1)))
    return out


def same_motions(a, b, tol=1e-4):
    assert [k for k, _ in a] == [k for k, _ in b]
    for (_, p), (_, q) in zip(a, b, strict=True):
        assert np.allclose(p, q, atol=tol), (p, q)


@needs_rs274
@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_cycle_moves_are_the_controllers(name, tmp_path):
    ref, log = rs274_motions(PROGRAMS[name], tmp_path)
    assert ref, log
    same_motions(our_motions(PROGRAMS[name]), ref)


@needs_rs274
@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_expanded_cycles_make_the_same_moves(name, tmp_path):
    out, rep = correct_text(PROGRAMS[name], IdentityEngine(BIG), ZERO, CorrectOptions(cycles="expand"))
    assert rep.cycles_expanded >= 1
    assert "G8" not in out.replace("G80", "")  # no cycle left
    assert "G73" not in out
    ref, _ = rs274_motions(PROGRAMS[name], tmp_path)
    got, log = rs274_motions(out, tmp_path)
    same_motions(got, ref)


def scale_engine(k):
    return StaticEngine(k * np.eye(3), np.zeros(3), BIG)


@needs_rs274
@pytest.mark.parametrize("name", ["g81_g98", "g83_peck", "g73_g99", "g82_dwell", "g85_g89", "inch"])
def test_kept_cycles_under_a_scale_land_every_hole_on_its_nominal(name, tmp_path):
    # a machine that moves k times what it is told: every commanded point of the
    # corrected program must be the original's divided by k (within the rounding)
    k = 1.0002
    out, rep = correct_text(PROGRAMS[name], scale_engine(k), ZERO, CorrectOptions())
    assert rep.cycles_kept >= 1
    ref, _ = rs274_motions(PROGRAMS[name], tmp_path)
    got, log = rs274_motions(out, tmp_path)
    assert got, log
    # peck levels derive from R and Q (Q is a length, not moved), so compare the holes:
    # every feed end at the bottom, and every point in X/Y
    tol = 0.6e-4  # rs274 prints 4 decimals
    ref_xy = [p[:2] for _, p in ref]
    got_xy = [p[:2] for _, p in got]
    assert len(ref_xy) == len(got_xy)
    for p, q in zip(ref_xy, got_xy, strict=True):
        assert np.allclose(np.array(p) / k, q, atol=tol)
    bottoms_ref = [p[2] for kind, p in ref if kind == "STRAIGHT_FEED"]
    bottoms_got = [p[2] for kind, p in got if kind == "STRAIGHT_FEED"]
    assert min(bottoms_got) == pytest.approx(min(bottoms_ref) / k, abs=tol)


def test_kept_cycle_rewrites_only_its_words_and_adds_z_r_only_when_they_change():
    k = 1.0002
    out, _ = correct_text(PROGRAMS["g81_g98"], scale_engine(k), ZERO, CorrectOptions())
    lines = emit.split_header(out)[1].splitlines()
    assert lines[2] == "G98 G81 X4.9990 Y5.9988 Z-2.9994 R1.9996 F100"
    assert lines[3] == "X6.9986"  # same Z and R: nothing added
    assert lines[4] == "Y8.9982"


def test_a_hole_whose_axis_the_correction_tilts_is_refused_naming_expand():
    # squareness: X grows with Z, so the hole's X at R and at the bottom differ by 1 mrad x 5 mm
    G = np.eye(3)
    G[0, 2] = 1e-3
    eng = StaticEngine(G, np.zeros(3), BIG)
    with pytest.raises(SafetyError) as err:
        correct_text(PROGRAMS["g81_g98"], eng, ZERO, CorrectOptions(cycles="keep"), path="p.ngc")
    assert err.value.lineno == 3
    assert "--cycles expand" in err.value.hint
    out, rep = correct_text(PROGRAMS["g81_g98"], eng, ZERO, CorrectOptions(cycles="expand"))
    assert rep.cycles_expanded == 3


def test_a_new_cycle_code_needs_its_r_again_as_in_linuxcnc():
    # rs274: "R clearance plane unspecified in cycle"
    with pytest.raises(Exception, match="without its R plane"):
        our_motions("G21 G90 G17\nG0 X0 Y0 Z10\nG99 G85 X5 Y6 Z-3 R2 F100\nG89 X9 P0.2\nM2\n")


def test_repeats_and_increments_stay_only_when_nothing_is_corrected():
    text = PROGRAMS["g91_repeats"]
    out, rep = correct_text(text, IdentityEngine(BIG), ZERO, CorrectOptions())
    assert emit.split_header(out)[1].splitlines() == text.splitlines()
    with pytest.raises(SafetyError, match="G81") as err:
        correct_text(text, scale_engine(1.001), ZERO, CorrectOptions(cycles="keep"), path="p.ngc")
    assert "--cycles expand" in err.value.hint
    # the default (auto) expands it
    out, rep = correct_text(text, scale_engine(1.001), ZERO, CorrectOptions())
    assert (rep.cycles_kept, rep.cycles_expanded) == (0, 1)


# A squareness of 0.1 mrad (X grows with Z) tilts a 5 mm deep hole by 0.5 um (kept at the
# 1 um tolerance) and a 20 mm deep one by 2 um (expanded); the block after an expanded one
# in the same series is expanded too (the controller is in G0/G1 after the expansion),
# and the next series, after G80, is kept again (with the G99 the expanded block set).
MIXED = ("G21 G90 G17\nG0 X0 Y0 Z30\nG98 G81 X5 Y6 Z-3 R2 F100\nX7\nG99 G81 X10 Y6 Z-18 R2\nX12 Z-3 R2\n"
         "G80\nG0 Z30\nG81 X20 Y6 Z-3 R2 F100\nY9\nG80\nM2\n")


def squareness_engine(s_xz):
    G = np.eye(3)
    G[0, 2] = s_xz
    return StaticEngine(G, np.zeros(3), BIG)


def test_auto_keeps_the_holes_within_tolerance_and_expands_the_others():
    out, rep = correct_text(MIXED, squareness_engine(1e-4), ZERO, CorrectOptions())
    assert (rep.cycles_kept, rep.cycles_expanded) == (4, 2)
    body = emit.split_header(out)[1].splitlines()
    assert body[2].startswith("G98 G81 X")
    assert body[3].startswith("X")
    assert body[4] == "G99"  # the expansion keeps the retract mode on a line of its own
    assert sum(ln.startswith("G81") or " G81 " in ln for ln in body) == 2
    assert "CYCLES EXPANDED" not in out


@needs_rs274
def test_auto_lands_every_point_through_the_machine(tmp_path):
    eng = squareness_engine(1e-4)
    out, _rep = correct_text(MIXED, eng, ZERO, CorrectOptions())
    ref, log0 = rs274_motions(MIXED, tmp_path)
    got, log = rs274_motions(out, tmp_path)
    assert got, log
    assert [k for k, _ in got] == [k for k, _ in ref]
    machine = eng.forward(np.array([p for _, p in got]))
    nominal = np.array([p for _, p in ref])
    # from the R plane down (a kept hole's rapid above it is at the bottom's X/Y): the
    # kept holes' points at the R plane lean by up to their tilt (0.5 um)
    low = nominal[:, 2] <= 2.0
    np.testing.assert_allclose(machine[low], nominal[low], atol=0.001)
    np.testing.assert_allclose(machine[:, 2], nominal[:, 2], atol=0.001)  # retract levels too
