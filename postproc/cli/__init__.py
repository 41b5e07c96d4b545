"""The postproc command line. Only this package prints, exits and reads options.

Each command lives in its own module and is imported only when it runs (or when the
command list is shown), so ``postproc correct`` does not pay for plotting or fitting.
"""

from __future__ import annotations

import importlib.util
import os
import sys

import click

from postproc import __version__
from postproc.errors import EXIT_INTERNAL, PostprocError

#: command name -> "module:attribute" (a click.Command)
COMMANDS = {
    "correct": "postproc.cli.correct:correct",
    "diff": "postproc.cli.diff:diff",
    "fit": "postproc.cli.fit:fit",
    "orders": "postproc.cli.orders:orders",
    "simulate": "postproc.cli.simulate:simulate",
    "verify": "postproc.cli.verify:verify",
    "check": "postproc.cli.check:check",
    "mirror": "postproc.cli.mirror:mirror",
    "predict": "postproc.cli.predict:predict",
    "iso230": "postproc.cli.iso230:iso230",
    "export": "postproc.cli.export:export",
}


#: command name -> its one-line help, shown by ``postproc --help`` without importing the
#: command (numpy, scipy); tests/test_docs.py checks it against each command's docstring
SHORT_HELP = {
    "check": "Check a calibration against measurements: residuals, noise floor, where it fails and which "
             "physical effect is missing.",
    "correct": "Correct NC programs for the machine's measured errors.",
    "diff": "Compare a program with its corrected version.",
    "export": "Write a controller's compensation table from a parametric calibration.",
    "fit": "Fit a calibration from point measurements or axis error tables.",
    "iso230": "Evaluate bidirectional positioning runs as ISO 230-2:2014 does.",
    "mirror": "Mirror milling of waffle shells: K_dist, feedback self-tuning, dead-band model.",
    "orders": "Compare the first- and second-order volumetric error at chosen points.",
    "predict": "Predict machined surfaces and feature errors from a machine chain.",
    "simulate": "Measure a virtual machine: tracker points or interferometer tables.",
    "verify": "Run a program, or control points, on a virtual machine and report the errors.",
}


class LazyGroup(click.Group):
    def format_commands(self, ctx, formatter):
        """The command list from :data:`SHORT_HELP` (no command module is imported)."""
        rows = []
        names = self.list_commands(ctx)
        width = formatter.width - 6 - max((len(n) for n in names), default=0)
        for name in names:
            text = SHORT_HELP.get(name)
            if text is None:
                cmd = self.get_command(ctx, name)
                text = cmd.get_short_help_str(width) if cmd is not None else ""
            elif len(text) > width:
                text = text[: max(width - 3, 1)].rstrip() + "..."
            rows.append((name, text))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def list_commands(self, ctx):
        return sorted(name for name in COMMANDS if self._spec_exists(name))

    @staticmethod
    def _spec_exists(name: str) -> bool:
        module = COMMANDS[name].partition(":")[0]
        return importlib.util.find_spec(module) is not None

    def get_command(self, ctx, name):
        if name not in COMMANDS or not self._spec_exists(name):
            return None
        module, _, attr = COMMANDS[name].partition(":")
        return getattr(importlib.import_module(module), attr)

    def invoke(self, ctx):
        from postproc.cli.signals import exit_code, signal_name, stopping_cleanly

        try:
            with stopping_cleanly():
                return super().invoke(ctx)
        except PostprocError as exc:
            click.echo(f"postproc: error: {exc.with_column()}", err=True)
            ctx.exit(exc.exit_code)
        except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP: the cleanup has run on the way here
            click.echo(f"postproc: stopped by {signal_name(exc)}; temporary files removed, no output file "
                       "left half-written", err=True)
            ctx.exit(exit_code(exc))
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except BrokenPipeError:
            # The reader went away (e.g. `| head`): not an error of ours.
            sys.stderr.close()
            ctx.exit(0)
        except OSError as exc:  # disk full where no writer named its file (stdout, a flush)
            from postproc.fileio import disk_full

            full = disk_full(exc, exc.filename)
            if full is None:
                _internal(ctx, exc)
                return
            click.echo(f"postproc: error: {full}", err=True)
            ctx.exit(full.exit_code)
        except Exception as exc:  # a bug: say so plainly, no traceback unless asked
            _internal(ctx, exc)


def _internal(ctx, exc: Exception) -> None:
    if os.environ.get("POSTPROC_DEBUG"):
        raise exc
    click.echo(
        f"postproc: internal error: {type(exc).__name__}: {exc}\n"
        "  hint: this is a bug in postproc; rerun with POSTPROC_DEBUG=1 for the traceback "
        "and report it. No output file was written.",
        err=True,
    )
    ctx.exit(EXIT_INTERNAL)


def _core() -> str:
    """Which of the G-code lane's hot modules run compiled (setup.py), for --version."""
    from importlib.util import find_spec

    names = ("scanner", "plainscan", "numfmt", "runwords", "fitcore", "hintcore")
    done = [n for n in names if not (getattr(find_spec(f"postproc.gcode.{n}"), "origin", "") or "").endswith(".py")]
    return f"compiled core: {', '.join(done)}" if done else "compiled core: none (pure Python)"


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="postproc", message=f"%(prog)s, version %(version)s ({_core()})")
def main() -> None:
    """Correct CNC G-code programs for a machine's measured geometric errors.

    Fit a calibration from measurements (fit), correct programs with it (correct),
    see what moved (diff), and hold the model against measurements (check, verify).

    Example:

        postproc correct samples/pocket.nc -c calibrations/s500_static.json -o pocket_corrected.nc
    """
