"""A program corrected in two processes (postproc.gcode.split) is the program one process
writes: the same bytes, report and errors, whether the child's part is taken or the
state at the cut disagrees and this process goes on alone."""

from __future__ import annotations

import dataclasses
import math
import multiprocessing

import numpy as np
import pytest

from postproc.calfile import load_calibration
from postproc.errors import PostprocError
from postproc.gcode import forking, split
from postproc.gcode.interp import NeedsExpansion
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, Corrector, CorrectReport, correct_file
from tests.conftest import PARAMETRIC, ROOT

pytestmark = pytest.mark.skipif(not forking.available(), reason="splitting a run needs fork (Linux)")

STATIC = ROOT / "calibrations" / "s500_static.json"
SETUP = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={t: 0.0 for t in range(1, 5)})


@pytest.fixture(scope="module")
def engines():
    return {"static": load_calibration(STATIC).engine, "parametric": load_calibration(PARAMETRIC).engine}


def program(n_moves: int, seed: int, *, extra: dict[int, str] | None = None, ending: str = "\n") -> str:
    """A CAM-like program inside the S500 volume (G54 Z100): straight moves, arcs with
    centre words, tool changes with G43, comments, N numbers, feeds; ``extra``: lines put
    before move k."""
    rng = np.random.default_rng(seed)
    out = ["%", "O1000 (SPLIT TEST)", "G90 G21 G17 G40 G49 G80", "G54", "T1 M6", "S9000 M3",
           "G0 X150.000 Y150.000", "G0 G43 H1 Z25.000", "F1200"]
    x, y, z = 150.0, 150.0, -2.0
    out.append(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f}")
    tool = 1
    modal_arc = False
    for k in range(n_moves):
        if extra and k in extra:
            out.append(extra[k])
        r = rng.random()
        if r < 0.02:
            tool = tool % 4 + 1
            out += [f"(TOOL {tool})", "G0 Z25.000", f"T{tool} M6", f"G0 G43 H{tool} Z25.000",
                    f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f} F900"]
            modal_arc = False
        elif r < 0.17:
            # an arc about a centre 1-4 mm away, a quarter to half a turn
            rad = rng.uniform(1.0, 4.0)
            a0 = rng.uniform(0, 2 * math.pi)
            cx, cy = x - rad * math.cos(a0), y - rad * math.sin(a0)
            cw = rng.random() < 0.5
            a1 = a0 + (-1 if cw else 1) * rng.uniform(math.pi / 4, math.pi)
            ex, ey = round(cx + rad * math.cos(a1), 4), round(cy + rad * math.sin(a1), 4)
            if not (20 < ex < 290 and 20 < ey < 290):
                continue
            out.append(f"G{2 if cw else 3} X{ex:.4f} Y{ey:.4f} I{cx - x:.4f} J{cy - y:.4f}")
            x, y = ex, ey
            modal_arc = True
        elif r < 0.2:
            out.append(f"(PASS {k})")
        else:
            x = float(np.clip(x + rng.normal(0, 4), 30, 280))
            y = float(np.clip(y + rng.normal(0, 4), 30, 280))
            words = [f"X{x:.4f}", f"Y{y:.4f}"]
            if rng.random() < 0.3:
                z = float(np.clip(z + rng.normal(0, 1), -8, 0))
                words.append(f"Z{z:.4f}")
            head = f"N{10 * k} " if rng.random() < 0.2 else ""
            motion = "G1 " if modal_arc or rng.random() < 0.4 else ""
            modal_arc = False
            feed = f" F{rng.choice([800, 1200, 1500])}" if rng.random() < 0.05 else ""
            out.append(head + motion + " ".join(words) + feed)
    out += ["G0 Z25.000", "M5", "M30", "%"]
    return ending.join(out) + ending


def correct(tmp_path, text: str, engine, processes: int, chunk: int, name: str = "p.nc", **options):
    src = tmp_path / name
    src.write_bytes(text.encode())
    dst = tmp_path / f"out{processes}_{name}"
    rep = correct_file(src, dst, engine, SETUP, CorrectOptions(processes=processes, chunk_lines=chunk, **options))
    return dst.read_bytes(), rep


