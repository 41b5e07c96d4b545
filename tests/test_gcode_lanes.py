"""Runs of plain lines read and written in bulk give byte for byte the output of the
general path."""

from pathlib import Path

import numpy as np
import pytest
from conftest import corpus_programs

from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"
G = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])
# corpus programs compared line for line (the suite's time goes with their length)
CORPUS_MAX_LINES = 2000
OFFSETS = {n: (0.0, 0.0, 0.0) for n in ["G54", "G55", "G56", "G57", "G58", "G59"]}


def _files():
    files = sorted(p for p in (ROOT / "samples").glob("*") if p.suffix in {".nc", ".ngc"})
    files += sorted((ROOT / "tests" / "cases").glob("*.nc"))
    if CORPUS.is_dir():
        # the longer ones take minutes each; generated programs of every shape are
        # compared in test_gcode_bulk.py; every one within the limit with
        # POSTPROC_FULL_CORPUS=1, else a subset naming every construct, source and suffix
        # they name (conftest.representative)
        files += corpus_programs(max_lines=CORPUS_MAX_LINES,
                                 keep=lambda p: p.suffix.lower() in {".nc", ".ngc", ".tap"})
    return files


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.name)
def test_bulk_lane_output_equals_general_path(path):
    eng = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    setup = Setup(offsets=OFFSETS | {"G54": (100.0, 80.0, 40.0)}, tool_lengths={t: 50.0 + t for t in range(100)})
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    outs = []
    for bulk_lane in (True, False):
        try:
            outs.append(correct_text(text, eng, setup, CorrectOptions(bulk_lane=bulk_lane))[0])
        except PostprocError as exc:
            outs.append(str(exc))
    assert outs[0] == outs[1]


def test_bulk_lane_handles_lower_case_spacing_and_added_words():
    eng = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    text = "g0 x10 y10 z10\ny20\nX 30 Y 5\ng1x40f100\nG2 X50 Y15 I5 J5\nG1 X60\nY20\n"
    a = correct_text(text, eng, Setup(), CorrectOptions(bulk_lane=True))[0]
    b = correct_text(text, eng, Setup(), CorrectOptions(bulk_lane=False))[0]
    assert a == b
    # Y moved, so X (squareness) gets a word too, in the line's own case and spacing
    assert emit.split_header(a)[1].splitlines()[1].startswith("y20.0140x9.9")
    assert a.splitlines()[-1].startswith("Y20.0140X")  # no blanks in the line: none added


@pytest.mark.parametrize("line", ["X1(c)Y2\n", "X1\fY2\n", "X1.2.3\n", "X1 )\n", "X1 Y2 #3\n", "X1 Y2;c\n",
                                  "/X1\n", "X1 Y2 Q3\n", "X1 X2\n", "G2 X1\n", "X1 Y2 M3\n", "G91 X1\n"])
def test_bulk_scan_takes_only_plain_straight_moves(line):
    from postproc.gcode import bulk

    blk = bulk.scan(["G0 X1 Y1 Z1\n", line, "N10 G1 X 1 Y-.5 F100\n"])
    assert blk is not None
    assert blk.plain.tolist() == [True, False, True]


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.name)
def test_output_does_not_depend_on_the_chunk_size(path):
    eng = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    setup = Setup(offsets=OFFSETS | {"G54": (100.0, 80.0, 40.0)}, tool_lengths={t: 50.0 + t for t in range(100)})
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    outs = []
    for chunk in (20_000, 5):
        try:
            outs.append(correct_text(text, eng, setup, CorrectOptions(chunk_lines=chunk))[0])
        except PostprocError as exc:
            outs.append(str(exc))
    assert outs[0] == outs[1]
