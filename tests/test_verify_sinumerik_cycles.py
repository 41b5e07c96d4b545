"""``verify`` and the path API follow the moves of Sinumerik drilling cycles (CYCLE81, an
MCALL of CYCLE83): the path holds each hole's G0/G1 steps, as the correction writes them,
and the corrected program runs on the virtual machine within the model's error."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions
from postproc.simulate import load_machine
from postproc.simulate.program import verify_program

ROOT = Path(__file__).parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
SETUP = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 100.0})
DRILL = ("%_N_DRILL_MPF\n;$PATH=/_N_MPF_DIR\nG17 G90 G54 D1\nG0 X10 Y10 Z20\nG1 F200\n"
         "CYCLE81(10,0,2,-6,0)\n"
         "G0 X40 Y10\n"
         "MCALL CYCLE83(10,0,2,-20,,-8,,3,0,0,1,0)\n"
         "X40 Y40\nX70 Y40\nMCALL\nG0 Z50\nM30\n")


def test_the_path_holds_the_cycle_moves(tmp_path):
    prog = tmp_path / "drill.mpf"
    prog.write_text(DRILL)
    pp = program_path(prog, SETUP, dialect="sinumerik")
    feed = pp.points_mm[~pp.rapid]
    # each hole drilled to its depth: Z = -6 (CYCLE81) and -20 (CYCLE83) in G54, tool tip
    for x, y, depth in ((10, 10, -6.0), (40, 40, -20.0), (70, 40, -20.0)):
        at = feed[(np.abs(feed[:, 0] - (100 + x)) < 1e-9) & (np.abs(feed[:, 1] - (80 + y)) < 1e-9)]
        assert at.size, (x, y)
        assert at[:, 2].min() == pytest.approx(40.0 + depth, abs=1e-9)
    # CYCLE83 with VARI=0 breaks the chip: G1 back by 1 mm after each stroke
    lines = pp.lineno[~pp.rapid]
    assert {6, 9, 10} <= set(lines.tolist())


def test_verify_runs_the_cycles_corrected(tmp_path):
    prog = tmp_path / "drill.mpf"
    prog.write_text(DRILL)
    cals = [load_calibration(ROOT / "calibrations" / name) for name in ("s500_parametric.json", "s500_static.json")]
    rep = verify_program(prog, load_machine(MACHINE), cals, {"offsets": {"G54": (100.0, 80.0, 40.0)},
                                                            "tool_lengths": {1: 100.0}},
                         options=CorrectOptions(dialect="sinumerik", cycles="expand"))
    unc, par, sta = rep.runs
    assert unc.feed.sum() > 20
    assert unc.max_mm > 0.2  # the machine's error along the holes
    assert par.max_mm < 0.002  # the model's own error plus the tolerance
    assert sta.max_mm < unc.max_mm


def test_verify_command_on_a_cycle_program(tmp_path):
    prog = tmp_path / "drill.mpf"
    prog.write_text(DRILL)
    # generic (the default) reads it as Sinumerik by its header, as correct does
    res = CliRunner().invoke(main, ["verify", str(prog), "--cycles", "expand",
                                    "-c", str(ROOT / "calibrations" / "s500_parametric.json"),
                                    "--machine", str(MACHINE), "--offset", "G54=X100,Y80,Z40",
                                    "--tool-length", "1=100"])
    assert res.exit_code == 0, res.output
    assert "no feed moves" not in res.output
    assert "corrected, parametric" in res.output


def test_the_holes_of_a_cycle_under_a_rotated_frame():
    """ROT RPL=90: the hole programmed at X10 Y0 is drilled at the machine's G54 X0 Y10."""
    text = ("%_N_ROTDRILL_MPF\nG17 G90 G54 D1\nG0 X0 Y0 Z20\nG1 F100\nROT RPL=90\n"
            "MCALL CYCLE81(10,0,2,-5,0)\nG0 X10 Y0\nMCALL\nROT\nM30\n")
    pp = program_path(text, SETUP, dialect="sinumerik")
    bottom = pp.points_mm[~pp.rapid][np.argmin(pp.points_mm[~pp.rapid][:, 2])]
    np.testing.assert_allclose(bottom, (100.0, 90.0, 35.0), atol=1e-9)
