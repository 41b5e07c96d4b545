"""The path sampler reads programs through the lane's reader (runs of plain lines in
bulk): its samples are bit for bit those of the interpreter read line by line
(tests/path_reference.py), and its errors the same, at the same place."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from path_reference import reference_sample_program

from postproc.errors import MissingSetupError, PostprocError, UnsupportedGcodeError
from postproc.gcode import pathread
from postproc.gcode.path import Setup, sample_program
from postproc.limits import ResourceLimitError

ROOT = Path(__file__).resolve().parents[1]
GENCAM = ROOT.parent / "shared" / "bench" / "gencam.py"
SAMPLINGS = [{"step_mm": 0.5}, {"chord_mm": 1e-5}, {"step_mm": 0.5, "chord_mm": 1e-5}, {}, {"step_mm": 0.07}]
BENCH = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}},
              tool_lengths={t: 0.0 for t in range(1, 21)})


def _bits(pp) -> list:
    arrays = [pp.points_mm, pp.tool_mm, pp.lineno, pp.rapid, *pp.context.values()]
    return [list(pp.context), *[(a.dtype.str, a.shape, a.tobytes()) for a in arrays]]


def _outcome(fn, *args, **kw):
    try:
        return "path", fn(*args, **kw)
    except PostprocError as exc:
        return "error", (type(exc).__name__, str(exc), exc.path, exc.lineno, exc.col, exc.hint)


def assert_same(source, setup=None, *, error: bool | None = False, **kw):
    """sample_program and the line-by-line reference agree bit for bit (``error``: fail
    alike; None: either); returns the path (or the error's class, message, file, line, column, hint)."""
    got = _outcome(sample_program, source, setup, **kw)
    ref = _outcome(reference_sample_program, source, setup, **kw)
    assert got[0] == ref[0], (got, ref)
    if error is not None:
        assert got[0] == ("error" if error else "path"), got
    if got[0] == "error":
        assert got[1] == ref[1]
    else:
        assert _bits(got[1]) == _bits(ref[1])
    return got[1]


@pytest.fixture
def runs(monkeypatch):
    """The runs of plain lines the sampler takes from their columns: (first line, lines, arcs)."""
    seen: list[tuple[int, int, int]] = []
    take = pathread.Sampler._block_runs

    def spy(self, blk, runs):
        seen.extend((run.lineno, run.b - run.a, len(run.arcs)) for run in runs)
        return take(self, blk, runs)

    monkeypatch.setattr(pathread.Sampler, "_block_runs", spy)
    return seen


ARCS = """%
G21 G90 G17 G94
G0 X0 Y0 Z10
G1 Z-1 F300
X10
Y5 F600
G2 X15 Y10 I5 J0
G1 X20
G3 X20 Y20 I0 J5
(a comment)
G1 X25 Y25
G03 X30 Y30 Z-1.5 I5 J0
G0 Z10
X0 Y0
G1 Z-2
X3.3333 Y1.1111
G2 X6.6667 Y1.1111 I1.6667 J0
M30
"""


@pytest.mark.parametrize("kw", SAMPLINGS)
def test_arcs_inside_a_run_are_sampled_as_the_interpreter_reads_them(runs, kw):
    pp = assert_same(ARCS, **kw)
    assert sum(n_arcs for _l, _n, n_arcs in runs) == 4  # every arc was read in a run
    # hand-checked: the quarter G2 from (10, 5) about (15, 5) ends at (15, 10), its samples on the circle
    on = pp.lineno == 7
    pts = pp.points_mm[on]
    np.testing.assert_allclose(np.hypot(pts[:, 0] - 15, pts[:, 1] - 5), 5.0, atol=1e-12)
    np.testing.assert_allclose(pts[-1], [15.0, 10.0, -1.0], atol=1e-12)
    assert not pp.rapid[on].any()


def test_absolute_arc_centres_and_inches_in_a_run(runs):
    text = "G20 G90 G90.1 G17\nG0 X0 Y0 Z1\nG1 X1 F10\nG2 X2 Y1 I1 J1\nG1 Y2\nG3 X1 Y3 I1 J2\nG1 X0\nM30\n"
    pp = assert_same(text, step_mm=0.5)
    assert runs
    assert runs[0][2] == 2
    np.testing.assert_allclose(pp.points_mm[pp.lineno == 4][-1], [50.8, 25.4, 25.4], atol=1e-12)


@pytest.mark.parametrize("kw", SAMPLINGS)
def test_rapid_and_feed_flags_follow_the_modal_motion(runs, kw):
    text = "G21 G90\nG0 X0 Y0 Z5\nG1 X1 F100\nX2\nG0 X3\nX4\nY1\nG01 Y2\nG00 Y3\nG1 Y4\nM30\n"
    pp = assert_same(text, **kw)
    assert runs
    rapid_lines = sorted(set(pp.lineno[pp.rapid].tolist()))
    feed_lines = sorted(set(pp.lineno[~pp.rapid].tolist()))
    assert rapid_lines == [2, 5, 6, 7, 9]
    assert feed_lines == [3, 4, 8, 10]
    # a rapid move gives its end alone
    assert all((pp.lineno == ln).sum() == 1 for ln in rapid_lines)


def test_tool_change_and_tool_length_inside_runs(runs):
    text = ("G21 G90 G54\nT1 M6\nG43 H1\nG0 X0 Y0 Z10\nG1 Z0 F100\nX5\nT2 M6\nX6\n"
            "G0 G43 H2 Z20\nX7 Y1\nG1 Z1\nM30\n")
    setup = Setup(offsets={"G54": (1.0, 2.0, 3.0)}, tool_lengths={1: 10.0, 2: 20.0})
    pp = assert_same(text, setup, step_mm=0.5)
    assert runs
    length = -pp.tool_mm[:, 2]
    assert set(length[pp.lineno < 9].tolist()) == {10.0}
    assert set(length[pp.lineno >= 9].tolist()) == {20.0}
    # functional point = program + offset: the tool length is in r, not in p
    assert pp.points_mm[pp.lineno == 10][-1].tolist() == [8.0, 3.0, 23.0]


def test_rotary_axes_used_after_runs_give_their_context(runs):
    text = ("G21 G90\nG0 X0 Y0 Z5\nG1 X1 F100\nX2\nX3\nG0 A90\nG1 X4\nX5 A45\nX6\nM30\n")
    pp = assert_same(text, step_mm=0.5)
    assert runs
    assert runs[0][0] == 3
    a = pp.context["A"]
    assert set(a[pp.lineno < 6].tolist()) == {0.0}
    assert set(a[(pp.lineno >= 6) & (pp.lineno < 8)].tolist()) == {90.0}
    assert set(a[pp.lineno >= 8].tolist()) == {45.0}


def test_setup_start_and_context(runs):
    setup = Setup(start={"X": -5.0, "Y": 0.0, "Z": 50.0}, context={"temp": 21.5})
    pp = assert_same("G21 G90\nG0 Z5\nX0 Y0\nG1 X1 F100\nX0.5\nY-1\nM30\n", setup, step_mm=0.25)
    assert pp.context["temp"].tolist() == [21.5] * len(pp)
    assert pp.context["dirx"][pp.lineno == 5].tolist() == [-1.0] * 2


EXPAND = """G21 G90
G0 X0 Y0 Z5
G1 X1 F100
X2
X3
o100 sub
G1 X[#1] Y1
G2 X[#1 + 2] Y3 I0 J2
o100 endsub
o100 call [7]
G1 X8
X9 Y9
M30
"""


@pytest.mark.parametrize("kw", SAMPLINGS)
def test_a_run_then_a_program_that_needs_expanding(runs, kw):
    pp = assert_same(EXPAND, **kw)
    # the run read before the line that needs expanding is dropped; the expanded program's
    # plain lines (3 to 5, the subroutine's two, 11 and 12) are read as one run, each
    # numbered as the line it comes from
    assert runs == [(3, 3, 0), (3, 7, 1)]
    assert sorted(set(pp.lineno.tolist())) == [2, 3, 4, 5, 7, 8, 11, 12]
    assert pp.points_mm[pp.lineno == 7][-1].tolist() == [7.0, 1.0, 5.0]


def test_expansion_errors_come_after_the_bound_of_the_lines_before():
    text = EXPAND.replace("o100 call [7]", "o100 call [7]\nG1 X#<_undefined_name>")
    assert_same(text, step_mm=0.5, error=True)
    assert_same(text, step_mm=0.5, max_samples=10, error=True)


def test_the_bound_is_refused_at_the_run_line_that_passes_it(runs):
    body = "".join(f"X{k + 1}\n" for k in range(100))
    text = "G21 G90\nG0 X0 Y0 Z5\nG1 X0.5 F100\n" + body + "G0 X@1\nM30\n"  # a polar word the interpreter refuses
    # 1 + 1 samples, then 2 a line: the 26th body line (line 29) passes 52
    err = assert_same(text, step_mm=0.5, max_samples=52, error=True)
    assert err[0] == "ResourceLimitError"
    assert err[3] == 29
    with pytest.raises(ResourceLimitError) as e:
        sample_program(text, step_mm=0.5, max_samples=52)
    assert e.value.lineno == 29
    assert e.value.col == 1
    assert runs  # (read in a run)
    # with room for every sample, the interpreter's refusal of the last line
    err = assert_same(text, step_mm=0.5, max_samples=1000, error=True)
    assert err[0] == "UnsupportedGcodeError"
    assert err[3] == 104
    # an error before the bound is passed is the one reported
    early = text.replace("X10\n", "X10 Y@2\n", 1)
    with pytest.raises(UnsupportedGcodeError):
        sample_program(early, step_mm=0.5, max_samples=52)
    assert_same(early, step_mm=0.5, max_samples=52, error=True)


def test_an_arc_in_a_run_past_the_bound_is_refused_before_its_points_are_made(runs):
    text = "G21 G90\nG0 X0 Y0 Z5\nG1 X1 F100\nG2 X3 Y0 I1 J0\nG1 X4\nM30\n"
    err = assert_same(text, step_mm=1e-12, error=True)
    assert err[0] == "ResourceLimitError"
    assert err[3] == 3
    err = assert_same(text, step_mm=1e-5, error=True)
    assert err[0] == "ResourceLimitError"
    assert err[3] == 4
    assert_same(text, step_mm=1e-320, error=True)


def test_unknown_axes_are_backfilled_or_refused_as_before():
    assert_same("G21 G90\nG1 X1 Y1 F100\nX2 Y2\nZ3\nX3\n", step_mm=0.5)
    with pytest.raises(MissingSetupError):
        sample_program("G21 G90\nG1 X1 Y1 F100\nX2 Y2\n", step_mm=0.5)
    assert_same("G21 G90\nG1 X1 Y1 F100\nX2 Y2\n", step_mm=0.5, error=True)


def test_a_line_too_long_is_refused_after_the_lines_before_it(tmp_path):
    prog = tmp_path / "long.nc"
    body = "".join(f"X{k + 1}\n" for k in range(50))
    prog.write_text("G21 G90\nG0 X0 Y0 Z5\nG1 F100\n" + body + "(" + "a" * 70_000 + ")\nX0\n")
    err = assert_same(str(prog), step_mm=0.5, error=True)
    assert err[0] == "PostprocError"
    assert err[3] == 54
    err = assert_same(str(prog), step_mm=0.5, max_samples=20, error=True)
    assert err[0] == "ResourceLimitError"


def test_blocks_of_the_reader_change_nothing(monkeypatch, runs):
    body, x, y = [], 0.0, 0.0
    for k in range(300):
        if k % 11 == 0:  # a half circle to x + 1 about (x + 0.5, y)
            body.append(f"G2 X{x + 1:g} Y{y:g} I0.5 J0\n")
        else:
            y = (k % 5) * 0.2
            body.append(f"G{k % 2} X{x + 1:g} Y{y:g}\n")
        x += 1
    text = "G21 G90\nG0 X0 Y0 Z5\nG1 F100\n" + "".join(body)
    whole = _bits(sample_program(text, step_mm=0.3))
    monkeypatch.setattr(pathread, "BLOCK_LINES", 7)
    assert _bits(sample_program(text, step_mm=0.3)) == whole
    assert_same(text, step_mm=0.3)
    assert sum(n_arcs for _l, _n, n_arcs in runs) == 3 * 28  # (every arc in a run, each time)


@pytest.mark.parametrize("prog", sorted(p for p in (ROOT / "samples").rglob("*") if p.suffix in {".nc", ".ngc"}),
                         ids=lambda p: p.name)
def test_sample_programs(prog):
    for kw in SAMPLINGS[:4]:
        assert_same(str(prog), Setup(offsets={"G54": (0, 0, 0)}, tool_lengths={t: 50.0 + t for t in range(30)}),
                    error=None, **kw)


@pytest.mark.skipif(not GENCAM.exists(), reason="the shared benchmark generator is not beside the repo")
@pytest.mark.parametrize("seed", [3, 11])
def test_gencam_programs(tmp_path, runs, seed):
    prog = tmp_path / "gencam.nc"
    subprocess.run([sys.executable, str(GENCAM), "4000", str(prog), str(seed)], check=True, capture_output=True)
    for kw in ({"step_mm": 0.5}, {"chord_mm": 1e-5}, {"step_mm": 0.5, "chord_mm": 1e-5}, {"step_mm": 20.0}):
        assert_same(str(prog), BENCH, **kw)
    assert sum(n for _l, n, _a in runs) > 1000


def test_an_expanded_loop_numbers_each_pass_as_its_line(runs):
    text = ("G21 G90\nG0 X0 Y0 Z5\nG1 X1 F100\nX2\n#1 = 0\no101 repeat [3]\n#1 = [#1 + 1]\nG1 X[10 + #1] Y#1\n"
            "X[20 + #1]\no101 endrepeat\nG1 X0 Y0\nX1\nM30\n")
    pp = assert_same(text, step_mm=0.5)
    ends = {ln: int((pp.lineno == ln).sum()) for ln in sorted(set(pp.lineno.tolist()))}
    assert sorted(ends) == [2, 3, 4, 8, 9, 11, 12]
    # each pass of the loop's two moves is numbered by its line; the last pass ends at (23, 3)
    assert pp.points_mm[pp.lineno == 9][-1].tolist() == [23.0, 3.0, 5.0]
    assert pp.lineno[-1] == 12
