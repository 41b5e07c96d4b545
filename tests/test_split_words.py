"""Words keep their meaning when their block is split or expanded (STYLE 23).

A move that ``correct`` writes as several moves (an arc split into exact arcs, a line
split where the error field curves, a canned cycle expanded) carries its S, T and
before-motion M words (M3-M5, M7-M9, M62-M68 with their P, E, Q, L words) on the first
line written for it, and no longer on its own line: LinuxCNC acts on them once, before
the first piece, as it did before the move was split. The check is rs274's order of
canonical calls: the same calls, in the same order, between the same comments, with
the motions of one block counted as one."""

from __future__ import annotations

import re

import pytest

from postproc.calfile import load_calibration
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from tests.conftest import PARAMETRIC
from tests.oracle import requires_rs274, run_rs274

pytestmark = requires_rs274

MOTIONS = ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED")
# the header of a corrected program, and calls a split repeats with the same value
_HEADER = re.compile(r"COMMENT\(\"POSTPROC")
# calls setting a mode: set again to the mode in effect, they change nothing
_MODES = {"SET_FEED_MODE", "SELECT_PLANE", "USE_LENGTH_UNITS", "SET_G5X_OFFSET", "SET_XY_ROTATION"}


def events(calls: list[str]) -> list[str]:
    """The canonical calls with each run of motions as one ``MOVE``, without a mode or a
    feed rate set again to the value it has (a split move's first piece carries copies of
    its modal G words, and its last line keeps its F word); in inverse
    time (G93) each piece has its own feed: the feeds between pieces are left out and
    the others read ``SET_FEED_RATE(inverse)``."""
    out: list[str] = []
    feed = None
    inverse = False
    modes: dict[str, str] = {}
    for k, c in enumerate(calls):
        if _HEADER.match(c):
            continue
        name = c.split("(", 1)[0]
        if name in _MODES or c.startswith("COMMENT(\"interpreter:"):
            key = name if name in _MODES else c.split(" set to")[0]
            if modes.get(key) == c:  # a modal word copied onto the first piece, again on its own line
                continue
            modes[key] = c
        if c == "SET_FEED_RATE(0.0000)" and k + 1 < len(calls) and calls[k + 1].startswith("SET_FEED_RATE("):
            continue  # G94 again (copied onto the first piece) resets the feed its F word sets
        if c.startswith("COMMENT(\"interpreter: feed mode set to"):
            inverse = "inverse time" in c
        if c.startswith(MOTIONS):
            if not out or out[-1] != "MOVE":
                out.append("MOVE")
            continue
        if c.startswith("SET_FEED_RATE("):
            if inverse:
                if out and out[-1] == "MOVE":
                    continue
                c = "SET_FEED_RATE(inverse)"
            if c == feed:
                continue
            feed = c
        out.append(c)
    return out


@pytest.fixture(scope="module")
def engine():
    return load_calibration(PARAMETRIC).engine


def _corrected(text: str, engine, **options) -> str:
    out, _rep = correct_text(text, engine, Setup(), CorrectOptions(**options))
    return out


# Half circles of radius 50 and long lines across the S500 volume: the parametric
# calibration splits each of them. A comment line between blocks marks where each
# block's calls must fall.
EVERY_WORD = """G21 G90 G17
G0 X50 Y100 Z10
(B1)
G2 X150 Y100 I50 J0 F500 M62 P1
(B2)
G3 X50 Y100 I-50 J0 M67 E0 Q40
(B3)
G2 X150 Y100 I50 J0 M64 P2 S8000 M3
(B4)
G3 X50 Y100 I-50 J0 M68 E1 Q2.5 M8
(B5)
G2 X150 Y100 I50 J0 M63 P1 M9
(B6)
G1 X250 Y250 Z5 F800 T2 M4 S6000 M7
(B7)
G1 X30 Y30 Z8 M66 P0 L0 M5
(B8)
G93 G1 X250 Y30 F2 M62 P3
(B9)
G94 G2 X250 Y130 I0 J50 F400 M63 P3
(B10)
G3 X250 Y30 I0 J-50 M65 P2
M2
"""


