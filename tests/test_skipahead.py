"""Where a later part's process goes on reading from (postproc.gcode.skipahead): the last
tool change before its warm-up, else a rapid move naming X and Y just before it; never
past a word whose state the lines after need not set again."""

from __future__ import annotations

from itertools import pairwise

import pytest

from postproc.fileio import count_lines
from postproc.gcode import skipahead

CHUNK = 10
HEADER = ["%", "O1000 (TEST)", "G90 G21 G17 G40 G49 G80", "G54", "T1 M6", "S9000 M3", "G0 X10 Y10", "G43 H1 Z5", "F500"]


def moves(n: int, start: int = 0) -> list[str]:
    """``n`` feed moves with no tool change, no rapid and no durable word."""
    return [f"G1 X{10 + (start + k) % 50}.5 Y{20 + (start + k) % 7}.25" for k in range(n)]


def write(tmp_path, lines: list[str], ending: str = "\n", name: str = "p.nc") -> str:
    path = tmp_path / name
    path.write_bytes(ending.join(lines).encode() + ending.encode())
    return str(path)


def go_on(tmp_path, lines: list[str], warm_up: int, ending: str = "\n") -> int:
    path = write(tmp_path, lines, ending)
    cut = warm_up + 2 * CHUNK
    return skipahead.go_on_from(path, skipahead.scan(path, CHUNK, cut), warm_up, cut, CHUNK)


def test_the_last_tool_change_before_the_warm_up(tmp_path):
    lines = (HEADER + moves(40) + ["G0 Z25", "T2 M6", "G0 G43 H2 Z25"] + moves(30) + ["T3 M6", "G0 G43 H3 Z25"]
             + moves(40))
    first, second = lines.index("T2 M6") + 1, lines.index("T3 M6") + 1
    assert go_on(tmp_path, lines, second + 5) == second
    assert go_on(tmp_path, lines, second - 1) == first  # (the later one is not before it)


def test_never_after_the_last_line_naming_an_axis(tmp_path):
    # after T3 no line names Z: Z is where "G0 G43 H2 Z25" put it, which must be read
    lines = HEADER + moves(40) + ["T2 M6", "G0 G43 H2 Z25"] + moves(30) + ["T3 M6"] + moves(40)
    assert go_on(tmp_path, lines, lines.index("T3 M6") + 5) == lines.index("T2 M6") + 1


def test_a_t_word_a_line_or_two_before_its_m6(tmp_path):
    lines = HEADER + moves(40) + ["(TOOL 2)", "T2", "(COOLANT OFF)", "M06"] + moves(40)
    assert go_on(tmp_path, lines, 90) == lines.index("T2") + 1


@pytest.mark.parametrize("word", ["M62 P1", "M60", "M61", "M600"])
def test_words_that_are_not_a_tool_change(tmp_path, word):
    lines = HEADER + moves(40) + ["T2 M6", word] + moves(40)
    path = write(tmp_path, lines)
    assert skipahead.scan(path, CHUNK, len(lines)).tool_starts(path) == [5, lines.index("T2 M6") + 1]  # (T1 M6 first)


def test_an_m6_in_a_comment_counts(tmp_path):
    # the scan does not read comments: it reads on from there, and the state at the cut
    # is compared as ever
    lines = HEADER + moves(40) + ["(THEN M6 AGAIN)"] + moves(40)
    path = write(tmp_path, lines)
    assert skipahead.scan(path, CHUNK, len(lines)).tool_starts(path)[-1] == lines.index("(THEN M6 AGAIN)") + 1


def test_lower_case_and_leading_zeros(tmp_path):
    lines = HEADER + moves(40) + ["t02 m06"] + moves(40)
    assert go_on(tmp_path, lines, 85) == lines.index("t02 m06") + 1


@pytest.mark.parametrize("word", ["G55", "G92 X0 Y0", "G10 L2 P1 X5", "G41 D1", "g42 d1", "G20", "G68 X0 Y0 R30",
                                  "#1=5", "G1 X[#1+2]", "O100 SUB", "M98 P100", "G28.1", "R1=5",
                                  "G81 X5 Y5 Z-3 R2"])
def test_a_durable_word_is_never_skipped(tmp_path, word):
    lines = HEADER + moves(30) + ["T2 M6"] + moves(10) + [word] + moves(20) + ["T3 M6"] + moves(40)
    durable = lines.index(word) + 1
    assert go_on(tmp_path, lines, lines.index("T3 M6") + 10) == lines.index("T2 M6") + 1 < durable


def test_a_durable_word_in_the_first_chunk_is_read_anyway(tmp_path):
    lines = HEADER + moves(40) + ["T2 M6"] + moves(40)
    assert "G54" in lines[:CHUNK]
    assert go_on(tmp_path, lines, 85) == lines.index("T2 M6") + 1


ARC = "G2 X12.5 Y20.25 I1 J0"


def test_without_a_tool_change_the_last_straight_line_where_no_arc_follows(tmp_path):
    lines = HEADER + moves(40) + [ARC] + moves(20) + ["X11 Y12", "G0 X20 Y20"] + moves(3) + ["X11 Y12"] * 5
    assert go_on(tmp_path, lines, len(lines) - 1) == len(lines) - 5  # the last with G0 or G1, after the arc


