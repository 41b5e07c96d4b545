"""postproc diff: what the correction changed in a program."""

from __future__ import annotations

import json
import os
import sys

import click

from postproc.cli.options import CORRECTION_OPTIONS, correction_options, program_setup_options

# Moved blocks listed in the text report (all of them go into --json).
LIST_MOVED = 15


@click.command()
@click.argument("original", type=click.Path(exists=True, dir_okay=False))
@click.argument("corrected", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON.")
@click.option("--all", "show_all", is_flag=True, help="List every moved block, not only the largest.")
@program_setup_options(leave_out=("--context",))
@correction_options(leave_out=tuple(flag for flag in CORRECTION_OPTIONS if flag != "--max-correction"))
def diff(original, corrected, as_json, show_all, reading, setup, correcting):
    """Compare a program with its corrected version.

    Reports which blocks moved and by how much (end points, mm, machine axes), the
    largest and mean correction per axis, the lines inserted by segmentation and
    the lines left unchanged. Lines that are not moves must be identical in both.
    The work offsets, tool lengths, tool vector, start and G28/G30 positions the
    program was corrected with are read from its header; give --offset,
    --tool-length (or --tool-table), --tool-vector, --start or --home only to
    override them (they matter for programs using G53, G28/G30 or an axis the
    program leaves where it was).

    A program corrected expanded (subprograms, loops and macros written out, as
    its header says) is compared with its original read expanded the same way;
    blocks are then numbered by their source lines, a line of a subprogram's
    file as file:line (its "file" in --json). A block moved by more than
    --max-correction is named after the report and the exit code is 5, as
    correct would have refused it. Give --dialect and --subroutine-path as given
    to correct. Canned cycles are compared as the moves correct writes for them;
    their G98/G99 retracts are left out when the program was corrected with
    --cycles expand, as its header says: give --cycles expand only for a
    corrected program whose header was removed.

    Example:

    \b
        postproc diff samples/pocket.nc pocket_corrected.nc
        postproc diff samples/g54_g43.ngc part_corrected.ngc --json
        postproc diff o1234.nc o1234_corrected.nc --dialect fanuc
    """
    from postproc.gcode.compare import compare_programs

    # a progress line on stderr for a big program, as 'correct' shows (when stderr is a terminal)
    progress = None
    if sys.stderr.isatty():
        from postproc.cli.correct import PROGRESS_MIN_BYTES, _progress_printer

        if os.path.isfile(original) and os.path.getsize(original) > PROGRESS_MIN_BYTES:
            progress = _progress_printer(original)
    try:
        # the text report lists the largest moved blocks only: keep just those (memory
        # then does not grow with the program); --all and --json list every one
        keep = None if (as_json or show_all) else LIST_MOVED
        from postproc.fileio import as_regular_file
        from postproc.gcode.options import CorrectOptions
        from postproc.gcode.recognise import dialect_of_file

        # a pipe (a shell's <(...)) is read once into a file: each program is read twice
        with as_regular_file(original) as orig, as_regular_file(corrected) as corr:
            given = CorrectOptions(**{**reading.correct_options(),
                                      "dialect": dialect_of_file(orig, reading.dialect.lower())})
            rep = compare_programs(orig, corr, setup, progress=progress, keep=keep, options=given)
        rep.original, rep.corrected = original, corrected
    finally:
        if progress is not None:
            click.echo("", err=True)
    if as_json:
        click.echo(json.dumps(rep.to_dict(), indent=2))
        _check_largest(rep, correcting["max_correction_mm"])
        return
    stats = rep.axis_stats()
    click.echo(f"{rep.original} -> {rep.corrected}")
    for row in rep.header.splitlines():
        click.echo(f"  {row}")
    click.echo(f"  lines: {rep.lines_original} original{' (expanded)' if rep.expanded else ''}, "
               f"{rep.lines_corrected} corrected "
               f"(+{rep.lines_inserted} inserted by segmentation), {rep.lines_unchanged} unchanged"
               + (f", {rep.lines_rewritten} G92 rewritten" if rep.lines_rewritten else ""))
    click.echo(f"  moves: {rep.moves}, {rep.n_moved} moved, {rep.moves_unchanged} unchanged")
    click.echo("  correction per axis (um):  " + "   ".join(
        f"{a} max {stats[a]['max_mm'] * 1000:.1f} mean {stats[a]['mean_mm'] * 1000:.1f}" for a in "XYZ"))
    moved = rep.moved if show_all else rep.largest(LIST_MOVED)
    if moved:
        click.echo("  moved blocks" + ("" if show_all else f" (largest {len(moved)})") + ":")
        for m in moved:
            dx, dy, dz = (d * 1000 for d in m.delta_mm)
            click.echo(f"    line {m.place:>6} -> {m.lineno_corrected:>6}: dX {dx:+8.2f} dY {dy:+8.2f} "
                       f"dZ {dz:+8.2f} um  |d| {m.size_mm * 1000:.2f} um")
    _check_largest(rep, correcting["max_correction_mm"])


def _check_largest(rep, max_correction_mm: float) -> None:
    """Refuse (exit 5, after the report) a comparison whose largest move exceeds the bound."""
    from postproc.errors import CorrectionTooLargeError

    largest = rep.largest(1)
    if largest and largest[0].size_mm > max_correction_mm:
        m = largest[0]
        raise CorrectionTooLargeError(
            f"block moved by {m.size_mm:.4f} mm (line {m.lineno} of {m.file or rep.original}), more than --max-correction "
            f"{max_correction_mm:g} mm", path=rep.corrected, lineno=m.lineno_corrected, col=1,
            hint="a correction this large suggests wrong units or a wrong calibration; give --max-correction "
                 "to allow it")