def test_every_word_acts_where_it_did_before_the_split(engine):
    out = _corrected(EVERY_WORD, engine)
    before, after = run_rs274(EVERY_WORD), run_rs274(out)
    assert before.ok, before.error
    assert after.ok, after.error + "\n" + out
    assert len(after.motions) > len(before.motions) + 8, "the moves were not split"
    assert events(after.calls) == events(before.calls)


def test_the_first_piece_carries_the_words_and_the_last_drops_them(engine):
    out = _corrected(EVERY_WORD, engine)
    lines = [ln for ln in out.splitlines() if not ln.startswith("(POSTPROC")]
    b1 = lines.index("(B1)")
    first, last = lines[b1 + 1], lines[lines.index("(B2)") - 1]
    assert first.startswith("M62 P1 G2 ")
    assert "M62" not in last
    assert "F500" in last
    b3 = lines.index("(B3)")
    assert lines[b3 + 1].startswith("M64 P2 S8000 M3 G2 ")
    b6 = lines.index("(B6)")
    assert lines[b6 + 1].startswith("T2 M4 S6000 M7 G1 ")
    assert not re.search(r"\b[STM]\d", lines[lines.index("(B7)") - 1])


def test_an_arc_keeps_its_turn_word_when_an_output_shares_it(engine):
    # P is both M62's output number and G2's turn count on this line: M62 P1 goes on the
    # first piece, and the last piece keeps P1 (one turn, as without it)
    out = _corrected("G21 G90\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 P1 F500 M62\nM2\n", engine)
    ok = run_rs274(out)
    assert ok.ok, ok.error
    assert "SET_MOTION_OUTPUT_BIT(1)" in events(ok.calls)


def test_an_expanded_cycle_carries_its_words_on_its_first_line(engine):
    prog = ("G21 G90 G17\nG0 X100 Y100 Z60\n(B1)\nG98 G81 X120 Y120 Z15 R40 F300 S5000 M3 M62 P1\n"
            "(B2)\nG80\nM2\n")
    out = _corrected(prog, engine)  # --cycles auto: the parametric calibration tilts the hole
    assert "G81" not in out
    before, after = run_rs274(prog), run_rs274(out)
    assert before.ok, before.error
    assert after.ok, after.error + "\n" + out
    # the F word goes on the first feed move of the expansion (rapids do not use it):
    # the feed is set before the first STRAIGHT_FEED, the other calls keep their order
    feed = after.calls.index("SET_FEED_RATE(300.0000)")
    assert feed < next(i for i, c in enumerate(after.calls) if c.startswith("STRAIGHT_FEED"))
    def no_feed(calls):
        # an expansion has no path mode of the cycle to set: its moves are written out
        return events([c for c in calls if not c.startswith((
            "SET_FEED_RATE", "SET_MOTION_CONTROL_MODE", "SET_NAIVECAM"))])
    assert no_feed(after.calls) == no_feed(before.calls)


def test_diff_pairs_a_split_move_whose_words_went_to_its_first_piece(engine):
    from postproc.gcode.compare import compare_programs

    out = _corrected(EVERY_WORD, engine)
    d = compare_programs(EVERY_WORD, out)
    assert d.moves == 11  # every block but the first (G21 G90 G17) and M2
    assert d.lines_inserted > 8


def test_lines_ending_in_cr_cr_lf_split_into_blocks_linuxcnc_reads():
    """A file ending its lines CR CR LF (UGS's ShapeOko pattern) reads here as lines ending
    in a lone CR: pieces of a split move written with that CR alone were one block to
    rs274 ("Two g codes used from same modal group"). Written lines end CR LF."""
    eng = load_calibration(PARAMETRIC).engine
    text = "G21 G90\r\r\nG0 X50 Y100 Z10\r\r\nG1 X150 Y100 F500\r\r\nG1 X50 Y150\r\r\nM2\r\r\n"
    out, rep = correct_text(text, eng, Setup(), CorrectOptions(dialect="linuxcnc"))
    assert rep.lines_inserted > 0
    assert re.search(r"\r(?![\r\n])", out) is None  # no CR alone between two blocks
    assert out.endswith("M2\r\r\n")
    result = run_rs274(out)
    assert result.ok, result.error
