"""Every option of every command is declared so that a bad value is one clear line:
float options refuse nan and inf (FiniteFloat), and --help reads properly."""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.cli.options import FiniteFloat
from postproc.errors import EXIT_USAGE


def walk(cmd=main, path=()):
    """(command path, click.Command) for every command and subcommand."""
    if isinstance(cmd, click.Group):
        for name in cmd.list_commands(None):
            yield from walk(cmd.get_command(None, name), (*path, name))
    else:
        yield path, cmd


def float_options():
    for path, cmd in walk():
        for p in cmd.params:
            if isinstance(p, click.Option) and isinstance(p.type, click.types.FloatParamType):
                yield pytest.param(path, p, id=f"{' '.join(path)} {p.opts[0]}")


FLOAT_OPTIONS = list(float_options())


def test_there_are_float_options_to_walk():
    assert len(FLOAT_OPTIONS) > 20


@pytest.mark.parametrize(("path", "param"), FLOAT_OPTIONS)
def test_every_float_option_is_finite(path, param):
    assert isinstance(param.type, FiniteFloat), f"{' '.join(path)} {param.opts[0]}: type=FiniteFloat(...)"


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "NaN", "1e999"])
@pytest.mark.parametrize(("path", "param"), FLOAT_OPTIONS)
def test_every_float_option_refuses_non_finite_values_in_one_line(path, param, value):
    result = CliRunner().invoke(main, [*path, param.opts[0], value])
    assert result.exit_code == EXIT_USAGE, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert errors == [f"Error: Invalid value for '{param.opts[0]}': {value!r} is not a finite number"], result.output
    assert "Traceback" not in result.output


def test_correct_max_correction_nan_is_refused_not_switched_off(tmp_path):
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["correct", "samples/pocket.nc", "-c", "calibrations/s500_static.json",
                                       "--max-correction", "nan", "-o", str(out)])
    assert result.exit_code == EXIT_USAGE, result.output
    assert "'nan' is not a finite number" in result.output
    assert not out.exists()


@pytest.mark.parametrize(("path", "param"), [pytest.param(path, p, id=f"{' '.join(path)} {p.opts[0]}")
                                             for path, cmd in walk() for p in cmd.params
                                             if isinstance(p, click.Option)])
def test_help_never_shows_a_none_bound(path, param):
    ctx = click.Context(dict(walk())[path], info_name=path[-1])
    record = param.get_help_record(ctx)
    if record is not None:
        assert "None" not in record[1].replace("\n", " "), record



@pytest.mark.parametrize("option", ["--start", "--offset"])
def test_an_axis_value_beyond_any_machine_is_refused_at_its_option(tmp_path, option):
    """A 400-digit position reads as inf: refused at the option, not an internal error."""
    from pathlib import Path

    cal = Path(__file__).parents[1] / "calibrations" / "s500_static.json"
    src = tmp_path / "p.nc"
    src.write_text("G21 G90\nG0 X1 Y1 Z1\nM2\n")
    huge = "9" * 400
    value = f"X{huge}" if option == "--start" else f"G54=X{huge},Y0,Z0"
    res = CliRunner().invoke(main, ["correct", str(src), "-c", str(cal), option, value,
                                    "-o", str(tmp_path / "o.nc")])
    assert res.exit_code == 2, res.output
    assert "no machine reaches that far" in res.output
    assert not (tmp_path / "o.nc").exists()
