"""The lines of a program read expanded are named with their file where it is not the
program's own (a subprogram's): in ``postproc diff``'s report (text and JSON) and its
refusals, in the samples of the path and the sampler's refusals. A Sinumerik drilling
cycle refused points at the column where its call starts.

A program read as written, or expanded without other files (loops, macros, a subroutine
of its own file), keeps its bare line numbers: its outputs are those of before."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.errors import MissingSetupError, PostprocError
from postproc.gcode import bulk, compare, forking
from postproc.gcode.compare import DiffReport, compare_programs
from postproc.gcode.path import Setup, sample_program
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.limits import ResourceLimitError

ROOT = Path(__file__).resolve().parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
SETUP = Setup(offsets={"G54": (100.0, 100.0, 100.0)}, tool_lengths={1: 0.0})

# a LinuxCNC subroutine in a file of its own, its lines plain enough to be read in runs
FAR = "o<far> sub\nG1 X90 Y10 F100\nG1 X50\nG1 X51 Y11\nG1 X52 Y12\nG1 X53 Y13\n(back)\nG1 X50 Y10\no<far> endsub\nM2\n"
MAIN = "G21 G90 G17\nG0 X10 Y10 Z10\no<far> call\nG1 X20 F100\nM2\n"


def corrected_pair(tmp_path: Path, text: str = MAIN, subs: dict[str, str] | None = None,
                   dialect: str = "linuxcnc", name: str = "main.ngc") -> tuple[Path, Path, Path]:
    """The program ``text`` (calling the files ``subs`` on its subroutine path, ``subs/``)
    and its corrected version: their paths and the subprograms' folder."""
    folder = tmp_path / "subs"
    folder.mkdir(exist_ok=True)
    for sub, body in ({"far.ngc": FAR} if subs is None else subs).items():
        (folder / sub).write_text(body)
    src, dst = tmp_path / name, tmp_path / f"corrected_{name}"
    src.write_text(text)
    cal = load_calibration(STATIC)
    out, rep = correct_text(text, cal.engine, SETUP, CorrectOptions(dialect=dialect, subroutine_path=(str(folder),)),
                            path=str(src))
    assert rep.expanded
    dst.write_text(out)
    return src, dst, folder


def diff_cli(src: Path, dst: Path, folder: Path, *extra: str, dialect: str = "linuxcnc"):
    return CliRunner().invoke(main, ["diff", str(src), str(dst), "--dialect", dialect,
                                     "--subroutine-path", str(folder), *extra])


# -- postproc diff ---------------------------------------------------------------------
def test_diff_names_the_file_of_a_moved_block_of_a_subprogram(tmp_path):
    src, dst, folder = corrected_pair(tmp_path)
    far = str(folder / "far.ngc")
    d = compare_programs(str(src), str(dst), options=CorrectOptions(dialect="linuxcnc", subroutine_path=(folder,)))
    got = sorted((m.file or "", m.lineno) for m in d.moved)
    assert got == [("", 2), ("", 4), *((far, n) for n in (2, 3, 4, 5, 6, 8))]
    res = diff_cli(src, dst, folder, "--all")
    assert res.exit_code == 0, res.output
    assert f"    line {far}:2 ->" in res.output
    assert "    line      4 ->" in res.output  # the program's own lines as before
    assert "    line      2 ->" in res.output


def test_diff_json_gives_the_file_of_a_subprogram_line_only(tmp_path):
    src, dst, folder = corrected_pair(tmp_path)
    res = diff_cli(src, dst, folder, "--json")
    assert res.exit_code == 0, res.output
    moved = json.loads(res.output)["moved"]
    own = [m for m in moved if "file" not in m]
    theirs = [m for m in moved if "file" in m]
    assert sorted(m["line"] for m in own) == [2, 4]
    assert {m["file"] for m in theirs} == {str(folder / "far.ngc")}
    assert sorted(m["line"] for m in theirs) == [2, 3, 4, 5, 6, 8]
    assert list(theirs[0]) == ["line", "file", "line_corrected", "delta_mm", "size_mm"]
    assert list(own[0]) == ["line", "line_corrected", "delta_mm", "size_mm"]


