"""postproc diff: blocks moved, per-axis corrections, inserted and unchanged lines."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.compare import compare_programs
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CASES = ROOT / "tests" / "cases"


def test_diff_counts_match_what_correct_reported():
    cal = load_calibration(CASES / "strong_static.json")
    text = (CASES / "arcs_linearised.nc").read_text()
    out, rep = correct_text(text, cal.engine, Setup(), CorrectOptions())
    d = compare_programs(text, out)
    assert d.lines_inserted == rep.lines_inserted
    assert d.moves == rep.moves
    assert len(d.moved) == rep.moves
    assert d.lines_unchanged == len(text.splitlines()) - rep.moves
    # end points moved by at most the largest correction the pipeline applied anywhere
    biggest = max(m.size_mm for m in d.moved)
    assert 0.9 * rep.max_correction_mm < biggest <= rep.max_correction_mm + 1e-4


def test_diff_of_identity_correction_moves_nothing():
    text = (ROOT / "samples" / "pocket.nc").read_text()
    out, _ = correct_text(text, IdentityEngine([[-1e4] * 3, [1e4] * 3]), Setup())
    d = compare_programs(text, out)
    assert d.moved == []
    assert d.lines_inserted == 0
    assert d.lines_unchanged == len(text.splitlines())
    assert all(v["max_mm"] == 0.0 for v in d.axis_stats().values())


def test_diff_per_axis_statistics():
    cal = load_calibration(CASES / "demo_static.json")
    text = (ROOT / "samples" / "pocket.nc").read_text()
    out, _ = correct_text(text, cal.engine, Setup())
    d = compare_programs(text, out)
    deltas = np.array([m.delta_mm for m in d.moved])
    stats = d.axis_stats()
    for k, a in enumerate("XYZ"):
        assert stats[a]["max_mm"] == pytest.approx(np.abs(deltas[:, k]).max())
        assert stats[a]["mean_mm"] == pytest.approx(np.abs(deltas[:, k]).mean())
    assert stats["X"]["max_mm"] > 0.03  # r_O1 x = 35 um dominates


def test_diff_keeping_only_the_largest_blocks_reports_what_keeping_all_does():
    """With ``keep``, memory holds the largest blocks only (pruned many times here); the
    largest blocks, ties in the original's order, and the per-axis figures are the same."""
    from postproc.gcode.compare import DiffReport

    rng = np.random.default_rng(20261126)
    full, kept = DiffReport("a", "b"), DiffReport("a", "b", keep=15)
    line = 1
    for size in rng.integers(1, 30_000, size=40):
        deltas = np.round(rng.normal(0.0, 0.05, size=(size, 3)), 4)  # rounded: many equal sizes
        deltas[rng.integers(0, size, size=3)] = [0.2, -0.1, 0.0]  # ties among the largest
        linenos = np.arange(line, line + size)
        line += size
        for rep in (full, kept):
            if size % 7 == 0:  # one at a time, as the slow pairing adds them
                for a, d in zip(linenos.tolist(), deltas.tolist(), strict=True):
                    rep.add_moved(a, a + 5, d)
            else:
                rep.add_moved_rows(linenos, linenos + 5, deltas)
    assert kept.n_moved == full.n_moved == line - 1
    assert len(kept._lines) <= max(8 * 15, 65_536) + 30_000
    assert kept.largest(15) == full.largest(15)
    assert kept.largest(3) == full.largest(3)
    stats, exact = kept.axis_stats(), full.axis_stats()
    for a in "XYZ":
        assert stats[a]["max_mm"] == exact[a]["max_mm"]
        assert stats[a]["mean_mm"] == pytest.approx(exact[a]["mean_mm"], rel=1e-12)
    with pytest.raises(ValueError, match="15 largest"):
        kept.moved  # noqa: B018
    with pytest.raises(ValueError, match="15 largest"):
        kept.largest(16)


def test_the_largest_blocks_are_the_first_of_a_stable_sort_by_size():
    # found without sorting them all: the same rows, ties in the order they came in
    from postproc.gcode.compare import DiffReport

    rng = np.random.default_rng(20261127)
    for trial in range(200):
        m = int(rng.integers(1, 2000))
        deltas = np.round(rng.normal(0.0, 1.0, size=(m, 3)), int(rng.integers(0, 3)))  # ties
        if trial % 4 == 0:
            deltas[:] = deltas[0]  # all equal
        rep = DiffReport("a", "b")
        rep.add_moved_rows(np.arange(m), np.arange(m), deltas)
        want = np.argsort(-np.linalg.norm(deltas, axis=1), kind="stable")
        for n in (1, 2, 7, m - 1, m, m + 3):
            assert np.array_equal(rep._largest_order(n), want[:n]), (trial, n)


def test_cli_diff_text_report_equals_the_full_comparison(tmp_path):
    """The text report keeps only the blocks it lists; its figures are those of --json."""
    cal = load_calibration(CASES / "demo_static.json")
    text = (ROOT / "samples" / "pocket.nc").read_text()
    out, _ = correct_text(text, cal.engine, Setup())
    (tmp_path / "o.nc").write_text(text)
    (tmp_path / "c.nc").write_text(out)
    args = ["diff", str(tmp_path / "o.nc"), str(tmp_path / "c.nc")]
    short, every = CliRunner().invoke(main, args), CliRunner().invoke(main, [*args, "--all"])
    assert short.exit_code == every.exit_code == 0, short.output + every.output
    full = compare_programs(text, out)
    listed = [line for line in short.output.splitlines() if line.strip().startswith("line ")]
    assert len(listed) == min(15, full.n_moved)
    for m, row in zip(full.largest(15), listed, strict=True):
        assert row.split(":")[0].split() == ["line", str(m.lineno), "->", str(m.lineno_corrected)]
    per_axis = [line for line in short.output.splitlines() if "correction per axis" in line]
    assert per_axis == [line for line in every.output.splitlines() if "correction per axis" in line]


