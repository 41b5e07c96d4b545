"""Bad input to the commands other than correct/diff: a one-line `postproc: error:`,
a non-zero exit code, no traceback and no output file left behind."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.errors import EXIT_INTERNAL, EXIT_USAGE, OutputError
from postproc.fileio import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
WALKTHROUGH = ROOT / "samples" / "walkthrough_points.csv"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def assert_user_error(result, code: int, *fragments: str) -> None:
    """A PostprocError reported on one `postproc: error:` line, not an internal error."""
    assert result.exit_code == code, result.output
    assert result.exit_code != EXIT_INTERNAL
    assert "internal error" not in result.output
    assert "Traceback" not in result.output
    assert "postproc: error: " in result.output, result.output
    for fragment in fragments:
        assert fragment in result.output, result.output


def test_atomic_write_into_a_missing_directory_is_an_output_error(tmp_path):
    target = tmp_path / "missing" / "out.txt"
    with pytest.raises(OutputError) as exc:
        atomic_write_text(target, "x\n")
    assert exc.value.exit_code == EXIT_USAGE
    assert str(exc.value).startswith(f"{target}: cannot write the output: directory")
    assert not (tmp_path / "missing").exists()


def test_fit_into_a_missing_directory(tmp_path):
    out = tmp_path / "missing" / "cal.json"
    result = run("fit", WALKTHROUGH, "-o", out)
    assert_user_error(result, EXIT_USAGE, f"{out}: cannot write the output")
    assert not out.parent.exists()


def test_simulate_tables_into_a_missing_directory(tmp_path):
    out = tmp_path / "missing" / "t.csv"
    result = run("simulate", MACHINE, "--tables", "--step", "100", "-o", out)
    assert_user_error(result, EXIT_USAGE, "cannot write the output")
    assert not out.parent.exists()
