"""Corrected arcs under a Sinumerik rotating, scaling or mirroring frame (ROT, AROT,
ASCALE, AMIRROR): written in the frame's coordinates, so that the controller, applying
the frame, draws the corrected arc.

The checks are independent of the writing code: the corrected program is read back by
the interpreter (which applies the frame), the corrected ideal path is the engine's
correction of the original's densely sampled nominal path (``ideal_vs_emitted``), and
the program runs on the virtual machine through ``verify``."""

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import TOL, ideal_vs_emitted

from postproc.calfile import load_calibration
from postproc.engine.identity import IdentityEngine
from postproc.engine.static import StaticEngine
from postproc.errors import UnsupportedGcodeError
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.state import PLANES
from postproc.simulate import load_machine
from postproc.simulate.program import verify_program

ROOT = Path(__file__).parents[1]
PROGRAM = ROOT / "tests" / "data" / "sinumerik" / "frame_arcs.mpf"
MACHINE = ROOT / "calibrations" / "s500.machine.json"
SETUP = Setup(offsets={"G54": (150.0, 150.0, 40.0)}, tool_lengths={1: 100.0})
OPTS = CorrectOptions(dialect="sinumerik")
# the frame lines of frame_arcs.mpf (ROT RPL=30, ATRANS, and AROT RPL=15 before N100)
# and what each variant puts there
FRAMES = {
    "rot": ("N20 ROT RPL=30\nN30 ATRANS X60 Y20\n", "N90 AROT RPL=15\n"),
    "mirror": ("N20 ROT RPL=20\nN25 AMIRROR X0\nN30 ATRANS X-30 Y10\n", "N90 AROT RPL=15\n"),
    "scale2": ("N20 ROT RPL=30\nN30 ASCALE X2 Y2\n", "N90 AROT RPL=15\n"),  # Z keeps its scale 1
    "scale05": ("N20 AROT RPL=-40\nN25 ASCALE X0.5 Y0.5\nN30 ATRANS X30 Y30\n", "N90 AROT RPL=15\n"),
    "scale3d": ("N20 ROT RPL=10\nN30 ASCALE X1.5 Y1.5 Z1.5\n", "N90 AMIRROR Y0\n"),
}


def program(variant: str) -> str:
    text = PROGRAM.read_text()
    first, second = FRAMES["rot"]
    new_first, new_second = FRAMES[variant]
    return text.replace(first, new_first).replace(second, new_second)


@pytest.fixture(scope="module", params=["s500_parametric", "s500_static"])
def calibration(request):
    return load_calibration(ROOT / "calibrations" / f"{request.param}.json")


def framed_arcs(text: str, setup: Setup = SETUP):
    """(scale in the plane, machine start radius, end radius, line) of every arc read
    under a frame."""
    it = Interpreter(setup, None, dialect="sinumerik")
    out = []
    for n, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = it.feed_line(n, line)
        if mv is None or mv.arc is None:
            continue
        assert mv.frame is not None, line
        (a1, a2, _an), _ = PLANES[mv.arc.plane]
        c = mv.arc.center
        k = math.sqrt(abs(mv.frame[0] * mv.frame[4] - mv.frame[1] * mv.frame[3]))
        out.append((k, math.hypot(mv.q0[a1] - c[a1], mv.q0[a2] - c[a2]),
                    math.hypot(mv.q1[a1] - c[a1], mv.q1[a2] - c[a2]), n))
    return out


@pytest.mark.parametrize("variant", sorted(FRAMES))
def test_framed_arcs_follow_the_corrected_path(variant, calibration):
    text = program(variant)
    out, rep = correct_text(text, calibration.engine, SETUP, OPTS, path="frame_arcs.mpf")
    assert rep.arcs_linearised == 0
    assert rep.arcs_kept + rep.arcs_split == len(framed_arcs(text)) == 6
    # each written arc is one exact circle: its radii agree to half a step of its words,
    # which the frame scales
    for k, r0, r1, lineno in framed_arcs(out):
        assert abs(r1 - r0) <= k * 0.5e-4 + 1e-9, (lineno, r0, r1, out.splitlines()[lineno - 1])
    assert ideal_vs_emitted(text, out, calibration.engine, SETUP, dialect="sinumerik") <= TOL


# G91 arcs (I/J and CR=) and an arc with absolute centre words (I=AC() J=AC(): absolute for
# that block only), under ROT RPL=30 or no frame
INCREMENTAL = ("%_N_INC_MPF\n;$PATH=/_N_MPF_DIR\nN10 G17 G90 G54 D1\n{rot}G0 X20 Y0 Z5\nG1 Z-2 F400\nG91\n"
               "G3 X-20 Y20 I-20 J0\nG3 X-20 Y-20 CR=20\nG1 Y-20\nG2 X-20 Y-20 I-10 J-10\nG90\n"
               "G2 X-20 Y-40 I=AC(-30) J=AC(-40)\n{unrot}G0 Z50\nM30\n")


