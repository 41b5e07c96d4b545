"""The bulk lane gives byte for byte the output of the general path, on generated
programs and at every chunk boundary."""

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import (
    CORPUS,
    ENGINE,
    INSIDE,
    ROOT,
    SETUP,
    assert_offsets_cut_the_line,
    assert_same,
    both_lanes,
    other_line,
    path_and_diff_both_ways,
    plain_line,
    run_all,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.calfile import load_calibration
from postproc.engine.static import StaticEngine
from postproc.gcode import bulk, emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, Corrector, correct_text
from postproc.gcode.state import ARC_CW


@st.composite
def program(draw):
    body = ["G21 G90 G17 G94", "G0 X10 Y10 Z10"]
    for _ in range(draw(st.integers(1, 40))):
        body.append(draw(other_line()) if draw(st.integers(0, 4)) == 0 else draw(plain_line()))
    ending = draw(st.sampled_from(["\n", "\n", "\r\n", "\r"]))
    text = ending.join(body)
    return text + (ending if draw(st.booleans()) else "")


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program(), st.sampled_from([1, 2, 3, 5, 20_000]))
def test_bulk_lane_equals_the_general_path_on_generated_programs(text, chunk_lines):
    assert_same(run_all(text, chunk_lines=chunk_lines))


@st.composite
def arc_program(draw):
    """Straight moves and arcs (exact to the written decimals, or with the centre words
    dropped or broken) from where the program is, with comments and modal lines between."""
    x, y, z = 10.0, 10.0, 10.0
    body = ["G21 G90 G17 G94", "G0 X10 Y10 Z10", "G1 F500"]
    for _ in range(draw(st.integers(1, 30))):
        kind = draw(st.integers(0, 9))
        if kind < 4:
            x, y = draw(st.integers(-1500, 1500)) / 10, draw(st.integers(-1500, 1500)) / 10
            body.append(draw(st.sampled_from(["G1 ", "", "G0 ", "N10 G01 "])) + f"X{x:.3f} Y{y:.3f}")
            continue
        if kind == 4:
            body.append(draw(st.sampled_from(["(note)", "", "M3 S1000", "X1 Y2 I3 J4", "G1 F300", "G18",
                                              "G17", "G90.1", "G91.1"])))
            continue
        r = draw(st.integers(5, 400)) / 10
        a0 = math.atan2(-draw(st.integers(-10, 10)) or 1, draw(st.integers(-10, 10)))
        cx, cy = x - r * math.cos(a0), y - r * math.sin(a0)
        a1 = a0 + draw(st.integers(-300, 300)) / 100
        ex, ey = cx + r * math.cos(a1), cy + r * math.sin(a1)
        if draw(st.integers(0, 5)) == 0:
            ex += draw(st.sampled_from([0.5, 0.002, 0.0]))  # an end point off the circle
        i, j = cx - x, cy - y
        # no motion word: an arc under a modal G2/G3, else the interpreter's to read (or refuse)
        words = [draw(st.sampled_from(["G2", "G3", "G02", "N7 G03", "", "N8"])), f"X{ex:.4f}", f"Y{ey:.4f}"]
        if draw(st.booleans()):
            z = draw(st.integers(-50, 50)) / 10
            words.append(f"Z{z:.3f}")
        centre = draw(st.sampled_from(["ij", "ij", "ij", "i", "j", "none"]))
        if "i" in centre:
            words.append(f"I{i:.4f}")
        if "j" in centre:
            words.append(f"J{j:.4f}")
        if draw(st.integers(0, 3)) == 0:
            words.append("F800")
        body.append(" ".join(w for w in words if w))
        x, y = float(f"{ex:.4f}"), float(f"{ey:.4f}")
    return "\n".join(body) + "\n"


@pytest.mark.parametrize("chunk_lines", [1, 2, 3, 4, 5, 20_000])
def test_lines_that_move_nothing_inside_runs_and_at_chunk_ends(chunk_lines):
    text = ("G21 G90 G17 G94\nG0 X10 Y10 Z10\nf500 x0\nx0 y0\n(comment X1 Y2)\nG2 X0 Y0 I5 J0\n"
            "(a)\n\nG1 X5 Y5\nS1200 M3\nX6\nM8 (coolant)\nY7\nN30 M9\n  \n"
            "G2 X16 Y7 I5 J0\n(b)\nG3 X16 Y7 I-5 J0\nG1 X3\n(end)\n")
    outs = run_all(text, chunk_lines=chunk_lines)
    assert_same(outs)
    out, rep = outs["bulk"]
    # every line that moves nothing is written as it is, and is no move
    for line in ["(a)", "S1200 M3", "M8 (coolant)", "N30 M9", "(end)"]:
        assert line in out.splitlines()
    assert rep["moves"] == 10


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(arc_program(), st.sampled_from([1, 2, 5, 20_000]))
def test_arcs_in_runs_equal_the_general_path(text, chunk_lines):
    assert_same(run_all(text, chunk_lines=chunk_lines))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program(), st.sampled_from([1, 3, 4, 6]))
