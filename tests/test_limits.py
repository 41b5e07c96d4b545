"""Bounds on the work of one run (postproc.limits): every hostile program
ends in a clean refusal that names its place, the bound and the option that raises it,
and nothing is written. Also: subprogram lookups stay inside --subroutine-path (item 6)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import ROOT

from postproc.cli import main
from postproc.engine.static import StaticEngine
from postproc.errors import EXIT_SAFETY, GcodeSyntaxError, PostprocError
from postproc.gcode.expand import ExpansionError, expand
from postproc.gcode.expr import MAX_EXPRESSION_DEPTH, MAX_EXPRESSION_NESTING
from postproc.gcode.lexer import split_lines
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.limits import OUTPUT_GROWTH, OUTPUT_LINES_EXTRA, Limits, ResourceLimitError

HEAD = "G21 G17 G90 G94 F100\n"
ENGINE = StaticEngine(np.eye(3), np.zeros(3), [[-1e4] * 3, [1e4] * 3])
SETUP = Setup(offsets={"G54": (0.0, 0.0, 0.0)})


def flat(text: str, **kw) -> list:
    return list(expand(split_lines(text), path="p.ngc", **kw))


# -- expressions: depth and length ----------------------------------------------------

DEEP = {
    "5000 brackets": "G0 X[" + "[" * 5000 + "1" + "]" * 5000 + "]\n",
    "5000 signs": "#1 = [" + "-" * 5000 + "1]\n",
    "5000 functions": "G0 X" + "ABS[" * 5000 + "1" + "]" * 5000 + "\n",
    "5000 indirections": "G0 X" + "#" * 5000 + "1\n",
    "100,000-term sum": "G0 X[" + "+".join(["1"] * 100_000) + "]\n",
    "100,000-term product": "G0 X[" + "*".join(["1"] * 100_000) + "]\n",
    "chains inside ATAN": "G0 X[" + "+".join(["ATAN[1" + "+1" * 200 + "]/[1]"] * 200) + "]\n",
}


@pytest.mark.parametrize("line", DEEP.values(), ids=DEEP.keys())
def test_deep_or_long_expressions_are_refused_with_their_place(line):
    with pytest.raises(GcodeSyntaxError) as err:
        flat(HEAD + line + "M2\n", dialect="linuxcnc")
    e = err.value
    assert (e.path, e.lineno) == ("p.ngc", 2)
    assert e.col is not None
    assert f"{MAX_EXPRESSION_NESTING} levels" in e.message or f"{MAX_EXPRESSION_DEPTH} operations" in e.message


def test_fanuc_deep_indirection_and_sum_are_refused():
    for line in ("#1=" + "#" * 5000 + "2\n", "#1=" + "+".join(["1"] * 100_000) + "\n"):
        with pytest.raises(GcodeSyntaxError) as err:
            flat("O0001\n" + line + "M30\n", dialect="fanuc")
        assert err.value.lineno == 2


def test_expressions_up_to_the_bounds_still_run():
    """A 250-term sum and brackets nested 60 deep: far beyond real programs, still read."""
    text = (HEAD + "G0 X[" + "+".join(["1"] * 250) + "]\n" + "G0 Y" + "[" * 60 + "2" + "]" * 60 + "\nM2\n")
    out = "".join(sl.text for sl in flat(text, dialect="linuxcnc"))
    assert "G0 X250.0" in out
    assert "G0 Y2.0" in out


# -- loop iterations ------------------------------------------------------------------

ENDLESS = {
    "o-word while": (HEAD + "o1 while [1]\n#1 = [#1 + 1]\no1 endwhile\nM2\n", "linuxcnc", 4),
    "o-word do/while": (HEAD + "o1 do\n#1 = [#1 + 1]\no1 while [1]\nM2\n", "linuxcnc", 4),
    # a count beyond the bound is refused where it is given, before the first pass
    "o-word repeat": (HEAD + "o1 repeat [1000000000]\n#1 = [#1 + 1]\no1 endrepeat\nM2\n", "linuxcnc", 2),
    "nested repeats": (HEAD + "o1 repeat [1000]\no2 repeat [1000]\no3 repeat [1000]\n#1 = 1\no3 endrepeat\n"
                       "o2 endrepeat\no1 endrepeat\nM2\n", "linuxcnc", 7),
    "o-word call in a loop": (HEAD + "o9 sub\n#1 = 1\no9 endsub\no1 while [1]\no9 call\no1 endwhile\nM2\n",
                              "linuxcnc", None),
    "Fanuc WHILE": ("O0001\n#1=0\nWHILE[#1LT1000000000]DO1\n#1=#1+1\nEND1\nM30\n", "fanuc", 5),
    "Fanuc GOTO": ("O0001\nN10 #1=#1+1\nGOTO10\nM30\n", "fanuc", 3),
    "Fanuc IF GOTO": ("O0001\n#1=0\nN10 #1=#1+1\nIF[#1GT0]GOTO10\nM30\n", "fanuc", 4),
    "M98 L99999999": ("O0001\nM98 P1000 L99999999\nM30\nO1000\n#1=1\nM99\n", "fanuc", 2),
    "M98 P count in P": ("O0001\nM98 P99991000\nM30\nO1000\n#1=1\nM99\n", "fanuc", 2),
    "G65 L": ("O0001\nG65 P1000 L99999999\nM30\nO1000\n#100=1\nM99\n", "fanuc", 2),
    "M99 P back": ("O0001\nN5 M98 P1000\nM30\nO1000\n#100=1\nM99 P5\n", "fanuc", 2),
}


@pytest.mark.parametrize(("text", "dialect", "lineno"), ENDLESS.values(), ids=ENDLESS.keys())
def test_endless_loops_stop_at_the_iteration_bound(text, dialect, lineno):
    with pytest.raises(ResourceLimitError) as err:
        flat(text, dialect=dialect, max_iterations=1000)
    e = err.value
    assert "--max-iterations" in str(e)
    assert "1,000" in e.message
    assert e.path == "p.ngc"
    assert e.col is not None
    assert e.exit_code == EXIT_SAFETY
    if lineno is not None:
        assert e.lineno == lineno, str(e)


def test_loops_within_the_bound_run_to_their_end():
    text = HEAD + "o1 repeat [999]\nG1 X1\no1 endrepeat\nM2\n"
    assert sum("X1" in sl.text for sl in flat(text, dialect="linuxcnc", max_iterations=1000)) == 999


def test_the_lines_a_loop_runs_are_bounded_too():
    """A body of settings only writes nothing: the lines run are bounded (a few a pass)."""
    text = HEAD + "o1 repeat [100]\n" + "#1 = 1\n" * 100 + "o1 endrepeat\nM2\n"
    with pytest.raises(ResourceLimitError) as err:
        flat(text, dialect="linuxcnc", max_iterations=1000, max_lines=5000)
    assert "--max-iterations" in str(err.value)
    assert err.value.col == 1


# -- output lines, helix turns --------------------------------------------------------

def test_output_lines_are_bounded_and_nothing_is_returned():
    text = HEAD + "G0 X0 Y0 Z0\no1 repeat [500]\nG1 X1\nG1 X0\no1 endrepeat\nM2\n"
    opts = CorrectOptions(limits=Limits(max_output_lines=300))
    with pytest.raises(ResourceLimitError) as err:
        correct_text(text, ENGINE, SETUP, opts, path="p.ngc")
    assert "--max-output-lines" in str(err.value)
    assert "300" in err.value.message
    assert err.value.path == "p.ngc"
    assert err.value.lineno is not None
    out, _ = correct_text(text, ENGINE, SETUP, CorrectOptions(limits=Limits(max_output_lines=2000)), path="p.ngc")
    assert out.count("G1 X1") == 500


@pytest.mark.parametrize("ending", ["\n", "\r\n", "\r"])
def test_output_lines_are_counted_whatever_their_ending(ending):
    from postproc.limits import BoundedWriter

    written: list[str] = []
    w = BoundedWriter(written.append, 3, lambda: ("p.ngc", 7))
    w(f"G0 X1{ending}G1 X2{ending}")
    w("(no line end yet)")
    w(f"{ending}")  # the third line
    assert w.lines == 3
    with pytest.raises(ResourceLimitError, match="more than 3 lines") as err:
        w(f"M2{ending}")
    assert (err.value.path, err.value.lineno) == ("p.ngc", 7)
    assert "".join(written) == f"G0 X1{ending}G1 X2{ending}(no line end yet){ending}"


def test_the_default_output_bound_grows_with_the_input():
    assert Limits().output_lines(1000) == OUTPUT_GROWTH * 1000 + OUTPUT_LINES_EXTRA
    assert Limits(max_output_lines=7).output_lines(10**9) == 7


def test_plain_programs_are_bounded_too():
    text = HEAD + "G0 X0 Y0 Z0\n" + "G1 X1\nG1 X0\n" * 200 + "M2\n"
    with pytest.raises(ResourceLimitError) as err:
        correct_text(text, ENGINE, SETUP, CorrectOptions(limits=Limits(max_output_lines=100)), path="p.ngc")
    assert err.value.lineno is not None


@pytest.mark.parametrize("p", ["P100000", "P" + "9" * 400])
def test_helix_turns_are_bounded(p):
    text = HEAD + f"G0 X10 Y0 Z0\nG2 X10 Y0 I-10 J0 Z-5 {p}\nM2\n"
    with pytest.raises(PostprocError) as err:
        correct_text(text, ENGINE, SETUP, CorrectOptions(), path="p.ngc")
    assert (err.value.lineno, err.value.col) == (3, 23)
    if len(p) < 20:
        assert isinstance(err.value, ResourceLimitError)
        assert "--max-arc-turns" in str(err.value)


def test_helix_turns_within_the_bound_are_corrected():
    text = HEAD + "G0 X10 Y0 Z0\nG2 X10 Y0 I-10 J0 Z-5 P3\nM2\n"
    out, _ = correct_text(text, ENGINE, SETUP, CorrectOptions(limits=Limits(max_arc_turns=3)), path="p.ngc")
    assert "P3" in out


@pytest.mark.parametrize("p", ["Pnan", "P0", "P-2", "P1.5"])
def test_helix_turns_must_be_a_positive_integer(p):
    text = HEAD + f"G0 X10 Y0 Z0\nG2 X10 Y0 I-10 J0 Z-5 {p}\nM2\n"
    with pytest.raises(PostprocError) as err:
        correct_text(text, ENGINE, SETUP, CorrectOptions(), path="p.ngc")
    assert "positive integer" in err.value.message or err.value.col is not None


# -- the CLI: options, messages, nothing written ----------------------------------------

def _run(args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_cli_names_the_bound_and_writes_nothing(tmp_path):
    src = tmp_path / "loop.ngc"
    src.write_text(HEAD + "G0 X0 Y0 Z0\no1 while [1]\n#1 = [#1 + 1]\no1 endwhile\nM2\n")
    out = tmp_path / "out.ngc"
    res = _run(["correct", src, "-c", ROOT / "calibrations" / "s500_static.json", "-o", out,
                "--max-iterations", "100", "--offset", "G54=X100,Y100,Z100"])
    assert res.exit_code == EXIT_SAFETY, res.output
    assert f"{src}:5:1:" in res.output
    assert "--max-iterations" in res.output
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop.ngc"]


def test_cli_limit_options_raise_the_bounds(tmp_path):
    src = tmp_path / "loop.ngc"
    src.write_text(HEAD + "G0 X0 Y0 Z0\no1 repeat [200]\nG1 X1\nG1 X0\no1 endrepeat\nM2\n")
    cal = ROOT / "calibrations" / "s500_static.json"
    base = ["correct", src, "-c", cal, "--offset", "G54=X100,Y100,Z100", "-j", "1"]
    res = _run([*base, "-o", tmp_path / "a.ngc", "--max-iterations", "100"])
    assert res.exit_code == EXIT_SAFETY
    assert "--max-iterations" in res.output
    res = _run([*base, "-o", tmp_path / "b.ngc", "--max-output-lines", "100"])
    assert res.exit_code == EXIT_SAFETY
    assert "--max-output-lines" in res.output
    res = _run([*base, "-o", tmp_path / "c.ngc", "--max-iterations", "200", "--max-output-lines", "1000"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "c.ngc").read_text().count("G1 X") >= 400


# -- subprogram lookups stay inside --subroutine-path (item 6) -----------------------------

@pytest.mark.parametrize("name", ["/tmp/x", "../y", "sub/z", "..", "a\\b"])
def test_subroutine_names_that_name_a_path_are_refused(tmp_path, name):
    subs = tmp_path / "subs"
    subs.mkdir()
    (tmp_path / "y.ngc").write_text("o<y> sub\nG1 X1\no<y> endsub\n")
    text = HEAD + f"o<{name}> call\nM2\n"
    with pytest.raises(ExpansionError) as err:
        flat(text, dialect="linuxcnc", subroutine_path=[subs])
    e = err.value
    assert (e.lineno, e.col) == (2, 1)
    assert "--subroutine-path" in e.message


def test_subroutines_on_the_path_are_still_found(tmp_path):
    subs = tmp_path / "subs"
    subs.mkdir()
    (subs / "ok.ngc").write_text("o<ok> sub\nG1 X7\no<ok> endsub\n")
    out = "".join(sl.text for sl in flat(HEAD + "o<ok> call\nM2\n", dialect="linuxcnc", subroutine_path=[subs]))
    assert "G1 X7" in out


# -- calibration grids ------------------------------------------------------------------

def test_astatic_grid_step_is_bounded_at_load(tmp_path):
    from postproc.calfile import load_calibration

    data = json.loads((ROOT / "calibrations" / "s500_parametric.json").read_text())
    data["model"]["solver"] = "astatic"
    data["model"]["astatic"] = {"grid_step_mm": 1e-9, "gain": 1.5, "time_step": 0.1, "max_iter": 2000}
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps(data))
    with pytest.raises(PostprocError) as err:
        load_calibration(cal)
    assert "cells" in err.value.message
    assert err.value.path == str(cal)
    data["model"]["astatic"] = {"grid_step_mm": 2.0, "gain": 1.5, "time_step": 0.1, "max_iter": 10**12}
    cal.write_text(json.dumps(data))
    with pytest.raises(PostprocError):
        load_calibration(cal)


def test_grid_fit_step_is_bounded():
    from postproc.engine.grid import MAX_GRID_NODES, detect_lattice

    q = np.array([[0.0, 0.0, 0.0], [300.0, 300.0, 300.0]])
    with pytest.raises(PostprocError) as err:
        detect_lattice(q, np.array([1e-9] * 3))
    assert f"{MAX_GRID_NODES:,}" in err.value.message
    with pytest.raises(PostprocError):
        detect_lattice(q, np.array([1e-320] * 3))


# -- the sizes of simulate and verify ---------------------------------------------------

@pytest.mark.parametrize("args", [["--grid", "1e-9"], ["--grid", "1e-320"], ["--random", "100000000000"],
                                  ["--static-set", "--repeats", "1000000000"], ["--tables", "--step", "1e-9"],
                                  ["--tables", "--step", "1e-320"]])
def test_simulate_sizes_are_bounded(tmp_path, args):
    out = tmp_path / "sim.csv"
    res = _run(["simulate", ROOT / "calibrations" / "s500.machine.json", *args, "-o", out])
    assert res.exit_code == 3, res.output
    assert "more than 1,000,000" in res.output, res.output
    assert not out.exists()


@pytest.mark.parametrize("step", ["1e-9", "1e-320"])
def test_verify_sampling_is_bounded_at_the_line_that_passes_it(tmp_path, step):
    prog = tmp_path / "v.ngc"
    prog.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X300 Y300 Z100 F500\nM2\n")
    res = _run(["verify", prog, "--machine", ROOT / "calibrations" / "s500.machine.json",
                "-c", ROOT / "calibrations" / "s500_static.json", "--max-step", step])
    assert res.exit_code == EXIT_SAFETY, res.output
    assert f"{prog}:3:1:" in res.output
    assert "--max-step" in res.output


# -- inputs that ended in an internal error (item 5) ------------------------------------

def _calibration_text(extra: str, where: str = '"volume_mm": [[') -> str:
    text = json.dumps(json.loads((ROOT / "calibrations" / "s500_static.json").read_text()))
    assert where in text
    return text.replace(where, where + extra, 1)


@pytest.mark.parametrize(("text", "fragment"), [
    (_calibration_text('"x": ' + "[" * 100_000 + "]" * 100_000 + ", ", "{"), "nests too deep"),
    (_calibration_text("9" * 5000 + ", "), "Exceeds the limit (4300 digits)"),
    (_calibration_text("9" * 4000 + ", "), "volume_mm[0][0] is an integer of 4000 digits"),
    (_calibration_text('"zz": ' + "9" * 4000 + ", ", '"model": {'), "model.zz is an integer of 4000 digits"),
])
def test_hostile_calibrations_are_refused(tmp_path, text, fragment):
    cal = tmp_path / "cal.json"
    cal.write_text(text)
    prog = tmp_path / "p.ngc"
    prog.write_text(HEAD + "G0 X10 Y10 Z10\nM2\n")
    res = _run(["correct", prog, "-c", cal, "-o", tmp_path / "o.ngc"])
    assert res.exit_code == 4, res.output
    assert fragment in res.output, res.output
    assert f"{cal}:" in res.output
    assert "internal error" not in res.output


def test_hostile_machine_definition_is_refused(tmp_path):
    text = (ROOT / "calibrations" / "s500.machine.json").read_text().rstrip()
    machine = tmp_path / "m.json"
    machine.write_text(text[:-1] + ', "x": ' + "[" * 100_000 + "]" * 100_000 + "}")
    res = _run(["simulate", machine, "--static-set", "-o", tmp_path / "s.csv"])
    assert res.exit_code == 4, res.output
    assert "nested too deeply" in res.output, res.output


@pytest.mark.parametrize(("row", "col"), [("T1 P1 Znan D6", 7), ("T1 P1 Zinf D6", 7), ("T1e400 P1 Z1", 1)])
def test_tool_tables_with_non_finite_values_are_refused(tmp_path, row, col):
    table = tmp_path / "t.tbl"
    table.write_text(row + "\n")
    prog = tmp_path / "p.ngc"
    prog.write_text(HEAD + "G0 X0 Y0 Z0\nG43 H1 Z10\nG1 X10\nM2\n")
    res = _run(["correct", prog, "-c", ROOT / "calibrations" / "s500_static.json", "-o", tmp_path / "o.ngc",
                "--tool-table", table, "--offset", "G54=X100,Y100,Z100"])
    assert res.exit_code == 3, res.output
    assert f"{table}:1:{col}:" in res.output, res.output


HUGE = "1" * 400


@pytest.mark.parametrize("extrapolate", ["refuse", "clamp", "linear"])
@pytest.mark.parametrize(("body", "lineno", "col"), [
    (f"G0 X{HUGE} Y0 Z0\n", 2, 4),  # read by the interpreter
    ("G0 X0 Y0 Z0\n" + "G1 X1 Y1 F100\nG1 X0 Y0\n" * 1500 + f"G1 X{HUGE}\n", 3003, 4),  # in a run of plain lines
    (f"G0 X{'1' * 300} Y0 Z0\n", 2, 4),  # finite, far beyond any machine
    (f"G0 X0 Y0 Z0\nG{HUGE} X1\n", 3, 1),
])
def test_huge_numbers_are_refused_at_their_word(tmp_path, extrapolate, body, lineno, col):
    prog = tmp_path / "p.ngc"
    prog.write_text(HEAD + body + "M2\n")
    res = _run(["correct", prog, "-c", ROOT / "calibrations" / "s500_static.json", "-o", tmp_path / "o.ngc",
                "--extrapolate", extrapolate, "-j", "1"])
    assert res.exit_code == 3, res.output
    assert f"{prog}:{lineno}:{col}:" in res.output
    assert "Warning" not in res.output


def test_export_detection_unit_must_be_positive(tmp_path):
    from postproc.errors import CalibrationError
    from postproc.metrology.controllers.fanuc import export_fanuc

    res = _run(["export", ROOT / "calibrations" / "s500_parametric.json", "-f", "fanuc", "--step", "25",
                "--detection-unit", "0", "-o", tmp_path / "e.txt"])
    assert res.exit_code == 2
    assert "--detection-unit" in res.output
    for unit in (0.0, 1e-320):
        with pytest.raises(CalibrationError):
            export_fanuc([], interval_mm=25.0, reference_mm={}, return_direction={}, detection_unit_mm=unit)


def test_output_size_is_bounded_for_few_long_lines():
    """A loop repeating a long comment makes few lines of many bytes: the size bound stops it."""
    text = HEAD + "G0 X0 Y0 Z0\no1 repeat [200]\nG1 X1\n(" + "c" * 10_000 + ")\no1 endrepeat\nM2\n"
    with pytest.raises(ResourceLimitError) as err:
        # (LinuxCNC reads lines of up to 252 characters: the comment goes on a line of its own)
        correct_text(text, ENGINE, SETUP, CorrectOptions(dialect="linuxcnc", limits=Limits(max_output_mb=1.0)),
                     path="p.ngc")
    assert "--max-output-mb" in str(err.value)
    assert err.value.lineno is not None  # (where reading reached)
    assert Limits().output_chars(10) == OUTPUT_GROWTH * 10 + 256_000_000


def test_lines_held_for_an_axis_never_positioned_are_bounded(monkeypatch):
    """Lines wait in memory until every axis is known (a few KB each): a program that
    never positions Y is refused once too many wait, not at its end (1.5M held: 3.7 GB)."""
    from postproc.gcode import pipeline

    monkeypatch.setattr(pipeline, "UNKNOWN_AXIS_LINES", 5000)
    text = "O0001\nG21 G90\nM98 P1000 L9999\nM30\nO1000\nG1 X1 F100\nG1 X0\nM99\n"
    with pytest.raises(PostprocError) as err:
        correct_text(text, ENGINE, Setup(), CorrectOptions(chunk_lines=1000), path="m.nc")
    assert "axis Y is still not positioned" in err.value.message
    assert err.value.lineno in (6, 7)  # a line of the subprogram, not of the expanded program
    assert "--start Y" in err.value.hint


@pytest.mark.parametrize("line", ["G0 X10." + "3" * 400 + " Y10 Z10", "G1 X10." + "3" * 400 + " F100"])
def test_a_word_of_hundreds_of_decimals_is_kept_or_refused_for_its_line(tmp_path, line):
    """The writer keeps a word's decimals: 400 of them was an internal error (read on its
    own line by the interpreter, or in a plain run). Written where the dialect reads such
    a line, refused for the line's length where it does not."""
    src = tmp_path / "d.nc"
    src.write_text(f"G21 G90\nG0 X10 Y10 Z10\n{line}\nG1 X20\nG1 X30\nM2\n")
    cal = ROOT / "calibrations" / "s500_static.json"
    res = _run(["correct", src, "-c", cal, "-o", tmp_path / "o.nc"])
    assert res.exit_code == EXIT_SAFETY, res.output
    assert f"{src}:3:" in res.output
    assert "characters" in res.output
    assert not (tmp_path / "o.nc").exists()
    res = _run(["correct", src, "-c", cal, "--dialect", "sinumerik", "-o", tmp_path / "o.nc"])
    assert res.exit_code == 0, res.output
    assert len((tmp_path / "o.nc").read_text().splitlines()[7]) > 400


