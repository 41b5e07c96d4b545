"""Golden cases: ``tests/cases/NAME.nc`` (input), ``NAME.flags`` (extra options, one
line; the calibration defaults to ``demo_static.json``), ``NAME.out`` (expected output).

Regenerate the expected outputs after a deliberate change with
``POSTPROC_REGEN_CASES=1 pytest tests/test_correct_cases.py`` and review the diff.
"""

import os
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import landing_error

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.cli.correct import build_setup
from postproc.errors import EXIT_SAFETY
from postproc.gcode.interp import Interpreter
from postproc.gcode.lexer import split_lines

CASES = Path(__file__).parent / "cases"
NAMES = sorted(p.stem for p in CASES.glob("*.nc"))


def _flags(name: str) -> list[str]:
    f = CASES / f"{name}.flags"
    args = shlex.split(f.read_text()) if f.exists() else []
    if "-c" not in args:
        args += ["-c", "demo_static.json"]
    return args


def _setup_and_cal(args: list[str]):
    opts = {"--offset": [], "--tool-length": [], "--tool-table": None, "--tool-vector": None, "--context": []}
    cal = None
    it = iter(args)
    for a in it:
        if a == "-c":
            cal = next(it)
        elif a in opts:
            v = next(it)
            if isinstance(opts[a], list):
                opts[a].append(v)
            else:
                opts[a] = v
    setup = build_setup(opts["--offset"], opts["--tool-length"], opts["--tool-table"],
                        opts["--tool-vector"], opts["--context"])
    return setup, load_calibration(CASES / cal)


def _run(name: str, out: Path):
    cwd = os.getcwd()
    os.chdir(CASES)
    try:
        return CliRunner().invoke(main, ["correct", f"{name}.nc", *_flags(name), "-o", str(out)],
                                  catch_exceptions=False)
    finally:
        os.chdir(cwd)


@pytest.mark.parametrize("name", NAMES)
def test_golden_output(name, tmp_path):
    out = tmp_path / f"{name}.out"
    r = _run(name, out)
    assert r.exit_code == 0, r.output
    got = out.read_bytes()
    expected_path = CASES / f"{name}.out"
    if os.environ.get("POSTPROC_REGEN_CASES"):
        expected_path.write_bytes(got)
    assert got == expected_path.read_bytes()


@pytest.mark.parametrize("name", NAMES)
def test_invariants(name, tmp_path):
    out = tmp_path / f"{name}.out"
    assert _run(name, out).exit_code == 0
    src_text = (CASES / f"{name}.nc").read_bytes().decode()
    out_text = out.read_bytes().decode()
    setup, cal = _setup_and_cal(_flags(name))
    # 1. every line that is not a move is copied byte for byte, in order
    interp = Interpreter(setup)
    still = [ln for i, ln in enumerate(split_lines(src_text), 1) if interp.feed_line(i, ln) is None]
    out_lines = split_lines(out_text)
    pos = 0
    for ln in still:
        pos = out_lines.index(ln, pos) + 1
    # 2. the corrected program lands on the nominal path through the forward model
    assert landing_error(src_text, out_text, cal.engine, setup) <= 0.001 * 1.01
    # 3. correcting twice is refused, and nothing is written
    again = tmp_path / "again.nc"
    r = CliRunner().invoke(main, ["correct", str(out), "-c", str(CASES / "demo_static.json"), "-o", str(again)])
    assert r.exit_code == EXIT_SAFETY
    assert not again.exists()