def test_bulk_lane_equals_the_general_path_with_other_decimals(text, decimals):
    assert_same(run_all(text, chunk_lines=7, decimals=decimals))


# -- the scanner ---------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(st.lists(plain_line(), min_size=1, max_size=20), st.sampled_from(["\n", "\r\n", "\r"]))
def test_scan_gives_every_line_the_offsets_of_its_words(lines, ending):
    lines = [ln + ending for ln in lines]
    block = bulk.scan(lines)
    assert block is not None
    for i, line in enumerate(lines):
        at = [col[i] for col in block.at]
        if block.plain[i] and not block.neutral[i]:
            assert_offsets_cut_the_line(line, at, [h[i] for h in block.has_l], [v[i] for v in block.ovl],
                                        i in block.late)
        elif not block.plain[i]:
            assert not any(at)


def test_scan_reads_lone_carriage_returns_and_keeps_the_other_lines_apart():
    lone = bulk.scan(["X1\r", "X2\r", "(c)\r", "X3"])  # lone CR endings: read in bulk, each line its own
    assert lone is not None
    assert lone.plain.tolist() == [True, True, True, True]
    assert lone.neutral.tolist() == [False, False, True, False]
    block = bulk.scan(["X1 Y2\n", "(c)\n", "\n", "G1 X3\r\n", "M3 S100\n", "S100 M3\n", "X4"])
    # a comment and a blank line move nothing: they stay in a run, written whole from one piece
    assert block.plain.tolist() == [True, True, True, True, False, True, True]
    assert block.neutral.tolist() == [False, True, True, False, False, True, False]
    # (a comment names no word: nothing of it is cut)
    assert [col[1] for col in block.at] == [0] * 11
    assert not any(h[1] for h in block.has_l)



def test_stops_and_semicolon_comments_move_nothing_and_stay_in_a_run():
    lines = ["G1 X1 Y2\n", "; finishing pass\n", "M1\n", "N5 M0 (check)\n", "(a) ; b\n", "M6\n", "M2\n", "X2\n",
             "M5 M9\n", "S1000 M3 M8 (on) (flood)\n", "M30\n", "M3 S100\n"]
    block = bulk.scan(lines)
    # M6 (tool change), M2 and M30 (end) are the interpreter's, and an S word after M words
    assert block.neutral.tolist() == [False, True, True, True, True, False, False, False, True, True, False, False]
    assert block.plain.tolist() == [True, True, True, True, True, False, False, True, True, True, False, False]


def test_runs_keep_semicolon_comments_and_stops_byte_for_byte():
    text = ("G0 X10 Y10 Z10\n" + "".join(f"G1 X{10 + i * 0.7:.3f} Y{20 - i * 0.3:.4f}\n; pass {i}\nM1\n"
                                         for i in range(12)) + "M30\n")
    for chunk in (1, 5, 20_000):
        outs = run_all(text, chunk_lines=chunk)
        assert_same(outs)
        assert "; pass 3\nM1\n" in outs["bulk"][0]


def test_a_tool_change_stays_in_a_run_and_a_later_g43_without_h_takes_its_length():
    lines = ["G1 X1\n", "T2 M6\n", "N40 M06 T03 (FLAT D6)\n", "T4\n", "T5 M6 X1\n", "X2\n"]
    block = bulk.scan(lines)
    assert block.neutral.tolist() == [False, True, True, False, False, False]
    assert block.tools == {1: 2, 2: 3}
    setup = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 0.0, 2: 5.0, 3: 7.0})
    text = ("G0 X10 Y10 Z10\nG1 X11 Y10.5\nX12 Y11\nT2 M6 (T2)\nX13 Y12\nX14\nN7 M6 T3\nX15\nG43 Z40\nX16\nX17 Y13\n"
            "T2 M6\nG43\nX18\n")
    for chunk in (1, 4, 20_000):
        outs = run_all(text, chunk_lines=chunk, setup=setup)
        assert_same(outs)
        assert outs["bulk"][1] is not None  # corrected, not refused

