"""No input ends in an internal error.

Hypothesis writes programs (words, expressions, parameters, bounded loops of LinuxCNC
and Fanuc, subprogram calls, canned cycles, junk) in every dialect, breaks calibrations
of every format field by field, writes tool tables, and gives every numeric option of
every command hostile values. Property: the command exits 0 or with a documented
refusal code; a refusal is one ``postproc: error:`` line (with ``path:line:col`` when it
is about a line of the program) or click's usage line; no traceback, no internal
error, no warning text on stderr.

Bounded: each test has its own ``max_examples`` and no deadline (the machine is shared);
the whole module runs in well under a minute. Loops here always end, in a few turns:
unbounded loops and huge repeat counts are the iteration limits' test, not this one.
"""

from __future__ import annotations

import contextlib
import copy
import json
import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from postproc.cli import main

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / "calibrations" / "s500_static.json"
PARAMETRIC = ROOT / "calibrations" / "s500_parametric.json"
MACHINE = ROOT / "calibrations" / "s500.machine.json"
POCKET = ROOT / "samples" / "pocket.nc"
DIALECTS = ["generic", "linuxcnc", "fanuc", "haas", "grbl", "mach3"]
#: exit codes a run may end with (postproc.errors and docs/batch.md); 1 is a bug
DOCUMENTED = {0, 2, 3, 4, 5, 6, 7}
PLACE = re.compile(r"^postproc: error: (?P<path>[^\n]+?):(?P<line>\d+)(?::(?P<col>\d+))?: ", re.MULTILINE)

def fuzz(max_examples: int):
    """Hypothesis settings of these tests: bounded, reproducible, no deadline (shared machine)."""
    return settings(max_examples=max_examples, deadline=None, suppress_health_check=list(HealthCheck),
                    derandomize=True, database=None)


class Calibrations(dict):
    """The calibrations by format (a short repr in Hypothesis' report of a failing example)."""

    def __repr__(self) -> str:
        return f"<calibrations {sorted(self)}>"


def check(result, program: Path | None = None) -> None:
    """The property every run holds."""
    out = result.output
    assert result.exit_code in DOCUMENTED, out
    assert "Traceback" not in out, out
    assert "internal error" not in out, out
    assert "Warning" not in out, out
    assert "warning:" not in out.lower() or result.exit_code == 0, out
    if result.exit_code in (3, 4, 5, 7):
        assert "postproc: error: " in out, out
    if program is not None and result.exit_code in (3, 5):
        for m in PLACE.finditer(out):
            if m["path"] == str(program) and m["line"] is not None:
                assert m["col"] is not None, f"no column: {out}"


#: address space a fuzzed run may add to this process: a run that would take more fails
#: with MemoryError (an internal error, reported) instead of pushing a shared machine
#: into its out-of-memory killer
RUN_MEMORY_BYTES = 3 << 30


@contextlib.contextmanager
def bounded_memory():
    try:
        import resource

        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        used = int(Path("/proc/self/statm").read_text().split()[0]) * resource.getpagesize()
    except (ImportError, OSError, ValueError):
        yield
        return
    limit = used + RUN_MEMORY_BYTES
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def run(*args, stdin=None):
    with bounded_memory():
        return CliRunner().invoke(main, [str(a) for a in args], input=stdin)


# -- programs ------------------------------------------------------------------------

HOSTILE_NUMBERS = ["0", "-0", ".5", "-.5", "1.", "1e3", "1E-9", "9" * 400, "1." + "0" * 60 + "1", "nan", "inf",
                   "-", "+.", "1e999", "0x10", "1,5", "١٢", "00000000000000000012", "-99999999", "1e-400"]