def _returns(monkeypatch, name: str) -> list:
    """What ``split.<name>`` returns, call by call (it is wrapped to record it)."""
    seen: list = []
    function = getattr(split, name)

    def record(*args):
        seen.append(function(*args))
        return seen[-1]

    monkeypatch.setattr(split, name, record)
    return seen


@pytest.fixture
def agreements(monkeypatch):
    """The decisions at the cut (True: the child's part taken)."""
    return _returns(monkeypatch, "_agree")


@pytest.mark.parametrize(("cal", "chunk"), [("static", 40), ("static", 97), ("parametric", 40)])
def test_two_processes_write_what_one_writes(tmp_path, engines, agreements, cal, chunk):
    text = program(900, seed=3)
    one = correct(tmp_path, text, engines[cal], 1, chunk)
    two = correct(tmp_path, text, engines[cal], 2, chunk)
    assert agreements == [True]  # the child's part was taken
    assert two[0] == one[0]
    assert two[1] == one[1]
    assert not multiprocessing.active_children()


def test_crlf_endings_and_a_cut_at_every_share(tmp_path, engines, agreements, monkeypatch):
    text = program(600, seed=5, ending="\r\n")
    one = correct(tmp_path, text, engines["static"], 1, 30)
    for share in (0.0, 0.4, 0.7):  # where the program is cut moves with the read share
        monkeypatch.setattr(split, "READ_SHARE_AFFINE", share)
        assert correct(tmp_path, text, engines["static"], 2, 30) == one
    assert agreements == [True, True, True]


def test_a_state_that_disagrees_leaves_the_run_to_this_process(tmp_path, engines, monkeypatch):
    text = program(700, seed=7)
    one = correct(tmp_path, text, engines["static"], 1, 40)
    monkeypatch.setattr(split, "_agree", lambda *args: False)
    assert correct(tmp_path, text, engines["static"], 2, 40) == one
    assert not multiprocessing.active_children()


@pytest.fixture
def plans(monkeypatch):
    """The cuts and the lines the children go on reading from (split.plan)."""
    return _returns(monkeypatch, "plan")


@pytest.mark.parametrize("cal", ["static", "parametric"])
def test_a_child_skips_to_the_last_tool_change_before_its_warm_up(tmp_path, engines, agreements, plans, cal):
    text = program(900, seed=3)
    one = correct(tmp_path, text, engines[cal], 1, 40)
    two = correct(tmp_path, text, engines[cal], 2, 40)
    [(at, go)] = plans
    warm_up = at[0] - split.WARMUP_CHUNKS * 40
    lines = text.splitlines()
    assert 2 * 40 < go[0] <= warm_up
    assert "M6" in lines[go[0] - 1]
    assert not any("M6" in line for line in lines[go[0]:warm_up])
    assert agreements == [True]
    assert two == one


def _one_tool(n_moves: int, extra: dict[int, str]) -> str:
    """A program with one tool: feed moves, a rapid every 25 moves, ``extra`` before move k."""
    out = ["%", "G90 G21 G17 G40 G49 G80", "G54", "T1 M6", "G0 X150 Y150", "G0 G43 H1 Z25", "G1 Z-2 F700"]
    for k in range(n_moves):
        out.append(extra.get(k, ""))
        x, y = 150 + 40 * math.sin(k / 9.0), 150 + 40 * math.cos(k / 7.0)
        out.append(f"G0 X{x:.3f} Y{y:.3f} Z2" if k % 25 == 0 else f"G1 X{x:.3f} Y{y:.3f} Z-2")
    out += ["M30", "%"]
    return "\n".join(line for line in out if line) + "\n"


def test_a_state_the_skipped_lines_left_is_caught_at_the_cut(tmp_path, engines, agreements, plans):
    # G49 (tool length off, for good) is no word the scan looks for: the child skips it and
    # reaches the cut with the tool length on; the states differ and this process goes on
    # alone, with the same output
    text = _one_tool(900, {300: "G49"})
    one = correct(tmp_path, text, engines["static"], 1, 40)
    two = correct(tmp_path, text, engines["static"], 2, 40)
    [(_at, go)] = plans
    assert go[0] > text.splitlines().index("G49") + 1  # a rapid after it
    assert agreements == [False]
    assert two == one


