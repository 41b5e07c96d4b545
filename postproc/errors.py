"""Project exceptions. Every error about user input names its place.

``str(err)`` is ``path:line:col: message`` (the parts that are known), followed
by a hint line saying what to do. Only :mod:`postproc.cli` turns these into exit
codes; library code raises them and never prints.
"""

from __future__ import annotations

# Exit codes, documented in the README. The CLI maps exceptions to them.
EXIT_OK = 0
EXIT_INTERNAL = 1  # a bug: please report it
EXIT_USAGE = 2  # bad command-line usage (click's own code)
EXIT_INPUT = 3  # a G-code, measurement or table file cannot be read as given
EXIT_CALIBRATION = 4  # a calibration file is malformed, in the wrong units or unfit
EXIT_SAFETY = 5  # a safety rule refused the job (bound, volume, missing offset, twice)
EXIT_NOT_HELD = 6  # predict --check: the predicted part does not hold its tolerance
EXIT_DISK_FULL = 7  # no space left on a device (ENOSPC) for the output or a temporary file: nothing written
# 128 + n: stopped by signal n (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP), temporary files removed


class PostprocError(Exception):
    """Base of every error caused by user input or a refused job."""

    exit_code = EXIT_INPUT
    #: which of the points given to a library call on many points was refused, where one was
    point_index: int | None = None

    def __init__(
        self,
        message: str,
        *,
        path: str | None = None,
        lineno: int | None = None,
        col: int | None = None,
        hint: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.path = path
        self.lineno = lineno
        self.col = col
        self.hint = hint

    @property
    def place(self) -> str:
        parts = [str(p) for p in (self.path, self.lineno, self.col) if p is not None]
        return ":".join(parts)

    def __str__(self) -> str:
        head = f"{self.place}: {self.message}" if self.place else self.message
        return f"{head}\n  hint: {self.hint}" if self.hint else head

    def with_column(self, source: str | None = None):
        """Fill in the column of an error that names a line but no column: the first
        character of that line that is not blank (a refusal about a whole block or row
        points at its start). ``source``: the file to read the line from, when it is not
        ``path`` (a piped program's copy). Nothing is read when the column is known."""
        where = source or self.path
        if self.col is None and self.lineno is not None and where:
            self.col = first_column(where, self.lineno)
        return self

    def at(self, path: str | None = None, lineno: int | None = None, col: int | None = None):
        """Fill in a place that was not known where the error was raised."""
        if self.path is None and path is not None:
            self.path = path
        if self.lineno is None and lineno is not None:
            self.lineno = lineno
        if self.col is None and col is not None:
            self.col = col
        return self


def first_column(path: str, lineno: int) -> int | None:
    """1-based column of the first non-blank character of line ``lineno`` of the file at
    ``path`` (1 for a blank line); None when the file or the line cannot be read."""
    try:
        with open(path, "rb") as fh:
            for n, line in enumerate(fh, start=1):
                if n == lineno:
                    body = line.rstrip(b"\r\n")
                    return len(body) - len(body.lstrip(b" \t")) + 1 if body.strip() else 1
    except (OSError, TypeError, ValueError):
        return None
    return None


class GcodeSyntaxError(PostprocError):
    """A character or word that is not G-code."""


class UnsupportedGcodeError(PostprocError):
    """Valid G-code that postproc refuses to correct (macros, subprograms, ...)."""


class MeasurementError(PostprocError):
    """A measurement or error-table file that does not follow formats.md."""


class CalibrationError(PostprocError):
    """A calibration file that is malformed, in the wrong units, or unusable."""

    exit_code = EXIT_CALIBRATION


class OutputError(PostprocError):
    """An output file that cannot be written where it was asked for (nothing was written)."""

    exit_code = EXIT_USAGE


class DiskFullError(OutputError):
    """No space left on the device for the output or a temporary file (ENOSPC); nothing
    was written (the temporary files were removed)."""

    exit_code = EXIT_DISK_FULL


class SafetyError(PostprocError):
    """A safety rule refused the job; nothing was written."""

    exit_code = EXIT_SAFETY


class OutOfVolumeError(SafetyError):
    """A target lies outside the calibrated volume."""


class CorrectionTooLargeError(SafetyError):
    """A correction exceeds --max-correction."""


class MissingSetupError(SafetyError):
    """A work offset or tool length that the program uses was not given."""


class AlreadyCorrectedError(SafetyError):
    """The program already carries a postproc header."""


class SolverError(PostprocError):
    """An inverse solver did not converge within its tolerance."""

    exit_code = EXIT_SAFETY
