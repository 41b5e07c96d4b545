"""The README's walkthroughs print what the README shows.

Every fenced block of commands after a ``<!-- walkthrough -->`` marker (``<!-- walkthrough
exit=N -->`` when the last command ends with exit code N) is run in order, in one folder
that sees the repository's ``samples/`` and ``calibrations/``, so a later block may use a
file an earlier one wrote. The fenced block right after it holds lines the commands
print: each must be a whole line of their output (``...`` stands for lines left out).
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from postproc.cli import main

ROOT = Path(__file__).parents[1]
README = ROOT / "README.md"

_BLOCK = re.compile(r"^<!-- walkthrough(?: exit=(\d+))? -->\n```\n(.*?)```\n\n```\n(.*?)```$",
                    re.MULTILINE | re.DOTALL)


def walkthroughs(text: str) -> list[tuple[list[list[str]], int, list[str]]]:
    """(commands as argument lists, exit code of the last, lines shown) per marked block."""
    found = []
    for m in _BLOCK.finditer(text):
        commands = []
        for line in m.group(2).replace("\\\n", " ").splitlines():
            line = line.split(" && ", 1)[1] if line.startswith("pip install") else line
            args = shlex.split(line, comments=True)
            assert args[0] == "postproc", f"not a postproc command: {line}"
            commands.append(args[1:])
        shown = [s for s in m.group(3).splitlines() if s.strip() != "..."]
        found.append((commands, int(m.group(1) or 0), shown))
    return found


def test_the_readme_marks_its_walkthroughs():
    text = README.read_text(encoding="utf-8")
    blocks = walkthroughs(text)
    markers = re.findall(r"^<!-- walkthrough", text, re.MULTILINE)
    assert len(markers) == len(blocks), "a marker is not followed by a command block and an output block"
    ran = {args[0] for commands, _, _ in blocks for args in commands}
    # the four jobs: machinist, CAM batch, metrologist, model check
    assert {"correct", "diff", "iso230", "fit", "export", "check"} <= ran


def missing_lines(commands: list[list[str]], exit_code: int, shown: list[str]) -> list[str]:
    """Run one block's commands in the current folder; the shown lines they did not print."""
    runner = CliRunner()
    output = []
    for i, args in enumerate(commands):
        result = runner.invoke(main, args)
        expected = exit_code if i == len(commands) - 1 else 0
        assert result.exit_code == expected, f"postproc {shlex.join(args)}: exit {result.exit_code}\n{result.output}"
        output.extend(line.rstrip() for line in result.output.splitlines())
    return [line for line in shown if line.rstrip() not in output]


@pytest.fixture
def in_folder(tmp_path, monkeypatch):
    """A folder that sees the repository's samples and calibrations, as the README's commands do."""
    for name in ("samples", "calibrations"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_readme_walkthroughs_print_what_the_readme_shows(in_folder):
    for commands, exit_code, shown in walkthroughs(README.read_text(encoding="utf-8")):
        missing = missing_lines(commands, exit_code, shown)
        assert not missing, (f"the README shows lines that `postproc {shlex.join(commands[-1])}` "
                             "does not print:\n" + "\n".join(missing))


def test_a_line_the_readme_shows_wrongly_is_caught(in_folder):
    blocks = [b for b in walkthroughs(README.read_text(encoding="utf-8")) if b[0][0][0] == "iso230"]
    assert blocks, "the README has no iso230 walkthrough"
    commands, exit_code, shown = blocks[0]
    assert missing_lines(commands, exit_code, shown) == []
    drifted = [line.replace("M 8.44", "M 8.45") for line in shown]
    assert drifted != shown
    assert missing_lines(commands, exit_code, drifted) == [line for line in drifted if "M 8.45" in line]