def test_a_durable_word_before_the_warm_up_is_read(tmp_path, engines, agreements, plans):
    text = _one_tool(900, {300: "G92 X145 Y145", 310: "G92.1"})
    one = correct(tmp_path, text, engines["static"], 1, 40)
    two = correct(tmp_path, text, engines["static"], 2, 40)
    [(_at, go)] = plans
    assert 0 < go[0] <= text.splitlines().index("G92 X145 Y145") + 1
    assert agreements == [True]
    assert two == one


@pytest.mark.parametrize("z_on_every_line", [True, False])
def test_an_axis_that_never_moves_in_the_window(tmp_path, engines, agreements, z_on_every_line):
    # Z moves once, at the start. Named on every line (as some posts write every axis),
    # it is known at the cut: the direction it last moved in is carried through the part
    # read without correcting, and the cut agrees. Named only at the start, the child
    # (which corrected no line naming Z) takes the machine to be at its nominal Z, as a
    # run does at the program's start: the correction there differs from it by more than
    # half a step, so the window's lines get the Z words the one process writes, and the
    # cut agrees too (it never did while the child took Z to be unknown: no word is
    # added for an axis never positioned)
    z = " Z-1" if z_on_every_line else ""
    lines = ["G90 G21 G54", "G0 X100 Y100 Z20", "G1 Z-1 F500"] + [
        f"G1 X{100 + 50 * math.sin(k / 9):.4f} Y{100 + 50 * math.cos(k / 7):.4f}{z}" for k in range(400)] + ["M30"]
    text = "\n".join(lines) + "\n"
    one = correct(tmp_path, text, engines["static"], 1, 20)
    assert correct(tmp_path, text, engines["static"], 2, 20) == one
    assert agreements == [True]


def _error(tmp_path, text, engine, processes, chunk, **options):
    with pytest.raises(PostprocError) as info:
        correct(tmp_path, text, engine, processes, chunk, **options)
    assert not (tmp_path / f"out{processes}_p.nc").exists()  # nothing half-written
    return str(info.value), type(info.value)


@pytest.mark.parametrize("where", [50, 800])  # before the cut (this process's) and after (the child's)
def test_an_error_is_the_one_one_process_raises(tmp_path, engines, where):
    text = program(900, seed=11, extra={where: "G1 X20000 Y150"})  # far outside the calibrated volume
    one = _error(tmp_path, text, engines["static"], 1, 40)
    assert _error(tmp_path, text, engines["static"], 2, 40) == one
    assert f":{text.splitlines().index('G1 X20000 Y150') + 1}:" in one[0]
    assert not multiprocessing.active_children()


def test_an_unsupported_code_after_the_cut(tmp_path, engines):
    text = program(900, seed=13, extra={820: "G1 X150 Y150 G41 D1"})
    one = _error(tmp_path, text, engines["parametric"], 1, 40)
    assert _error(tmp_path, text, engines["parametric"], 2, 40) == one


def test_a_program_needing_expansion_after_the_cut_is_expanded(tmp_path, engines, agreements):
    text = program(900, seed=17, extra={850: "#1 = 150.0\nG1 X#1 Y150"})
    one = correct(tmp_path, text, engines["static"], 1, 40)
    two = correct(tmp_path, text, engines["static"], 2, 40)
    assert two == one
    assert one[1].expanded
    assert agreements == [True]  # the child's part was taken, and raised NeedsExpansion
    assert issubclass(NeedsExpansion, PostprocError)


def test_a_short_program_stays_in_one_process(tmp_path, engines, agreements):
    text = program(100, seed=19)
    assert correct(tmp_path, text, engines["static"], 2, 40) == correct(tmp_path, text, engines["static"], 1, 40)
    assert agreements == []
    assert split.cuts(split.MIN_CHUNKS * 40 - 1, 40, True, 2) is None


def test_the_cut_balances_the_two_parts():
    at = split.cuts(1_000_000, 20_000, True, 2)
    assert len(at) == 1
    s = at[0]
    w = s - split.WARMUP_CHUNKS * 20_000  # where the child starts correcting (run's window)
    r = split.READ_SHARE_AFFINE
    # this process corrects S lines; the child reads W and corrects the rest
    assert abs(s - (r * w + (1_000_000 - w))) < 2