def test_where_an_arc_follows_a_rapid_naming_x_and_y(tmp_path):
    lines = (HEADER + moves(40) + ["G0 X20 Y20 Z5", "G1 Z-1"] + moves(25) + ["G0 Z5", "G00 X30.5 Y31 Z5", "G1 Z-1"]
             + moves(3) + [ARC] + moves(30))
    rapid = lines.index("G00 X30.5 Y31 Z5") + 1
    for warm_up in (rapid, rapid + 3, rapid + 8):  # the last before the warm-up
        assert go_on(tmp_path, lines, warm_up) == rapid
    assert go_on(tmp_path, lines, rapid - 3) == lines.index("G0 X20 Y20 Z5") + 1


def test_where_an_arc_follows_and_no_rapid_names_x_and_y_every_line_is_read(tmp_path):
    lines = HEADER + moves(60) + ["G0 Z5", "G0 X30"] + moves(3) + [ARC] + moves(30)
    assert go_on(tmp_path, lines, 70) == 0


def test_never_in_the_first_two_chunks(tmp_path):
    lines = HEADER + moves(5) + ["T2 M6"] + moves(60)
    assert lines.index("T2 M6") + 1 <= 2 * CHUNK
    assert go_on(tmp_path, lines, 60) == 0


def test_lines_ending_in_a_lone_cr_are_read(tmp_path):
    lines = HEADER + moves(40) + ["T2 M6"] + moves(40)
    assert go_on(tmp_path, lines, 85, ending="\r") == 0
    assert go_on(tmp_path, lines, 85, ending="\r\n") == lines.index("T2 M6") + 1


def test_lines_are_numbered_as_they_are_counted_across_blocks(tmp_path, monkeypatch):
    monkeypatch.setattr(skipahead, "_BLOCK", 64)  # many blocks, lines cut across them
    long = "(" + "x" * 300 + ")"  # a line longer than a block
    lines = HEADER + moves(17) + [long] + moves(23) + ["T2 M6"] + moves(9) + [long, "T3 M6"] + moves(40)
    path = write(tmp_path, lines)
    sc = skipahead.scan(path, CHUNK, 200)
    assert sc.tool_starts(path)[-2:] == [lines.index("T2 M6") + 1, lines.index("T3 M6") + 1]
    assert sc.blocks[0][:2] == (1, 0)
    assert all(b[0] - a[0] >= 1 and b[1] == a[1] + a[2] for a, b in pairwise(sc.blocks))
    with open(path, "rb") as fh:
        data = fh.read()
    for line, offset, size in sc.blocks:  # every block starts at the line it names, ends at a line's end
        assert data[:offset].count(b"\n") + 1 == line
        assert data[offset + size - 1:offset + size] == b"\n"
    assert count_lines(path) == len(lines)


def test_the_scan_stops_at_the_first_durable_word(tmp_path):
    lines = HEADER + moves(40) + ["G55"] + moves(10) + ["T2 M6"] + moves(40)
    path = write(tmp_path, lines)
    sc = skipahead.scan(path, CHUNK, len(lines))
    assert sc.durable == lines.index("G55") + 1
    assert not any(t > sc.durable for t in sc.tool_starts(path))


def test_never_after_the_last_line_naming_a_rotary_axis(tmp_path):
    lines = HEADER + moves(30) + ["G1 X20 A10"] + moves(30) + ["T2 M6"] + moves(30)
    assert go_on(tmp_path, lines, len(lines) - 5) == lines.index("G1 X20 A10") + 1


def test_an_axis_last_named_before_the_lines_looked_at(tmp_path, monkeypatch):
    lines = HEADER + moves(20) + ["G1 Z-1"] + moves(80) + ["T2 M6"] + moves(30)
    assert go_on(tmp_path, lines, len(lines) - 25) == lines.index("G1 Z-1") + 1
    monkeypatch.setattr(skipahead, "LOOK_BACK", 40)  # Z's line is out of sight: every line read
    assert go_on(tmp_path, lines, len(lines) - 25) == 0


def test_what_the_scan_keeps_does_not_grow_with_the_tool_changes(tmp_path):
    lines = HEADER + ["T1 M6", "G1 X10.5 Y20.25"] * 20_000 + moves(40)
    path = write(tmp_path, lines)
    sc = skipahead.scan(path, CHUNK, len(lines))
    assert len(sc.tools) == len(sc.blocks) < 20  # a block index each, not a position each
    assert go_on(tmp_path, lines, len(lines) - 45) == len(lines) - 45  # (the last before the warm-up)


def test_lines_looked_at_are_bounded_in_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(skipahead, "_BLOCK", 4096)  # blocks finer than the budgets below
    long = "G1 X10.5 Y20.25 Z-1 (" + "x" * 2000 + ")"
    lines = HEADER + moves(40) + ["T2 M6"] + [long] * 60 + moves(5)
    assert go_on(tmp_path, lines, len(lines) - 2) == lines.index("T2 M6") + 1
    monkeypatch.setattr(skipahead, "LOOK_BACK_BYTES", 30_000)  # the last lines only: the same start
    assert go_on(tmp_path, lines, len(lines) - 2) == lines.index("T2 M6") + 1
    monkeypatch.setattr(skipahead, "LOOK_BACK_BYTES", 1_000)  # not even those: every line read
    assert go_on(tmp_path, lines, len(lines) - 2) == 0
