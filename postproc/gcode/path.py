"""The nominal path of a program: points along every move, in the machine frame.

``program_path(source, setup)`` reads the program as ``correct`` does (the modal
interpreter, runs of plain lines in bulk: :mod:`postproc.gcode.pathread`) and samples every move
(lines and arcs) at most ``max_step_mm`` apart. Points are *functional-point*
positions ``p = q + r`` (after units, work offsets, G92 and tool length); ``tool_mm``
is the tool vector ``r``, so ``q = points_mm - tool_mm`` is what the controller
commands and ``machine.forward(q, tool_mm, context)`` is where the tool really goes.

Axes not yet positioned when a program starts are where the machine is, when
``Setup.start`` gives that position; otherwise they take the value of their next known
position (the first move of most programs is a retract on one axis).

:class:`Setup`, :class:`ProgramPath` and the reading of a program's source are
:mod:`postproc.gcode.source`'s (the readers import them there, below this module); they
are given here too, for the path API's users.
"""

from __future__ import annotations

import gc

# what the path API's users read a program with (postproc.gcode.source), given here too
from postproc.gcode.source import (
    MOTION_EPS_MM,
    PROGRAM_SUFFIXES,
    ProgramPath,
    Setup,
    backfill_unknown,
    iter_source_lines,
    motion_signs,
    open_source,
)
from postproc.limits import Limits

__all__ = ["DEFAULT_MAX_STEP_MM", "MAX_SAMPLES", "MOTION_EPS_MM", "PROGRAM_SUFFIXES", "ProgramPath", "Setup",
           "backfill_unknown", "iter_source_lines", "motion_signs", "open_source", "program_path", "sample_program"]

DEFAULT_MAX_STEP_MM = 0.5
# Points one program may be sampled into (verify, the path API): verify peaks near 7.5 KB
# for each (270,000 points: 2 GB), so this keeps it under 2 GB, and a step of 1e-9 mm
# (93.6 GiB asked for) is refused at its line. At verify's 0.5 mm: 125 m of path.
MAX_SAMPLES = 250_000


def program_path(source, setup: Setup | None = None, *, max_step_mm: float = DEFAULT_MAX_STEP_MM,
                 dialect: str = "generic", subroutine_path=(), limits: Limits | None = None) -> ProgramPath:
    """Sample the nominal path of a program (path or text); see the module docstring."""
    return sample_program(source, setup, step_mm=max_step_mm, dialect=dialect, subroutine_path=subroutine_path,
                          limits=limits)


def sample_program(source, setup: Setup | None = None, *, step_mm: float | None = None,
                   chord_mm: float | None = None, dialect: str = "generic", subroutine_path=(),
                   max_samples: int = MAX_SAMPLES, limits: Limits | None = None) -> ProgramPath:
    """The program's moves as points: the one sampler of correct's checks, verify and the
    path API (the program is read by :func:`postproc.gcode.pathread.read_program`, as
    ``correct`` reads it: runs of plain lines in bulk, every other line by the interpreter).
    Each sample carries the line it comes from (``lineno``); for a program read expanded,
    ``files`` names the file of the lines that come from another file (a subprogram's).

    Each move gives its end point, and before it, on feed moves from a known position:
    straight moves a point every ``step_mm`` (None: their end alone); arcs a point
    every ``step_mm`` of their length and, with ``chord_mm``, every chord whose
    sagitta stays below it (the finer of the two). Rapid moves give their end point
    only. The context holds each sample's approach directions (from the start position
    when ``setup.start`` gives it), the rotary axes' positions and ``setup.context``.
    More than ``max_samples`` points in all are refused
    (:class:`~postproc.limits.ResourceLimitError`, at the line that passes the bound)."""
    from postproc.gcode.pathread import Sampler, read_program

    setup = setup or Setup()
    # Many small short-lived objects, none of them cyclic: the cyclic garbage collector
    # only costs time here (as in the corrector's run)
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        rd = read_program(source, setup, lambda interp, path: Sampler(interp, path, step_mm, chord_mm, max_samples),
                          dialect=dialect, subroutine_path=subroutine_path, limits=limits)
        return rd.path_of(setup, rd.interp.used_rotary)
    finally:
        if was_enabled:
            gc.enable()