def test_every_report_field_merges():
    fields = {f.name: f for f in dataclasses.fields(CorrectReport)}
    named = split._TAKE_TAIL | split._LARGEST | split._SAME | split._COMBINED
    assert named <= set(fields)
    for name in set(fields) - named:  # the rest are counts
        assert fields[name].type in ("int", int), name
    head = CorrectReport(lines_in=100, lines_out=110, moves=50, max_correction_mm=0.2, header_lines=8,
                         solver="newton", max_residual_mm=1e-9, g54_assumed_zero=False)
    tail = CorrectReport(lines_in=300, lines_out=200, moves=120, max_correction_mm=0.3, solver="newton",
                         max_residual_mm=1e-10, g54_assumed_zero=True)
    both = split.merge(head, tail)
    assert (both.lines_in, both.lines_out, both.moves, both.header_lines) == (300, 310, 170, 8)
    assert (both.max_correction_mm, both.max_residual_mm, both.g54_assumed_zero) == (0.3, 1e-9, True)


def test_the_state_compared_is_data(engines):
    c = Corrector(engines["parametric"], SETUP, CorrectOptions())
    state = split.state_of(c)
    assert state == split.state_of(Corrector(engines["parametric"], SETUP, CorrectOptions()))
    c.writer.qe[0] = 1.0  # what the controller holds (the writer's)
    assert state != split.state_of(c)
    c.writer.qe[0] = Corrector(engines["parametric"], SETUP, CorrectOptions()).writer.qe[0]
    c.planner.dirs[1] = -1.0  # the directions carried (the planner's)
    assert state != split.state_of(c)
    nan = split._canon(float("nan"))
    assert nan == split._canon(float("nan"))
    assert split._canon(-0.0) != split._canon(0.0)
    with pytest.raises(TypeError):
        split._canon(lambda: None)


def test_count_lines(tmp_path):
    for text, n in (("", 0), ("a", 1), ("a\n", 1), ("a\nb", 2), ("a\r\nb\r\n", 2)):
        (tmp_path / "f").write_bytes(text.encode())
        assert split.count_lines(str(tmp_path / "f")) == n


def test_chunks_read_without_correcting_let_go_of_their_blocks(engines, monkeypatch):
    # the run disables the cyclic collector: a block whose runs still point back to it
    # would stay in memory for good (the reading child's memory grew with the program)
    import weakref

    from postproc.gcode import bulk
    from postproc.gcode.lexer import split_lines

    alive: weakref.WeakSet = weakref.WeakSet()
    scan = bulk.scan

    def counting(lines):
        block = scan(lines)
        if block is not None:
            alive.add(block)
        return block

    monkeypatch.setattr(bulk, "scan", counting)
    seen = []

    def boundary(n: int) -> bool:
        seen.append(len(alive))
        return False

    c = Corrector(engines["static"], SETUP, CorrectOptions(chunk_lines=40))
    c.run(split_lines(program(900, seed=23)), lambda _text: None, skip_until=10**9, boundary=boundary)
    assert len(seen) > 10
    assert max(seen) <= 1


# state the cut must carry: an offset set from where the machine is (G92), incremental
# moves, inch units, a cycle kept or expanded, a stored G28 position, a tool change
FEATURES = {
    "g92": "G92 X10 Y10\nG1 X150 Y150\nG92.1",
    "g91": "G91\nG1 X1.5 Y-2.25\nG1 X-1.5 Y2.25\nG90",
    "inch": "G20\nG1 X5.9 Y5.9\nG21",
    "cycle": "G0 Z5\nG81 X140 Y140 Z-3 R2 F100\nX150\nY150\nG80",
    "g28": "G28.1\nG0 Z20\nG28 Z20",
}


def outcome(tmp_path, text, engine, processes, chunk, **options):
    """(output, report) of a correction, or the error's type and message."""
    try:
        return correct(tmp_path, text, engine, processes, chunk, **options)
    except PostprocError as exc:
        return type(exc).__name__, str(exc)