numbers = st.one_of(
    st.integers(-400, 400).map(str),
    st.floats(-500, 500, allow_nan=False).map(lambda v: f"{v:.4f}"),
    st.sampled_from(HOSTILE_NUMBERS),
)
params = st.integers(1, 40).map(lambda n: f"#{n}")
expressions = st.recursive(
    st.one_of(numbers, params),
    lambda e: st.one_of(
        st.tuples(e, st.sampled_from(["+", "-", "*", "/", "**", "MOD", "AND", "OR", "XOR", "LT", "GT", "EQ", "NE"]),
                  e).map(lambda t: f"[{t[0]} {t[1]} {t[2]}]"),
        st.tuples(st.sampled_from(["SIN", "COS", "TAN", "SQRT", "ABS", "ATAN", "EXP", "LN", "FIX", "FUP",
                                   "ROUND", "ASIN", "ACOS"]), e).map(lambda t: f"{t[0]}[{t[1]}]"),
        e.map(lambda x: f"[{x}]"),
    ),
    max_leaves=6,
)
values = st.one_of(numbers, numbers, expressions, params)
small = st.integers(0, 4).map(str)
words = st.one_of(
    st.tuples(st.sampled_from("XYZIJKRF"), values).map("".join),
    st.tuples(st.sampled_from("SHDT"), st.integers(0, 25).map(str)).map("".join),
    st.tuples(st.sampled_from("PQL"), small).map("".join),
)
codes = st.sampled_from(["G0", "G1", "G2", "G3", "G4", "G17", "G18", "G19", "G20", "G21", "G28", "G30", "G40", "G43",
                         "G49", "G53", "G54", "G55", "G59.3", "G64", "G73", "G80", "G81", "G82", "G83", "G90", "G91",
                         "G91.1", "G92", "G92.1", "G93", "G94", "G98", "G99", "G5", "G5.1", "G7", "G8", "G10 L2 P1",
                         "G33", "G38.2", "G5.1 Q1", "M3", "M5", "M6", "M30", "M62 P1", "M67 E0 Q40", "M98 P2000",
                         "N10", "O1234", "/", "G70", "G71", "G15", "G16", "G68", "G51"])
motion_lines = st.tuples(st.lists(codes, max_size=3), st.lists(words, max_size=5)).map(
    lambda t: " ".join(t[0] + t[1]))
lines = st.one_of(
    motion_lines, motion_lines, motion_lines,
    st.tuples(params, expressions).map(lambda t: f"{t[0]}={t[1]}"),
    st.text(st.characters(min_codepoint=32, max_codepoint=126, exclude_characters="()"), max_size=20)
    .map(lambda s: f"({s})"),
    st.text(max_size=12).map(lambda s: s.replace("\n", " ").replace("\r", " ")),
    st.sampled_from(["%", "", "O1000", ";comment", "(MSG, hello)", "o<sub> call [1] [2]", "o100 sub", "o100 endsub",
                     "o100 call", "M99", "G65 P9000 A1", "IF [#1 GT 0] GOTO 10", "#<name>=2", "G1 X#<name>",
                     "#5220=1", "#[1+2]=3", "G1 X[#[1+2]]"]),
)


def linuxcnc_loop(body: list[str], n: int, kind: int) -> list[str]:
    if kind == 0:
        return ["#31=0", f"o100 while [#31 LT {n}]", *body, "#31=[#31+1]", "o100 endwhile"]
    if kind == 1:
        return [f"o101 repeat [{n}]", *body, "o101 endrepeat"]
    return ["#32=0", "o102 do", *body, "#32=[#32+1]", f"o102 while [#32 LT {n}]"]


def fanuc_loop(body: list[str], n: int, kind: int) -> list[str]:
    if kind == 0:
        return ["#31=0", f"WHILE [#31 LT {n}] DO1", *body, "#31=#31+1", "END1"]
    return ["M98 P2001 L" + str(n)]  # the body is subprogram O2001 (see programs)


@st.composite
def programs(draw):
    dialect = draw(st.sampled_from(DIALECTS))
    body = draw(st.lists(lines, min_size=0, max_size=12))
    head = ["G21 G90 G17", "G54 G0 X50 Y50 Z50"] if draw(st.booleans()) else []
    loop_body: list[str] = []
    if draw(st.booleans()):
        loop = draw(st.lists(motion_lines, min_size=1, max_size=3))
        n, kind = draw(st.integers(0, 3)), draw(st.integers(0, 2))
        at = draw(st.integers(0, len(body)))
        made = (fanuc_loop if dialect in ("fanuc", "haas") else linuxcnc_loop)(loop, n, kind)
        loop_body = loop
        body[at:at] = made
    end = draw(st.sampled_from(["M2", "M30", "", "%"]))
    sub = ["O2000", "G1 X1 Y1", "M99"] if dialect in ("fanuc", "haas") and draw(st.booleans()) else []
    if loop_body and dialect in ("fanuc", "haas"):
        sub += ["O2001", *loop_body, "M99"]
    eol = draw(st.sampled_from(["\n", "\r\n"]))
    return dialect, eol.join(head + body + [end] + sub) + eol


SETUP = ["--offset", "G54=X100,Y100,Z100", "--offset", "G55=X100,Y100,Z100", "--offset", "G59.3=X100,Y100,Z100",
         "--tool-length", "1=100", "--home", "G28=X0,Y0,Z300", "--home", "G30=X0,Y0,Z300", "--start", "X150,Y150,Z150"]


