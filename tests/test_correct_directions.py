"""Approach directions are those of the corrected commands, on both sides: ``correct``
evaluates a direction-dependent effect (backlash) with the direction each axis is
commanded to move in the corrected program, and the virtual machine of ``verify``
reverses an axis when its commanded position moves back by an amount it resolves.

Hand-made programs; expected words and positions are computed by hand from the
machine model ``p = q + (s * q_z, 0, 0) + (b / 2 * dir_x, 0, 0)``."""

from pathlib import Path

import numpy as np
import pytest

from postproc.effects import compose, get_effect
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import SafetyError
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_file, correct_text
from postproc.simulate.program import verify_program
from postproc.simulate.verify import machine_run

VOLUME = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]
B_MM = -0.012  # lost motion: X stops 6 um short on either side (ISO 230-2 B = -12 um)
TOL = 0.001


class _Model:
    """An engine as the virtual machine: forward with the commanded directions."""

    def __init__(self, engine) -> None:
        self.engine = engine

    def forward(self, q, r=None, context=None):
        return self.engine.forward(q, r, context)


def squareness_with_backlash(s_xz: float):
    """X leans with Z by ``s_xz`` (mm/mm) and lags its approach direction by |b|/2."""
    G = np.eye(3)
    G[0, 2] = s_xz
    base = StaticEngine(G, [0.0, 0.0, 0.0], VOLUME)
    return compose(base, [get_effect("backlash:X", params={"b_mm": B_MM}).to_dict()])


# X out to 150 (+), a 10 mm plunge, X on to 200 (+)
PLUNGE = "G21 G90 G17\nG0 X100 Y100 Z60\nG1 Z50 F300\nG1 X150 F800\nG1 Z40 F300\nG1 X200 F800\nG0 Z60\nM2\n"


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln and not ln.startswith(("(", "%"))]


def test_a_plunge_whose_correction_moves_x_back_reverses_x(tmp_path):
    # X moves +; in the plunge from Z50 to Z40 the correction of X falls by 300e-6 * 10 mm
    # = 3 um, against the approach: the machine reverses X there. With the direction of
    # the corrected commands the plunge is corrected as an X- move (take-up before it),
    # and the next X+ move takes the reversal up again.
    eng = squareness_with_backlash(-300e-6)
    out, rep = correct_text(PLUNGE, eng, Setup(), CorrectOptions())
    lines = _lines(out)
    # q_x = p_x - s * z - b/2 * dir = p_x + 0.0003 z + 0.006 dir
    i = lines.index(next(ln for ln in lines if ln.startswith("G1 X150.0210")))
    assert lines[i + 1] == "G1 X150.0090 F300"  # take-up at Z50: X 150 + 0.015 - 0.006, moving -X
    assert lines[i + 2].startswith("G1 Z40 X150.0060")  # 150 + 0.012 - 0.006
    assert lines[i + 3] == "G1 X150.0180 F800"  # take-up at Z40: 150 + 0.012 + 0.006, moving +X
    assert lines[i + 4].startswith("G1 X200.0180")
    # also at the start of the first plunge (X from the unknown direction to -) and before
    # X150 (to +)
    assert rep.takeups == 4
    prog, fixed = tmp_path / "plunge.nc", tmp_path / "plunge_corrected.nc"
    prog.write_text(PLUNGE)
    fixed.write_text(out)
    run = verify_program(prog, _Model(eng), [], corrected=fixed).runs[1]
    assert run.max_mm <= TOL


def test_a_correction_within_one_output_unit_against_the_direction_is_held(tmp_path):
    # 5e-6 * 10 mm = 0.05 um back: less than the output unit (0.1 um); X stays where it
    # is (no X word, no take-up): the controller does not move it and nothing reverses
    eng = squareness_with_backlash(-5e-6)
    out, rep = correct_text(PLUNGE, eng, Setup(), CorrectOptions())
    lines = _lines(out)
    plunge = next(ln for ln in lines if ln.startswith("G1 Z40"))
    assert "X" not in plunge
    assert rep.takeups == 1  # the first X move only
    prog, fixed = tmp_path / "plunge.nc", tmp_path / "plunge_corrected.nc"
    prog.write_text(PLUNGE)
    fixed.write_text(out)
    assert verify_program(prog, _Model(eng), [], corrected=fixed).runs[1].max_mm <= TOL


