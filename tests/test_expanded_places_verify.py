"""The worst lines of ``postproc verify`` and the refusals of ``postproc mirror pockets``
name the file of a line that comes from a subprogram's file (``subs/far.ngc:3``, in
``--json`` a ``"file"`` key on that line only), and verify shows that file's line.

A program read as written, or expanded in its own file, keeps its bare line numbers."""

from __future__ import annotations

import json
import re
from pathlib import Path

from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.gcode.pipeline import CorrectOptions
from postproc.mirror.synthetic import (
    Shell,
    plan_csv,
    pocket_program,
    shell_calibration_text,
    thickness_csv,
)
from postproc.simulate import load_machine
from postproc.simulate.program import verify_program
from postproc.simulate.verify import VerifyReport

ROOT = Path(__file__).resolve().parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
S500 = str(ROOT / "calibrations" / "s500.machine.json")
SETUP_ARGS = ["--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100"]
SETUP = {"offsets": {"G54": (100.0, 100.0, 100.0)}, "tool_lengths": {1: 100.0}}

# two feed lines in each file, one of them at the same line number (3) in both
FAR = "o<far> sub\n(go)\nG1 X90 Y10 F100\nG1 X50 Y30\no<far> endsub\nM2\n"
MAIN = "G21 G90 G17\nG0 X10 Y10 Z10\nG1 X20 F100\no<far> call\nG1 X20 Y40\nM2\n"


def expanded(tmp_path: Path, text: str = MAIN, subs: dict[str, str] | None = None,
             name: str = "main.ngc") -> tuple[Path, Path]:
    """The program ``text`` calling the files ``subs`` in the folder ``subs/``."""
    folder = tmp_path / "subs"
    folder.mkdir(exist_ok=True)
    for sub, body in ({"far.ngc": FAR} if subs is None else subs).items():
        (folder / sub).write_text(body)
    src = tmp_path / name
    src.write_text(text)
    return src, folder


def verify_cli(src: Path, folder: Path, *extra: str, dialect: str = "linuxcnc"):
    return CliRunner().invoke(main, ["verify", str(src), "-c", STATIC, "--machine", S500, *SETUP_ARGS,
                                     "--dialect", dialect, "--subroutine-path", str(folder), *extra])


def worst_rows(output: str) -> dict[str, list[tuple[str, str]]]:
    """The worst lines of each run of verify's text report: (place, text)."""
    rows: dict[str, list[tuple[str, str]]] = {}
    run = ""
    for line in output.splitlines():
        if m := re.match(r"  worst lines, (.*):$", line):
            run = m.group(1)
            rows[run] = []
        elif m := re.match(r" +[\d.]+ um  line (\S+): (.*)$", line):
            rows[run].append((m.group(1), m.group(2)))
    return rows


# -- postproc verify ------------------------------------------------------------------
def test_verify_names_the_file_and_text_of_a_subprograms_worst_line(tmp_path):
    src, folder = expanded(tmp_path)
    far = folder / "far.ngc"
    res = verify_cli(src, folder)
    assert res.exit_code == 0, res.output
    rows = worst_rows(res.stdout)
    assert list(rows) == ["uncorrected", "corrected, static (s500_static)"]
    for listed in rows.values():
        # line 3 of each file is listed once each, with its own text
        assert sorted(listed) == sorted([("3", "G1 X20 F100"), ("5", "G1 X20 Y40"),
                                         (f"{far}:3", "G1 X90 Y10 F100"), (f"{far}:4", "G1 X50 Y30")])


def test_verify_json_gives_the_file_of_a_subprogram_line_only(tmp_path):
    src, folder = expanded(tmp_path)
    res = verify_cli(src, folder, "--json")
    assert res.exit_code == 0, res.output
    worst = json.loads(res.stdout)["runs"][0]["worst_lines"]
    own = [w for w in worst if "file" not in w]
    theirs = [w for w in worst if "file" in w]
    assert sorted((w["line"], w["text"]) for w in own) == [(3, "G1 X20 F100"), (5, "G1 X20 Y40")]
    assert sorted((w["line"], w["file"], w["text"]) for w in theirs) == [
        (3, str(folder / "far.ngc"), "G1 X90 Y10 F100"), (4, str(folder / "far.ngc"), "G1 X50 Y30")]
    assert list(theirs[0]) == ["line", "file", "deviation_mm", "text"]
    assert list(own[0]) == ["line", "deviation_mm", "text"]