def test_diff_of_a_program_expanded_in_its_own_file_keeps_bare_lines(tmp_path):
    # a Fanuc subprogram of the program's own file, called three times: no file named
    text = ("%\nO1000\nG21 G90 G17\nG54\nG0 X10 Y10 Z10\nM98 P2000 L3\nG0 Z50.\nM30\nO2000\nG91 G1 X5. F500.\n"
            "G90\nM99\n%\n")
    src, dst, folder = corrected_pair(tmp_path, text, {}, dialect="fanuc", name="o1000.nc")
    d = compare_programs(str(src), str(dst), options=CorrectOptions(dialect="fanuc"))
    assert d.moved
    assert all(m.file is None for m in d.moved)
    assert d._files is None  # nothing stored for the files of its blocks
    res = diff_cli(src, dst, folder, "--json", dialect="fanuc")
    assert all("file" not in m for m in json.loads(res.output)["moved"])
    listed = [ln for ln in diff_cli(src, dst, folder, dialect="fanuc").output.splitlines() if ln.startswith("    line")]
    assert listed
    assert all(re.match(r"    line +\d+ -> +\d+: dX", ln) for ln in listed)


def test_diff_of_a_fanuc_program_file_called_by_m98(tmp_path):
    sub = "%\nO5001 (SUB)\nG1 X60 Y10 F100\n  G1 X70\nM99\n%\n"
    text = "%\nO1\nG21 G90 G17\nG0 X10 Y10 Z10\nM98 P5001\nG1 X20 F100\nM30\n%\n"
    src, dst, folder = corrected_pair(tmp_path, text, {"5001.NC": sub}, dialect="fanuc", name="o1.nc")
    res = diff_cli(src, dst, folder, "--all", dialect="fanuc")
    assert res.exit_code == 0, res.output
    assert f"    line {folder / '5001.NC'}:4 ->" in res.output
    assert "    line      6 ->" in res.output


def test_diff_refuses_a_block_moved_too_far_naming_its_subprogram_file(tmp_path):
    src, dst, folder = corrected_pair(tmp_path)
    res = diff_cli(src, dst, folder, "--max-correction", "0.001")
    assert res.exit_code == 5
    # the largest move is a line of the subprogram: the corrected line, and the line it comes from
    d = compare_programs(str(src), str(dst), options=CorrectOptions(dialect="linuxcnc", subroutine_path=(folder,)))
    m = d.largest(1)[0]
    assert m.file == str(folder / "far.ngc")
    assert (f"{dst}:{m.lineno_corrected}:1: block moved by {m.size_mm:.4f} mm (line {m.lineno} of {m.file}), "
            "more than --max-correction 0.001 mm") in res.output
    assert "hint: a correction this large" in res.output


def test_diff_refusal_of_a_line_of_the_subprogram_names_its_file(tmp_path):
    src, dst, folder = corrected_pair(tmp_path)
    # the subprogram's comment changed in the corrected program
    dst.write_text(dst.read_text().replace("(back)", "(away)"))
    with pytest.raises(PostprocError) as err:
        compare_programs(str(src), str(dst), options=CorrectOptions(dialect="linuxcnc", subroutine_path=(folder,)))
    c_line = dst.read_text().splitlines().index("(away)") + 1
    assert err.value.path == str(dst)
    assert err.value.lineno == c_line
    assert (f"line {c_line} of the corrected program differs from line 7 of {folder / 'far.ngc'} "
            "(called by the original)") in err.value.message
    # and of the program's own line, as before
    src2, dst2, folder2 = corrected_pair(tmp_path, MAIN.replace("G0 X10", "(start)\nG0 X10"))
    dst2.write_text(dst2.read_text().replace("(start)", "(begin)"))
    with pytest.raises(PostprocError) as err:
        compare_programs(str(src2), str(dst2), options=CorrectOptions(dialect="linuxcnc", subroutine_path=(folder2,)))
    assert err.value.message.endswith("differs from line 2 of the original")


