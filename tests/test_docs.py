"""The README and the commands stay in step: every command is listed with exactly its options."""

import json
import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from postproc.cli import main

README = Path(__file__).parents[1] / "README.md"


def leaf_commands():
    ctx = click.Context(main)

    def walk(cmd, prefix):
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                yield from walk(cmd.get_command(ctx, name), prefix + [name])
        else:
            yield " ".join(prefix), cmd

    return list(walk(main, ["postproc"]))


def signature(cmd: click.Command) -> list[str]:
    out = []
    for p in cmd.params:
        if isinstance(p, click.Option):
            out.append(max(p.opts, key=len))
        else:
            out.append(p.name.upper())
    return out


def readme_table() -> dict[str, list[str]]:
    text = README.read_text(encoding="utf-8")
    section = text.split("\n## Commands\n", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for m in re.finditer(r"^\| `(postproc [^`]+)` \| ([^|]+) \|$", section, re.MULTILINE):
        rows[m.group(1)] = m.group(2).split()
    return rows


def test_every_command_is_in_the_readme_with_its_options():
    documented = readme_table()
    actual = {name: signature(cmd) for name, cmd in leaf_commands()}
    assert sorted(documented) == sorted(actual), "README command table and CLI commands differ"
    for name, opts in actual.items():
        assert documented[name] == opts, f"{name}: README lists {documented[name]}, CLI has {opts}"


@pytest.mark.parametrize(("name", "cmd"), leaf_commands(), ids=lambda v: v if isinstance(v, str) else "")
def test_every_command_has_help_with_an_example(name, cmd):
    args = name.split()[1:] + ["--help"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "Example" in result.output, f"{name} --help has no example"
    assert (cmd.help or "").strip(), f"{name} has no docstring"


def test_readme_quick_start_commands():
    text = README.read_text(encoding="utf-8")
    ci = (Path(__file__).parents[1] / ".ci" / "run").read_text()
    test_cmd = 'pip install -e ".[test]" && python3 -m pytest -q -p no:cacheprovider -n auto'
    assert test_cmd in text
    assert 'python3 -m pip install --quiet -e ".[test]" && python3 -m pytest -q -p no:cacheprovider -n auto' in ci
    m = re.search(r"pip install -e \. && postproc correct (\S+) -c (\S+) -o (\S+)", text)
    assert m, "README has no install-and-correct command"
    for path in m.group(1, 2):
        assert (README.parent / path).is_file(), path


def test_readme_links_exist():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(((?:docs|samples|calibrations)/[^)#]+)\)", text):
        assert (README.parent / target).exists(), target


def test_readme_main_job_runs(tmp_path, monkeypatch):
    text = README.read_text(encoding="utf-8")
    m = re.search(r"pip install -e \. && postproc correct (\S+) -c (\S+) -o (\S+)", text)
    monkeypatch.chdir(README.parent)
    out = tmp_path / m.group(3)
    result = CliRunner().invoke(main, ["correct", m.group(1), "-c", m.group(2), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text().count("\n") > 34


def _readme_block_after(text: str, command_start: str) -> str:
    """The first fenced block that follows the block holding ``command_start``."""
    at = text.index(command_start)
    rest = text[text.index("```\n", at) + 4:]
    start = rest.index("```\n") + 4
    return rest[start:rest.index("```", start)]


def test_readme_quick_start_figures_are_what_correct_prints(tmp_path, monkeypatch):
    text = README.read_text(encoding="utf-8")
    m = re.search(r"pip install -e \. && postproc correct (\S+) -c (\S+) -o (\S+)", text)
    printed = _readme_block_after(text, m.group(0)).splitlines()[0]
    monkeypatch.chdir(README.parent)
    out = tmp_path / m.group(3)
    result = CliRunner().invoke(main, ["correct", m.group(1), "-c", m.group(2), "-o", str(out)])
    assert result.exit_code == 0, result.output
    figures = printed.split(": ", 1)[1]
    assert f"{m.group(1)} -> {out}: {figures}" in result.output


def test_readme_verify_table_is_what_verify_prints(monkeypatch):
    text = README.read_text(encoding="utf-8")
    m = re.search(r"^postproc verify (samples/pocket\.nc .+)$", text, re.MULTILINE)
    rows = re.findall(r"^\| (uncorrected|corrected, \w+) .*?\| ([\d.]+) µm \| ([\d.]+) µm \|$", text, re.MULTILINE)
    assert [r[0] for r in rows] == ["uncorrected", "corrected, parametric", "corrected, static"]
    monkeypatch.chdir(README.parent)
    result = CliRunner().invoke(main, ["verify", *m.group(1).split(), "--json"])
    assert result.exit_code == 0, result.output
    runs = json.loads(result.output)["runs"]
    assert len(runs) == len(rows)
    for run, (label, max_um, rms_um) in zip(runs, rows, strict=True):
        assert run["label"].startswith(label)
        assert f"{run['max_mm'] * 1000:.2f}" == max_um, label
        assert f"{run['rms_mm'] * 1000:.2f}" == rms_um, label


def test_the_command_list_needs_no_command_module_and_says_what_each_docstring_says():
    import re
    import subprocess
    import sys

    from postproc.cli import COMMANDS, SHORT_HELP, main

    for name in COMMANDS:
        cmd = main.get_command(None, name)
        para = " ".join((cmd.help or "").strip().split("\n\n")[0].split())
        m = re.match(r"(.*?\.)(\s|$)", para)
        assert SHORT_HELP.get(name) == (m.group(1) if m else para), name
    # `postproc --help` imports no command module (so neither numpy nor scipy)
    code = ("import sys\nfrom postproc.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith(('numpy', 'scipy', 'postproc.cli.'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_readme_is_a_front_door_for_users():
    """The README stays short and about the program; details live on the docs/ pages,
    history in CHANGELOG.md."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 350, "README over 350 lines: move the details to a page under docs/"
    assert not re.search(r"\b(sessions?|rounds?|issue \d+)\b", text, re.IGNORECASE), "history belongs in CHANGELOG.md"
    for page in ("docs/performance.md", "docs/architecture.md", "CHANGELOG.md"):
        assert f"]({page})" in text, f"README does not link {page}"