def test_a_move_that_sets_the_tool_length_starts_a_run():
    lines = ["G1 X1\n", "G0 G43 H2 Z40\n", "N7 G1 G43 H3 X16 Z20\n", "g0g43h0z5\n", "G43 H2\n", "G2 G43 H1 X1 I1\n"]
    block = bulk.scan(lines)
    assert block.tlo == {1: 2, 2: 3, 3: 0}
    assert block.plain.tolist() == [True, True, True, True, False, False]
    setup = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 10.0, 2: 25.0, 3: 7.0})
    text = ("G0 X10 Y10 Z80\nT1 M6\nG0 G43 H1 Z60\nG1 X11 Y10.5 F300\nX12 Y11\nT2 M6 (T2)\nN10 G0 G43 H2 Z50\n"
            "X13 Y12\nG1 Z45 X14\nT3 M6\ng0g43h3x15z40\nX16\nG43 H0 Z30\nX17 Y13\nG0 G43 H2 Y14 X18 Z35\nX19\n"
            "G91\nG43 H1 Z-5\nG90\nX20\nM30\n")
    for chunk in (1, 3, 20_000):
        outs = run_all(text, chunk_lines=chunk, setup=setup)
        assert_same(outs)
        assert outs["bulk"][1] is not None  # corrected, not refused
    # under a calibration that splits lines, a split G43 line carries its G43 H.. on its
    # first piece, as the interpreter's move does
    from postproc.calfile import load_calibration

    curved = load_calibration(Path(__file__).parents[1] / "calibrations" / "s500_parametric.json").engine
    far = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={1: 10.0, 2: 25.0})
    long = "G0 X10 Y10 Z200\nT1 M6\nG1 G43 H1 X290 Y280 Z20 F900\nG1 X20 Y30 F500\nG1 G43 H2 X280 Y20 Z150\nX15 Y290\n"
    for chunk in (1, 20_000):
        outs = run_all(long, chunk_lines=chunk, setup=far, engine=curved)
        assert_same(outs)
        assert outs["bulk"][1]["lines_inserted"] > 4
        assert outs["bulk"][0].count("G43 H1") == 2  # the first piece and the line itself
    # a tool length not given: the same refusal, at the same line and column
    missing = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 10.0})
    outs = run_all("G0 X10 Y10 Z80\nG0 G43 H1 Z60\nX11\nN5 G0 G43 H2 Z50\nX12\n", setup=missing)
    assert_same(outs)
    assert outs["bulk"][1] is None
    assert outs["bulk"][0].startswith("4:7: tool length of tool 2 is used (G43)")  # line 4, the G43 word


# -- fixed cases --------------------------------------------------------------------------
def test_runs_across_chunks_arcs_units_and_incremental_sections():
    text = ("%\nG21 G90 G17\nG0 X10 Y10 Z10\n" + "".join(f"G1 X{10 + i * 0.7:.3f} Y{20 - i * 0.3:.4f}\n" for i in range(30))
            + "G2 X40 Y20 I5 J0\nX41 Y21\nG1 X42\nG20\nX1.7 Y0.8\nG91\nX0.1\nY0.1\nG90 G21\nX30 Y30 Z12\n"
            + "".join(f"N{i} X{30 + i:.1f} Y{30 - i:.2f}\r\n" for i in range(10)) + "M30\nX999\n%\n")
    for chunk in (1, 2, 7, 16, 20_000):
        assert_same(run_all(text, chunk_lines=chunk))


def test_numbers_with_many_decimals_and_no_digits_after_the_point():
    text = "G0 X10 Y10 Z10\nG1 X12.123456789012345678901234 Y5.\nX.5 Y-.25\nX+3 Y-0.00001\n"
    assert_same(run_all(text))


def test_a_word_rewritten_to_minus_zero_is_written_as_zero():
    eng = StaticEngine(np.eye(3), [0.00004, 0.0, 0.0], [[-1e4] * 3, [1e4] * 3])
    text = "G0 X10 Y10 Z10\nG1 X0.0001 Y1\nX0.00009 Y2\n"
    outs = run_all(text, setup=Setup(), engine=eng, decimals=4)
    assert_same(outs)
    assert "X-0.0000" not in outs["bulk"][0]