def test_diff_reads_the_files_in_bulk_as_line_by_line(monkeypatch, tmp_path):
    folder = tmp_path / "subs"
    folder.mkdir()
    (folder / "far.ngc").write_text(FAR)
    options = compare._ReadOptions(dialect="linuxcnc", expand=True, subroutine_path=(folder,))
    text = MAIN.replace("o<far> call", "o<far> call\no<far> call")
    src = tmp_path / "main.ngc"
    src.write_text(text)

    def rows(bulk_lane: bool) -> tuple[list, list]:
        rd = compare._Reader(str(src), SETUP, compare._Keys(), options)
        rd._rd.use_bulk = bulk_lane
        parts = list(rd.chunks())
        files = [f for p in parts for f in (p.files.tolist() if p.files is not None else [None] * len(p))]
        return np.concatenate([p.lineno for p in parts]).tolist(), files

    want = rows(False)
    far = str(folder / "far.ngc")
    assert [(f, n) for n, f in zip(*want, strict=True) if f is not None] == [(far, n) for n in range(2, 9)] * 2
    spied: list[int] = []
    real = compare._LineRows.queue_run
    monkeypatch.setattr(compare._LineRows, "queue_run", lambda self, run: (spied.append(len(run)), real(self, run)))
    assert rows(True) == want
    assert max(spied) >= 4  # read in runs


@pytest.mark.skipif(not forking.available(), reason="no fork on this system")
def test_diff_names_the_files_of_an_original_read_in_a_child(monkeypatch, tmp_path):
    src, dst, folder = corrected_pair(tmp_path)
    options = CorrectOptions(dialect="linuxcnc", subroutine_path=(folder,))
    want = [(m.lineno, m.file) for m in compare_programs(str(src), str(dst), options=options).moved]
    monkeypatch.setattr(compare, "FORK_MIN_BYTES", 0)
    assert [(m.lineno, m.file) for m in compare_programs(str(src), str(dst), options=options).moved] == want


def test_the_largest_blocks_kept_keep_their_files(monkeypatch):
    monkeypatch.setattr(DiffReport, "_limit", lambda self: self.keep)  # pruned as soon as more are stored
    rep = DiffReport("main.ngc", "out.ngc", keep=2)
    rep.add_moved(1, 1, (0.001, 0.0, 0.0))
    rep.add_moved_rows(np.array([5, 6, 7]), np.array([2, 3, 4]), np.array([[0.003, 0, 0], [0.0, 0.002, 0], [0.004, 0, 0]]),
                       np.array(["sub.ngc", None, "other.ngc"], dtype=object))
    rep.add_moved(8, 5, (0.0, 0.0, 0.005), "sub.ngc")
    assert [(m.lineno, m.file) for m in rep.largest(2)] == [(8, "sub.ngc"), (7, "other.ngc")]
    assert rep.axis_stats()["X"]["max_mm"] == 0.004


# -- the path's samples --------------------------------------------------------------------
def test_samples_of_an_expanded_program_give_the_file_of_their_line(monkeypatch, tmp_path):
    src, _dst, folder = corrected_pair(tmp_path)
    far = str(folder / "far.ngc")

    def sampled():
        return sample_program(str(src), SETUP, step_mm=5.0, dialect="linuxcnc", subroutine_path=[folder])

    pp = sampled()
    assert pp.files is not None
    assert len(pp.files) == len(pp)
    theirs = np.array([f is not None for f in pp.files.tolist()])
    assert set(pp.files[theirs].tolist()) == {far}
    assert sorted(set(pp.lineno[theirs].tolist())) == [2, 3, 4, 5, 6, 8]
    assert sorted(set(pp.lineno[~theirs].tolist())) == [2, 4]
    # the same read line by line (no runs)
    monkeypatch.setattr(bulk, "scan", lambda lines: None)
    again = sampled()
    np.testing.assert_array_equal(again.lineno, pp.lineno)
    assert again.files is not None
    assert again.files.tolist() == pp.files.tolist()


def test_samples_of_a_program_read_as_written_name_no_file(tmp_path):
    prog = tmp_path / "plain.ngc"
    prog.write_text("G21 G90 G17\nG0 X10 Y10 Z10\nG1 X90 F100\nG1 Y50\nM2\n")
    assert sample_program(str(prog), SETUP, step_mm=5.0).files is None