def test_cli_diff_text_and_json(tmp_path):
    out = tmp_path / "o.nc"
    r = CliRunner().invoke(main, ["correct", str(CASES / "arcs_linearised.nc"), "-c",
                                  str(CASES / "strong_static.json"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["diff", str(CASES / "arcs_linearised.nc"), str(out)])
    assert r.exit_code == 0, r.output
    assert "inserted by segmentation" in r.output
    assert "correction per axis" in r.output
    r = CliRunner().invoke(main, ["diff", str(CASES / "arcs_linearised.nc"), str(out), "--json"])
    data = json.loads(r.output)
    assert data["lines_inserted"] == 3  # one inserted exact arc per ellipse-like corrected arc (was > 100 chords)
    assert data["moves_moved"] == 7
    assert set(data["per_axis"]) == {"X", "Y", "Z"}


def test_diff_of_unrelated_programs_is_an_error():
    a = (ROOT / "samples" / "pocket.nc").read_text()
    b = (ROOT / "samples" / "holes_g91.nc").read_text()
    with pytest.raises(PostprocError):
        compare_programs(a, b)


def test_diff_pairs_steps_shorter_than_the_correction():
    from postproc.engine.static import StaticEngine

    # 0.01 mm steps, 0.2 mm correction: the nearest corrected end point of a step is
    # usually another step's; pairing must still find each step's own line
    eng = StaticEngine(np.eye(3), [0.2, -0.1, 0.05], [[0, 0, 0], [315, 315, 315]])
    text = "G21 G90 G0 X10 Y10 Z10\n" + "".join(f"G1 X{10 + 0.01 * i:.2f}\n" for i in range(1, 400)) + "M2\n"
    out, rep = correct_text(text, eng, Setup())
    d = compare_programs(text, out)
    assert d.moves == rep.moves
    np.testing.assert_allclose(np.array([m.delta_mm for m in d.moved]), [[-0.2, 0.1, -0.05]] * d.n_moved,
                               atol=1e-9)
    n_header = len(emit.split_header(out)[0])
    assert [m.lineno for m in d.moved] == [m.lineno_corrected - n_header for m in d.moved]


def test_diff_of_a_twice_corrected_program_skips_both_headers():
    cal = load_calibration(CASES / "demo_static.json")
    text = (ROOT / "samples" / "pocket.nc").read_text()
    once, _ = correct_text(text, cal.engine, Setup())
    twice, _ = correct_text(once, cal.engine, Setup(), CorrectOptions(force=True))
    d = compare_programs(text, twice)
    assert d.moves == 26


def _cam_program(rng: np.random.Generator, n: int) -> str:
    """A CAM-like program: straight moves (modal and not), arcs, N numbers, comments,
    coolant lines, tool changes with G43, an inch stretch, a G91 stretch and G28."""
    out = ["%", "O1000 (TEST)", "G90 G21 G17 G40 G49 G80", "G54", "T1 M6", "G0 X100 Y100", "G0 G43 H1 Z20",
           "F1500"]
    x, y, tool, mode = 100.0, 100.0, 1, "G0"
    while len(out) < n:
        r = rng.random()
        pre = f"N{len(out) * 10} " if rng.random() < 0.2 else ""
        if r < 0.6:
            x, y = x + rng.uniform(-2, 2), y + rng.uniform(-2, 2)
            z = f" Z{rng.uniform(-5, 0):.3f}" if rng.random() < 0.3 else ""
            out.append(pre + ("G1 " if mode != "G1" or rng.random() < 0.3 else "") + f"X{x:.4f} Y{y:.4f}{z}")
            mode = "G1"
        elif r < 0.75:
            i, j = rng.uniform(-3, 3), rng.uniform(-3, 3)
            cx, cy = x + i, y + j
            rad = float(np.hypot(i, j))
            a = np.arctan2(-j, -i) + rng.uniform(0.3, 2.0)
            x, y = cx + rad * np.cos(a), cy + rad * np.sin(a)
            out.append(pre + f"G3 X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}")
            mode = "G3"
        elif r < 0.82:
            out.append(rng.choice(["(PASS)", "; finishing", "M8", "S9000 M3", "M9"]))
        elif r < 0.85:
            tool = tool % 3 + 1
            out += [f"T{tool} M6 (TOOL {tool})", f"G0 G43 H{tool} Z20"]
            mode = "G0"
        elif r < 0.87:
            out += ["G91", "G1 X0.5 Y-0.25", "Z-0.1", "G90"]
            mode = "G1"
            x, y = x + 0.5, y - 0.25
        elif r < 0.89:
            out += ["G20", f"G1 X{x / 25.4:.5f} Y{y / 25.4:.5f}", "G21"]
            mode = "G1"
        else:
            x, y = x + rng.uniform(-8, 8), y + rng.uniform(-8, 8)
            out.append(pre + f"G0 X{x:.3f} Y{y:.3f} Z5.000")
            mode = "G0"
    out += ["G28 G91 Z0", "G90", "M30", "%"]
    return "\n".join(out) + "\n"


def _interpreter_ends(text: str, setup: Setup) -> tuple[list[bool], list[tuple]]:
    """For each line, as the interpreter reads it (lenient setup, as diff reads): whether
    it makes a move, and its end point (NaN for none)."""
    from postproc.gcode.interp import Interpreter

    interp = Interpreter(setup, None, lenient_setup=True)
    moves, ends = [], []
    for k, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = interp.feed_line(k, line)
        moves.append(mv is not None)
        ends.append(mv.q1 if mv is not None else (np.nan,) * 3)
    return moves, ends


def test_diff_reads_in_bulk_the_end_points_the_interpreter_reads(monkeypatch):
    from postproc.gcode import compare

    rng = np.random.default_rng(11)
    text = _cam_program(rng, 3000)
    setup = Setup(offsets={"G54": (10.0, 20.0, 30.0)}, tool_lengths={1: 50.0, 2: 60.0, 3: 70.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 300.0}})
    want_move, want_end = _interpreter_ends(text, setup)
    for chunk in (20_000, 97):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        parts = list(compare._Reader(text, setup, compare._Keys()).chunks())
        assert sum(len(p) for p in parts) == len(want_move)
        np.testing.assert_array_equal(np.concatenate([p.move for p in parts]), want_move)
        np.testing.assert_array_equal(np.concatenate([p.end for p in parts]), np.array(want_end))


def test_diff_reads_an_expanded_program_in_bulk_as_line_by_line(monkeypatch):
    # a LinuxCNC loop whose body is plain once substituted (runs read in bulk), with an arc
    # and a subroutine: each row numbered by its source line, the same rows as the
    # interpreter line by line gives
    from postproc.gcode import compare, reader

    text = ("G21 G90 G17\nG0 X0 Y0 Z10\n#1 = 0\no100 while [#1 LT 40]\nG1 X[#1] Y[#1 * 0.5] F300\n"
            "G1 X[#1 + 1] Y0\nG2 X[#1 + 3] Y0 I1 J0\nG0 Z[10 + #1 / 100]\n#1 = [#1 + 1]\no100 endwhile\n"
            "o200 sub\nG1 X[#1] Y[#1]\nG1 X5 Y5\no200 endsub\no200 call [3]\nG0 Z30\nM2\n")
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
    options = compare._ReadOptions(dialect="linuxcnc", expand=True)

    def rows(bulk_lane: bool, chunk: int) -> list:
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        monkeypatch.setattr(compare, "BLOCK_LINES", min(chunk, 5_000))
        rd = compare._Reader(text, setup, compare._Keys(), options)
        rd._rd.use_bulk = bulk_lane
        parts = list(rd.chunks())
        return [np.concatenate([getattr(p, k) for p in parts]) for k in ("lineno", "move", "end", "keys")]

    want = rows(False, 20_000)
    assert len(want[0]) == 40 * 4 + 2 + 2 + 2  # the passes, the lines before and after them, the call
    assert sorted(set(want[0][want[1]].tolist())) == [2, 5, 6, 7, 8, 12, 13, 16]
    spied = []
    monkeypatch.setattr(reader.LineReader, "queue_run", lambda self, run: (spied.append(len(run)),
                                                                            self.entries.append(run)))
    for chunk in (20_000, 37, 5):
        got = rows(True, chunk)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
    assert max(spied) >= 4  # read in runs, not line by line


def test_diff_lets_go_of_each_block_it_reads(monkeypatch):
    # a run refers to its block and the block to its runs; diff reads with the cyclic
    # garbage collector off, so each block read is let go of by hand (memory stays bounded)
    import gc

    from postproc.gcode import bulk, compare

    monkeypatch.setattr(compare, "CHUNK_LINES", 400)
    monkeypatch.setattr(compare, "BLOCK_LINES", 100)
    text = _cam_program(np.random.default_rng(5), 3000)
    was = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        reader = compare._Reader(text, Setup(offsets={"G54": (10.0, 20.0, 30.0)}), compare._Keys())
        chunks = reader.chunks()
        for k, rows in enumerate(chunks):
            assert len(rows)
            if k == 3:
                break
        chunks.close()
        held = [o for o in gc.get_objects() if type(o) is bulk.Block]
        assert len(held) <= 1, len(held)
    finally:
        if was:
            gc.enable()


def test_diff_reads_tool_changes_in_bulk_as_the_interpreter_does(monkeypatch):
    # a tool change alone on its line stays in a run read in bulk; the tool it
    # loads is the one a later G43 without H takes
    from postproc.gcode import compare

    text = ("G21 G90 G54\nT1 M6\nG0 G43 H1 Z50\nX10 Y10\nG1 X11 Y12 F500\nT2 M6 (D6 FLAT)\nX12 Y13\n"
            "N40 M06 T03\nX13\nG43 Z40\nX14 Y15\n(next)\nT1 M6 ; back\nX15\nG43\nX16 Z35\nM30\n")
    setup = Setup(offsets={"G54": (10.0, 20.0, 30.0)}, tool_lengths={1: 50.0, 2: 60.0, 3: 70.0})
    _moves, want_end = _interpreter_ends(text, setup)
    assert want_end[9][2] != want_end[2][2]  # G43 without H took tool 3's length
    for chunk in (20_000, 5, 1):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        parts = list(compare._Reader(text, setup, compare._Keys()).chunks())
        np.testing.assert_array_equal(np.concatenate([p.end for p in parts]), np.array(want_end))


def test_diff_reads_g43_lines_and_axis_words_in_any_order_in_bulk_as_the_interpreter_does(monkeypatch):
    # a move that sets the tool length (G43 H..) starts a run of its own; a line with axis
    # words out of X, Y, Z order (the words correct adds: Z X Y) is the interpreter's, and
    # a line naming an axis twice is refused with the interpreter's error
    from postproc.gcode import compare

    text = ("G21 G90 G54\nT1 M6\nG0 G43 H1 Z50 X1 Y2\nX10 Y10\nG1 Z-1 X11 Y12 F500\nY13 X12\n"
            "N7 G0 G43 H2 Z45\nZ30 Y14\nX14 Z29 Y15\ng1 g43 h3 z20 x16 f300\nG43 H0 Z10\nG0 X17\nG43 H2 Y18 Z11\n"
            "G43 H3\nX19\nM30\n")
    setup = Setup(offsets={"G54": (10.0, 20.0, 30.0)}, tool_lengths={1: 50.0, 2: 60.0, 3: 70.0})
    _moves, want_end = _interpreter_ends(text, setup)
    # the tool lengths along the program: 50, 60, 70, 0, 60 (G54 Z 30)
    assert [want_end[k][2] for k in (2, 6, 9, 10, 12)] == [130.0, 135.0, 120.0, 40.0, 101.0]
    keys = compare._Keys()
    results = []
    for chunk, in_bulk in ((20_000, False), (20_000, True), (4, True), (1, True)):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        reader = compare._Reader(text, setup, keys)
        reader._rd.use_bulk = in_bulk  # False: every line through the interpreter
        parts = list(reader.chunks())
        np.testing.assert_array_equal(np.concatenate([p.end for p in parts]), np.array(want_end))
        results.append(np.concatenate([p.keys for p in parts]))
    for got in results[1:]:
        np.testing.assert_array_equal(got, results[0])
    # an axis named twice: refused with the interpreter's error, in bulk or not
    for bad in ("X1 Z2 X3\n", "G0 G43 H1 Z5 Z6\n"):
        with pytest.raises(PostprocError, match="appears twice") as exc:
            list(compare._Reader("G21 G90 G54\nG0 X0 Y0 Z50\nX1\n" + bad, setup, compare._Keys()).chunks())
        assert exc.value.lineno == 4


def test_diff_pairs_inserted_lines_at_any_chunk_size(monkeypatch):
    from postproc.gcode import compare

    rng = np.random.default_rng(5)
    text = _cam_program(rng, 1500)
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={1: 0.0, 2: 0.0, 3: 0.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    out, rep = correct_text(text, cal.engine, setup)
    assert rep.lines_inserted > 10  # moves split: the pairing must skip inserted lines
    results = []
    for chunk, scan, window in ((20_000, 256, 256), (31, 4, 2), (200, 9, 16)):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        monkeypatch.setattr(compare, "SCAN_AHEAD", scan)
        monkeypatch.setattr(compare, "MIN_WINDOW", window)
        d = compare_programs(text, out)
        assert d.lines_inserted == rep.lines_inserted
        assert d.moves == rep.moves + 1  # diff counts the G28 line too (correct writes it as it is)
        assert d.lines_original == len(text.splitlines())
        assert d.lines_corrected == len(out.splitlines()) - len(emit.split_header(out)[0])
        # no end point moved by more than the largest correction the pipeline applied
        assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4
        results.append(d.to_dict())
    assert results[1] == results[0]
    assert results[2] == results[0]


def test_diff_progress(monkeypatch, tmp_path, capsys):
    import sys

    from postproc.cli import correct as correct_cli
    from postproc.gcode import compare

    rng = np.random.default_rng(3)
    src = tmp_path / "p.nc"
    src.write_text(_cam_program(rng, 400))
    dst = tmp_path / "q.nc"
    assert main(["correct", str(src), "-c", str(CASES / "demo_static.json"), "-o", str(dst), "--offset",
                 "G54=X0,Y0,Z100", "--home", "G28=X0,Y0,Z200", *sum((["--tool-length", f"{h}=0"] for h in (1, 2, 3)),
                                                                  [])], standalone_mode=False) in (0, None)
    monkeypatch.setattr(compare, "CHUNK_LINES", 100)
    seen = []
    d = compare_programs(str(src), str(dst), progress=seen.append)
    assert seen == sorted(seen)
    assert len(seen) >= 3
    assert seen[-1] == d.lines_original
    # on a terminal, for a big program, diff shows the lines read on stderr, as correct does
    capsys.readouterr()
    monkeypatch.setattr(correct_cli, "PROGRESS_MIN_BYTES", 0)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    main(["diff", str(src), str(dst)], standalone_mode=False)
    cap = capsys.readouterr()
    assert f"\r{src}: {d.lines_original:,} lines" in cap.err
    assert cap.err.endswith("\n")
    assert "moves:" in cap.out


def test_diff_of_a_corrected_program_missing_a_move_is_an_error(monkeypatch):
    from postproc.gcode import compare

    rng = np.random.default_rng(8)
    text = _cam_program(rng, 600)
    eng = IdentityEngine([[-1e4] * 3, [1e4] * 3])
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0, 2: 0.0, 3: 0.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    out, _ = correct_text(text, eng, setup)
    lines = out.splitlines(keepends=True)
    k = next(i for i in range(len(lines) // 2, len(lines)) if lines[i].startswith("X"))  # a plain move
    monkeypatch.setattr(compare, "CHUNK_LINES", 64)
    with pytest.raises(PostprocError, match="has no counterpart in the corrected program"):
        compare_programs(text, "".join(lines[:k] + lines[k + 1:]))
    # the same line written twice: the second one is taken for a line inserted by segmentation
    d = compare_programs(text, "".join(lines[:k] + [lines[k]] + lines[k:]))
    assert d.lines_inserted == 1
    assert d.moved == []


def test_diff_pairs_line_for_line_where_no_line_was_inserted():
    from postproc.engine.static import StaticEngine

    # a jump of 30 mm in Z changes the correction by 0.15 mm, ten times the next steps:
    # the nearest end point (own + the previous correction) is the next step's line, but
    # as many moves in both programs between two anchors pair line for line
    A = np.eye(3) + np.diag([0.0, 0.0, 5e-3]) + np.array([[0, 0, 2e-3], [0, 0, 1e-3], [0, 0, 0]])
    eng = StaticEngine(A, [0.0, 0.0, 0.0], [[0, 0, 0], [315, 315, 315]])
    text = ("G21 G90 G0 X10 Y10 Z10\nG1 X20 Z5 F500\n(next pass)\nG0 X50 Y50 Z40\nG1 X50.01 Y50\n"
            "G1 X50.02 Y50.004\nG1 X50.03\nM2\n")
    out, rep = correct_text(text, eng, Setup())
    d = compare_programs(text, out)
    n_header = len(emit.split_header(out)[0])
    assert d.moves == rep.moves == 6
    assert [m.lineno for m in d.moved] == [1, 2, 4, 5, 6, 7]
    assert [m.lineno_corrected - n_header for m in d.moved] == [1, 2, 4, 5, 6, 7]
    # each delta is the corrected end point minus the original one, read off the lines
    ends = {4: (50, 50, 40), 5: (50.01, 50, 40), 6: (50.02, 50.004, 40), 7: (50.03, 50.004, 40)}
    body = out.splitlines()[n_header:]
    for m in d.moved:
        if m.lineno in ends:
            words = dict(re.findall(r"([XYZ])([-\d.]+)", body[m.lineno - 1]))
            prev = [body[i] for i in range(m.lineno - 1)]
            got = []
            for k, a in enumerate("XYZ"):
                v = words.get(a) or next(dict(re.findall(r"([XYZ])([-\d.]+)", ln)).get(a) for ln in reversed(prev)
                                         if a in ln)
                got.append(float(v) - ends[m.lineno][k])
            np.testing.assert_allclose(m.delta_mm, got, atol=1e-12)


def test_diff_pairs_a_line_whose_words_follow_a_comment():
    cal = load_calibration(CASES / "demo_static.json")
    text = "G21 G90 G0 X10 Y10 Z10\nG1 (cut) X20 Y15 F100\nG17 G2 (quarter) X30 Y25 I10 J0\nM2\n"
    out, rep = correct_text(text, cal.engine, Setup())
    d = compare_programs(text, out)
    assert d.moves == rep.moves == 3
    assert [m.lineno for m in d.moved] == [1, 2, 3]


def _numbered_program(rng: np.random.Generator, n: int) -> str:
    """A program whose every line is a move with its own N word (as some CAM programs are):
    no anchor between the first line and the last; long straight moves and arcs, which a
    parametric correction splits."""
    out = ["N10 G90 G21 G17 G0 X100 Y100 Z120"]
    x, y = 100.0, 100.0
    while len(out) < n:
        nw = f"N{10 * (len(out) + 1)}"
        if rng.random() < 0.8:
            step = 60.0 if rng.random() < 0.2 else 2.0
            x = float(np.clip(x + rng.uniform(-step, step), 50, 250))
            y = float(np.clip(y + rng.uniform(-step, step), 50, 250))
            out.append(f"{nw} G1 X{x:.4f} Y{y:.4f} F900")
        else:
            i, j = rng.uniform(-20, 20), rng.uniform(-20, 20)
            cx, cy = x + i, y + j
            a = np.arctan2(-j, -i) + rng.uniform(0.3, 2.0)
            rad = float(np.hypot(i, j))
            x, y = cx + rad * np.cos(a), cy + rad * np.sin(a)
            out.append(f"{nw} G3 X{x:.4f} Y{y:.4f} I{i:.4f} J{j:.4f}")
    return "\n".join(out + ["M30"]) + "\n"


def test_diff_of_a_program_without_anchors_pairs_in_windows(monkeypatch):
    # Every move's N word is its own: no later line can pair with it, which the pairing
    # knows from the N words' index, without reading every line up to the next anchor
    # (the end of the program) for each move.
    from postproc.gcode import compare

    rng = np.random.default_rng(21)
    text = _numbered_program(rng, 3000)
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
    out, rep = correct_text(text, cal.engine, setup)
    assert rep.lines_inserted > 100
    calls = {"one": 0, "indexed": 0}
    pair_one, index_init = compare._pair_one, compare._Index.__init__

    def counted_pair_one(*args):
        calls["one"] += 1
        return pair_one(*args)

    def counted_index(self, rows):
        calls["indexed"] += len(rows)
        index_init(self, rows)

    monkeypatch.setattr(compare, "_pair_one", counted_pair_one)
    monkeypatch.setattr(compare._Index, "__init__", counted_index)
    results = []
    for chunk in (20_000, 300):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        calls.update(one=0, indexed=0)
        d = compare_programs(text, out)
        assert d.lines_inserted == rep.lines_inserted
        assert d.moves == rep.moves
        assert d.lines_original == 3001
        assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4
        # one at a time only where lines were inserted (and a few records after)
        places = sum(1 for m in re.finditer(r"\n(?!N)", out.split("N10 ", 1)[1]))
        assert calls["one"] <= (compare.SLOW_STRETCH + 1) * places + 10
        # the keys indexed a few times over, not once per record
        assert calls["indexed"] <= 10 * len(out.splitlines())
        results.append(d.to_dict())
    assert results[1] == results[0]
    # a move left out: still found missing
    lines = out.splitlines(keepends=True)
    k = next(i for i in range(len(lines) // 2, len(lines)) if lines[i].startswith("N"))
    with pytest.raises(PostprocError, match="has no counterpart in the corrected program"):
        compare_programs(text, "".join(lines[:k] + lines[k + 1:]))


def test_diff_pairs_moves_shorter_than_the_change_of_the_correction():
    from postproc.engine.static import StaticEngine

    # Over the 20 mm move to X70 Y55 the correction changes by 40 um, over the two moves
    # after it by less than 1 um: the line nearest the prediction (the previous delta) is
    # the next move's, not the own one. The arc is split (lines inserted in the stretch),
    # so the stretch is paired by the nearest-end-point rule, not line for line.
    A = np.eye(3) + np.array([[1.5e-3, 2e-3, 0], [-1e-3, 2e-3, 0], [0, 0, 1e-3]])
    eng = StaticEngine(A, [0.0, 0.0, 0.0], [[0, 0, 0], [315, 315, 315]])
    text = ("G21 G90 G17\nG0 X50 Y50 Z20\nG1 Z10 F300\nG1 X70 Y55\nX70.0004 Y55.0004\nX70.0008 Y55.0001\n"
            "G1 Z9\nG1 X90 Y60\nG2 X130 Y60 I20 J0\nG1 X131 Y61\nM2\n")
    out, rep = correct_text(text, eng, Setup())
    assert rep.lines_inserted >= 1
    d = compare_programs(text, out)
    n_header = len(emit.split_header(out)[0])
    assert d.moves == rep.moves
    assert d.lines_inserted == rep.lines_inserted
    pairs = {m.lineno: m.lineno_corrected - n_header for m in d.moved}
    assert all(pairs[k] == k for k in range(2, 9))  # line for line up to the arc
    assert pairs[9] == 9 + rep.lines_inserted
    assert pairs[10] == 10 + rep.lines_inserted
    # each delta is the correction of its own end point (A c = q), within the output's rounding
    ends = {2: (50, 50, 20), 3: (50, 50, 10), 4: (70, 55, 10), 5: (70.0004, 55.0004, 10), 6: (70.0008, 55.0001, 10),
            7: (70.0008, 55.0001, 9), 8: (90, 60, 9), 9: (130, 60, 9), 10: (131, 61, 9)}
    for m in d.moved:
        q = np.array(ends[m.lineno], dtype=float)
        np.testing.assert_allclose(m.delta_mm, np.linalg.solve(A, q) - q, atol=1e-4)


def test_diff_finds_the_header_after_blank_lines_and_reads_in_the_dialect(tmp_path):
    # correct keeps blank lines before '%', the '%' and the O number before its header;
    # diff takes the header from the same place, and reads G53 in G91 as Haas does
    cal = load_calibration(CASES / "demo_static.json")
    text = "\n%\nO1000\nG21 G90 G54 G0 X10 Y10 Z10\nG1 X20 F100\nG91 G53 Z0\nG90\nM30\n%\n"
    out, rep = correct_text(text, cal.engine, Setup(offsets={"G54": (0.0, 0.0, 0.0)}),
                            CorrectOptions(dialect="haas"))
    assert out.startswith("\n%\nO1000\n(POSTPROC ")
    head, body = emit.split_header(out)
    assert body == "\n%\nO1000\n" + "".join(out.splitlines(keepends=True)[3 + len(head):])
    with pytest.raises(PostprocError, match="G53 is not allowed in G91"):
        compare_programs(text, out)
    d = compare_programs(text, out, options=CorrectOptions(dialect="haas"))
    assert d.header == "".join(head).strip()
    assert d.moves == rep.moves == 3
    assert d.lines_unchanged == len(text.splitlines()) - 3
    src, dst = tmp_path / "o1000.nc", tmp_path / "o1000_c.nc"
    src.write_text(text)
    dst.write_text(out)
    res = CliRunner().invoke(main, ["diff", str(src), str(dst), "--dialect", "haas", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["moves_moved"] == 3


def test_dialect_choices_are_the_dialects():
    from postproc.cli.options import DIALECT_CHOICE
    from postproc.gcode.dialect import DIALECTS

    assert set(DIALECT_CHOICE.choices) == set(DIALECTS)


def test_diff_takes_a_g92_line_correct_rewrote():
    # G92 names the current position; correct rewrites its axis words by the correction
    # there, so that the coordinates after it stay nominal: diff pairs it as rewritten
    cal = load_calibration(CASES / "demo_static.json")
    text = "G21 G90 G0 X10 Y10 Z10\nG1 X20 F100\nG92 X110 (re-zero)\nG1 X120 Y20\nG1 X130\nM2\n"
    out, rep = correct_text(text, cal.engine, Setup())
    assert "G92 X110 (re-zero)" not in out
    d = compare_programs(text, out)
    assert d.lines_rewritten == 1
    assert d.moves == rep.moves == 4
    assert d.lines_unchanged == 1  # M2
    # the moves after it are compared in the machine frame: deltas as small as before it
    assert max(m.size_mm for m in d.moved) < 0.1
    # any other difference on such a line is still refused
    wrong = out.replace("(re-zero)", "(re-zero) T2")
    with pytest.raises(PostprocError, match="differs from line 3 of the original"):
        compare_programs(text, wrong)


def test_diff_pairs_a_program_that_numbers_its_blocks_again_in_windows(monkeypatch):
    # N10, N20, ... twice over (a second operation numbered from N10 again), no anchor
    # between: a move's N word comes once more later; its own line is still the nearest,
    # which the window checks instead of pairing every record one at a time
    from postproc.engine.static import StaticEngine
    from postproc.gcode import compare

    rng = np.random.default_rng(4)
    A = np.eye(3) + np.diag([1e-3, -5e-4, 2e-4])
    eng = StaticEngine(A, [0.01, 0.0, 0.0], [[0, 0, 0], [315, 315, 315]])
    lines = ["G21 G90 G0 X100 Y100 Z50"]
    for _ in range(2):
        lines += [f"N{10 * (k + 1)} G1 X{x:.3f} Y{y:.3f} F500"
                  for k, (x, y) in enumerate(rng.uniform(50, 250, size=(400, 2)))]
    text = "\n".join(lines + ["M2"]) + "\n"
    out, rep = correct_text(text, eng, Setup())
    calls = {"one": 0}
    pair_one = compare._pair_one

    def counted(*args):
        calls["one"] += 1
        return pair_one(*args)

    monkeypatch.setattr(compare, "_pair_one", counted)
    monkeypatch.setattr(compare, "CHUNK_LINES", 100)  # windows without the anchor at the end
    d = compare_programs(text, out)
    assert d.moves == rep.moves == 801
    n_header = len(emit.split_header(out)[0])
    assert all(m.lineno_corrected - n_header == m.lineno for m in d.moved)
    assert calls["one"] <= 10


def _written_pair(tmp_path, rng_seed: int, n: int) -> tuple[Path, Path, str, str]:
    """A CAM-like program and its version corrected with the S500 parametric calibration,
    both written to files (the corrected one with its header)."""
    rng = np.random.default_rng(rng_seed)
    text = _cam_program(rng, n)
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={1: 0.0, 2: 0.0, 3: 0.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    out, rep = correct_text(text, cal.engine, setup)
    assert rep.lines_inserted > 10
    src, dst = tmp_path / "p.nc", tmp_path / "q.nc"
    src.write_text(text)
    dst.write_text(out)
    return src, dst, text, out


def _forked_reads(monkeypatch) -> dict:
    """Count the programs read by a child process."""
    from postproc.gcode import compare

    seen = {"forked": 0}
    chunks = compare._ForkedReader.chunks

    def counted(self):
        seen["forked"] += 1
        return chunks(self)

    monkeypatch.setattr(compare._ForkedReader, "chunks", counted)
    return seen


_NO_FORK = pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="no fork here")


@_NO_FORK
def test_diff_reads_the_original_in_a_child_as_it_does_itself(monkeypatch, tmp_path):
    from postproc.gcode import compare

    src, dst, _text, _out = _written_pair(tmp_path, 5, 1500)
    seen = _forked_reads(monkeypatch)
    monkeypatch.setattr(compare, "CHUNK_LINES", 97)  # many chunks: the keys of each mapped
    reports = []
    for least in (10**15, 0):  # read here, then in a child
        monkeypatch.setattr(compare, "FORK_MIN_BYTES", least)
        reports.append(compare_programs(str(src), str(dst)).to_dict())
    assert seen["forked"] == 1  # the original (the corrected program is read here, beside the pairing)
    assert reports[1] == reports[0]
    assert reports[0]["lines_inserted"] > 10
    assert reports[0]["header"]


@_NO_FORK
def test_diff_reports_an_error_of_a_program_read_in_a_child(monkeypatch, tmp_path):
    import multiprocessing

    from postproc.gcode import compare

    src, dst, text, out = _written_pair(tmp_path, 5, 1500)
    lines = out.splitlines(keepends=True)
    k = next(i for i in range(len(lines) * 3 // 4, len(lines)) if lines[i].startswith("X"))
    dst.write_text("".join(lines[:k] + ["G1 X#1\n"] + lines[k + 1:]))
    seen = _forked_reads(monkeypatch)
    monkeypatch.setattr(compare, "CHUNK_LINES", 100)
    errors = []
    for least in (10**15, 0):
        monkeypatch.setattr(compare, "FORK_MIN_BYTES", least)
        with pytest.raises(PostprocError) as exc:
            compare_programs(str(src), str(dst))
        errors.append((type(exc.value), str(exc.value), exc.value.lineno))
    assert seen["forked"] == 1
    assert errors[1] == errors[0]
    assert errors[0][2] == k + 1
    assert str(dst) in errors[0][1]
    # an error of the original, read in a child, is the one read here, and stops the child
    src.write_text("".join(text.splitlines(keepends=True)[:50] + ["G1 X#1\n"]))
    errors = []
    for least in (10**15, 0):
        monkeypatch.setattr(compare, "FORK_MIN_BYTES", least)
        with pytest.raises(PostprocError, match=":51:") as exc:
            compare_programs(str(src), str(dst))
        errors.append((type(exc.value), str(exc.value), exc.value.lineno))
    assert errors[1] == errors[0]
    assert str(src) in errors[0][1]
    assert multiprocessing.active_children() == []
    assert seen["forked"] == 2


def test_diff_reads_the_original_expanded_when_the_program_was_corrected_expanded(tmp_path):
    # a Fanuc subprogram called three times (M98 L3) and a macro variable: correct writes
    # the program flat; diff reads the original the same way and numbers its blocks by
    # their source lines (a subprogram's line once per call)
    text = ("%\nO1000\nG21 G90 G17\nG54\nT1 M6\nG0 G43 H1 Z20.\n#101=10.\nG0 X#101 Y10.\nM98 P2000 L3\n"
            "G0 Z50.\nM30\nO2000\nG91 G1 X5. F500.\nG90\nM99\n%\n")
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={1: 0.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    out, rep = correct_text(text, cal.engine, setup, CorrectOptions(dialect="fanuc"))
    assert rep.expanded
    src, dst = tmp_path / "o1000.nc", tmp_path / "o1000_c.nc"
    src.write_text(text)
    dst.write_text(out)
    d = compare_programs(str(src), str(dst), options=CorrectOptions(dialect="fanuc"))
    assert d.expanded
    assert d.moves == rep.moves == 6
    assert d.lines_inserted == 0
    assert d.lines_corrected == len(out.splitlines()) - len(emit.split_header(out)[0])
    assert d.lines_original == d.lines_corrected  # the program as executed, line for line
    assert sorted(m.lineno for m in d.moved) == [6, 8, 10, 13, 13, 13]
    assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4
    # the text report says so
    res = CliRunner().invoke(main, ["diff", str(src), str(dst), "--dialect", "fanuc"])
    assert res.exit_code == 0, res.output
    assert "original (expanded)" in res.output
    js = json.loads(CliRunner().invoke(main, ["diff", str(src), str(dst), "--dialect", "fanuc", "--json"]).output)
    assert js["expanded"] is True


def test_diff_reads_a_linuxcnc_subroutine_from_the_subroutine_path(tmp_path):
    sub = tmp_path / "subs"
    sub.mkdir()
    (sub / "step.ngc").write_text("o<step> sub\nG91 G1 X[#1] F300\nG90\no<step> endsub\nM2\n")
    text = "G21 G90 G17\nG0 X10 Y10 Z10\no<step> call [4]\no<step> call [2.5]\nG0 Z30\nM2\n"
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)})
    out, rep = correct_text(text, cal.engine, setup, CorrectOptions(dialect="linuxcnc", subroutine_path=(str(sub),)))
    assert rep.expanded
    src, dst = tmp_path / "p.ngc", tmp_path / "q.ngc"
    src.write_text(text)
    dst.write_text(out)
    with pytest.raises(PostprocError):  # the subroutine is not found without its folder
        compare_programs(str(src), str(dst), options=CorrectOptions(dialect="linuxcnc"))
    d = compare_programs(str(src), str(dst), options=CorrectOptions(dialect="linuxcnc", subroutine_path=(sub,)))
    assert d.moves == rep.moves == 4
    assert sorted(m.lineno for m in d.moved) == [2, 2, 2, 5]  # step.ngc's line 2, twice
    res = CliRunner().invoke(main, ["diff", str(src), str(dst), "--dialect", "linuxcnc",
                                    "--subroutine-path", str(sub)])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("spline", ["G5.1 X20 Y20 I5 J0", "G5 X20 Y18 I3 J0 P-3 Q4", "G05.1 X20 Y20 I5 J0"])
def test_diff_pairs_a_spline_with_the_last_of_its_chords(spline):
    text = f"G21 G90 G17\nG0 X10 Y10 Z10\nG1 Z5 F100\n{spline}\nG1 X30\nM2\n"
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)})
    out, rep = correct_text(text, cal.engine, setup)
    d = compare_programs(text, out)
    chords = len(out.splitlines()) - len(emit.split_header(out)[0]) - len(text.splitlines()) + 1
    assert chords > 10
    assert d.moves == 4
    assert d.lines_inserted == chords - 1
    spline_end = next(m for m in d.moved if m.lineno == 4)
    n_header = len(emit.split_header(out)[0])
    assert spline_end.lineno_corrected == n_header + 3 + chords  # the last chord
    assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4


def test_diff_reads_canned_cycles_as_correct_wrote_them_expanded(tmp_path):
    # --cycles expand writes each cycle block as its G0/G1 moves (and its other modal
    # words, its dwells as G4 lines); the header says so and diff reads the original's
    # cycle blocks the same way: each step pairs with its line
    text = ("G21 G90 G17 G54\nT1 M6\nG0 G43 H1 Z30\nG0 X20 Y20\nG90 G98 G81 X20 Y20 Z-5 R2 F100\nX40\n"
            "G99 G82 X60 Y20 Z-4 R2 P0.5\nG83 X60 Y40 Z-12 R2 Q3\nG91 G81 X10 Z-7 R-28 L3\nG90 G80\nG0 Z50\nM2\n")
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (50.0, 50.0, 100.0)}, tool_lengths={1: 20.0})
    out, rep = correct_text(text, cal.engine, setup, CorrectOptions(cycles="expand"))
    assert rep.cycles_expanded == 5
    assert "(POSTPROC CYCLES EXPANDED)" in out.splitlines()
    assert "G4 P0.5" in out.splitlines()
    kept, _ = correct_text(text.replace("G91 G81 X10 Z-7 R-28 L3\n", ""), cal.engine, setup,
                           CorrectOptions(tolerance_mm=0.05))
    assert "CYCLES EXPANDED" not in kept
    d = compare_programs(text, out)
    assert d.moves == rep.moves
    assert d.lines_inserted == 0
    assert d.lines_original == len(text.splitlines())
    assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4
    # every step of a cycle block is numbered by the block's line: G83 pecks 3 mm to 14 mm
    # deep (Q3), each with its retract and rapid down
    assert sum(m.lineno == 8 for m in d.moved) > 10
    # each move of the corrected program (as the interpreter reads it) pairs once
    from postproc.gcode.interp import Interpreter

    interp = Interpreter(setup, None)
    moving = [k for k, line in enumerate(out.splitlines(keepends=True), start=1) if interp.feed_line(k, line)]
    assert d.moves_unchanged == 0
    assert sorted(m.lineno_corrected for m in d.moved) == moving
    # the CLI on the files
    src, dst = tmp_path / "p.ngc", tmp_path / "q.ngc"
    src.write_text(text)
    dst.write_text(out)
    res = CliRunner().invoke(main, ["diff", str(src), str(dst)])
    assert res.exit_code == 0, res.output
    assert "CYCLES EXPANDED" in res.output


def test_diff_cycles_expand_reads_a_program_without_its_header_as_correct_wrote_it(tmp_path):
    # correct --cycles expand leaves out the G98/G99 retracts (the header records CYCLES
    # EXPANDED); with the header removed, diff --cycles expand reads the cycles so, and
    # the header's record stays the one read when there is a header
    from postproc.gcode import emit

    text = ("G21 G90 G17 G54\nG0 G43 H1 Z30\nG0 X20 Y20\nG98 G81 X20 Y20 Z-5 R2 F100\nX40\n"
            "G99 G82 X60 Y20 Z-4 R2 P0.5\nG80\nG0 Z50\nM2\n")
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (50.0, 50.0, 100.0)}, tool_lengths={1: 20.0})
    out, rep = correct_text(text, cal.engine, setup, CorrectOptions(cycles="expand"))
    bare = "".join(line for line in out.splitlines(keepends=True) if not emit.is_header(line))
    assert "POSTPROC" not in bare
    src, dst, dst_bare = tmp_path / "p.ngc", tmp_path / "q.ngc", tmp_path / "r.ngc"
    src.write_text(text)
    dst.write_text(out)
    dst_bare.write_text(bare)
    want = compare_programs(str(src), str(dst))
    assert want.moves == rep.moves
    assert want.lines_inserted == 0
    got = compare_programs(str(src), str(dst_bare), setup, options=CorrectOptions(cycles="expand"))
    assert (got.moves, got.lines_inserted, got.n_moved) == (want.moves, 0, want.n_moved)
    assert [m.delta_mm for m in got.moved] == [m.delta_mm for m in want.moved]
    # without it, the retracts are looked for: the programs do not pair
    with pytest.raises(PostprocError):
        compare_programs(str(src), str(dst_bare), setup)
    # the header's record, whatever --cycles says
    assert compare_programs(str(src), str(dst), options=CorrectOptions(cycles="auto")).to_dict()["moved"] == want.to_dict()["moved"]
    setup_args = ["--offset", "G54=X50,Y50,Z100", "--tool-length", "1=20"]
    res = CliRunner().invoke(main, ["diff", str(src), str(dst_bare), *setup_args, "--cycles", "expand", "--json"])
    assert res.exit_code == 0, res.output
    assert [(m["line"], m["delta_mm"]) for m in json.loads(res.output)["moved"]] == [
        (m.lineno, [round(x, 7) for x in m.delta_mm]) for m in want.moved]
    res = CliRunner().invoke(main, ["diff", str(src), str(dst_bare), *setup_args])
    assert res.exit_code != 0


def test_diff_of_the_fanuc_sample_expanded_with_its_cycles():
    text = (ROOT / "samples" / "fanuc_drill.nc").read_text()
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (100.0, 100.0, 100.0)}, tool_lengths={1: 100.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 300.0}})
    out, rep = correct_text(text, cal.engine, setup, CorrectOptions(dialect="fanuc", cycles="expand"))
    assert rep.expanded
    assert rep.cycles_expanded == 5
    d = compare_programs(text, out, options=CorrectOptions(dialect="fanuc"))
    assert d.expanded
    assert d.moves == rep.moves + 2  # and the two G28 lines, written as they are
    assert d.lines_inserted == 0
    assert max(m.size_mm for m in d.moved) == pytest.approx(rep.max_correction_mm, abs=1e-4)