@pytest.mark.parametrize("feature", sorted(FEATURES))
@pytest.mark.parametrize("at", [300, 780])  # across the cut (state carried), after it (the child's)
def test_features_around_the_cut(tmp_path, engines, agreements, feature, at):
    text = program(900, seed=29, extra={at: FEATURES[feature], at + 5: FEATURES[feature]})
    for options in ({}, {"cycles": "expand"}) if feature == "cycle" else ({},):
        one = outcome(tmp_path, text, engines["parametric"], 1, 40, **options)
        two = outcome(tmp_path, text, engines["parametric"], 2, 40, **options)
        assert two == one
    if feature == "g28" and at == 300:
        # the controller stored the corrected position before the cut: the child, which did
        # not correct that line, cannot know it; this process goes on alone
        assert agreements == [False]
    else:
        assert agreements
        assert all(agreements)


def test_a_child_that_fails_leaves_the_run_to_one_process(tmp_path, engines, agreements, monkeypatch):
    # a failure of the child's own (not the program's) after the cut: the program is
    # corrected again in one process, to the same output
    import os

    parent = os.getpid()
    calls = []
    chunk = Corrector._chunk

    def failing(self, entries, write):
        if os.getpid() != parent:
            calls.append(1)
            if len(calls) > split.WARMUP_CHUNKS + 1:
                raise OSError(28, "No space left on device")
        return chunk(self, entries, write)

    monkeypatch.setattr(Corrector, "_chunk", failing)
    text = program(900, seed=31)
    one = correct(tmp_path, text, engines["static"], 1, 40)
    assert correct(tmp_path, text, engines["static"], 2, 40) == one
    assert agreements == [True]
    assert not multiprocessing.active_children()


def test_progress_goes_on_through_the_second_part(tmp_path, engines, agreements):
    text = program(900, seed=37)
    src = tmp_path / "p.nc"
    src.write_text(text)
    counts: dict[int, list[int]] = {1: [], 2: []}
    for processes in (1, 2):
        correct_file(src, tmp_path / "o.nc", engines["static"], SETUP,
                     CorrectOptions(processes=processes, chunk_lines=40), progress=counts[processes].append)
    assert agreements == [True]
    assert counts[2] == sorted(counts[2])
    assert counts[2][-1] == counts[1][-1] == len(text.splitlines())
    assert len(counts[2]) > 10


# -- more than two processes -----------------------------------------------------------------
def test_three_and_four_processes_write_what_one_writes(tmp_path, engines, monkeypatch):
    starts: list[object] = []
    starts_at = split._starts_at

    def record(recv, end):
        starts.append(starts_at(recv, end))
        return starts[-1]

    monkeypatch.setattr(split, "_starts_at", record)
    text = program(1500, seed=41)
    monkeypatch.setattr(split, "MIN_GAIN", 0.0)  # as many processes as asked (parts of a window at least)
    for cal in ("static", "parametric"):
        one = correct(tmp_path, text, engines[cal], 1, 40)
        for processes in (3, 4):
            starts.clear()
            assert correct(tmp_path, text, engines[cal], processes, 40) == one
            assert starts == [True] * (processes - 1)  # every cut agreed
    assert not multiprocessing.active_children()


def test_a_later_cut_that_disagrees_corrects_again_in_one_process(tmp_path, engines, monkeypatch):
    text = program(1500, seed=43)
    one = correct(tmp_path, text, engines["static"], 1, 40)
    monkeypatch.setattr(split, "MIN_GAIN", 0.0)  # three processes, two cuts
    starts: list[bool] = []
    starts_at = split._starts_at

    def first_only(recv, end):  # the first cut as it is, the second taken as disagreeing
        starts.append(starts_at(recv, end) if not starts else False)
        return starts[-1]

    monkeypatch.setattr(split, "_starts_at", first_only)
    assert correct(tmp_path, text, engines["static"], 3, 40) == one
    assert starts == [True, False]
    assert not multiprocessing.active_children()


@pytest.mark.parametrize("where", [100, 700, 1300])  # in the first, second and third part
def test_an_error_in_any_of_three_parts(tmp_path, engines, where):
    text = program(1500, seed=47, extra={where: "G1 X20000 Y150"})
    assert _error(tmp_path, text, engines["static"], 3, 40) == _error(tmp_path, text, engines["static"], 1, 40)
    assert not multiprocessing.active_children()