def test_the_sampling_bound_is_refused_at_the_subprograms_line(tmp_path):
    src, _dst, folder = corrected_pair(tmp_path)
    with pytest.raises(ResourceLimitError) as err:
        sample_program(str(src), SETUP, step_mm=1.0, dialect="linuxcnc", subroutine_path=[folder], max_samples=40)
    assert (err.value.path, err.value.lineno, err.value.col) == (str(folder / "far.ngc"), 2, 1)
    assert "hint: give postproc verify a larger --max-step" in str(err.value)


def test_an_axis_never_positioned_is_refused_at_the_subprograms_line(tmp_path):
    folder = tmp_path / "subs"
    folder.mkdir()
    (folder / "xy.ngc").write_text("o<xy> sub\n  G0 X10 Y10\nG1 X20 F100\no<xy> endsub\nM2\n")
    prog = tmp_path / "main.ngc"
    prog.write_text("G21 G90 G17\no<xy> call\nM2\n")
    with pytest.raises(MissingSetupError, match="axis Z is never positioned") as err:
        sample_program(str(prog), Setup(), dialect="linuxcnc", subroutine_path=[folder])
    assert (err.value.path, err.value.lineno, err.value.with_column().col) == (str(folder / "xy.ngc"), 2, 3)


# -- Sinumerik drilling cycle refused: the column of its call -----------------------------
CAL_ARGS = ["-c", STATIC, "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100"]


@pytest.mark.parametrize(("call", "col"), [
    ("   CYCLE81(10, 0, 2, -5)", 4),
    ("N20 CYCLE81(10, 0, 2, -5)", 5),
    ("N20   CYCLE82(10, 0, 2, -5, , 1)", 7),
    ("N20 MCALL CYCLE81(10, 0, 2, -5)", 5),
    ("CYCLE81(10, 0, 2, -5)", 1),
])
def test_a_cycle_call_refused_points_at_its_column(tmp_path, call, col):
    prog = tmp_path / "drl.mpf"
    prog.write_text(f"G54 D1\nG0 X10 Y10 Z20 F100\n{call}\nX20\nMCALL\nM30\n")
    res = CliRunner().invoke(main, ["correct", str(prog), *CAL_ARGS, "--cycles", "keep", "--dialect", "sinumerik",
                                    "-o", str(tmp_path / "o.mpf")])
    assert res.exit_code != 0
    assert f"{prog}:3:{col}: Sinumerik " in res.output
    assert "(drilling cycle call): read only when written as its moves" in res.output
    assert "hint: give --cycles expand or auto" in res.output


def test_a_cycle_call_in_a_subprogram_refused_at_its_file_line_and_column(tmp_path):
    folder = tmp_path / "subs"
    folder.mkdir()
    (folder / "DRL.SPF").write_text("PROC DRL\nG0 X10 Y10 Z10\n   N30 CYCLE81(10, 0, 2, -5)\nRET\n")
    prog = tmp_path / "main.mpf"
    prog.write_text("G54 D1\nG0 X10 Y10 Z10\nDRL\nM30\n")
    res = CliRunner().invoke(main, ["correct", str(prog), *CAL_ARGS, "--cycles", "keep", "--dialect", "sinumerik",
                                    "--subroutine-path", str(folder), "-o", str(tmp_path / "o.mpf")])
    assert res.exit_code != 0
    assert f"{folder / 'DRL.SPF'}:3:8: Sinumerik CYCLE81 (drilling cycle call)" in res.output


def test_a_modal_cycle_refused_where_it_runs_points_at_that_block(tmp_path):
    # MCALL's parameters are read when the cycle runs, after the block that moves: the
    # refusal names that block's line and its start, not a column of the MCALL line
    prog = tmp_path / "drl.mpf"
    prog.write_text("G54 D1\nG0 X10 Y10 Z20 F100\nN10 MCALL CYCLE81(10, 0, 2)\n  N20 X20\nMCALL\nM30\n")
    res = CliRunner().invoke(main, ["correct", str(prog), *CAL_ARGS, "--dialect", "sinumerik",
                                    "-o", str(tmp_path / "o.mpf")])
    assert res.exit_code != 0
    assert f"{prog}:4:3: Sinumerik CYCLE81 without its final depth (DP or DPR)" in res.output