@fuzz(60)
@given(programs(), st.sampled_from(["refuse", "clamp", "linear"]), st.sampled_from(["keep", "expand"]),
       st.sampled_from([STATIC, PARAMETRIC]))
def test_fuzz_programs_correct(tmp_path_factory, prog, extrapolate, cycles, calibration):
    dialect, text = prog
    d = tmp_path_factory.mktemp("p")
    src = d / "prog.nc"
    src.write_text(text, encoding="utf-8", newline="")
    out = d / "out.nc"
    result = run("correct", src, "-c", calibration, "--dialect", dialect, "--extrapolate", extrapolate,
                 "--cycles", cycles, *SETUP, "-o", out)
    check(result, src)
    assert out.exists() == (result.exit_code == 0), result.output
    assert [p.name for p in d.iterdir() if p.name.startswith(".")] == []


@fuzz(12)
@given(programs())
def test_fuzz_programs_diff_and_verify(tmp_path_factory, prog):
    dialect, text = prog
    d = tmp_path_factory.mktemp("p")
    src = d / "prog.nc"
    src.write_text(text, encoding="utf-8", newline="")
    check(run("diff", src, src, "--dialect", dialect, *SETUP[:-2]), src)
    check(run("verify", src, "-c", STATIC, "--machine", STATIC, "--dialect", dialect, "--max-step", "5",
              "--cycles", "expand", *SETUP), src)


@fuzz(10)
@given(programs())
def test_fuzz_piped_programs(prog):
    dialect, text = prog
    result = run("correct", "-", "-c", STATIC, "--dialect", dialect, *SETUP, "-o", "-", stdin=text)
    check(result)


# -- calibrations --------------------------------------------------------------------

HOSTILE_VALUES = [float("nan"), float("inf"), -1.0, 0.0, 1e308, -1e308, 1e-320, "x", "", None, True, [], {}, [1, 2],
                  {"a": 1}, 10 ** 5000 if False else int("9" * 400), [[0, 0, 0], [1e308, 1e308, 1e308]],
                  [[300, 300, 300], [0, 0, 0]], [[float("nan")] * 3] * 2, "1e3", -0.0, 2 ** 63, [[]], [None]]


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node[:6]):
            yield from _paths(v, (*prefix, i))


def _set(node, path, value):
    if not path:
        return value
    node = copy.deepcopy(node)
    cur = node
    for key in path[:-1]:
        cur = cur[key]
    cur[path[-1]] = value
    return node


def _drop(node, path):
    node = copy.deepcopy(node)
    cur = node
    for key in path[:-1]:
        cur = cur[key]
    del cur[path[-1]]
    return node


@pytest.fixture(scope="module")
def calibrations(tmp_path_factory):
    """One calibration of each format: static, parametric (tables), parametric from runs,
    grid, interval, identity, and static with effects."""
    d = tmp_path_factory.mktemp("cal")
    pts = d / "pts.csv"
    assert run("simulate", MACHINE, "--grid", "105", "-o", pts).exit_code == 0
    made = Calibrations(static=json.loads(STATIC.read_text()), parametric=json.loads(PARAMETRIC.read_text()))
    for name, args in {"grid": ["-m", "grid", "--step", "105"], "interval": ["-m", "interval", "--intervals",
                                                                            "X=2;Y=2;Z=2"]}.items():
        assert run("fit", pts, *args, "-o", d / f"{name}.json").exit_code == 0
        made[name] = json.loads((d / f"{name}.json").read_text())
    assert run("fit", ROOT / "samples" / "iso230_runs_x.csv", "-o", d / "runs.json").exit_code == 0
    made["runs"] = json.loads((d / "runs.json").read_text())
    identity = {k: v for k, v in made["static"].items() if k not in ("model", "fit")}
    made["identity"] = {**identity, "method": "identity", "model": {}}
    made["effects"] = {**made["static"], "effects": [
        {"name": "backlash:X", "params": {"b_mm": 0.002}},
        {"name": "thermal:t", "config": {"tau_s": 600.0}, "params": {"dx_mm": 0.001}}]}
    return made


CALIBRATION_NAMES = ["effects", "grid", "identity", "interval", "parametric", "runs", "static"]


@fuzz(60)
@given(st.sampled_from(CALIBRATION_NAMES), st.integers(0, 10 ** 6), st.integers(0, len(HOSTILE_VALUES) - 1),
       st.integers(0, 5))