def test_verify_program_gives_the_file_of_each_worst_line(tmp_path):
    src, folder = expanded(tmp_path)
    far = str(folder / "far.ngc")
    rep = verify_program(src, load_machine(S500), [load_calibration(STATIC)], SETUP,
                         options=CorrectOptions(dialect="linuxcnc", subroutine_path=(str(folder),)))
    run = rep.runs[0]
    assert sorted((ln, f or "") for ln, f, _d in run.worst_places()) == [(3, ""), (3, far), (4, far), (5, "")]
    # the pairs of worst_lines() follow worst_places(), without the file
    assert run.worst_lines() == [(ln, d) for ln, _f, d in run.worst_places()]
    assert rep.line_text(3, far) == "G1 X90 Y10 F100"
    assert rep.line_text(3) == "G1 X20 F100"
    assert set(run.nominal_sample_file.tolist()) == {None, far}


def test_line_text_of_a_file_that_cannot_be_read_is_empty(tmp_path):
    rep = VerifyReport(source_lines=["G1 X1"])
    assert rep.line_text(1, str(tmp_path / "gone.ngc")) == ""
    (tmp_path / "sub.ngc").write_text("o<sub> sub\r\nG1 X2\rG1 X3\n")  # the reader's line ends
    assert [rep.line_text(n, str(tmp_path / "sub.ngc")) for n in (2, 3, 4)] == ["G1 X2", "G1 X3", ""]


def test_verify_of_a_program_expanded_in_its_own_file_keeps_bare_lines(tmp_path):
    # a Fanuc subprogram of the program's own file, called three times: no file named
    text = ("%\nO1000\nG21 G90 G17\nG54\nG0 X10 Y10 Z10\nM98 P2000 L3\nG0 Z50.\nM30\nO2000\nG91 G1 X5. F500.\n"
            "G90\nM99\n%\n")
    src, folder = expanded(tmp_path, text, {}, name="o1000.nc")
    res = verify_cli(src, folder, dialect="fanuc")
    assert res.exit_code == 0, res.output
    assert all(rows == [("10", "G91 G1 X5. F500.")] for rows in worst_rows(res.stdout).values())
    res = verify_cli(src, folder, "--json", dialect="fanuc")
    assert all(list(w) == ["line", "deviation_mm", "text"]
               for run in json.loads(res.stdout)["runs"] for w in run["worst_lines"])


def test_a_program_read_as_written_has_no_files_in_its_runs(tmp_path):
    prog = tmp_path / "plain.ngc"
    prog.write_text("G21 G90 G17\nG0 X10 Y10 Z10\nG1 X90 F100\nG1 Y50\nM2\n")
    rep = verify_program(prog, load_machine(S500), [load_calibration(STATIC)], SETUP)
    for run in rep.runs:
        assert run.nominal_file is None
        assert run.nominal_sample_file is None
        assert all(f is None for _ln, f, _d in run.worst_places())
        assert "file" not in json.dumps(run.to_dict())
    assert sorted(ln for ln, _d in rep.runs[0].worst_lines()) == [3, 4]


# -- postproc mirror pockets ----------------------------------------------------------
def test_mirror_pockets_names_the_subprogram_line_outside_the_map(tmp_path):
    shell = Shell()
    prog = pocket_program(shell, -5.0)
    # the last pass moves into a subprogram file, one of its points outside the map
    tail = prog.index("G0 Y-25.0000\nM30")
    sub = "o<far> sub\n(out of the pocket)\n  G1 B9.0000\nG1 B3.7500\no<far> endsub\nM2\n"
    src, folder = expanded(tmp_path, prog[:tail] + "o<far> call\n" + prog[tail:], {"far.ngc": sub}, "pocket.ngc")
    (tmp_path / "cal.json").write_text(shell_calibration_text())
    b, z = shell.local_grid()
    (tmp_path / "s.csv").write_text(thickness_csv(shell.machine(0, b, z, -0.3), "semi"))
    (tmp_path / "plan.csv").write_text(plan_csv(shell, [("s.csv", "")]))
    args = ["mirror", "pockets", str(tmp_path / "plan.csv"), "-c", str(tmp_path / "cal.json"),
            "--program", str(src), "--t-ref", "2.0", "--band", "1.98,2.02", "--allowance", "0.3",
            "--dialect", "linuxcnc", "--subroutine-path", str(folder), "-o", str(tmp_path / "out")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 5, res.output
    assert f"{folder / 'far.ngc'}:3:3: program point B=9.0000" in res.output
    assert "outside the correction map" in res.output
    assert not (tmp_path / "out").exists()
    # a point outside the map on the program's own line names the program, as before
    src.write_text(prog.replace("B3.7500", "B9.0000", 1))
    lineno = next(k for k, ln in enumerate(src.read_text().splitlines(), 1) if "B9.0000" in ln)
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 5, res.output
    assert f"{src}:{lineno}:1: program point B=9.0000" in res.output