def test_cuts_share_the_work(monkeypatch):
    monkeypatch.setattr(split, "MIN_GAIN", 0.0)
    for affine, chunk in ((True, 5000), (False, 2000)):
        r = split.READ_SHARE_AFFINE if affine else split.READ_SHARE_SAMPLED
        window = split.WARMUP_CHUNKS * chunk
        for k in (2, 3, 4):
            at = split.cuts(1_000_000, chunk, affine, k)
            assert at == sorted(at)
            assert len(at) == k - 1
            ends = [*at, 1_000_000]
            # every process: the same cost (reading W_j at r, correcting the rest of its part)
            costs = [at[0]] + [r * (s - window) + (e - (s - window)) for s, e in zip(at, ends[1:], strict=False)]
            assert max(costs) - min(costs) < 2
    assert split.cuts(split.MIN_CHUNKS * 5000 - 1, 5000, True, 4) is None
    assert len(split.cuts(split.MIN_CHUNKS * 5000, 5000, True, 4)) == 1  # parts of a window at least


def test_the_command_cuts_a_large_program_unless_told_j_1(tmp_path, agreements):
    from click.testing import CliRunner

    from postproc.cli import main

    text = program(38_000, seed=53)
    assert len(text.splitlines()) >= split.MIN_CHUNKS * 5000
    src = tmp_path / "big.nc"
    src.write_text(text)
    outs = {}
    for jobs in ("1", "2"):
        dst = tmp_path / f"big_{jobs}.nc"
        r = CliRunner().invoke(main, ["correct", str(src), "-c", str(STATIC), "-o", str(dst), "-j", jobs,
                                      "--offset", "G54=X0,Y0,Z100", *[a for t in range(1, 5)
                                                                      for a in ("--tool-length", f"{t}=0")]])
        assert r.exit_code == 0, r.output
        outs[jobs] = (dst.read_bytes(), r.output.replace(dst.name, "OUT"))
    assert outs["2"] == outs["1"]  # the same program and the same summary
    assert agreements == [True]


def test_a_program_that_changes_while_it_is_read_is_refused(tmp_path, engines, agreements, monkeypatch):
    # every process opens the file itself: parts of two versions must not be joined
    seen = iter(range(100))
    monkeypatch.setattr(split, "_identity", lambda path: next(seen))
    text = program(900, seed=59)
    message, kind = _error(tmp_path, text, engines["static"], 2, 40)
    assert "changed while it was being corrected" in message
    assert agreements == [True]


def test_bytes_that_are_not_utf8_after_the_cut(tmp_path, engines, agreements):
    # a comment in Latin-1 on either side of the cut: the parts go through files of their
    # own and come back byte for byte
    text = program(900, seed=61, extra={100: "(CAF\u00c9 1)", 800: "(CAF\u00c9 2)"})
    src = tmp_path / "p.nc"
    src.write_bytes(text.encode("latin-1"))
    outs = []
    for processes in (1, 2):
        dst = tmp_path / f"o{processes}.nc"
        correct_file(src, dst, engines["static"], SETUP, CorrectOptions(processes=processes, chunk_lines=40))
        outs.append(dst.read_bytes())
    assert outs[0] == outs[1]
    assert b"(CAF\xc9 2)" in outs[1]
    assert agreements == [True]


@pytest.mark.parametrize("cal", ["static", "parametric"])
def test_incremental_moves_across_the_cut(tmp_path, engines, agreements, cal):
    # G91 for the whole program: an incremental word is the corrected target less the
    # position written before it, which a child (that corrected nothing before its
    # window) cannot know: it gives up, and this process corrects the whole program
    rng = np.random.default_rng(67)
    lines = ["G90 G21 G54", "G0 X150 Y150 Z5", "G1 Z-1 F800", "G91"]
    for k in range(1200):
        dx, dy = rng.normal(0, 0.7, 2)
        lines.append(f"G1 X{dx:.4f} Y{dy:.4f}" + (f" Z{(-1) ** k * 0.05:.3f}" if k % 7 == 0 else ""))
    lines += ["G90", "G0 Z20", "M30"]
    text = "\n".join(lines) + "\n"
    one = correct(tmp_path, text, engines[cal], 1, 40)
    assert correct(tmp_path, text, engines[cal], 2, 40) == one
    assert agreements == [False]


def test_no_process_to_be_had(tmp_path, engines, monkeypatch):
    # a fork that fails (too many processes, no memory): one process corrects the program
    text = program(900, seed=71)
    one = correct(tmp_path, text, engines["static"], 1, 40)

    def refuse(self):
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(multiprocessing.get_context("fork").Process, "start", refuse)
    assert correct(tmp_path, text, engines["static"], 3, 40) == one