def test_fuzz_calibrations(tmp_path_factory, calibrations, name, at, hostile, drop):
    """One calibration of each format with one field replaced by a hostile value, or dropped."""
    data = calibrations[name]
    paths = list(_paths(data))
    path = paths[at % len(paths)]
    if path and drop == 0:
        cal = _drop(data, path)
    else:
        cal = _set(data, path, copy.deepcopy(HOSTILE_VALUES[hostile]))
    d = tmp_path_factory.mktemp("c")
    path = d / "cal.json"
    path.write_text(json.dumps(cal, allow_nan=True))
    out = d / "out.nc"
    result = run("correct", POCKET, "-c", path, "--context", "t=100", "-o", out)
    check(result)
    assert out.exists() == (result.exit_code == 0)


@fuzz(15)
@given(st.sampled_from(["[" * 3000 + "]" * 3000, '{"a":' * 3000 + "1" + "}" * 3000, "9" * 5000, "",
                        "\x00\xff", '{"format": "postproc calibration", "version": ' + "9" * 5000 + "}",
                        "[1e309]", "NaN", '{"format": "postproc calibration"}' * 2]))
def test_fuzz_calibration_text(tmp_path_factory, text):
    d = tmp_path_factory.mktemp("c")
    path = d / "cal.json"
    path.write_text(text, encoding="utf-8", errors="surrogateescape")
    check(run("correct", POCKET, "-c", path, "-o", d / "out.nc"))


# -- tool tables ---------------------------------------------------------------------

tool_fields = st.tuples(st.sampled_from("TPZDXYQ"), st.one_of(numbers, st.just(""))).map("".join)
tool_lines = st.one_of(st.lists(tool_fields, max_size=5).map(" ".join),
                       st.text(max_size=15).map(lambda s: s.replace("\n", " ")),
                       st.tuples(st.integers(-2, 30), numbers).map(lambda t: f"T{t[0]} P1 Z{t[1]} ;c"))


@fuzz(30)
@given(st.lists(tool_lines, max_size=6))
def test_fuzz_tool_tables(tmp_path_factory, rows):
    d = tmp_path_factory.mktemp("t")
    table = d / "tools.tbl"
    table.write_text("\n".join(rows) + "\n", encoding="utf-8", errors="surrogateescape")
    result = run("correct", ROOT / "samples" / "g54_g43.ngc", "-c", STATIC, "--offset", "G54=X100,Y80,Z40",
                 "--tool-table", table, "-o", d / "out.nc")
    check(result, table)


# -- every numeric option of every command -------------------------------------------


def _commands(cmd=main, path=()):
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(None):
            yield from _commands(cmd.get_command(None, name), (*path, name))
    else:
        yield " ".join(path), cmd


def base_args(tmp: Path) -> dict[str, list]:
    """A run of each command that succeeds (or is refused cleanly) as it stands."""
    mirror = ROOT / "samples" / "mirror"
    predict = ROOT / "samples" / "predict"
    return {
        "check": ["check", ROOT / "samples" / "walkthrough_points.csv", "-c", STATIC],
        "correct": ["correct", POCKET, "-c", STATIC, "-o", tmp / "o.nc"],
        "diff": ["diff", POCKET, POCKET],
        "export": ["export", PARAMETRIC, "--format", "linuxcnc", "-o", tmp / "comp"],
        "fit": ["fit", ROOT / "samples" / "walkthrough_points.csv", "-o", tmp / "cal.json"],
        "iso230": ["iso230", ROOT / "samples" / "iso230_runs_x.csv"],
        "mirror deadband": ["mirror", "deadband", mirror / "zigzag_sensor.csv", "--gap", "0.02"],
        "mirror kdist": ["mirror", "kdist", mirror / "backwall_sensor.csv", "--cutter-radius", "10",
                         "--diameter", "2000", "-o", tmp / "k.csv"],
        "mirror kfb": ["mirror", "kfb", mirror / "P01_semi.csv", "--t-ref", "2", "--allowance", "0.3",
                       "--origin", "3,100", "-o", tmp / "kfb.csv"],
        "mirror pockets": ["mirror", "pockets", mirror / "plan.csv", "-c", mirror / "shell_static.json", "--program",
                           mirror / "pocket.nc", "--t-ref", "2.0", "--band", "1.98,2.02", "--allowance", "0.3",
                           "-o", tmp / "next"],
        "mirror synth": ["mirror", "synth", tmp / "shell"],
        "orders": ["orders", "-c", PARAMETRIC, "--point", "60,50,50"],
        "predict bore": ["predict", "bore", predict / "bore_50H7.operation.json", "-n", "50"],
        "predict chain": ["predict", "chain", ROOT / "calibrations" / "s500_tables.csv", "--squareness",
                          ROOT / "calibrations" / "s500_tables_squareness.csv", "-o", tmp / "m.chain.json"],
        "predict init": ["predict", "init", "--layout", "vertical-mill", "-c", PARAMETRIC, "-o", tmp / "i.json"],
        "predict point": ["predict", "point", predict / "mc12.machine.json", "--set", "X=0", "--set", "S=90",
                          "--tool", "100,25,0"],
        "predict tolerance": ["predict", "tolerance", predict / "bore_50H7.operation.json", "-n", "50"],
        "predict trace": ["predict", "trace", predict / "flank_5mm.operation.json"],
        "simulate": ["simulate", MACHINE, "--random", "5", "-o", tmp / "s.csv"],
        "verify": ["verify", POCKET, "-c", STATIC, "--machine", STATIC],
    }


