"""Lines naming rotary axes (A, B, C after Z) are read in bulk too: the rotary words pass
through as written, and each row's rotary positions (the engine's context) are those of
the line read by the interpreter. The output, the path's samples and diff's pairing are
the general path's."""

from pathlib import Path

import numpy as np
import pytest
from conftest import both_lanes

from postproc.effects import compose, get_effect
from postproc.engine.static import StaticEngine
from postproc.gcode import bulk
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text

G = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])
SETUP = Setup(offsets={"G54": (100.0, 80.0, 40.0)})
CORPUS = Path(__file__).parents[2] / "shared" / "corpus" / "real" / "ugs" / "test_files__rotation.ngc"


def _engine(letter="A"):
    """A static error, and a shift in proportion to a rotary axis's angle (a rotary
    table's runout), so that a row given another angle than the interpreter's would move."""
    base = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    return compose(base, [get_effect(f"linear:{letter}", config={"reference": 0.0},
                                     params={"ax_mm_per_unit": 2e-4, "ay_mm_per_unit": -1e-4,
                                             "az_mm_per_unit": 3e-5}).to_dict()])


def _both(text, setup=SETUP, letter="A"):
    return both_lanes(text, _engine(letter), setup)


def _rotary_program(rng, n, letters="A"):
    # (the engine reads the first letter's angle: the program names it first)
    out = ["G21 G90 G17\n", f"G0 X0 Y0 Z5 {letters[0]}0\n", "G1 Z0 F300\n"]
    angle = {c: 0.0 for c in letters}
    for k in range(n):
        words = f"X{rng.uniform(0, 50):.3f} Y{rng.uniform(0, 50):.3f}"
        if k % 3 == 0:
            words += f" Z{rng.uniform(-2, 2):.3f}"
        for c in letters:
            if rng.random() < 0.5:
                angle[c] = round(angle[c] + rng.uniform(-20, 40), 2)
                words += f" {c}{angle[c]:g}"
        if k % 11 == 5:
            words += " F200"
        if k % 17 == 8:
            words = f"G2 X{rng.uniform(0, 50):.3f} Y{rng.uniform(0, 50):.3f} R60"
        elif k % 17 == 9:
            words = "G1 " + words
        out.append(words + "\n")
        if k == n // 2:
            out.append(f"(a comment)\nG92 {letters[0]}10\n")  # a rotary offset, read by the interpreter
    out.append("M2\n")
    return "".join(out)


@pytest.mark.parametrize(("seed", "letters"), [(0, "A"), (1, "A"), (2, "AB"), (3, "ABC"), (4, "C")])
def test_rotary_lines_in_bulk_give_the_general_paths_output(seed, letters):
    text = _rotary_program(np.random.default_rng(seed), 120, letters)
    a, b = _both(text, letter=letters[0])
    assert a == b
    assert "Error" not in a


def test_rotary_lines_are_read_in_runs_with_their_angles(planned_tables):
    text = "G21 G90\nG0 X0 Y0 Z5\nG1 X1 F100\nX2 A30\nX3\nX4 A45\nG92 A0\nX5\nX6 A10\nM2\n"
    correct_text(text, StaticEngine(G, [0.0] * 3, [[-1e4] * 3, [1e4] * 3]), SETUP, CorrectOptions())
    (tab,) = planned_tables
    assert sum(len(r) for r in tab.runs) >= 5  # the lines naming A among them
    by_line = dict(zip(tab.lineno.tolist(), tab.rot, strict=True))
    assert by_line[3] == {}  # before the program names A
    assert by_line[4] == {"A": 30.0}
    assert by_line[5] == {"A": 30.0}
    assert by_line[6] == {"A": 45.0}
    assert by_line[8] == {"A": 45.0}  # G92 A0 sets the offset, not the position
    assert by_line[9] == {"A": 55.0}  # A10 with A offset by 45


def test_rotary_samples_of_the_path_are_the_general_paths(monkeypatch):
    text = _rotary_program(np.random.default_rng(7), 60, "AB")
    paths = []
    allows = bulk.state_allows
    for use in (True, False):
        monkeypatch.setattr(bulk, "state_allows", allows if use else (lambda *a, **k: False))
        paths.append(program_path(text, SETUP, max_step_mm=0.5))
    a, b = paths
    assert np.array_equal(a.points_mm, b.points_mm)
    assert sorted(a.context) == sorted(b.context)
    for key in a.context:
        assert np.array_equal(a.context[key], b.context[key]), key


@pytest.mark.parametrize("line", ["X1 B2 A3\n", "A1 X2\n", "X1 A2 Z3\n", "G1 A5\n"])
def test_rotary_words_out_of_order_or_alone_are_not_plain(line):
    blk = bulk.scan(["G0 X1 Y1 Z1\n", line, "N10 G1 X 1 Y-.5 A3 F100\n"])
    assert blk is not None
    assert blk.plain.tolist() == [True, False, True]


@pytest.mark.skipif(not CORPUS.is_file(), reason="needs ../shared/corpus")
def test_a_real_four_axis_program_agrees():
    lines = CORPUS.read_text().splitlines(True)[:3000]
    a, b = _both("".join(lines), Setup(offsets={"G54": (150.0, 150.0, 150.0)}))
    assert a == b


def test_diff_pairs_rotary_lines_as_the_general_path_does(monkeypatch, tmp_path):
    from postproc.gcode.compare import compare_programs

    text = _rotary_program(np.random.default_rng(11), 80, "AB")
    orig, corr = tmp_path / "o.ngc", tmp_path / "c.ngc"
    orig.write_text(text)
    corr.write_text(correct_text(text, _engine(), SETUP, CorrectOptions())[0])
    allows = bulk.state_allows
    reports = []
    for use in (True, False):
        monkeypatch.setattr(bulk, "state_allows", allows if use else (lambda *a, **k: False))
        reports.append(compare_programs(str(orig), str(corr), SETUP).to_dict())
    assert reports[0] == reports[1]
    assert reports[0]["moves_moved"] > 50


def test_x_and_y_after_z_as_correct_adds_them_are_read_in_bulk(planned_tables):
    # correct adds the words of an axis a line does not name after its last axis word
    # (G0 G43 H2 Z25 -> ... Z24.8732 X182.6499 Y151.8130): reading its output back (diff,
    # a second correction) takes such lines in runs, each written by the general emitter
    text = ("G21 G90 G17\nG0 X10 Y10 Z5\nG1 Z-1 F100\nX20\nG0 Z5\nG1 X30 Y30 Z-1\nG0 Z5 A10\nX40 Y40\n"
            "G43 H1 Z6\nM2\n")
    once = correct_text(text, _engine(), Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 0.0}),
                        CorrectOptions())[0]
    body = [line for line in once.splitlines(True) if not line.startswith("(")]
    late = [line for line in body if "Z" in line and "X" in line and line.index("X") > line.index("Z")]
    assert len(late) >= 3  # G1 Z-1, G0 Z5 and G0 Z5 A10 got X and Y words after Z
    again = "".join(body)
    a, b = _both(again, Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 0.0}))
    assert a == b
    blk = bulk.scan(body)
    assert blk is not None
    rows = [i for i, line in enumerate(body) if line in late]
    assert all(blk.plain[i] for i in rows)
    assert set(rows) <= set(blk.late)
    # named once only: X before Z and X again after it is not plain
    assert bulk.scan(["G0 X1 Y1 Z1\n", "X1 Z2 X3\n"]).plain.tolist() == [True, False]
