"""Bounds on the resources one run may use, so that a hostile or broken program ends in a
clear refusal instead of hours of work, gigabytes of memory or a disk filled.

Each bound is named in its refusal with the option that raises it. Memory does not
depend on the program's size (programs are read, expanded and written in chunks); what
a program can make grow is bounded here:

- loop passes and subprogram calls of the expansion, in all (``--max-iterations``), and
  the lines it runs, a few per allowed pass;
- the lines written (``--max-output-lines``; by default 50 times the input plus a
  million) and their size (``--max-output-mb``; by default 50 times the input plus
  256 MB), which bound the temporary file the output is written to before it replaces
  the destination (a loop repeating a long comment line makes few lines of many bytes);
- the turns of one helix (``--max-arc-turns``).

Expressions are bounded in :mod:`postproc.gcode.expr`, calibration grids in
:mod:`postproc.engine.grid`, the sizes of ``simulate`` and ``verify`` in their modules.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from postproc.errors import SafetyError

# Loop passes and subprogram calls of one program's expansion: a program that runs
# ten million passes is an endless loop far more often than a part.
DEFAULT_MAX_ITERATIONS = 10_000_000
# Lines the expansion may run for each allowed pass (a loop body's control lines and
# settings run without writing anything; this bounds the time they take).
LINES_PER_ITERATION = 5
# The output may grow to this many times the input's lines, plus OUTPUT_LINES_EXTRA
# (a corrected program grows 1-5 times; a flat expansion of loops more).
OUTPUT_GROWTH = 50
OUTPUT_LINES_EXTRA = 1_000_000
# ... and this many bytes (characters) plus OUTPUT_GROWTH times the input's.
OUTPUT_MB_EXTRA = 256
# Turns of one helix (G2/G3 P): correcting an arc costs time growing with the square of
# its turns (100 turns: about a minute), and thread milling needs tens.
DEFAULT_MAX_ARC_TURNS = 100


class ResourceLimitError(SafetyError):
    """A bound on the work of one run (iterations, output lines, turns, sizes) refused the
    job; the message names the bound and the option that raises it. Nothing is written."""


@dataclass(frozen=True, slots=True)
class Limits:
    max_iterations: int = DEFAULT_MAX_ITERATIONS
    max_output_lines: int | None = None  # None: OUTPUT_GROWTH x the input's lines + OUTPUT_LINES_EXTRA
    max_arc_turns: int = DEFAULT_MAX_ARC_TURNS
    max_output_mb: float | None = None  # None: OUTPUT_GROWTH x the input's size + OUTPUT_MB_EXTRA

    def output_lines(self, input_lines: int) -> int:
        """The most lines the corrected program of ``input_lines`` lines may have."""
        if self.max_output_lines is not None:
            return self.max_output_lines
        return OUTPUT_GROWTH * input_lines + OUTPUT_LINES_EXTRA

    def output_chars(self, input_chars: int) -> int:
        """The most characters (bytes, for ASCII) the corrected program may have."""
        if self.max_output_mb is not None:
            return int(self.max_output_mb * 1e6)
        return OUTPUT_GROWTH * input_chars + OUTPUT_MB_EXTRA * 1_000_000


def flat_program_too_long(limit: int, path: str | None, lineno: int) -> ResourceLimitError:
    """The refusal of a program whose expansion alone runs more than ``limit`` lines, the
    bound on the corrected program's (found by a dry run of the expansion, before any
    line is corrected: :func:`postproc.gcode.expand.expand`, ``max_lines_out``)."""
    return ResourceLimitError(
        f"the corrected program would have more than {limit:,} lines: the program's loops and subprograms alone "
        "run that many (--max-output-lines)", path=path, lineno=lineno, col=1,
        hint="raise --max-output-lines if the program is meant to grow this much; otherwise check its loops")


class BoundedWriter:
    """``write`` that refuses to write more than ``limit`` lines in all; ``where()`` gives
    the (path, line) of the input being corrected, for the refusal's place."""

    def __init__(self, write: Callable[[str], object], limit: int,
                 where: Callable[[], tuple[str | None, int | None]], limit_chars: int | None = None):
        self._write = write
        self.limit = limit
        self.limit_chars = limit_chars
        self.lines = 0
        self.chars = 0
        self.where = where

    def __call__(self, text: str) -> None:
        # line ends: LF, CRLF and a lone CR (looked for only where a CR is)
        self.lines += text.count("\n")
        if "\r" in text:
            self.lines += text.count("\r") - text.count("\r\n")
        self.chars += len(text)
        if self.lines > self.limit:
            self._refuse(f"more than {self.limit:,} lines", "--max-output-lines")
        if self.limit_chars is not None and self.chars > self.limit_chars:
            self._refuse(f"more than {self.limit_chars / 1e6:,.6g} MB", "--max-output-mb")
        self._write(text)

    def _refuse(self, what: str, option: str) -> None:
        path, lineno = self.where()
        raise ResourceLimitError(
            f"the corrected program would have {what} ({option})", path=path, lineno=lineno,
            col=1 if lineno is not None else None,
            hint=f"raise {option} if the program is meant to grow this much; otherwise check its loops and arcs")

    def restart(self) -> None:
        """What was written was dropped: count again from zero."""
        self.lines = 0
        self.chars = 0
