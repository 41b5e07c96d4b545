"""verify PROGRAM: the original and the corrected program on a virtual machine."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from postproc.errors import PostprocError
from postproc.simulate.machine import Machine
from postproc.simulate.verify import (
    RUN_STEP_MM,
    VerifyReport,
    actual_path_samples,
    evaluate_run,
    nominal_path,
    nominal_polyline,
    program_lines,
)


def make_setup(setup_args: dict | None):
    """A :class:`postproc.gcode.path.Setup` from offsets, tool lengths, tool vector, context
    (a Setup is taken as it is)."""
    from postproc.gcode.path import Setup

    if isinstance(setup_args, Setup):
        return setup_args
    args = dict(setup_args or {})
    offsets = {name: (v.get("X", 0.0), v.get("Y", 0.0), v.get("Z", 0.0)) if isinstance(v, dict) else v
               for name, v in (args.get("offsets") or {}).items()}
    return Setup(offsets=offsets, tool_lengths=dict(args.get("tool_lengths") or {}),
                 tool_vector=args.get("tool_vector"), context=dict(args.get("context") or {}))


def correct_program_text(text: str, calibration, setup, path: str | None = None, options=None) -> str:
    """The program corrected in-process with the correction pipeline (``options``:
    :class:`postproc.gcode.pipeline.CorrectOptions`, default the pipeline's)."""
    from postproc.gcode.pipeline import correct_text

    fixed, _ = correct_text(text, calibration.engine, setup, options, path=path,
                            calibration_name=calibration.name, calibration_sha256=calibration.sha256)
    return fixed


def verify_program(program, machine: Machine, calibrations: list, setup_args: dict | None = None, *,
                   corrected=None, max_step_mm: float = RUN_STEP_MM, options=None) -> VerifyReport:
    """Deviation from the nominal path of the original program and of each corrected one.

    ``calibrations``: loaded :class:`Calibration` objects, each used to correct
    ``program`` in-process, unless ``corrected`` (a path) gives the corrected program.
    Each run is measured both ways: its actual points against the nominal path, and
    the original program's samples against its actual path (see
    :mod:`postproc.simulate.verify`).
    """
    from postproc.gcode.path import program_path

    if max_step_mm <= 0:
        raise PostprocError(f"sampling step must be positive, got {max_step_mm}")
    setup = make_setup(setup_args)
    program = str(program)
    # read as the correction reads it: the controller's dialect (generic: Sinumerik by its
    # header, as correct and diff choose it), subprogram files
    from dataclasses import replace

    from postproc.gcode.recognise import dialect_of_file

    dialect = dialect_of_file(program, getattr(options, "dialect", "generic"))
    if options is None:
        from postproc.gcode.pipeline import CorrectOptions

        options = CorrectOptions(dialect=dialect)
    elif options.dialect != dialect:
        options = replace(options, dialect=dialect)
    reading: dict[str, Any] = {"dialect": dialect,
                               "subroutine_path": tuple(getattr(options, "subroutine_path", ())),
                               "limits": getattr(options, "limits", None)}
    nominal = nominal_path(program, setup, **reading)
    if len(nominal) < 2:
        raise PostprocError("the program has no moves to verify", path=program)
    poly = nominal_polyline(nominal)
    text = Path(program).read_text(encoding="utf-8", errors="surrogateescape")
    report = VerifyReport(source_lines=program_lines(program))
    original = program_path(program, setup, max_step_mm=max_step_mm, **reading)

    def run(label: str, source):
        path = original if source is program else program_path(source, setup, max_step_mm=max_step_mm, **reading)
        fine = actual_path_samples(source, setup, max_step_mm, **reading)
        report.runs.append(evaluate_run(label, machine, path, poly, nominal.lineno, original, fine,
                                        nominal_files=nominal.files))
        return report.runs[-1]

    if not run("uncorrected", program).feed.any():
        raise PostprocError("the program has no feed moves to verify (the deviation is measured on feed moves)",
                            path=program)
    if corrected is not None:
        if not run(f"corrected ({Path(corrected).name})", str(corrected)).feed.any():
            raise PostprocError("the corrected program has no feed moves: there is nothing to compare",
                                path=str(corrected), hint="give the corrected version of PROGRAM")
        return report
    for cal in calibrations:
        fixed = correct_program_text(text, cal, setup, path=program, options=options)
        run(f"corrected, {cal.method}" + (f" ({cal.name})" if cal.name != cal.method else ""), fixed)
    return report