@pytest.mark.parametrize("volume", ["nan,0,0,10,10,10", "0,0,0,inf,10,10", "10,0,0,0,10,10", "0,0,0,1e9,10,10"])
def test_simulate_volume_must_be_finite_ordered_and_bounded(tmp_path, volume):
    res = _run(["simulate", ROOT / "calibrations" / "s500.machine.json", "--random", "10", "--volume", volume,
                "-o", tmp_path / "s.csv"])
    assert res.exit_code == 2, res.output
    assert "--volume" in res.output


@pytest.mark.parametrize("spec", ["X=1000000", "X=1000;Y=1000;Z=1000"])
def test_interval_counts_are_bounded(tmp_path, spec):
    res = _run(["fit", ROOT / "samples" / "s500_static_6points.csv", "--method", "interval", "--intervals", spec,
                "-o", tmp_path / "i.json"])
    assert res.exit_code == 3, res.output
    assert "--intervals" in res.output


@pytest.mark.parametrize("args", [
    ["verify", "samples/pocket.nc", "-c", "calibrations/s500_static.json", "--machine", "calibrations/s500.machine.json",
     "--points", "samples/s500_static_6points.csv", "--shots", "1000000000"],
    ["export", "calibrations/s500_parametric.json", "--format", "linuxcnc", "--step", "1e-9", "-o", "{tmp}/comp"],
    ["fit", "samples/walkthrough_points.csv", "--method", "parametric", "--knot-spacing", "1e-9", "-o", "{tmp}/p.json"],
], ids=["verify-shots", "export-step", "fit-knot-spacing"])
def test_sizes_that_would_take_terabytes_are_refused(tmp_path, args):
    """Each was a MemoryError (224 GiB, 2.29 TiB): now refused with the option named."""
    args = [a.replace("{tmp}", str(tmp_path)) if "{tmp}" in a else (str(ROOT / a) if "/" in a else a) for a in args]
    res = _run(args)
    assert res.exit_code in (2, 3, 4), res.output
    assert "internal error" not in res.output
