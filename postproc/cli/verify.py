"""postproc verify: run programs or control points through a virtual machine."""

from __future__ import annotations

import json

import click

from postproc.cli.options import FiniteFloat, correction_options, program_setup_options


@click.command()
@click.argument("program", required=False, type=click.Path(exists=True, dir_okay=False))
@click.option("-c", "--calibration", "calibrations", multiple=True, type=click.Path(exists=True, dir_okay=False),
              help="Calibration file (repeatable: with --points, one column per calibration).")
@click.option("--machine", "machine_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Machine definition (JSON, \"format\": \"postproc machine\"), or a calibration file: "
                   "the machine as measured (the calibration's forward model, no instrument noise).")
@click.option("--points", "points", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Control points CSV (X,Y,Z targets): print a Table-1 style report instead.")
@click.option("--corrected", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Already corrected program to run instead of correcting PROGRAM in-process.")
@program_setup_options
@correction_options
@click.option("--max-step", "max_step", type=FiniteFloat(min=0, min_open=True), default=0.5, show_default=True, metavar="MM",
              help="Sampling step along the program's moves.")
@click.option("--shots", type=click.IntRange(min=1, max=10_000), default=12, show_default=True,
              help="With --points: tracker shots averaged per point.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="With --points: seed of the tracker noise.")
@click.option("--no-noise", "no_noise", is_flag=True, help="With --points: exact positions, no tracker noise.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="PNG of the deviation along the program (needs matplotlib).")
def verify(program, calibrations, machine_path, points, corrected, reading, setup, correcting, max_step, shots, seed,
           no_noise, as_json, plot):
    """Run a program, or control points, on a virtual machine and report the errors.

    PROGRAM mode: the original program and its corrected version (corrected here with
    each -c calibration, or --corrected FILE) are sampled along every move and run
    through the machine. The deviation is measured both ways over feed moves: (a)
    each actual tool point's distance from the nominal path, and (b) each nominal
    point's distance from the actual path, which shows a program that stops early or
    skips a stretch. Reported before and after: the two-sided max (the larger of (a)
    and (b)), max and RMS of each direction, and the worst lines.

    --machine may be a calibration made by fit: the program then runs on the machine
    as that calibration measured it (its forward model with its effects).

    --points mode: for each control point, Delta = |actual - target| uncorrected and
    with each calibration, their sums and the improvement in percent, in the layout
    of seed 000's Tables 1 and 5. The tracker is simulated (--shots averaged, --seed).
    The targets are machine positions: of the setup options only --tool-vector (for
    points without their own) and --context apply.

    Example:

    \b
        postproc verify --points samples/s500_control_points.csv -c calibrations/s500_static.json --machine calibrations/s500.machine.json
        postproc verify samples/pocket.nc -c calibrations/s500_static.json --machine calibrations/s500.machine.json --plot dev.png
        postproc verify samples/pocket.nc -c calibrations/s500_static.json --machine calibrations/s500_parametric.json
    """
    import numpy as np

    from postproc.calfile import load_calibration

    if plot:
        from postproc.fileio import require_matplotlib

        require_matplotlib("--plot")
    machine = _load_machine(machine_path)
    if points is not None:
        if program is not None or corrected is not None:
            raise click.UsageError("give either PROGRAM or --points, not both")
        _refuse_program_options_with_points(click.get_current_context())
        _verify_points(machine, points, calibrations, setup, seed, shots, no_noise, as_json)
        return

    if program is None:
        raise click.UsageError("give a PROGRAM to verify, or --points CONTROL.csv")
    if corrected is not None and len(calibrations) > 1:
        raise click.UsageError("--corrected takes one program: give at most one -c with it")
    if corrected is None and not calibrations:
        raise click.UsageError("give -c CALIBRATION to correct PROGRAM with, or --corrected FILE")
    from postproc.gcode.pipeline import CorrectOptions
    from postproc.gcode.places import line_place
    from postproc.simulate.program import verify_program

    cals = [load_calibration(c) for c in calibrations]
    options = CorrectOptions(**correcting, **reading.correct_options())
    from contextlib import nullcontext

    from postproc.fileio import as_regular_file

    # a pipe (a shell's <(...)) is read once into a file: a program is read twice
    with as_regular_file(program) as prog, \
            (nullcontext() if corrected is None else as_regular_file(corrected)) as corr:
        report = verify_program(prog, machine, cals, setup, corrected=corr, max_step_mm=max_step, options=options)
    if plot:
        from postproc.fileio import save_figure
        from postproc.simulate.verify import plot_deviation

        ax = plot_deviation(report, title=f"{program} on {machine.name}")
        save_figure(ax.figure, plot, dpi=120, bbox_inches="tight")
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2))
        return
    click.echo(f"{program} on machine {machine.name}: deviation from the nominal path (feed moves), um")
    click.echo("  (a) actual tool point -> nominal path; (b) nominal point -> actual path; "
               "max = two-sided, the larger of (a) and (b)")
    width = max(len(run.label) for run in report.runs)
    click.echo(f"  {'':<{width}}  {'max':>9}  {'(a) max':>9}  {'(a) RMS':>9}  {'(b) max':>9}  {'(b) RMS':>9}  "
               "samples (a)/(b)")
    for run in report.runs:
        click.echo(f"  {run.label:<{width}}  {run.max_mm * 1000:9.2f}  {run.actual_to_nominal_max_mm * 1000:9.2f}  "
                   f"{run.rms_mm * 1000:9.2f}  {run.nominal_to_actual_max_mm * 1000:9.2f}  "
                   f"{run.nominal_to_actual_rms_mm * 1000:9.2f}  "
                   f"{int(np.count_nonzero(run.feed))}/{len(run.nominal_to_actual_mm)}")
    for run in report.runs:
        click.echo(f"  worst lines, {run.label}:")
        for ln, file, d in run.worst_places():  # a subprogram file's line as file:line
            click.echo(f"    {d * 1000:9.2f} um  line {line_place(ln, file, None)}: {report.line_text(ln, file)}")
    for note in report.notes:
        click.echo(f"note: {note}", err=True)
    if plot:
        click.echo(f"wrote {plot}", err=True)


def _load_machine(path: str):
    """A machine definition, or a calibration standing in as the machine: a noise-free
    machine whose truth is the calibration's forward model (engine with its effects)."""
    from pathlib import Path

    from postproc.simulate import load_machine

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):  # UnicodeDecodeError, JSONDecodeError, 4300 digits
        return load_machine(path)  # which names what is wrong with the file
    if not isinstance(data, dict) or data.get("format") != "postproc calibration":
        return load_machine(path)
    from postproc.calfile import load_calibration
    from postproc.simulate.machine import Machine, MachineGeometry

    cal = load_calibration(path)
    machine = Machine(MachineGeometry({}, {}, cal.engine.volume_mm), name=f"{cal.name} (calibration as measured)",
                      description=f"the forward model of calibration {path}", path=path)
    machine.model = cal.engine
    return machine


def _label(cal) -> str:
    return f"{cal.method} ({cal.name})" if cal.name and cal.name != cal.method else cal.method


def _refuse_program_options_with_points(ctx) -> None:
    """--points runs no program: the options of how a program is read and corrected would not be used."""
    from postproc.cli.options import CORRECTION_OPTIONS, PROGRAM_OPTIONS

    given = [flag for flag, (name, _attrs) in {**PROGRAM_OPTIONS, **CORRECTION_OPTIONS}.items()
             if ctx.get_parameter_source(name) is click.core.ParameterSource.COMMANDLINE]
    if given:
        raise click.UsageError(f"--points runs no program: {', '.join(given)} would not be used; drop it")


def _verify_points(machine, points, calibrations, setup, seed, shots, no_noise, as_json) -> None:
    """--points mode of :func:`verify`."""
    import numpy as np

    from postproc.calfile import load_calibration

    ctx, tool = setup.context, setup.tool_vector
    unused = [flag for flag, value in (("--offset", setup.offsets), ("--tool-length/--tool-table", setup.tool_lengths),
                                       ("--start", setup.start), ("--home", setup.home)) if value]
    if unused:
        raise click.UsageError(f"--points takes machine targets: {', '.join(unused)} would not be used; "
                               "drop it (of the setup options, --tool-vector and --context apply)")
    from postproc.simulate.control import (
        control_experiment,
        format_control_report,
        read_control_points,
    )

    cps = read_control_points(points)
    cals = [load_calibration(c) for c in calibrations]
    r = cps.tool if cps.tool is not None else (np.asarray(tool) if tool is not None else None)
    report = control_experiment(machine, cps.targets, [(_label(c), c.engine) for c in cals], r, ctx,
                                np.random.default_rng(seed), shots=shots, noise=not no_noise)
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2))
        return
    shot_text = (f"tracker {report.shots} shots averaged per point (sigma {report.sigma_mm * 1000:g} um "
                 f"per shot), seed {seed}" if report.shots else "no tracker noise")
    tool_text = ("per-point tool vectors" if cps.tool is not None
                 else f"tool vector {','.join(f'{v:g}' for v in (tool or (0, 0, 0)))}")
    click.echo(f"machine {machine.name}: {len(cps.targets)} control points from {points}; {tool_text}; "
               f"{shot_text}")
    click.echo("D = |actual - target| in mm")
    click.echo(format_control_report(report), nl=False)
    for note in report.notes:
        click.echo(f"note: {note}", err=True)
