"""Every line ``correct`` writes meets the dialect's limits (postproc.gcode.dialect):
a line whose correction takes it past them gets its comment on a line of its own before
it, or, with no comment to move, the program is refused naming the line and column."""

from __future__ import annotations

import re

import numpy as np
import pytest

from postproc.engine.static import StaticEngine
from postproc.errors import SafetyError
from postproc.gcode import dialect as dialects
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from tests.oracle import requires_rs274, run_rs274

VOLUME = [[-1e4] * 3, [1e4] * 3]
NAMES = sorted(n for n, d in dialects.DIALECTS.items() if d.machine == "mill")  # lathe programs are refused


def engine():
    """Z leans with X (0.1 mrad) and X scales by 20 ppm: a move along X gets a Z word
    and its X grows decimals."""
    G = np.eye(3) * (1 + 20e-6)
    G[2, 0] = 1e-4
    return StaticEngine(G, np.zeros(3), VOLUME)


def words_limit(d) -> int:
    return min(d.max_line_chars, d.max_word_chars or d.max_line_chars)


def test_a_line_a_comment_takes_past_the_limit_is_written_with_the_comment_before_it():
    for name in NAMES:
        d = dialects.get(name)
        head = "G1 X150 Y100 F500 "
        fill = "C" * (d.max_line_chars - len(head) - 4)  # the line: 2 characters short of it
        comment = f"({fill})" if d.paren_comments else f";{fill}C"
        prog = f"G21 G90 G17\nG0 X50 Y100 Z10\n{head}{comment}\nM2\n"
        out, rep = correct_text(prog, engine(), Setup(), CorrectOptions(dialect=name))
        body = emit.split_header(out)[1].splitlines()
        assert body[2] == comment, name
        assert body[3].startswith("G1 X149.9970 Y99.9980 Z9.9848 F500"), (name, body[3])
        for line in body:
            dialects.check_output_line(d, line)
        assert rep.lines_inserted == 1


@pytest.mark.parametrize("name", NAMES)
def test_a_line_with_nothing_to_move_is_refused_naming_it(name):
    d = dialects.get(name)
    head = "G1 X150 Y100 F500."
    pad = words_limit(d) - len(head.replace(" ", "")) - 2  # 2 characters of words short of the limit
    prog = f"G21 G90 G17\nG0 X50 Y100 Z10\n{head}{'0' * pad}\nM2\n"
    with pytest.raises(SafetyError, match=re.escape(f"more than {d.title}")) as exc:
        correct_text(prog, engine(), Setup(), CorrectOptions(dialect=name), path="p.nc")
    assert exc.value.lineno == 3
    assert exc.value.col == words_limit(d) + 1 if d.max_word_chars is None else exc.value.col > 1
    assert "--dialect" in exc.value.hint


def test_lines_within_the_limits_are_left_alone():
    prog = "G21 G90 G17\nG0 X50 Y100 Z10\nG1 X150 Y100 F500 (SHORT)\nM2\n"
    out, rep = correct_text(prog, engine(), Setup(), CorrectOptions(dialect="grbl"))
    assert "G1 X149.9970 Y99.9980 Z9.9848 F500 (SHORT)" in out
    assert rep.lines_inserted == 0


@requires_rs274
def test_linuxcnc_reads_the_rewritten_line():
    # a 245-character line grows past LinuxCNC's 252 ("Command too long" before)
    prog = "G21 G90 G17\nG0 X50 Y100 Z10\nG1 X150 Y100 F500 (" + "X" * 225 + ")\nM2\n"
    assert len(prog.splitlines()[2]) == 245
    out, _rep = correct_text(prog, engine(), Setup(), CorrectOptions(dialect="linuxcnc"))
    res = run_rs274(out)
    assert res.ok, res.error


@pytest.mark.parametrize("name", ["grbl", "fanuc", "linuxcnc"])
def test_a_form_feed_inside_a_line_is_no_line_end_to_the_limits(name):
    # A form feed is a blank of a G-code line: the line is measured and fitted whole (its
    # comment moved before it), not as the two pieces str.splitlines makes of it, each of
    # which would pass the limit while the line the controller reads does not.
    d = dialects.get(name)
    head = "G1 X150 Y100\fF500 "
    fill = "C" * (d.max_line_chars - len(head) - 4)  # the line: 2 characters short of it
    comment = f"({fill})" if d.paren_comments else f";{fill}C"
    prog = f"G21 G90 G17\nG0 X50\fY100 Z10\n{head}{comment}\nM2\n"
    out, rep = correct_text(prog, engine(), Setup(), CorrectOptions(dialect=name))
    body = emit.split_header(out)[1].split("\n")
    assert body[2] == comment
    assert body[3] == "G1 X149.9970 Y99.9980 Z9.9848\fF500"
    assert max(len(line) for line in body) <= d.max_line_chars
    assert rep.lines_inserted == 1