def test_a_plunge_moving_x_on_keeps_the_direction():
    # the correction of X grows in the plunge (+3 um, along +X): no reversal, no take-up
    eng = squareness_with_backlash(300e-6)
    out, rep = correct_text(PLUNGE, eng, Setup(), CorrectOptions())
    plunge = next(ln for ln in _lines(out) if ln.startswith("G1 Z40"))
    # q_x = 150 - 0.0003 * 40 + 0.006 = 149.994 (from 149.991 at Z50)
    assert "X149.9940" in plunge
    assert rep.takeups == 1


def test_an_axis_that_runs_ahead_cannot_follow_a_small_reversal_and_is_refused():
    # b > 0: X runs ahead. The plunge's correction moves X back by 3 um: commanded as an
    # X- move it jumps back by b and becomes an X+ move, and the other way round; the
    # line is named
    G = np.eye(3)
    G[0, 2] = -300e-6
    eng = compose(StaticEngine(G, [0.0, 0.0, 0.0], VOLUME),
                  [get_effect("backlash:X", params={"b_mm": -B_MM}).to_dict()])
    with pytest.raises(SafetyError, match="approach direction of X does not settle") as exc:
        correct_text(PLUNGE, eng, Setup(), CorrectOptions())
    assert exc.value.lineno == 3
    assert "b < 0" in exc.value.hint


def test_the_virtual_machine_reverses_on_commanded_motion_it_resolves(tmp_path):
    # backlash only: actual x = commanded x + b/2 * dir_x
    eng = compose(IdentityEngine(VOLUME), [get_effect("backlash:X", params={"b_mm": B_MM}).to_dict()])
    prog = tmp_path / "hand.nc"
    prog.write_text("G21 G90 G17\nG1 X10 Y10 Z10 F100\nG1 X20\n"
                    # X back by one output unit while Y moves: a reversal
                    "G1 X19.9999 Y15\n"
                    # X on again, then an arc of a huge radius whose end points have the
                    # same X: its sampled X is float noise, no motion
                    "G1 X123.4567 Y20\nG2 Y20.005 I191152729.0652 J0.0025\nG1 X130\nM2\n")
    path = program_path(prog, Setup())
    q = path.points_mm - path.tool_mm  # commanded
    lag = machine_run(_Model(eng), path)[:, 0] - q[:, 0]  # identity base: b/2 * dir_x
    line = np.asarray(path.lineno)
    np.testing.assert_allclose(lag[line == 3], -0.006, atol=1e-12)  # X+
    np.testing.assert_allclose(lag[line == 4], +0.006, atol=1e-12)  # X back by 0.1 um: reversed
    np.testing.assert_allclose(lag[line == 5], -0.006, atol=1e-12)  # X+ again
    assert q[line == 6, 0].min() < 123.4567 - 1e-9  # the arc's sampled X falls back (float noise) ...
    np.testing.assert_allclose(lag[line == 6], -0.006, atol=1e-12)  # ... and X does not reverse
    np.testing.assert_allclose(lag[line == 7], -0.006, atol=1e-12)
    assert verify_program(prog, _Model(eng), []).runs[0].max_mm == pytest.approx(0.006, abs=1e-6)


# Reversal of either sign on an arc program: X reverses only where a move
# along X starts back (at X150 after the quarter arc and the Y move, at X60, at X30).
ARCS_ALONG = ("G21 G90 G17\nG0 X20 Y50 Z60\nG1 Z50 F300\nG1 X150 F800\nG3 X180 Y80 I0 J30\nG1 Y120\n"
              "G1 X60\nG3 X30 Y90 I0 J-30\nG1 Y60\nG1 X100\nG0 Z60\nM2\n")