def test_a_process_is_added_only_where_it_gains(monkeypatch):
    # each child repeats the reading of the program before its part: with an affine
    # calibration read at 0.5 of correcting (the uncompiled reader's share) a fourth
    # process would shorten the first part by less than MIN_GAIN, at 0.3 (the compiled
    # one's) a fifth; with a sampled one (0.1) six processes still gain
    monkeypatch.setattr(split, "READ_SHARE_AFFINE", 0.5)
    assert len(split.cuts(1_000_000, 5000, True, 64)) + 1 == 3
    monkeypatch.setattr(split, "READ_SHARE_AFFINE", 0.3)
    assert len(split.cuts(1_000_000, 5000, True, 64)) + 1 == 4
    sampled = split.cuts(1_000_000, 2000, False, 64)
    assert len(sampled) + 1 == 6
    more = split.cuts(1_000_000, 2000, False, 7)
    assert more == sampled  # a seventh would gain less than MIN_GAIN
    assert len(split.cuts(10_000_000, 2000, False, 64)) + 1 <= split.MAX_PROCESSES


def test_a_parent_killed_outright_leaves_no_child(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    src = tmp_path / "big.nc"
    src.write_text(program(110_000, seed=73))
    cmd = [sys.executable, "-m", "postproc", "correct", str(src), "-c", str(STATIC), "-o", str(tmp_path / "o.nc"),
           "-j", "2", "--offset", "G54=X0,Y0,Z100", *[a for t in range(1, 5) for a in ("--tool-length", f"{t}=0")]]
    parent = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children: list[str] = []
    deadline = time.monotonic() + 30
    while not children and parent.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
        try:
            children = Path(f"/proc/{parent.pid}/task/{parent.pid}/children").read_text().split()
        except OSError:
            pass
    if not children:
        parent.kill()
        parent.wait()
        pytest.skip("the run ended before its second process could be seen")
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(os.path.exists(f"/proc/{c}") for c in children):
        time.sleep(0.05)
    assert not any(os.path.exists(f"/proc/{c}") for c in children)
    assert not (tmp_path / "o.nc").exists()


@pytest.mark.parametrize("arcs", ["r", "ij"])
def test_the_warm_up_starts_where_the_program_put_the_machine(engines, arcs):
    # A child reads without correcting up to its warm-up window, then corrects from the
    # last nominal position, uncorrected, as a run does from the program's start: not
    # from the start position, nor from no position on an axis the window never names
    # (Z here, set once at the start: every fit in the window started from an unknown Z,
    # split every move and asked for the engine's subdivision at each sample, and the
    # window cost many times the part it prepares)
    from postproc.gcode.lexer import split_lines

    out = ["G90 G21 G54", "G0 X190 Y150 Z20", "G1 Z-1 F500"]
    rad, ang = 40.0, 0.0  # arcs about (150, 150), a step out or in between them
    for k in range(300):
        x, y = 150 + rad * math.cos(ang), 150 + rad * math.sin(ang)
        ang += 0.3
        ex, ey = 150 + rad * math.cos(ang), 150 + rad * math.sin(ang)
        centre = f"R{rad:.4f}" if arcs == "r" else f"I{150 - x:.4f} J{150 - y:.4f}"
        out.append(f"G3 X{ex:.4f} Y{ey:.4f} {centre}")
        rad = 40.5 if k % 2 == 0 else 40.0
        out.append(f"G1 X{150 + rad * math.cos(ang):.4f} Y{150 + rad * math.sin(ang):.4f}")
    text = "\n".join(out + ["M30"]) + "\n"
    whole = Corrector(engines["parametric"], SETUP, CorrectOptions(chunk_lines=40))
    whole.run(split_lines(text), lambda _text: None)
    child = Corrector(engines["parametric"], SETUP, CorrectOptions(chunk_lines=40))
    written = []
    child.run(split_lines(text), written.append, skip_until=400)
    assert written  # it corrected from line 400 on
    assert not any(math.isnan(v) for v in child.writer.qe)
    assert child.report.lines_inserted <= whole.report.lines_inserted + 2