class ArcModeCorrector(Corrector):
    """Pretends the controller is left in an arc mode before every chunk (as after a
    linearised arc), so a run's first line needs its motion word back."""

    def _chunk(self, entries, write_out):
        self.writer.emitted_motion = ARC_CW
        super()._chunk(entries, write_out)


def test_first_run_line_gets_the_motion_word_when_the_controller_mode_differs():
    # chunks: line 1 alone, lines 2-4, lines 5-6 (a run whose first line needs G1)
    text = "G0 X10 Y10 Z10\nG1 X12 Y11\nX13 Y12\nX14 Y11\nX15 Y12\nX16 Y13\n"
    outs = []
    for bulk_lane in (True, False):
        c = ArcModeCorrector(ENGINE, Setup(), CorrectOptions(chunk_lines=3, bulk_lane=bulk_lane))
        out: list[str] = []
        c.run(text.splitlines(keepends=True), out.append)
        outs.append(("".join(out), dataclasses.asdict(c.report)))
    assert outs[0] == outs[1]
    lines = emit.split_header(outs[0][0])[1].splitlines()
    # line 2 carries its G1; line 5 gets one; the others keep the modal motion
    assert [ln.split(".")[0] for ln in lines[1:]] == ["G1 X11", "X12", "X13", "G1 X14", "X15"]


def test_an_arc_too_short_to_span_the_plane_is_corrected():
    # 0.1 um of a 40 mm circle: its samples make the centre's normal equations singular
    text = "G21 G90\nG0 X0.0001 Y0 Z0\nG3 X0 Y0 R40\nG1 X5\n"
    outs = run_all(text, setup=Setup())
    assert_same(outs)
    assert outs["general"][1] is not None, outs["general"][0]
    assert outs["general"][1]["moves"] == 3


# -- lone carriage returns -------------------------------------------------------------
_LONE_CR = ["%", "G21 G90 G17 G94", "G0 X10 Y10 Z10", "G1 X20 Y10 Z5 F300", "(pass)", "G2 X30 Y20 I0 J10",
            "X40 Y30 I10 J0", "G1 X35", "Y25 Z4", "M3 S1000", "G3 X30 Y30 R5", "G1 X20 Y30", "G0 Z10", "M30", "%"]


def _lines_in_runs(monkeypatch, text, engine, setup, **options):
    """The output of the bulk lane and how many lines its runs took."""
    taken = []
    read_run = bulk.read_run

    def spy(*args, **kwargs):
        run = read_run(*args, **kwargs)
        taken.append(0 if run is None else len(run))
        return run

    monkeypatch.setattr(bulk, "read_run", spy)
    out = correct_text(text, engine, setup, CorrectOptions(**options))[0]
    monkeypatch.setattr(bulk, "read_run", read_run)
    return out, sum(taken)


@pytest.mark.parametrize("chunk_lines", [3, 20_000])
def test_lone_carriage_return_lines_are_read_in_bulk_as_the_interpreter_reads_them(monkeypatch, tmp_path, chunk_lines):
    text = "\r".join(_LONE_CR) + "\r"
    out, taken = _lines_in_runs(monkeypatch, text, ENGINE, SETUP)
    assert taken >= 9  # the moves, the comment and the M3 line among them
    a, b = both_lanes(text, ENGINE, SETUP, chunk_lines=chunk_lines)
    assert a == b == out
    # every line of the program keeps its own ending (the lines postproc adds, the header
    # and the pieces of the split arc, end CR LF, as every controller ends a block)
    ends = re.findall(r"[^\r\n]*(\r\n|\r|\n)", out)
    assert ends.count("\r") == len(_LONE_CR)  # (the split arc's last piece ends as its line did)
    assert "F300\r(pass)\rG2 " in out
    assert "\rG1 X34.8575\rY24.9970 Z3.9834 X34.8614\rM3 S1000\r" in out
    assert_same(run_all(text, chunk_lines=chunk_lines))
    report = path_and_diff_both_ways(monkeypatch, tmp_path, text, ENGINE, SETUP)
    assert report["moves_moved"] >= 9


