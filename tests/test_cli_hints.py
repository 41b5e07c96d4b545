"""A hint never names an option the command lacks.

Every refusal message and hint of the program reader (postproc/gcode) and of the
correction pipeline names options (``give --cycles expand``, ``raise --tolerance``,
``choose --dialect fanuc``). Each option named must be an option of every command that
runs that code: the commands that read programs take the same reading and setup options,
and those that correct them the same correction options (postproc/cli/options.py)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from postproc.cli import main

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "postproc"
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*[a-z0-9]")

#: commands that read a program with postproc/gcode ...
READERS = ("correct", "verify", "diff", "mirror pockets")
#: ... and those of them that also correct it (the pipeline, its segmentation and emitter)
CORRECTORS = ("correct", "verify", "mirror pockets")
#: modules run only when a program is corrected (the others of postproc/gcode read programs)
CORRECTING_MODULES = {"pipeline", "reader", "planner", "table", "sampling", "dirplan", "writer", "arcfit", "framed",
                      "options", "segment", "engine_use", "split", "emit", "emitter", "vplan", "bulk", "directions"}


def commands(cmd=main, path=()):
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(None):
            yield from commands(cmd.get_command(None, name), (*path, name))
    else:
        yield " ".join(path), cmd


COMMANDS = dict(commands())
TOP = {name.split()[0] for name in COMMANDS}
COMMAND_NAME = re.compile(r"postproc ([a-z0-9]+)")


def options(name: str) -> set[str]:
    return {opt for p in COMMANDS[name].params for opt in p.opts}


def named_options(path: Path):
    """(line, option, text) for each ``--option`` in the string constants of a raise
    statement's exception or of a ``hint=`` keyword in ``path`` (docstrings are not
    messages)."""
    seen = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        parts = []
        if isinstance(node, ast.Raise) and node.exc is not None:
            parts.append(node.exc)
        elif isinstance(node, ast.keyword) and node.arg == "hint":
            parts.append(node.value)
        elif isinstance(node, ast.FunctionDef) and node.name.startswith(("_hint", "hint")):
            parts.extend(node.body[1:] if ast.get_docstring(node) else node.body)
        for part in parts:
            for sub in ast.walk(part):
                if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                    for m in FLAG.finditer(sub.value):
                        flag = m.group()
                        # "refit with 'postproc fit --effect'": another command's option, named with it
                        other = [c for c in COMMAND_NAME.findall(sub.value[:m.start()]) if c in TOP]
                        if other:
                            continue  # checked by test_options_named_with_their_command_are_theirs
                        if (sub.lineno, flag) not in seen:
                            seen.add((sub.lineno, flag))
                            yield sub.lineno, flag, sub.value


def cases():
    for path in sorted((PACKAGE / "gcode").glob("*.py")):
        names = CORRECTORS if path.stem in CORRECTING_MODULES else READERS
        for lineno, flag, text in named_options(path):
            yield pytest.param(path, lineno, flag, text, names, id=f"{path.stem}:{lineno}:{flag}")
    for path in [PACKAGE / "effects" / "base.py", PACKAGE / "simulate" / "program.py"]:
        for lineno, flag, text in named_options(path):
            yield pytest.param(path, lineno, flag, text, CORRECTORS, id=f"{path.stem}:{lineno}:{flag}")


CASES = list(cases())


def test_the_walk_finds_the_hints():
    flags = {c.values[2] for c in CASES}
    assert {"--cycles", "--dialect", "--subroutine-path", "--tolerance", "--offset", "--start"} <= flags
    assert len(CASES) > 30


@pytest.mark.parametrize(("path", "lineno", "flag", "text", "names"), CASES)
def test_every_option_a_hint_names_is_an_option_of_each_command_that_can_give_it(path, lineno, flag, text, names):
    lacking = [name for name in names if flag not in options(name)]
    assert not lacking, f"{path.relative_to(ROOT)}:{lineno} names {flag} ({text!r}), which {lacking} lack"


def test_the_command_hints_name_their_own_options():
    """Hints written in the commands themselves (postproc/cli/<command>.py)."""
    module_of = {"correct": "correct", "verify": "verify", "diff": "diff", "fit": "fit", "check": "check",
                 "simulate": "simulate", "orders": "orders", "export": "export", "iso230": "iso230"}
    for name, module in module_of.items():
        for lineno, flag, text in named_options(PACKAGE / "cli" / f"{module}.py"):
            assert flag in options(name), f"cli/{module}.py:{lineno} names {flag} ({text!r}), not an option of {name}"


def test_verify_runs_the_readme_fanuc_sample(tmp_path):
    """The Fanuc sample: with --cycles keep refused with the hint to give --cycles expand, which
    verify takes; by default (auto) its tilted cycles are expanded."""
    args = ["verify", str(ROOT / "samples" / "fanuc_drill.nc"), "-c", str(ROOT / "calibrations" / "s500_static.json"),
            "--machine", str(ROOT / "calibrations" / "s500_static.json"), "--dialect", "fanuc",
            "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100", "--home", "G28=X0,Y0,Z300"]
    refused = CliRunner().invoke(main, [*args, "--cycles", "keep"])
    assert refused.exit_code == 5, refused.output
    assert "give --cycles expand" in refused.output
    for cycles in (["--cycles", "expand"], []):
        result = CliRunner().invoke(main, [*args, *cycles])
        assert result.exit_code == 0, result.output
        corrected = next(line for line in result.output.splitlines() if line.strip().startswith("corrected"))
        assert float(corrected.split()[3]) < 1.0  # um: the machine is the calibration itself


@pytest.mark.parametrize("name", ["correct", "verify", "diff", "mirror pockets"])
def test_the_program_options_are_declared_once(name):
    from postproc.cli.options import CORRECTION_OPTIONS, PROGRAM_OPTIONS

    reference = {max(p.opts, key=len): p for p in COMMANDS["correct"].params}
    declared = {max(p.opts, key=len): p for p in COMMANDS[name].params}
    shared = list(PROGRAM_OPTIONS) + (list(CORRECTION_OPTIONS) if name != "diff" else ["--max-correction"])
    for flag in shared:
        p, ref = declared[flag], reference[flag]
        assert (p.name, p.help, p.default, type(p.type)) == (ref.name, ref.help, ref.default, type(ref.type)), flag


def test_options_named_with_their_command_are_theirs():
    """``postproc fit --effect`` in any message: --effect is an option of fit."""
    pattern = re.compile(r"postproc ([a-z0-9]+)((?: [a-z0-9]+)?)[^'\"`\n]*?(--[a-z][a-z0-9-]*[a-z0-9])")
    found = 0
    for path in PACKAGE.rglob("*.py"):
        for m in pattern.finditer(path.read_text(encoding="utf-8")):
            top, sub, flag = m.group(1), m.group(2).strip(), m.group(3)
            if top not in TOP:
                continue
            name = f"{top} {sub}" if f"{top} {sub}" in COMMANDS else top
            names = [name] if name in COMMANDS else [n for n in COMMANDS if n.split()[0] == top]
            if flag == "--help":
                continue
            assert any(flag in options(n) for n in names), f"{path.relative_to(ROOT)}: {m.group()!r}"
            found += 1
    assert found > 5


@pytest.mark.parametrize("extra", [["--dialect", "fanuc"], ["--cycles", "expand"], ["--tolerance", "0.01"],
                                   ["--extrapolate", "clamp"], ["--no-expand"]])
def test_verify_points_refuses_program_options_it_would_not_use(extra):
    result = CliRunner().invoke(main, ["verify", "--points", str(ROOT / "samples" / "s500_control_points.csv"),
                                       "-c", str(ROOT / "calibrations" / "s500_static.json"),
                                       "--machine", str(ROOT / "calibrations" / "s500.machine.json"), *extra])
    assert result.exit_code == 2, result.output
    assert f"--points runs no program: {extra[0]} would not be used" in result.output