@pytest.mark.parametrize("radius", [40, 140])
def test_diff_pairs_a_full_circle_cut_into_many_arcs_with_its_last_piece(radius):
    # the plunge before the circle ends where the circle ends; the circle is cut into
    # 18 to 62 arcs whose ends walk away from that point and back: the nearest line lies
    # beyond the first eight pieces, which are all farther than the first one
    text = (f"G21 G90 G17\nG0 X{150 - radius} Y150 Z20\nG1 Z5 F500\nG1 Z5\nG2 X{150 - radius} Y150 I{radius} J0\n"
            "G0 Z20\nG0 X10 Y10\nM2\n")
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    out, rep = correct_text(text, cal.engine, Setup(offsets={"G54": (0.0, 0.0, 100.0)}))
    assert rep.lines_inserted > 15
    d = compare_programs(text, out)
    assert d.lines_inserted == rep.lines_inserted
    assert max(m.size_mm for m in d.moved) <= rep.max_correction_mm + 1e-4
    lines = out.splitlines()
    circle = next(m for m in d.moved if m.lineno == 5)
    assert lines[circle.lineno_corrected - 1].startswith("G2 ")
    assert lines[circle.lineno_corrected].startswith("G0 Z")  # the next line: the retract


@_NO_FORK
@pytest.mark.parametrize("variant", ["crlf", "form feed", "lone cr"])
def test_diff_in_children_keeps_every_line_ending_and_character(monkeypatch, tmp_path, variant):
    # the child reading the original sends a chunk's lines joined where str.splitlines
    # gives them back unchanged, else as a list: either way the parent pairs the same lines
    from postproc.gcode import compare

    rng = np.random.default_rng(21)
    text = _cam_program(rng, 600)
    if variant == "crlf":
        text = text.replace("\n", "\r\n")
    elif variant == "form feed":
        text = text.replace("(PASS)", "(PA\x0cSS)")
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={1: 0.0, 2: 0.0, 3: 0.0},
                  home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})
    out, _rep = correct_text(text, cal.engine, setup)
    if variant == "lone cr":  # the same line of each ends with a lone carriage return
        assert "\nM9\n" in text
        text, out = text.replace("\nM9\n", "\nM9\r", 1), out.replace("\nM9\n", "\nM9\r", 1)
    src, dst = tmp_path / "p.nc", tmp_path / "q.nc"
    src.write_bytes(text.encode())
    dst.write_bytes(out.encode())
    seen = _forked_reads(monkeypatch)
    monkeypatch.setattr(compare, "CHUNK_LINES", 64)
    reports = []
    for least in (10**15, 0):
        monkeypatch.setattr(compare, "FORK_MIN_BYTES", least)
        reports.append(compare_programs(str(src), str(dst)).to_dict())
    assert seen["forked"] == 1
    assert reports[1] == reports[0]
    assert reports[0]["moves"] > 100