def numeric_options():
    for name, cmd in _commands():
        for p in cmd.params:
            if isinstance(p, click.Option) and isinstance(p.type, (click.types.FloatParamType,
                                                                    click.types.IntParamType)):
                yield name, p.opts[0], isinstance(p.type, click.types.IntParamType)


NUMERIC = sorted(numeric_options())
HOSTILE_OPTION_VALUES = ["0", "-1", "1e-9", "1e9", "1e300", "-0", "nan", "inf", "-inf", "1e999", "9" * 400, "0.5",
                         "3", "100000", "2147483648", "abc", "", " 1", "1_000", "0x10"]
#: values that make a run long by design (sizes, counts, steps): the resource limits bound them
SLOW = {("simulate", "--step"), ("simulate", "--random"), ("simulate", "--repeats"), ("verify", "--max-step"),
        ("verify", "--shots"), ("predict bore", "-n"), ("predict tolerance", "-n"), ("check", "--folds"),
        ("mirror kdist", "--segment-deg"), ("mirror kdist", "--z-bin"), ("export", "--step"),
        ("mirror synth", "--pockets"), ("mirror deadband", "--drive-tau"), ("predict trace", "--samples"),
        ("fit", "--max-effects"), ("fit", "--knot-spacing"), ("predict bore", "--samples"), ("correct", "--jobs"),
        ("fit", "--folds"), ("predict trace", "--points"), ("predict bore", "--points"), ("mirror pockets", "--smooth"),
        ("correct", "--tolerance"), ("verify", "--tolerance"), ("mirror pockets", "--tolerance"),
        ("predict trace", "--heights"), ("predict trace", "--windows"), ("check", "--max-effects"),
        ("mirror kfb", "--smooth"), ("mirror kdist", "--diameter"), ("mirror kdist", "--cutter-radius"),
        ("fit", "--border-blend"), ("correct", "-j"), ("mirror deadband", "--gap"), ("simulate", "--time-span")}


def test_the_numeric_options_are_walked():
    assert len(NUMERIC) > 30


@fuzz(80)
@given(st.sampled_from(NUMERIC), st.sampled_from(HOSTILE_OPTION_VALUES))
def test_fuzz_numeric_options(tmp_path_factory, option, value):
    name, flag, _is_int = option
    try:
        number = float(value)
    except ValueError:
        number = None
    if (name, flag) in SLOW and number is not None and (abs(number) > 100 or 0 < abs(number) < 1e-3):
        return  # a long run by design, bounded by the resource limits
    tmp = tmp_path_factory.mktemp("o")
    args = base_args(tmp)[name]
    check(run(*args, flag, value))


# -- internal errors found before the expression and limits bounds --


@pytest.mark.parametrize("line", ["G0 X[" + "[" * 3000 + "1" + "]" * 3000 + "] Y10 Z10",
                                  "#1=[" + "+".join(["1"] * 20000) + "]"], ids=["3000-deep", "20000-terms"])
def test_deep_or_long_expressions_are_refused(tmp_path, line):
    src = tmp_path / "deep.ngc"
    src.write_text(f"G21 G90\n{line}\nG0 X10 Y10 Z10\nM2\n")
    check(run("correct", src, "-c", STATIC, "--offset", "G54=X100,Y100,Z100", "-o", tmp_path / "o.nc"), src)


def test_a_huge_coordinate_with_clamp_is_refused(tmp_path):
    src = tmp_path / "huge.nc"
    src.write_text("G21 G90\nG0 X10 Y10 Z10\nG1 X" + "9" * 400 + " F100\nG1 X20\nM2\n")
    check(run("correct", src, "-c", STATIC, "--extrapolate", "clamp", "-o", tmp_path / "o.nc"), src)