@pytest.mark.parametrize("framed", [True, False], ids=["rot", "no frame"])
def test_incremental_and_absolute_centre_words(framed, calibration):
    """An arc cut into several keeps each piece's centre words in its block's form: a
    piece inserted before an ``I=AC() J=AC()`` block is written ``I=AC(..) J=AC(..)`` too
    (a plain ``I`` would be read relative to the piece's start)."""
    text = INCREMENTAL.format(rot="ROT RPL=30\n" if framed else "", unrot="ROT\n" if framed else "")
    out, rep = correct_text(text, calibration.engine, SETUP, OPTS)
    assert rep.arcs_linearised == 0
    assert ideal_vs_emitted(text, out, calibration.engine, SETUP, dialect="sinumerik") <= TOL
    after = out.split("G90\n")[-1].split("G0 Z")[0].splitlines()
    arcs = [ln for ln in after if ln.startswith("G2")]
    assert arcs
    assert all("I=AC(" in ln and "J=AC(" in ln for ln in arcs), arcs


def test_the_arc_words_are_the_frames():
    """ROT RPL=90 (machine x = -y, y = x of the frame): a calibration whose correction is
    +0.1 mm along machine X moves the frame's Y by -0.1. The corrected arc is the same
    circle moved: its end words change in the frame's coordinates, its centre words
    (relative to its start) stay."""
    text = "%_N_R_MPF\nG54 D1\nG0 X0 Y0 Z0\nROT RPL=90\nG0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\nROT\nM30\n"
    engine = StaticEngine(np.eye(3), np.array([-0.1, 0.0, 0.0]), [[-1e5] * 3, [1e5] * 3])
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0})
    out, _ = correct_text(text, engine, setup, OPTS)
    body = [ln for ln in out.splitlines() if not emit.is_header(ln)]
    # machine X + 0.1 is the frame's Y - 0.1 (machine = R90 frame: x_m = -y_f, y_m = x_f)
    assert body[4] == "G0 X10 Y-0.1000"
    assert body[5] == "G3 X0 Y9.9000 I-10 J0 F100"


def test_identity_and_no_op_keep_every_byte():
    for variant in sorted(FRAMES):
        text = program(variant)
        for engine in (IdentityEngine([[-1e5] * 3, [1e5] * 3]),
                       StaticEngine(np.eye(3), np.array([2e-6, -3e-6, 1e-6]), [[-1e5] * 3, [1e5] * 3])):
            out, rep = correct_text(text, engine, SETUP, OPTS)
            assert "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln)) == text, variant
            assert rep.lines_changed == 0


def test_verify_runs_the_framed_arcs_on_the_virtual_machine(tmp_path):
    """The independent check: the S500 virtual machine runs the program uncorrected and
    corrected; the parametric calibration brings it to the model's own error."""
    prog = tmp_path / "frame_arcs.mpf"
    prog.write_text(program("rot"))
    cals = [load_calibration(ROOT / "calibrations" / f"{n}.json") for n in ("s500_parametric", "s500_static")]
    rep = verify_program(prog, load_machine(MACHINE), cals, {"offsets": {"G54": (150.0, 150.0, 40.0)},
                                                            "tool_lengths": {1: 100.0}})
    unc, par, sta = rep.runs
    assert unc.max_mm > 0.2
    assert par.max_mm < 0.002
    assert sta.max_mm < 0.6 * unc.max_mm


def test_an_ellipse_is_refused_at_its_line(tmp_path):
    from click.testing import CliRunner

    from postproc.cli import main

    prog = tmp_path / "ellipse.mpf"
    prog.write_text("%_N_E_MPF\nG54 D1\nG0 X0 Y0 Z0\nSCALE X2 Y3\nG1 X10 Y0 F100\nG3 X0 Y10 I-10 J0\nM30\n")
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", str(ROOT / "calibrations" / "s500_static.json"),
                                    "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100",
                                    "-o", str(tmp_path / "out.mpf")])
    assert res.exit_code != 0
    assert "ellipse.mpf:6:1: Sinumerik arc under a frame that does not keep it a circle" in res.output
    assert "hint:" in res.output
    with pytest.raises(UnsupportedGcodeError):
        correct_text(prog.read_text(), IdentityEngine([[-1e5] * 3, [1e5] * 3]), SETUP, OPTS)


def test_an_absolute_centre_word_is_removed_whole():
    """A linearised ``I=AC(-10)`` block loses its centre words up to their parenthesis."""
    from postproc.gcode.emitter import _word_span

    it = Interpreter(Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0}), None, dialect="sinumerik")
    line = "G2 X-20 Y0 I=AC(-10) J=AC(0)\n"
    it.feed_line(1, "G54 D1 G0 X0 Y0 Z0\n")
    mv = it.feed_line(2, line)
    spans = [_word_span(line, mv.words[i]) for i in mv.arc.offset_idx]
    assert [line[a:b] for a, b in spans] == ["I=AC(-10)", "J=AC(0)"]
    assert line[slice(*_word_span(line, mv.words[1]))] == "X-20"