@_NO_FORK
def test_diff_raises_a_failure_of_a_reading_child_and_leaves_no_child(monkeypatch, tmp_path):
    import multiprocessing

    from postproc.gcode import compare

    src, dst, _text, _out = _written_pair(tmp_path, 5, 1500)
    monkeypatch.setattr(compare, "FORK_MIN_BYTES", 0)
    monkeypatch.setattr(compare, "CHUNK_LINES", 200)
    rows = compare._LineRows.rows

    def failing(self):
        got = rows(self)
        if len(got) and got.lineno[0] > 600:
            raise ValueError("reader bug")
        return got

    monkeypatch.setattr(compare._LineRows, "rows", failing)
    with pytest.raises(ValueError, match="reader bug"):
        compare_programs(str(src), str(dst))
    assert multiprocessing.active_children() == []


def test_diff_pairs_sinumerik_words_written_name_equals_value():
    # Sinumerik axis words whose value is an expression (X=R1+5, Y=R1 * 2, X=(R1+R2)*2),
    # AC() and the radius CR=: correct writes a number in place of the value (X=14.8888,
    # Y=AC(24.9)); diff pairs each with its line, no N word needed, and reads the same
    # deltas as for the program written with numbers
    cal = load_calibration(ROOT / "calibrations" / "s500_static.json")
    setup = Setup(offsets={"G54": (150.0, 150.0, 150.0)})
    head = "G90 G54 G17 G71\nR1=10\nR2=2\nG0 X0 Y0 Z5\n"
    tail = "G2 X34 Y35 CR=10\nG1 X40\nM30\n"
    with_expressions = head + "G1 X=R1 Y5 F500\nG1 X=R1+5 Y10\nG1 X20 Y=R1 * 2\nG1 X=(R1+R2)*2 Y=AC(25)\n" + tail
    with_numbers = head + "G1 X10 Y5 F500\nG1 X15 Y10\nG1 X20 Y20\nG1 X24 Y25\n" + tail
    reports, outs = [], []
    for text in (with_expressions, with_numbers):
        out, rep = correct_text(text, cal.engine, setup, CorrectOptions(dialect="sinumerik"), path="p.mpf")
        d = compare_programs(text, out, options=CorrectOptions(dialect="sinumerik"))
        assert (d.moves, d.lines_inserted) == (rep.moves, rep.lines_inserted)
        reports.append(d)
        outs.append(out)
    assert re.search(r"\nG1 X=\d+\.\d+ Y=AC\(\d+\.\d+\)", outs[0])  # numbers in place of the values
    expr, num = reports
    assert expr.moves == 7
    assert [(m.lineno, m.lineno_corrected, m.delta_mm) for m in expr.moved] == \
           [(m.lineno, m.lineno_corrected, m.delta_mm) for m in num.moved]
    assert expr.n_moved == expr.moves


