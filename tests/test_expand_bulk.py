"""An expanded program's runs of plain lines are read in bulk, each line numbered by its
source line and file: the output, the report and every error's place are those of the
program read line by line (``CorrectOptions(bulk_lane=False)``).

The programs here are made so that a wrong numbering shows: a loop body read once per
pass (its lines repeat a few source lines), a subprogram from another file whose plain
lines form a run, errors and bounds met inside a run at pass N, and chunks that cut
runs anywhere."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import ENGINE, SETUP, corpus_files, corpus_setup
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode import bulk
from postproc.gcode.expand import needs_expansion
from postproc.gcode.lexer import split_lines
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.limits import Limits

# an engine whose calibrated volume ends at X 150 (machine): a target beyond is refused,
# naming its lines
SMALL = StaticEngine(np.eye(3) * 1.0001 + 1e-4 * np.triu(np.ones((3, 3)), 1), [0.01, -0.02, 0.0],
                     [[-200.0] * 3, [150.0, 400.0, 400.0]])


def _outcome(text: str, engine=ENGINE, setup: Setup = SETUP, path: str = "main.ngc", **options):
    """(output, report as a dict, None) or (None, None, (path, line, col, message)) of ``text``
    corrected with ``options``."""
    try:
        out, rep = correct_text(text, engine, setup, CorrectOptions(**options), path=path)
    except PostprocError as exc:
        return None, None, (exc.path, exc.lineno, exc.col, str(exc))
    return out, dataclasses.asdict(rep), None


def both(text: str, **kw):
    """The outcome read in bulk and line by line (asserted equal), and the lines the bulk
    reading read in runs (a program that makes none tests nothing of them)."""
    counted: list[int] = []
    read_run = bulk.read_run

    def counting(*args, **kwargs):
        run = read_run(*args, **kwargs)
        if run is not None:
            counted.append(len(run))
        return run

    bulk.read_run = counting
    try:
        fast = _outcome(text, **kw)
    finally:
        bulk.read_run = read_run
    slow = _outcome(text, bulk_lane=False, **kw)
    assert fast[2] == slow[2]
    assert fast[0] == slow[0]
    assert fast[1] == slow[1]
    return fast, sum(counted)


LOOP = """G21 G17 G90 G94
G0 X0 Y0 Z5
#1 = 0
o100 while [#1 LT 12]
  #2 = [#1 * 12]
  G1 X[#2] Y1 F500
  G1 X[#2 + 3] Y2
  #3 = [#2 + 5]
  (a comment inside the loop)
  G1 Y4
  G2 X[#3] Y6 I2 J0
  G0 Z3
  #1 = [#1 + 1]
o100 endwhile
G0 Z20
M2
"""


@pytest.mark.parametrize("chunk_lines", [1, 2, 3, 7, 20_000])
def test_a_loop_is_read_in_runs_and_written_as_read_line_by_line(chunk_lines):
    (out, rep, err), in_runs = both(LOOP, chunk_lines=chunk_lines)
    assert err is None
    assert rep["expanded"]
    assert in_runs >= 12 * 4
    assert out.count("G2 X") == 12


@pytest.mark.parametrize("chunk_lines", [2, 5, 20_000])
def test_a_target_refused_inside_a_loop_at_pass_n_names_the_body_lines(chunk_lines):
    # X 100 + 12 * pass: pass 3 is the first beyond X 150 (the volume's end)
    text = LOOP.replace("G0 X0 Y0 Z5", "G10 L2 P1 X100 Y80 Z40\nG0 X0 Y0 Z5")
    (_out, _rep, err), in_runs = both(text, engine=SMALL, setup=Setup(), chunk_lines=chunk_lines)
    assert in_runs > 0
    path, lineno, _col, message = err
    # the first target beyond: line 8 (G1 X[#2 + 3] Y2) of pass 4 (#2 = 36, X 139 + ...)
    assert (path, lineno) == ("main.ngc", 8)
    listed = re.search(r"outside the calibrated volume at lines ([\d, ]+):", message)
    assert listed is not None, message
    # every line of the chunk whose target is beyond: the body's moves, and the last G0
    assert {int(x) for x in listed.group(1).split(", ")} <= {7, 8, 11, 12, 13, 16}, message


def test_an_arc_refused_at_pass_n_after_runs_names_its_line_and_column():
    # the arc of pass 5 has a zero radius: the interpreter reads it (the run ends before it)
    text = LOOP.replace("G2 X[#3] Y6 I2 J0", "G2 X[#3] Y6 I[2 * [#1 NE 5]] J0")
    (_out, _rep, err), in_runs = both(text, chunk_lines=20_000)
    assert in_runs > 0
    assert err is not None
    assert err[:2] == ("main.ngc", 11), err


SUB = """o<edge> sub
G1 X[#1 * 0] Y0 F500
(the lines below are plain as written)
G1 X10 Y10
#5 = [#1 + 1]
G1 X20 Y10
G1 X20 Y20
G1 X10 Y20
o<edge> endsub
M2
"""
MAIN = """G21 G17 G90 G94
G0 X0 Y0 Z5
#1 = 0
o100 while [#1 LT 6]
  G10 L2 P1 X[#1 * 27] Y0 Z0
  o<edge> call [#1]
  #1 = [#1 + 1]
o100 endwhile
G0 Z20
M30
"""


@pytest.mark.parametrize("chunk_lines", [3, 4, 20_000])
def test_a_subprogram_file_whose_plain_lines_form_runs(tmp_path, chunk_lines):
    (tmp_path / "edge.ngc").write_text(SUB)
    (out, _rep, err), in_runs = both(MAIN, subroutine_path=[str(tmp_path)], chunk_lines=chunk_lines)
    assert err is None
    assert in_runs >= 6 * 4


@pytest.mark.parametrize("chunk_lines", [3, 20_000])
def test_a_target_refused_in_a_subprogram_run_names_its_line(tmp_path, chunk_lines):
    (tmp_path / "edge.ngc").write_text(SUB)
    # G54 at X 27 per pass: pass 6 (X 135) takes X20 (line 6 of edge.ngc) beyond X 150
    (_out, _rep, err), in_runs = both(MAIN, engine=SMALL, setup=Setup(), subroutine_path=[str(tmp_path)],
                                      chunk_lines=chunk_lines)
    assert in_runs > 0
    assert err is not None
    assert err[1] == 6, err
    assert re.search(r"outside the calibrated volume at lines 6(, 7)?:", err[3]), err


def test_a_tool_length_refused_in_a_subprogram_run_names_its_file(tmp_path):
    # a straight move that sets the tool length starts a run: its refusal (tool 7 has no
    # length given) names the subprogram's file, line and column
    # (the subprogram's first line, after lines of the main file)
    (tmp_path / "edge.ngc").write_text(SUB.replace("G1 X[#1 * 0] Y0 F500", "G0 G43 H7 Z5"))
    (_out, _rep, err), in_runs = both(MAIN, subroutine_path=[str(tmp_path)])
    assert err is not None
    assert err[:3] == (str(tmp_path / "edge.ngc"), 2, 4), err
    (tmp_path / "edge.ngc").write_text(SUB.replace("G1 X10 Y20", "G0 G43 H7 Z5"))  # after a run
    (_out, _rep, err), in_runs = both(MAIN, subroutine_path=[str(tmp_path)])
    assert in_runs > 0
    assert err is not None
    assert err[:3] == (str(tmp_path / "edge.ngc"), 8, 4), err


def test_a_line_refused_in_a_subprogram_after_runs_names_its_file(tmp_path):
    (tmp_path / "edge.ngc").write_text(SUB.replace("G1 X10 Y20", "G2 X10 Y20 I0 J0"))
    (_out, _rep, err), in_runs = both(MAIN, subroutine_path=[str(tmp_path)])
    assert in_runs > 0
    assert err is not None
    assert err[:2] == (str(tmp_path / "edge.ngc"), 8), err


def _flat_lines(text: str) -> int:
    out, _rep = correct_text(text, ENGINE, SETUP, CorrectOptions())
    return out.count("\n")


@pytest.mark.parametrize("chunk_lines", [4, 20_000])
def test_bounds_met_inside_an_expanded_run(chunk_lines):
    lines = _flat_lines(LOOP)
    # the output's lines: past the expansion's own count (its dry run lets it through),
    # refused while the runs are written
    (_o, _r, err), in_runs = both(LOOP, chunk_lines=chunk_lines, limits=Limits(max_output_lines=lines - 5))
    assert in_runs > 0
    assert err is not None
    assert "--max-output-lines" in err[3], err
    (_o, _r, err), in_runs = both(LOOP, chunk_lines=chunk_lines, limits=Limits(max_output_mb=0.0008))
    assert in_runs > 0
    assert err is not None
    assert err[1] is not None, err


FANUC = """%
O0001
G21 G17 G90 G94
G0 X0 Y0 Z5
#1 = 0
WHILE [#1 LT 8] DO1
#2 = #1 * 7
G1 X#2 Y1 F500
G1 X[#2 + 3] Y2
G1 Y4
M98 P1000
#1 = #1 + 1
END1
G0 Z20
M30
O1000
G1 X1 Y1
#3 = 1
G1 X2 Y1
G1 X2 Y2
M99
%
"""


@pytest.mark.parametrize("chunk_lines", [2, 5, 20_000])
def test_fanuc_while_and_m98_subprogram(chunk_lines):
    (_out, _rep, err), in_runs = both(FANUC, dialect="fanuc", chunk_lines=chunk_lines)
    assert err is None
    assert in_runs >= 8 * 3
    text = FANUC.replace("G1 X2 Y2", "G1 X200 Y2")  # the subprogram's line 20, at every pass
    (_out, _rep, err), _n = both(text, dialect="fanuc", engine=SMALL, setup=Setup(), chunk_lines=chunk_lines)
    assert err is not None
    assert err[:2] == ("main.ngc", 20), err


@pytest.mark.parametrize("chunk_lines", [3, 20_000])
def test_a_line_too_long_once_corrected_inside_an_expanded_run(chunk_lines):
    # 125 characters, within the generic dialect's 127 as written, not once its Y word has
    # its decimals (and an X word is added)
    text = LOOP.replace("  G1 Y4\n", "  G1 Y4" + " " * 118 + "\n")
    (_o, _r, err), in_runs = both(text, chunk_lines=chunk_lines)
    assert in_runs > 0
    assert err is not None
    assert err[:3] == ("main.ngc", 10, 128), err


# -- generated programs -------------------------------------------------------------------
@st.composite
def expanded_program(draw):
    """A LinuxCNC program of loops (nested), conditions, parameters and subprogram calls
    whose lines, once substituted, are mostly plain: straight moves, arcs, comments, tool
    changes, moves that set the tool length, with modal changes (G91, G18, G20) between."""
    body = ["G21 G90 G17 G94", "G0 X10 Y10 Z10", "#1 = 0", "#9 = 0"]

    def moves(indent: str, k: int) -> list[str]:
        out = []
        for _ in range(draw(st.integers(1, 6))):
            kind = draw(st.integers(0, 11))
            x = draw(st.integers(-40, 40)) / 4
            y = draw(st.integers(-40, 40)) / 4
            if kind < 4:
                out.append(f"{indent}G1 X[#{k} * {x:g} + 5] Y{y:g}")
            elif kind == 4:
                out.append(f"{indent}X{x:g} Y[#{k} + {y:g}] F[300 + #{k}]")
            elif kind == 5:  # a half circle from a point the line before sets (an arc the run takes)
                out.append(f"{indent}G17 G90 G1 X[#{k} + {x:g}] Y{y:g}")
                out.append(f"{indent}G{draw(st.sampled_from([2, 3]))} X[#{k} + {x + 4:g}] Y{y:g} I2 J0")
            elif kind == 6:
                out.append(indent + draw(st.sampled_from(["(note)", "", "M3 S1000", "T2 M6", "G0 G43 H1 Z[10 + #9]",
                                                          "G91", "G90", "G18", "G17", "G20", "G21", "G1 F400"])))
            elif kind == 7:
                out.append(f"{indent}#9 = [#9 + 1]")
            elif kind == 8:
                out.append(f"{indent}o<side> call [#{k}]")
            elif kind == 9:
                out.append(f"{indent}G0 Z[5 + #{k}]")
            else:
                out.append(f"{indent}G1 X{x:g} Y{y:g} Z{draw(st.integers(-5, 5)):d}")
        return out

    for loop in range(draw(st.integers(1, 3))):
        body += ["#1 = 0", f"o1{loop} while [#1 LT {draw(st.integers(1, 5))}]"]
        body += moves("  ", 1)
        if draw(st.booleans()):
            body += ["  #2 = 0", f"  o2{loop} while [#2 LT {draw(st.integers(1, 3))}]"]
            body += moves("    ", 2)
            body += ["    #2 = [#2 + 1]", f"  o2{loop} endwhile"]
        if draw(st.booleans()):
            body += [f"  o3{loop} if [#1 GT 1]", "    G1 X[#1] Y[#1]", f"  o3{loop} else", "    G0 Z12",
                     f"  o3{loop} endif"]
        body += ["  #1 = [#1 + 1]", f"o1{loop} endwhile"]
    body += moves("", 9)
    body += ["G0 Z20", "M2"]
    sub = ["o<side> sub", "G1 X[#1 + 1] Y2", "G1 X3 Y3", "G1 Y4", "G0 Z6", "o<side> endsub", "M2"]
    return "\n".join(body) + "\n", "\n".join(sub) + "\n"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                HealthCheck.function_scoped_fixture])
@given(expanded_program(), st.sampled_from([1, 2, 3, 5, 8, 20_000]))
def test_generated_expanded_programs_read_in_bulk_as_line_by_line(tmp_path, prog, chunk_lines):
    text, sub = prog
    (tmp_path / "side.ngc").write_text(sub)
    both(text, subroutine_path=[str(tmp_path)], chunk_lines=chunk_lines)
    both(text, subroutine_path=[str(tmp_path)], chunk_lines=chunk_lines, engine=SMALL, setup=Setup())


# -- the corpus -----------------------------------------------------------------------------
def _read(path: Path) -> str:
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _expanding() -> list[Path]:
    out = []
    for p in corpus_files():
        if p.stat().st_size <= 60_000 and needs_expansion(split_lines(_read(p))):
            out.append(p)
    return out


EXPANDING = _expanding()


@pytest.fixture(scope="module")
def corpus_subroutines(tmp_path_factory):
    """The corpus' subroutine files under the names their callers use."""
    d = tmp_path_factory.mktemp("subs")
    if not EXPANDING:
        return d
    real = EXPANDING[0].parents[2] / "real" if "real" in EXPANDING[0].parts else None
    if real is not None:
        for f in (real / "lagun_linuxcnc").glob("nc_files__*.ngc"):
            name = f.name.removeprefix("nc_files__")
            if "__" not in name:
                (d / name).write_text(_read(f))
        for f in (real / "fanuc_sim").glob("*Fanuc__[0-9]*.nc"):
            m = re.search(r"__(\d+)\.nc$", f.name)
            if m is not None:
                (d / f"{m.group(1)}.nc").write_text(_read(f))
    return d


@pytest.mark.skipif(not EXPANDING, reason="../shared/corpus is absent")
@pytest.mark.parametrize("path", EXPANDING, ids=[p.name[-40:] for p in EXPANDING])
def test_corpus_programs_that_expand_read_in_bulk_as_line_by_line(path, corpus_subroutines):
    text = _read(path)
    own = "fanuc" if "fanuc" in path.parent.name or "haas" in path.parent.name else "linuxcnc"
    for chunk_lines, dialect in ((7, own), (20_000, "generic")):  # (generic: the shortest lines)
        both(text, setup=corpus_setup(path), path=str(path), dialect=dialect, cycles="expand",
             subroutine_path=[str(corpus_subroutines)], chunk_lines=chunk_lines)


# -- the expansion's dry run ------------------------------------------------------------------
@pytest.mark.parametrize("kept", [1, 5, 200_000])
def test_the_lines_held_from_the_dry_run_are_those_the_expansion_yields(monkeypatch, kept):
    from postproc.gcode import expand as expand_module

    monkeypatch.setattr(expand_module, "KEPT_LINES", kept)
    lines = split_lines(LOOP)
    flat = list(expand_module.expand(lines, path="main.ngc"))
    assert list(expand_module.expand(lines, path="main.ngc", max_lines_out=10_000)) == flat
    with pytest.raises(PostprocError, match="--max-output-lines") as refused:
        expand_module.expand(lines, path="main.ngc", max_lines_out=20)
    assert (refused.value.path, refused.value.lineno) == (flat[20].path, flat[20].lineno)


# -- lines written by the general emitter inside a run --------------------------------------
SPLIT_ARCS = """G21 G17 G90 G94
G54
T1 M6
G43 H1
S12000 M3
G0 X0 Y0 Z5
G1 Z-1 F300
#1 = 1661
#2 = 5
o100 while [#1 LT 1701]
  #3 = [#1 MOD 100 * 0.5]
  #4 = [FIX[#1 / 100] * 0.5]
  G1 X[#3] Y[#4] F600
  G1 X[#3 + #2] Y[#4]
  G2 X[#3 + #2] Y[#4 + 2] I0 J1
  G0 X[#3] Y[#4 + 2]PAD
  #1 = [#1 + 1]
o100 endwhile
G0 Z20
M30
"""


@pytest.mark.parametrize("flat", [False, True])
def test_a_line_too_long_after_arcs_the_general_emitter_splits_inside_a_run(flat):
    # s500 static splits some of the arcs into several exact arcs (lines the general
    # emitter writes between the run's own); the G0 line of the last pass is the first
    # one too long once corrected (its X and Y words have two digits before the point)
    from postproc.calfile import load_calibration
    from postproc.gcode.expand import expand

    cal = load_calibration(Path(__file__).resolve().parents[1] / "calibrations" / "s500_static.json")
    text = SPLIT_ARCS.replace("PAD", " " * 97)
    if flat:  # the same lines written out: numbered 1, 2, 3, ... in one run
        text = "".join(sl.text for sl in expand(split_lines(text), path="main.ngc"))
    setup = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 100.0})
    (_o, _r, err), in_runs = both(text, engine=cal.engine, setup=setup)
    assert in_runs > 0
    assert err is not None
    assert err[1:3] == (7 + 40 * 4 if flat else 16, 128), err  # (flat: 7 lines, then 4 a pass)
    assert "once corrected" in err[3]
    (out, rep, err), _n = both(SPLIT_ARCS.replace("PAD", ""), engine=cal.engine, setup=setup)
    assert err is None
    assert rep["arcs_split"] > 0


@pytest.mark.parametrize("flat", [False, True])
def test_a_comment_longer_than_the_dialect_reads_inside_a_run_is_passed_as_it_is(flat):
    # as the interpreter passes a line that moves nothing (the input has it so)
    text = LOOP.replace("(a comment inside the loop)", "(DEBUG, pass #1 of " + "a" * 130 + ")")
    if flat:
        from postproc.gcode.expand import expand

        text = "".join(sl.text for sl in expand(split_lines(text), path="main.ngc"))
    (out, _rep, err), in_runs = both(text)
    assert in_runs > 0
    assert err is None
    assert out.count("(DEBUG, pass #1 of " + "a" * 130 + ")\n") == 12
