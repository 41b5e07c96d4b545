"""Hostile inputs that were accepted with exit 0, or hung, in the hostile-input survey
(benchmarks/hostile_after.json): each is refused with a documented exit code, naming its
file (and line and column where there is one), and nothing is written."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import ROOT
from oracle import RS274, requires_rs274

from postproc.cli import main
from postproc.errors import (
    EXIT_CALIBRATION,
    EXIT_INPUT,
    EXIT_USAGE,
    GcodeSyntaxError,
    PostprocError,
)
from postproc.fileio import (
    MAX_INPUT_LINE_CHARS,
    bounded_blocks,
    count_lines,
    read_blocks,
    read_lines,
)
from postproc.gcode.expand import expand
from postproc.gcode.lexer import split_lines

STATIC = str(ROOT / "calibrations" / "s500_static.json")
PARAMETRIC = str(ROOT / "calibrations" / "s500_parametric.json")
MACHINE = ROOT / "calibrations" / "s500.machine.json"
SIMPLE = "G21 G90\nG0 X10 Y10 Z10\nG1 X100 Y100 Z20 F500\nM2\n"


def run(*args: str, input: str | bytes | None = None):
    return CliRunner().invoke(main, list(args), input=input)


def refused(result, code: int, *fragments: str) -> str:
    assert result.exit_code == code, result.output
    assert "Traceback" not in result.output
    for f in fragments:
        assert f in result.output
    return result.output


# -- programs with nothing to correct -------------------------------------------------

@pytest.mark.parametrize("text", ["(just a comment)\n; another\n", "%\n%\n", "%\n(header only)\n\n%\n"],
                         ids=["comments", "percent", "percent-and-comment"])
def test_a_program_without_code_is_refused_and_nothing_written(tmp_path, text):
    src = tmp_path / "p.nc"
    src.write_text(text)
    out = tmp_path / "out.nc"
    res = run("correct", str(src), "-c", STATIC, "-o", str(out))
    refused(res, EXIT_INPUT, f"{src}: the program holds only comments", "hint:")
    assert not out.exists()


def test_a_program_without_code_on_stdin_and_in_a_folder(tmp_path):
    res = run("correct", "-", "-c", STATIC, "-o", str(tmp_path / "o.nc"), input="(nothing)\n")
    refused(res, EXIT_INPUT, "<stdin>: the program holds only comments")
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "a.nc").write_text("(nothing)\n")
    (folder / "b.nc").write_text(SIMPLE)
    res = run("correct", str(folder), "-c", STATIC, "--output-dir", str(tmp_path / "out"))
    refused(res, EXIT_INPUT, "1 corrected, 1 refused", "a.nc: the program holds only comments")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["b.nc"]


# -- blocks left open ----------------------------------------------------------------------

OPEN_AT_M2 = {
    "while": "G21 G90\nG0 X10 Y10 Z10\no100 while [#1 LT 3]\nG1 X20 F100\nM2\n",
    "if": "G21 G90\nG0 X10 Y10 Z10\no100 if [1]\nG1 X20 F100\nM2\n",
}


@pytest.mark.parametrize("text", OPEN_AT_M2.values(), ids=OPEN_AT_M2.keys())
def test_a_block_left_open_by_m2_runs_as_on_linuxcnc(text):
    """rs274 runs these (exit 0): M2 ends the program before the block's end is looked
    for. The expansion is the program as LinuxCNC runs it."""
    flat = [sl.text for sl in expand(split_lines(text), path="p.ngc", dialect="linuxcnc")]
    assert flat == ["G21 G90\n", "G0 X10 Y10 Z10\n", "G1 X20 F100\n", "M2\n"]


@requires_rs274
@pytest.mark.parametrize("text", OPEN_AT_M2.values(), ids=OPEN_AT_M2.keys())
def test_rs274_runs_a_block_left_open_by_m2(tmp_path, text):
    p = tmp_path / "p.ngc"
    p.write_text(text)
    r = subprocess.run([RS274, "-g", str(p)], stdin=subprocess.DEVNULL, capture_output=True, timeout=60)
    assert r.returncode == 0, r.stderr


OPEN_AT_EOF = {
    "while": ("G21 G90\nG0 X10 Y10 Z10\no100 while [#1 LT 3]\nG1 X20 F100\n", "'o100 while' is never closed"),
    "repeat": ("G21 G90\no7 repeat [2]\nG1 X20 F100\n", "'o7 repeat' is never closed"),
    "do": ("G21 G90\no8 do\nG1 X20 F100\n", "'o8 do' is never closed"),
    "if-false": ("G21 G90\nG0 X10 Y10 Z10\no100 if [0]\nG1 X20 F100\nM2\n", "file ended before the o100 line"),
}


@pytest.mark.parametrize(("text", "message"), OPEN_AT_EOF.values(), ids=OPEN_AT_EOF.keys())
def test_a_file_that_ends_inside_an_open_block_is_refused(text, message):
    """The file ends (no M2, no closing %) inside a loop or if that no line closes: rs274
    refuses such a file ("File ended with no percent sign or program end")."""
    with pytest.raises(GcodeSyntaxError) as err:
        list(expand(split_lines(text), path="p.ngc", dialect="linuxcnc"))
    assert message in err.value.message
    assert (err.value.path, err.value.col) == ("p.ngc", 1)
    assert err.value.lineno == next(k for k, line in enumerate(split_lines(text), 1) if line.startswith("o"))


@requires_rs274
@pytest.mark.parametrize(("text", "message"), OPEN_AT_EOF.values(), ids=OPEN_AT_EOF.keys())
def test_rs274_refuses_a_file_that_ends_inside_an_open_block(tmp_path, text, message):
    p = tmp_path / "p.ngc"
    p.write_text(text)
    r = subprocess.run([RS274, "-g", str(p)], stdin=subprocess.DEVNULL, capture_output=True, timeout=60)
    assert r.returncode != 0


def test_a_closed_block_at_the_end_of_the_file_is_not_refused():
    text = "G21 G90\n#1=0\no100 while [#1 LT 2]\nG1 X[#1] F100\n#1=[#1+1]\no100 endwhile\n"
    assert len(list(expand(split_lines(text), path="p.ngc", dialect="linuxcnc"))) == 3


@pytest.mark.parametrize("head", ["WHILE [#1 LT 3] DO1", "DO2"])
def test_a_fanuc_do_without_its_end_is_refused_where_it_first_runs(tmp_path, head):
    """Fanuc: DO and END must be paired (alarm PS0126): refused at the DO even when the
    program ends (M30) inside the loop before the END would be looked for."""
    text = f"%\nO1000\nG21 G90\nG0 X10 Y10 Z10\n{head}\n#1=#1+1\nM30\n%\n"
    with pytest.raises(GcodeSyntaxError) as err:
        list(expand(split_lines(text), path="p.nc", dialect="fanuc"))
    assert "has no END" in err.value.message
    assert "PS0126" in err.value.message
    assert (err.value.lineno, err.value.col) == (5, 1)
    src = tmp_path / "p.nc"
    src.write_text(text)
    res = run("correct", str(src), "-c", STATIC, "-o", str(tmp_path / "o.nc"), "--dialect", "fanuc")
    refused(res, EXIT_INPUT, f"{src}:5:")
    assert not (tmp_path / "o.nc").exists()


def test_a_fanuc_loop_with_its_end_still_runs():
    text = "%\nO1000\n#1=0\nWHILE [#1 LT 3] DO1\nG1 X#1 F100\n#1=#1+1\nEND1\nM30\n%\n"
    flat = [sl.text for sl in expand(split_lines(text), path="p.nc", dialect="fanuc")]
    assert [t for t in flat if t.startswith("G1")] == ["G1 X0.0 F100\n", "G1 X1.0 F100\n", "G1 X2.0 F100\n"]


# -- options and files of the other commands -------------------------------------------------

@pytest.mark.parametrize("profile", ["nan", "inf", "20:nan", "20:23:inf", "1e400", "20:23:0", "5000"])
def test_simulate_temp_profile_must_be_finite(tmp_path, profile):
    out = tmp_path / "sim.csv"
    res = run("simulate", str(MACHINE), "--static-set", "-o", str(out), "--temp-profile", profile)
    refused(res, EXIT_USAGE, "--temp-profile")
    assert not out.exists()


@pytest.mark.parametrize("point", ["1e308,0,0", "0,-2e6,0", "0,0,1e7"])
def test_orders_point_beyond_any_machine_is_refused(point):
    res = run("orders", "-c", PARAMETRIC, "--point", point)
    refused(res, EXIT_USAGE, "--point", "beyond")


def test_machine_volume_beyond_100_m_is_refused(tmp_path):
    data = json.loads(MACHINE.read_text())
    data["volume_mm"] = [[0, 0, 0], [1e308, 1e308, 1e308]]
    for name in ("s500_tables.csv", "s500_tables_squareness.csv"):
        (tmp_path / name).write_bytes((ROOT / "calibrations" / name).read_bytes())
    bad = tmp_path / "bad.machine.json"
    bad.write_text(json.dumps(data))
    res = run("simulate", str(bad), "--static-set", "-o", str(tmp_path / "sim.csv"))
    refused(res, EXIT_CALIBRATION, f"{bad}: machine volume_mm", "100 m")
    assert not (tmp_path / "sim.csv").exists()


def _calibration(tmp_path, change) -> Path:
    data = json.loads(Path(STATIC).read_text())
    change(data)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize(("change", "fragment"), [
    (lambda d: d["model"].__setitem__("G", [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]),
     'model.G[0][0] is "1"'),
    (lambda d: d["model"].__setitem__("G", [[True, 0, 0], [0, 1, 0], [0, 0, 1]]), "model.G[0][0] is true"),
    (lambda d: d["model"].__setitem__("r_O1_mm", [None, 0, 0]), "model.r_O1_mm[0] is null"),
    (lambda d: d.__setitem__("effects", [{"name": "backlash:X"}]), "effects[0] (backlash:X) does not give"),
    (lambda d: d.__setitem__("effects", [{"name": "backlash:X", "params": {}}]), "b_mm"),
], ids=["g-strings", "g-bool", "origin-null", "effect-no-params", "effect-empty-params"])
def test_calibrations_that_would_be_read_as_something_else_are_refused(tmp_path, change, fragment):
    cal = _calibration(tmp_path, change)
    src = tmp_path / "p.nc"
    src.write_text(SIMPLE)
    res = run("correct", str(src), "-c", str(cal), "-o", str(tmp_path / "o.nc"))
    refused(res, EXIT_CALIBRATION, f"{cal}: ", fragment)
    assert not (tmp_path / "o.nc").exists()


def test_an_effect_with_all_its_params_is_still_read(tmp_path):
    cal = _calibration(tmp_path, lambda d: d.__setitem__("effects", [{"name": "backlash:Z", "params": {"b_mm": 0.0}}]))
    src = tmp_path / "p.nc"
    src.write_text(SIMPLE)
    res = run("correct", str(src), "-c", str(cal), "-o", str(tmp_path / "o.nc"))
    assert res.exit_code == 0, res.output


def test_axis_table_positions_closer_than_a_micrometre_are_refused_at_their_cell(tmp_path):
    tables = tmp_path / "t.csv"
    tables.write_text("# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                      "X,0,0,0,0,0,0,0\nX,0.000000001,0,0,0,0,0,0\nX,300,0,0,0,0,0,0\n")
    res = run("fit", str(tables), "-o", str(tmp_path / "fitted.json"))
    refused(res, EXIT_INPUT, f"{tables}:5:3: axis X: position 1e-09", "at least 1 um apart")
    assert not (tmp_path / "fitted.json").exists()


def test_parametric_calibration_table_positions_closer_than_a_micrometre_are_refused(tmp_path):
    data = json.loads(Path(PARAMETRIC).read_text())
    x = data["model"]["tables"]["X"]["position_mm"]
    x[1] = x[0] + 1e-9
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(data))
    src = tmp_path / "p.nc"
    src.write_text(SIMPLE)
    res = run("correct", str(src), "-c", str(cal), "-o", str(tmp_path / "o.nc"))
    refused(res, EXIT_CALIBRATION, "X table positions are closer than 1 um")


# -- a file without line ends ---------------------------------------------------------------

class _Endless(io.RawIOBase):
    """/dev/zero, counting what is read from it."""

    def __init__(self, byte: bytes = b"\0"):
        self.byte = byte
        self.given = 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = len(b)
        b[:n] = self.byte * n
        self.given += n
        return n


@pytest.mark.parametrize("reader", [read_lines, read_blocks])
def test_reading_a_stream_without_line_ends_stops_at_the_line_bound(reader):
    raw = _Endless(b"G")
    text = io.TextIOWrapper(io.BufferedReader(raw, buffer_size=4096), encoding="utf-8", newline="")
    with pytest.raises(PostprocError) as err:
        list(reader(text, "p.nc", limit=100_000))
    assert (err.value.path, err.value.lineno, err.value.col) == ("p.nc", 1, 1)
    assert "line longer than 100,000 characters" in err.value.message
    assert raw.given < 100_000 + 2 * 65_536  # the bound, a read of read_blocks, and the decoder's read-ahead
    raw = _Endless()
    with pytest.raises(PostprocError):
        for _ in bounded_blocks(raw, "<stdin>"):
            pass
    assert raw.given <= 2 * MAX_INPUT_LINE_CHARS


def test_lines_up_to_the_bound_are_read_and_counted(tmp_path):
    p = tmp_path / "p.nc"
    long = "(" + "a" * (MAX_INPUT_LINE_CHARS - 3) + ")\n"
    p.write_text("G0 X1\r\n" + long + "G1 X2")
    with open(p, encoding="utf-8", newline="") as fh:
        assert list(read_lines(fh)) == ["G0 X1\r\n", long, "G1 X2"]
    assert count_lines(str(p)) == 3
    p.write_text("G0 X1\n" + "(" + "a" * MAX_INPUT_LINE_CHARS + ")\nM2\n")
    with pytest.raises(PostprocError) as err:
        count_lines(str(p))
    assert err.value.lineno == 2


@pytest.mark.parametrize("how", ["file", "stdin"])
def test_dev_zero_as_the_program_is_refused_at_once(tmp_path, how):
    out = tmp_path / "out.nc"
    argv = [sys.executable, "-m", "postproc", "correct", "/dev/zero" if how == "file" else "-", "-c", STATIC,
            "-o", str(out)]
    t0 = time.monotonic()
    with open("/dev/zero", "rb") as zero:
        r = subprocess.run(argv, stdin=zero if how == "stdin" else subprocess.DEVNULL, capture_output=True,
                           timeout=60, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "TMPDIR": str(tmp_path)})
    assert time.monotonic() - t0 < 30
    err = r.stderr.decode()
    assert r.returncode == EXIT_INPUT, err
    assert f"{'/dev/zero' if how == 'file' else '<stdin>'}:1:1: line longer than" in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# -- endless loops: found in two passes, or at the count that passes the bound -----------

ENDLESS = {
    "while [1]": ("G21 G90\nG0 X10 Y10 Z10\no100 while [1]\nG1 X20 F100\nG1 X10\no100 endwhile\nM2\n", "linuxcnc", 6),
    "while [1] empty": ("G21 G90\no100 while [1]\no100 endwhile\nM2\n", "linuxcnc", 3),
    "do while [1]": ("G21 G90\no100 do\nG1 X20 F100\no100 while [1]\nM2\n", "linuxcnc", 4),
    "while with a setting of the same value": ("G21 G90\no1 while [1]\n#1 = 1\n#<a> = 2\no1 endwhile\nM2\n",
                                               "linuxcnc", 5),
    "Fanuc WHILE": ("%\nO1000\n#1=1\nWHILE [#1 EQ 1] DO1\nG1 X20 F100\nEND1\nM30\n%\n", "fanuc", 6),
    "Fanuc GOTO": ("%\nO1000\nN10 G1 X20 F100\nG1 X10\nGOTO 10\nM30\n%\n", "fanuc", 5),
    "Fanuc IF GOTO": ("%\nO1000\n#1=0\nN10 G1 X20 F100\nIF [#1 EQ 0] GOTO 10\nM30\n%\n", "fanuc", 5),
}


@pytest.mark.parametrize(("text", "dialect", "lineno"), ENDLESS.values(), ids=ENDLESS.keys())
def test_a_loop_whose_pass_changes_nothing_is_refused_at_its_second_pass(text, dialect, lineno):
    from postproc.limits import ResourceLimitError

    with pytest.raises(ResourceLimitError) as err:
        list(expand(split_lines(text), path="p.nc", dialect=dialect))
    assert "endless loop" in err.value.message
    assert (err.value.path, err.value.lineno) == ("p.nc", lineno)
    assert err.value.col is not None


LOOPS_THAT_END = {
    "counter": ("#1=0\no1 while [#1 LT 5]\nG1 X[#1] F100\n#1=[#1+1]\no1 endwhile\nM2\n", 5),
    "same value set, count changes": ("#2=0\no1 while [#2 LT 4]\n#1=1\nG1 X1 F100\n#2=[#2+1]\no1 endwhile\nM2\n", 4),
    "nested, inner reset each pass": ("#1=0\no1 while [#1 LT 3]\n#2=0\no2 while [#2 LT 3]\nG1 X[#2] F100\n"
                                      "#2=[#2+1]\no2 endwhile\n#1=[#1+1]\no1 endwhile\nM2\n", 9),
    "break": ("#1=0\no1 while [1]\nG1 X1 F100\n#1=[#1+1]\no2 if [#1 GE 3]\no1 break\no2 endif\no1 endwhile\nM2\n", 3),
    "repeat": ("o1 repeat [4]\nG1 X1 F100\no1 endrepeat\nM2\n", 4),
    "call in a loop": ("o9 sub\nG1 X#1 F100\no9 endsub\n#2=0\no1 while [#2 LT 3]\no9 call [#2]\n#2=[#2+1]\no1 endwhile\nM2\n",
                       3),
}


@pytest.mark.parametrize(("text", "moves"), LOOPS_THAT_END.values(), ids=LOOPS_THAT_END.keys())
def test_loops_that_end_are_not_taken_for_endless(text, moves):
    flat = list(expand(split_lines("G21 G90\n" + text), path="p.ngc", dialect="linuxcnc"))
    assert sum(sl.text.startswith("G1") for sl in flat) == moves


def test_fanuc_loops_that_end_are_not_taken_for_endless():
    text = "%\nO1000\n#1=0\nN10 G1 X#1 F100\n#1=#1+1\nIF [#1 LT 3] GOTO 10\nM98 P2000 L3\nM30\nO2000\nG1 X9\nM99\n%\n"
    flat = list(expand(split_lines(text), path="p.nc", dialect="fanuc"))
    assert sum("G1" in sl.text for sl in flat) == 6


@pytest.mark.parametrize(("text", "dialect"), [
    ("%\nO1000\nM98 P2000 L99999999\nM30\nO2000\nG1 X20 F100\nM99\n%\n", "fanuc"),
    ("%\nO1000\nM98 P2000 L10000001\nM30\nO2000\nG1 X20 F100\nM99\n%\n", "fanuc"),
    ("G21\no1 repeat [100000000]\nG1 X1 F100\no1 endrepeat\nM2\n", "linuxcnc"),
])
def test_a_repeat_count_beyond_the_bound_is_refused_at_its_call(text, dialect):
    from postproc.limits import ResourceLimitError

    t0 = time.monotonic()
    with pytest.raises(ResourceLimitError) as err:
        list(expand(split_lines(text), path="p.nc", dialect=dialect))
    assert time.monotonic() - t0 < 5
    assert "--max-iterations" in str(err.value)
    assert err.value.lineno in (2, 3)
    assert list(expand(split_lines(text.replace("99999999", "3").replace("10000001", "3").replace("100000000", "3")),
                       path="p.nc", dialect=dialect))


def test_the_dry_run_refuses_a_flat_program_beyond_the_output_bound_before_yielding():
    from postproc.limits import ResourceLimitError

    text = "G21\no1 repeat [100000]\no2 repeat [100000]\nG1 X20 F100\nG1 X10\no2 endrepeat\no1 endrepeat\nM2\n"
    t0 = time.monotonic()
    with pytest.raises(ResourceLimitError) as err:
        expand(split_lines(text), path="p.ngc", dialect="linuxcnc", max_lines_out=20_000)  # before any line
    assert time.monotonic() - t0 < 10
    assert "--max-output-lines" in str(err.value)
    assert (err.value.path, err.value.col) == ("p.ngc", 1)
    small = text.replace("100000", "10")
    assert ([sl.text for sl in expand(split_lines(small), path="p.ngc", dialect="linuxcnc", max_lines_out=20_000)]
            == [sl.text for sl in expand(split_lines(small), path="p.ngc", dialect="linuxcnc")])


@pytest.mark.parametrize("text", [ENDLESS["while [1]"][0], "%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P2000 L99999999\n"
                                  "M30\nO2000\nG1 X20 F100\nG1 X10\nM99\n%\n"], ids=["while", "M98 L"])
def test_the_cli_refuses_the_surveys_endless_loops_in_seconds(tmp_path, text):
    src = tmp_path / "p.nc"
    src.write_text(text)
    t0 = time.monotonic()
    res = run("correct", str(src), "-c", STATIC, "-o", str(tmp_path / "o.nc"),
              "--dialect", "fanuc" if "O1000" in text else "linuxcnc")
    assert time.monotonic() - t0 < 20
    refused(res, 5, f"{src}:")
    assert not (tmp_path / "o.nc").exists()