def test_diff_reads_the_keys_of_numbered_lines_in_bulk_as_the_interpreter_does(monkeypatch):
    # heads with N words of every form (lower case, blanks before, leading zeros, N0, too
    # nine digits, followed by a point), repeated and new heads across blocks, rotary words:
    # the pairing keys of lines read in runs are those of the lines read one by one
    from postproc.gcode import compare

    rows = ["G21 G90 G54", "G0 X0 Y0 Z50", "G1 Z1 F500"]
    forms = ["N{k} G1 X{x} Y{y}", "n{k} X{x} Y{y}", "  N{k} G1 X{x} Y{y}", "N00{k} X{x} Y{y}", "N0 X{x} Y{y}",
             "N999999999 X{x} Y{y}", "N{k}.5 X{x} Y{y}", "N{k} G1 M8 X{x} Y{y}", "G1 X{x} Y{y}",
             "X{x} Y{y} Z1", "N{k} G0 X{x} Y{y} A{k}", "X{x} Y{y} B2", "G0 G90 X{x} Y{y}", "N{k}G1X{x}Y{y}",
             "(PASS {k})"]
    for k in range(1, 400):
        rows.append(forms[k % len(forms)].format(k=k, x=k % 37, y=k % 23))
    text = "\n".join([*rows, "M30"]) + "\n"
    setup = Setup(offsets={"G54": (10.0, 20.0, 30.0)})
    keys = compare._Keys()
    results = []
    for chunk, in_bulk in ((20_000, False), (20_000, True), (7, True)):
        monkeypatch.setattr(compare, "CHUNK_LINES", chunk)
        monkeypatch.setattr(compare, "BLOCK_LINES", min(chunk, 5_000))
        reader = compare._Reader(text, setup, keys)
        reader._rd.use_bulk = in_bulk  # False: every line through the interpreter
        results.append(np.concatenate([p.keys for p in reader.chunks()]))
    assert results[0][:, 0].any()
    assert results[0][:, 1].any()
    for got in results[1:]:
        np.testing.assert_array_equal(got, results[0])
