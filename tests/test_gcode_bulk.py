"""The bulk lane gives byte for byte the output of the general path, on generated
programs and at every chunk boundary."""

import dataclasses

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode import bulk, emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, Corrector, correct_text
from postproc.gcode.state import ARC_CW

# squareness and scale: a move on one axis moves the others, so words get added
G = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])
ENGINE = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
SETUP = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 50.0})
MODES = {
    "bulk": {},
    "general": {"bulk_lane": False},
}


def run_all(text, *, chunk_lines=20_000, setup=SETUP, engine=ENGINE, **options):
    outs = {}
    for name, mode in MODES.items():
        opts = CorrectOptions(chunk_lines=chunk_lines, **options, **mode)
        try:
            out, rep = correct_text(text, engine, setup, opts)
            outs[name] = (out, dataclasses.asdict(rep))
        except PostprocError as exc:
            outs[name] = (str(exc), None)
    return outs


def assert_same(outs):
    ref = outs["general"]
    assert outs["bulk"][0] == ref[0]
    assert outs["bulk"][1] == ref[1]


# -- generated programs ------------------------------------------------------------------
def number(draw, lo=-200.0, hi=200.0):
    v = draw(st.floats(lo, hi, allow_nan=False))
    d = draw(st.sampled_from([0, 1, 2, 3, 4, 4, 4, 5, 6, 8]))
    text = f"{v:.{d}f}"
    style = draw(st.sampled_from(["plain", "plain", "plus", "trail", "lead"]))
    if style == "plus" and not text.startswith("-"):
        text = "+" + text
    elif style == "trail" and "." in text:
        text = text.rstrip("0")
    elif style == "lead" and text.startswith("0."):
        text = text[1:]
    elif style == "lead" and text.startswith("-0."):
        text = "-" + text[2:]
    return text


@st.composite
def plain_line(draw):
    sp = draw(st.sampled_from([" ", " ", "", "\t", "  "]))
    words = []
    if draw(st.booleans()):
        words.append(f"N{draw(st.integers(0, 99999))}")
    if draw(st.integers(0, 2)):
        words.append("G" + draw(st.sampled_from(["0", "1", "00", "01", "1", "1"])))
    axes = draw(st.lists(st.sampled_from("XYZ"), min_size=1, max_size=3, unique=True))
    for a in "XYZ":
        if a in axes:
            words.append(a + draw(st.sampled_from(["", "", " "])) + number(draw))
    if draw(st.integers(0, 4)) == 0:
        words.append(f"F{draw(st.sampled_from(['500', '1200.5', '80']))}")
    if draw(st.integers(0, 9)) == 0 and len(words) > 1:  # a non-canonical order
        words[-1], words[-2] = words[-2], words[-1]
    line = draw(st.sampled_from(["", " ", "\t"])) + sp.join(words) + draw(st.sampled_from(["", "", " "]))
    return line.lower() if draw(st.integers(0, 9)) == 0 else line


@st.composite
def other_line(draw):
    return draw(st.sampled_from([
        "G2 X{a} Y{b} I5 J0", "G3 X{a} Y{b} R40", "(comment X1 Y2)", "", "G91", "G90", "G20", "G21",
        "G1 X{a} (tail comment)", "G0 Z{b} ; note", "G54", "G43 H1", "G49", "M3 S1000", "/G1 X{a}",
        "G92 X{a}", "G92.1", "G17", "G18 G2 X{a} Z{b} I3 K3", "G1 F300", "N5", "%", "M30",
    ])).format(a=draw(st.integers(-150, 150)), b=draw(st.integers(-150, 150)))


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


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program(), st.sampled_from([1, 3, 4, 6]))
def test_bulk_lane_equals_the_general_path_with_other_decimals(text, decimals):
    assert_same(run_all(text, chunk_lines=7, decimals=decimals))


# -- the scanner ---------------------------------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(st.lists(plain_line(), min_size=1, max_size=20), st.sampled_from(["\n", "\r\n"]))
def test_scan_splits_every_line_into_pieces_that_join_back(lines, ending):
    lines = [ln + ending for ln in lines]
    block = bulk.scan(lines)
    assert block is not None
    cols = block.cols
    for i, line in enumerate(lines):
        pieces = [c[i] for c in cols]
        if block.plain[i]:
            joined = "".join(pieces[j] for j in (0, 2, 3, 4, 5, 6, 7, 8)) + "\n"
            assert joined == line
            for k, j in enumerate((3, 5, 7)):
                assert block.has[k][i] == bool(pieces[j])
                if pieces[j]:
                    assert block.ov[k][i] == float(pieces[j])
        else:
            assert not any(pieces)


def test_scan_refuses_lone_carriage_returns_and_keeps_the_other_lines_apart():
    assert bulk.scan(["X1\r", "X2\r"]) is None
    block = bulk.scan(["X1 Y2\n", "(c)\n", "\n", "G1 X3\r\n", "X4"])
    assert block.plain.tolist() == [True, False, False, True, True]
    assert not any(c[1] for c in block.cols)


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
        self.emitted_motion = ARC_CW
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