@pytest.mark.skipif(not (CORPUS / "real").is_dir(), reason="needs ../shared/corpus")
@pytest.mark.parametrize("calibration", ["s500_static", "s500_parametric"])
def test_a_real_program_with_lone_carriage_returns_reads_in_bulk_as_the_interpreter_reads_it(monkeypatch, calibration):
    raw = (CORPUS / "real" / "ugs" / "test_files__ShapeOko_Calibration_Pattern_01b.ngc").read_bytes()
    text = raw.decode("utf-8", "surrogateescape")
    assert "\r\r\n" in text  # CR CR LF: a line ending at a lone CR, then an empty one
    engine = load_calibration(ROOT / "calibrations" / f"{calibration}.json").engine
    out, taken = _lines_in_runs(monkeypatch, text, engine, INSIDE, extrapolate="linear")
    assert taken > text.count("\r\r\n") // 2
    a, b = both_lanes(text, engine, INSIDE, extrapolate="linear")
    assert a == b == out


def _arc_chain(rng, n: int, absolute: bool):
    """``n`` arcs chained from (1, 2), each of a random radius and start and end angles:
    its end (rounded to 4 decimals), its centre words (absolute or from its start) and
    its radius."""
    x, y = 1.0, 2.0
    for _ in range(n):
        r = float(rng.uniform(0.5, 3))
        a0, a1 = (float(v) for v in rng.uniform(0, 2 * math.pi, 2))
        cx, cy = x - r * math.cos(a0), y - r * math.sin(a0)
        i, j = (cx, cy) if absolute else (cx - x, cy - y)
        x, y = round(cx + r * math.cos(a1), 4), round(cy + r * math.sin(a1), 4)
        yield x, y, i, j, r


@pytest.mark.parametrize("head", ["G21 G90 G17", "G20 G90 G17", "G21 G90 G17 G90.1"])
def test_a_run_arcs_turn_is_its_arc_params(monkeypatch, head):
    # the turn a run's arc is read with (plainscan.run_arcs) is the one arc_params gives
    # its move, to the bit: the planner takes it in its place
    from postproc.gcode.geometry import arc_params

    rng = np.random.default_rng(7)
    lines = [head, "G0 X1 Y2 Z0.5"]
    for k, (x, y, i, j, r) in enumerate(_arc_chain(rng, 300, head.endswith("G90.1"))):
        g = "G2" if k % 2 else "G3"
        if k % 7 == 0:
            lines.append(f"{g} X{x:.4f} Y{y:.4f} R{r:.4f} F500")
        elif k % 5 == 0:
            lines.append(f"G1 X{x:.4f} Y{y:.4f} Z{float(rng.uniform(0, 1)):.4f}")
        else:
            lines.append(f"{g} X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}")
    lines.append("M2")
    seen = []
    arc_moves = bulk.arc_moves

    def spy(run):
        got = arc_moves(run)
        for j, mv in got:
            seen.append((run.arcs[j][2], arc_params(mv.arc, mv.q0, mv.q1)))
        return got

    monkeypatch.setattr(bulk, "arc_moves", spy)
    correct_text("\n".join(lines) + "\n", ENGINE, Setup(), CorrectOptions(chunk_lines=40, extrapolate="linear"))
    assert len(seen) > 100
    for turn, prm in seen:
        assert prm[0] == (0, 1, 2)
        assert [v.hex() for v in turn] == [float(v).hex() for v in prm[1:]]


def _planned_arcs(monkeypatch, text: str, chunk_lines: int, bulk_lane: bool, **options) -> list:
    """``text`` corrected (``options``: more of CorrectOptions), the arcs the planner is
    given, in program order (Move or RunMove)."""
    from postproc.gcode.planner import Planner

    seen = []
    plan = Planner.plan

    def spy(self, tab):
        seen.extend(m for _i, m in sorted(tab.moves, key=lambda im: im[0]) if m.arc is not None)
        return plan(self, tab)

    monkeypatch.setattr(Planner, "plan", spy)
    correct_text(text, ENGINE, Setup(), CorrectOptions(chunk_lines=chunk_lines, extrapolate="linear",
                                                       bulk_lane=bulk_lane, **options), path="main.ngc")
    monkeypatch.setattr(Planner, "plan", plan)
    return seen


def _arc_fields(mv) -> tuple:
    return (mv.lineno, mv.kind, mv.feed, mv.rotary, mv.path, mv.unit, tuple(mv.shift), bool(mv.arc_absolute),
            mv.arc.clockwise, mv.arc.r_idx >= 0)