# X reverses inside the arc, at its quadrant point (70, 80), where the path runs along Y
ARC_QUADRANT = "G21 G90 G17\nG0 X100 Y50 Z60\nG1 Z50 F300\nG2 X100 Y110 I0 J30 F800\nG0 Z60\nM2\n"


def _arcs_with_backlash(b_mm: float):
    G = np.eye(3)
    G[0, 1] = -20e-6  # X shrinks with Y: the corrections of X grow along the X direction of each move
    base = StaticEngine(G, [0.0, 0.0, 0.0], VOLUME)
    return compose(base, [get_effect("backlash:X", params={"b_mm": b_mm}).to_dict()])


@pytest.mark.parametrize("b_mm", [-0.012, 0.012])  # lost motion, and an axis that runs ahead
def test_a_reversal_of_either_sign_lands_where_the_program_asked(tmp_path, b_mm):
    eng = _arcs_with_backlash(b_mm)
    out, rep = correct_text(ARCS_ALONG, eng, Setup(), CorrectOptions())
    prog, fixed = tmp_path / "arcs.nc", tmp_path / "arcs_corrected.nc"
    prog.write_text(ARCS_ALONG)
    fixed.write_text(out)
    report = verify_program(prog, _Model(eng), [], corrected=fixed)
    uncorrected, corrected = report.runs
    assert uncorrected.max_mm > 0.005  # half the reversal and the squareness
    assert corrected.max_mm <= TOL
    # lost motion is taken up in the new direction at each reversal; an axis that runs
    # ahead is not (a take-up in its old direction would overshoot by b)
    assert (rep.takeups > 0) == (b_mm < 0)


def test_a_run_ahead_reversal_across_the_path_is_refused_before_any_output(tmp_path):
    prog, out = tmp_path / "quadrant.nc", tmp_path / "quadrant_corrected.nc"
    prog.write_text(ARC_QUADRANT)
    fixed = correct_file(prog, out, _arcs_with_backlash(-0.012))
    assert fixed.takeups >= 1
    assert verify_program(prog, _Model(_arcs_with_backlash(-0.012)), [], corrected=out).runs[1].max_mm <= TOL
    out.unlink()
    with pytest.raises(SafetyError, match="runs ahead") as exc:
        correct_file(prog, out, _arcs_with_backlash(0.012))
    assert exc.value.lineno == 4
    assert "b > 0" in exc.value.hint
    assert not out.exists()


@pytest.mark.parametrize("mirror", [False, True])
def test_the_readme_calibration_corrects_x_slots_at_every_line(tmp_path, monkeypatch, mirror):
    # the README's metrologist walkthrough: fit makes a run-ahead X (b = +8.9 um) from
    # samples/iso230_runs_x.csv; mirrored, the same runs give lost motion. Either way
    # the corrected slots run within the tolerance of the path at every line, on the
    # machine the calibration describes (model error 0)
    import json

    from click.testing import CliRunner

    from postproc.cli import main

    root = Path(__file__).parents[1]
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    res = runner.invoke(main, ["fit", str(root / "samples" / "iso230_runs_x.csv"), "-o", "x_runs.json"])
    assert res.exit_code == 0, res.output
    cal = json.loads(Path("x_runs.json").read_text())
    b = cal["effects"][0]["params"]["b_mm"]
    assert b > 0.008
    if mirror:
        cal["effects"][0]["params"]["b_mm"] = -b
        Path("x_runs.json").write_text(json.dumps(cal))
    res = runner.invoke(main, ["verify", str(root / "samples" / "x_slots.nc"), "-c", "x_runs.json",
                               "--machine", "x_runs.json", "--json"])
    assert res.exit_code == 0, res.output
    runs = json.loads(res.output)["runs"]
    assert runs[0]["max_mm"] > 0.006  # uncorrected: the reversal and the positioning error
    assert runs[1]["max_mm"] <= TOL
