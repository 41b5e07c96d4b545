"""Every row of a chunk's table has a typed kind (``Table.kind``, :class:`Kind`): the
motion of a motion block, whether read in bulk as a run of plain lines or line by line,
or what else the row is (a cycle block, its R point, a position reached uncorrected, a
spline's chords, a run's line that moves nothing). The planner picks its rows by it."""

import itertools

import numpy as np

from postproc.engine.static import StaticEngine
from postproc.gcode.moves import Kind
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.source import Setup

PROGRAM = """G21 G90 G17 G94
G0 X10 Y10 Z50
G1 Z40 F500
X20
(a comment)
Y20
G2 X30 Y30 I10 J0
G1 X40 M8
G3 X50 Y40 R10
G0 Z60
G81 X60 Y60 Z30 R45 F200
X70
G80
G28 X0
G5 I5 J5 P-5 Q5 X80 Y80
G1 X90
M2
"""

# line -> the kinds of its rows, in order (line 15, a G5 spline: its chords, checked apart)
EXPECTED = {
    2: [Kind.RAPID], 3: [Kind.FEED], 4: [Kind.FEED], 5: [Kind.STILL], 6: [Kind.FEED], 7: [Kind.ARC_CW],
    8: [Kind.FEED],  # not a plain line (M8): read line by line, the same kind
    9: [Kind.ARC_CCW],  # R form: read line by line
    10: [Kind.RAPID],
    11: [Kind.CYCLE, Kind.R_POINT], 12: [Kind.CYCLE, Kind.R_POINT],
    14: [Kind.RAPID, Kind.AT],  # G28: to the intermediate point, then the stored position
    16: [Kind.FEED],
}

SETUP = Setup(offsets={"G54": (100, 100, 100)}, home={"G28": {"X": 0, "Y": 0, "Z": 200}})


def _engine():
    return StaticEngine(np.diag([1.0002, 1.0, 1.0]), [0, 0, 0], [[0] * 3, [315] * 3])


def test_each_row_has_the_kind_of_what_its_line_does(planned_tables):
    correct_text(PROGRAM, _engine(), SETUP, CorrectOptions())
    (tab,) = planned_tables
    got = {line: [Kind(k) for _line, k in rows]
           for line, rows in itertools.groupby(zip(tab.lineno.tolist(), tab.kind.tolist(), strict=True),
                                               key=lambda r: r[0])}
    chords = got.pop(15)
    assert len(chords) > 10
    assert set(chords) == {Kind.CHORD}
    assert got == {line: kinds for line, kinds in EXPECTED.items() if line != 15}
    assert len(tab.runs) >= 2  # lines 2-7 (and 16) are read in bulk, the rest line by line


def test_run_rows_are_the_runs_rows_of_that_kind(planned_tables):
    correct_text(PROGRAM, _engine(), SETUP, CorrectOptions())
    (tab,) = planned_tables
    rows, owner = tab.run_rows(Kind.FEED)
    want = [(i, o) for o, r in enumerate(tab.runs) for i in range(r.trow, r.trow + len(r)) if tab.kind[i] == Kind.FEED]
    assert list(zip(rows.tolist(), owner.tolist(), strict=True)) == want
    lines = tab.lineno[rows].tolist()
    assert {3, 4, 6, 16} <= set(lines)
    assert 8 not in lines  # a straight move read line by line is not a run's


def test_a_modal_motion_carries_into_a_run_that_names_none(planned_tables):
    # the second chunk's run starts without a G word: its rows take the motion modal there
    text = "G21 G90 G17\nG0 X1 Y1 Z1\nG1 F100 M8\n" + "".join(f"X{1 + i * 0.5:.1f} Y2\n" for i in range(30)) + "M2\n"
    correct_text(text, _engine(), Setup(offsets={"G54": (100, 100, 100)}), CorrectOptions(chunk_lines=8))
    kinds = [Kind(k) for tab in planned_tables for k in tab.kind.tolist()]
    lines = [n for tab in planned_tables for n in tab.lineno.tolist()]
    assert lines == [2, *range(4, 34)]  # (line 3 moves nothing: no row)
    assert kinds == [Kind.RAPID] + [Kind.FEED] * 30
    assert sum(len(tab.runs) for tab in planned_tables) >= 3