def _arc_moves_compared(monkeypatch, text: str, chunk_lines: int, **options) -> list[tuple]:
    """The arcs of ``text`` as the planner gets them read in runs (RunMove) beside those
    the interpreter reads line by line (Move): (run's, interpreter's) of each run arc."""
    fast = _planned_arcs(monkeypatch, text, chunk_lines, True, **options)
    slow = _planned_arcs(monkeypatch, text, chunk_lines, False, **options)
    assert len(fast) == len(slow)
    compared = []
    for f, s in zip(fast, slow, strict=True):
        assert type(s) is not bulk.RunMove
        assert np.allclose(f.q0, s.q0, rtol=0, atol=1e-9)
        assert np.allclose(f.q1, s.q1, rtol=0, atol=1e-9)
        assert np.allclose(f.arc.center, s.arc.center, rtol=0, atol=1e-9)
        if type(f) is bulk.RunMove:
            compared.append((_arc_fields(f), _arc_fields(s)))
    return compared


@pytest.mark.parametrize("head", ["G21 G90 G17", "G20 G90 G17 G90.1"])
def test_a_runs_arcs_are_the_moves_of_their_lines(monkeypatch, head):
    # a run's arcs are the moves the interpreter makes of their lines: motion (named, or
    # modal with no G word), feed (on the line, on a line before, alone on a line, or
    # from before the run), rotary positions, R form
    rng = np.random.default_rng(11)
    lines = [head, "G0 X1 Y2 Z0.5 A0", "F300"]
    for k, (x, y, i, j, r) in enumerate(_arc_chain(rng, 240, head.endswith("G90.1"))):
        g = "G2" if k % 3 else "G3"
        feed = f" F{100 + k}" if k % 4 == 0 else ""
        if k % 11 == 0:
            lines.append(f"{g} X{x:.4f} Y{y:.4f} R{r:.4f}{feed}")
        elif k % 9 == 0:
            lines.append(f"G1 X{x:.4f} Y{y:.4f} Z{float(rng.uniform(0, 1)):.4f} A{k}")
        elif k % 13 == 0:
            lines.append(f"F{50 + k}")
            lines.append(f"{g} X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}")
        elif k % 2 and not lines[-1].startswith(("G1", "F")):
            lines.append(f"X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}{feed}")  # the modal arc's own sense
        else:
            lines.append(f"{g} X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}{feed}")
    lines.append("M2")
    compared = _arc_moves_compared(monkeypatch, "\n".join(lines) + "\n", 40)
    assert len(compared) > 150
    assert {f[1] for f, _ in compared} == {20, 30}
    assert len({f[2] for f, _ in compared}) > 20
    assert any(f[9] for f, _ in compared)  # R form
    assert any(f[3] for f, _ in compared)  # rotary positions
    for fast, one in compared:
        assert fast == one


def test_a_loops_arcs_are_the_moves_of_their_source_lines(monkeypatch):
    # in an expanded program the arcs of a run carry their source lines, as the
    # interpreter's moves do
    text = ("G21 G90 G17\nG0 X10 Y0 Z1\n#1 = 0\no100 while [#1 LT 5]\n"
            "G2 X0 Y-10 I-10 J0 F[100 + #1]\nX-10 Y0 I0 J10\nG1 X-10 Y1\nG3 X-11 Y0 R1\nG1 X-10 Y0\nG2 X10 Y0 I10 J0\n"
            "#1 = [#1 + 1]\no100 endwhile\nM2\n")
    compared = _arc_moves_compared(monkeypatch, text, 7)
    assert len(compared) >= 10
    assert len({f[0] for f, _ in compared}) == 4  # four source lines, read five times
    for fast, one in compared:
        assert fast == one


def test_a_subprograms_arcs_carry_its_file(monkeypatch, tmp_path):
    # the arcs a run reads from a subprogram's own file name that file, as the
    # interpreter's moves do
    (tmp_path / "arcs.ngc").write_text("o<arcs> sub\nG2 X0 Y-10 I-10 J0 F300\nX-10 Y0 I0 J10\nG3 X0 Y10 I10 J0\n"
                                       "G1 X10 Y0\no<arcs> endsub\nM2\n")
    text = ("G21 G90 G17\nG0 X10 Y0 Z1\n#1 = 0\no100 while [#1 LT 4]\no<arcs> call\n#1 = [#1 + 1]\n"
            "o100 endwhile\nM2\n")
    compared = _arc_moves_compared(monkeypatch, text, 5, subroutine_path=[str(tmp_path)])
    assert len(compared) >= 6
    assert {f[4] for f, _ in compared} == {str(tmp_path / "arcs.ngc")}
    for fast, one in compared:
        assert fast == one
