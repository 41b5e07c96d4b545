"""A feed word before the axis words (``G1 F300 X.. Y..``, as UGS's test programs and
many hand-written ones have it) and a feed alone on its line (``F300``, CAMotics) are read
in bulk with the plain lines around them: the output, the path and diff's report are the
general path's, byte for byte, and the modal feed the lines leave is the interpreter's."""

from pathlib import Path

import numpy as np
import pytest
from conftest import ENGINE, INSIDE, SETUP, both_lanes, path_and_diff_both_ways

from postproc.calfile import load_calibration
from postproc.gcode import bulk
from postproc.gcode.moves import Kind
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
REAL = ROOT.parent / "shared" / "corpus" / "real"


def _both(text, engine=None, setup=SETUP, **options):
    return both_lanes(text, engine or ENGINE, setup, **options)


def _program(rng, n):
    out = ["G21 G90 G17\n", "G0 X10 Y10 Z5\n", "G1 F300 Z-1\n"]
    x, y = 10.0, 10.0
    for k in range(n):
        x, y = round(x + rng.uniform(-8, 8), 3), round(y + rng.uniform(-8, 8), 3)
        feed = f"F{int(rng.integers(50, 3000))}"
        form = k % 5
        if form == 0:
            out.append(f"G1 {feed} X{x:.3f} Y{y:.3f}\n")
        elif form == 1:
            out.append(f"{feed}\n")  # alone: the next moves take it
            out.append(f"X{x:.3f} Y{y:.3f}\n")
        elif form == 2:
            out.append(f"N{10 * k} G01 {feed} X{x:.3f}\n")
        elif form == 3:
            out.append(f"N{10 * k} {feed.lower()}\n")
            out.append(f"y{y:.3f}\n")
        else:
            out.append(f"X{x:.3f} Y{y:.3f} {feed}\n")
    out.append("M2\n")
    return "".join(out)


@pytest.mark.parametrize("seed", range(3))
def test_feed_first_and_feed_alone_give_the_general_paths_output(seed):
    text = _program(np.random.default_rng(seed), 80)
    a, b = _both(text)
    assert a == b
    assert "Error" not in a


def test_feed_lines_are_read_in_runs(planned_tables):
    text = _program(np.random.default_rng(1), 40)
    correct_text(text, ENGINE, SETUP, CorrectOptions())
    (tab,) = planned_tables
    in_runs = sum(len(r) for r in tab.runs)
    lines = text.count("\n")
    assert in_runs == lines - 3  # all but G21, the first G0 (no position yet) and M2
    # a feed alone moves nothing: a row that stays still
    still = np.flatnonzero(tab.kind == Kind.STILL)
    assert len(still) == 16


def test_the_feed_a_split_move_carries_is_the_interpreters(planned_tables):
    # a split move's pieces are written by the general emitter from its RunMove: its feed
    # is the modal one, whichever form set it
    text = "G21 G90 G17\nG0 X10 Y10 Z5\nG1 F300 X20\nF450\nX30\nN5 F600\nY20\n"
    correct_text(text, ENGINE, SETUP, CorrectOptions())
    (tab,) = planned_tables
    (run,) = tab.runs
    feeds = [bulk._row_move(run, j).feed for j in range(len(run)) if not run.inert_at(j)]
    assert feeds == [300.0, 450.0, 600.0]


def test_a_second_feed_or_a_feed_before_other_words_is_not_plain():
    lines = ["G0 X1 Y1 Z1\n", "G1 F300 X1 F200\n", "F300 G1 X2\n", "A5 F300\n", "G43 H1 F300\n",
             "G1 F300\n", "F300 A5\n", "N10 G1 X 1 Y-.5 F100\n"]
    blk = bulk.scan(lines)
    assert blk is not None
    assert blk.plain.tolist() == [True, False, False, False, False, False, False, True]


@pytest.mark.parametrize("line", ["F250\n", "N30 F1200.5\n", " f80 \r\n", "F-5\n"])
def test_a_feed_alone_is_inert_and_kept_byte_for_byte(line):
    text = f"G21 G90\nG0 X1 Y1 Z1\nG1 X2 F100\n{line}X3\nM2\n"
    blk = bulk.scan(text.splitlines(True))
    assert blk is not None
    assert blk.neutral.tolist() == [False, False, False, True, False, False]
    a, b = _both(text)
    assert a == b
    assert line in a


def test_feed_lines_path_and_diff_are_the_general_paths(monkeypatch, tmp_path):
    text = _program(np.random.default_rng(3), 60)
    report = path_and_diff_both_ways(monkeypatch, tmp_path, text, ENGINE, SETUP)
    assert report["moves_moved"] > 40


@pytest.mark.skipif(not REAL.is_dir(), reason="needs ../shared/corpus")
@pytest.mark.parametrize("name", [
    "ugs/test_files__electric_turtle.nc",  # G1 F.. Z.., G2 F.. X.. Y.. I.. J..
    "camotics/examples__wave__wave.gcode",  # a feed alone before each move
    "ugs/test_files__communicator.nc",
])
@pytest.mark.parametrize("calibration", ["s500_static", "s500_parametric"])
def test_real_programs_with_feed_lines_agree(name, calibration):
    lines = (REAL / name).read_text(errors="surrogateescape").splitlines(True)[:1200]
    engine = load_calibration(ROOT / "calibrations" / f"{calibration}.json").engine
    a, b = _both("".join(lines), engine, INSIDE, extrapolate="linear")
    assert a == b
