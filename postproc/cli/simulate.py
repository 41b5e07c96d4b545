"""postproc simulate: measure a virtual machine with simulated instruments."""

from __future__ import annotations

import math

import click

from postproc.cli.options import FiniteFloat, context_option, parse_vector
from postproc.constants import MAX_VOLUME_MM


def _parse_volume(text: str) -> list[list[float]]:
    parts = [p.strip() for p in text.split(",")]
    try:
        v = [float(p) for p in parts]
    except ValueError:
        v = []
    if len(v) != 6 or not all(math.isfinite(x) for x in v):
        raise click.BadParameter(f"--volume must be six finite numbers xmin,ymin,zmin,xmax,ymax,zmax, got {text!r}")
    if not all(lo < hi for lo, hi in zip(v[:3], v[3:], strict=True)):
        raise click.BadParameter(f"--volume must have each min below its max, got {text!r}")
    if max(abs(x) for x in v) > MAX_VOLUME_MM:
        raise click.BadParameter(f"--volume reaches beyond {MAX_VOLUME_MM / 1000:g} m, got {text!r}")
    return [v[:3], v[3:]]


def _parse_floats(text: str, what: str) -> list[float]:
    try:
        values = [float(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise click.BadParameter(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not all(math.isfinite(x) for x in values):
        raise click.BadParameter(f"{what} must be finite numbers, got {text!r}")
    return values


def _temp_profile(_ctx, _param, text: str | None) -> tuple[float, float, float | None] | None:
    """``--temp-profile`` read at the option, so a bad one is a usage error (exit 2)."""
    from postproc.errors import PostprocError
    from postproc.simulate.points import parse_temp_profile

    if text is None:
        return None
    try:
        return parse_temp_profile(text)
    except PostprocError as exc:
        raise click.BadParameter(exc.message) from None


@click.command()
@click.argument("machine", type=click.Path(exists=True, dir_okay=False))
@click.option("--grid", "grid_step", default=None, metavar="STEP",
              help="Tracker grid over the volume with this step in mm (one value or SX,SY,SZ).")
@click.option("--random", "n_random", type=int, default=None, metavar="N",
              help="N tracker points drawn uniformly in the volume.")
@click.option("--static-set", "static", is_flag=True,
              help="The static method's six points: two per axis (low corner and each axis end).")
@click.option("--tables", "tables", is_flag=True,
              help="Interferometer axis error tables; the squareness goes to OUTPUT_squareness.csv.")
@click.option("--step", "step", type=FiniteFloat(min=0, min_open=True), default=5.0, show_default=True, metavar="MM",
              help="Position step of the interferometer tables.")
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="File to write (formats.md CSV), written atomically.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of the instrument noise.")
@click.option("--no-noise", "no_noise", is_flag=True, help="Exact values, no instrument noise.")
@click.option("--volume", default=None, metavar="X0,Y0,Z0,X1,Y1,Z1",
              help="Measure this part of the travel (mm); default: the machine's whole volume.")
@click.option("--tool-vector", "tool_vectors", multiple=True, metavar="X,Y,Z",
              help="Reflector/tool vector from the gauge point (mm); repeat to measure the set "
                   "with each. Default 0,0,0.")
@click.option("--approach", type=click.Choice(["positive", "both"]), default="positive", show_default=True,
              help="Approach each point moving + on every axis, or both + and -.")
@click.option("--repeats", type=int, default=1, show_default=True,
              help="Shots per point (the seed averaged 12); each is its own row.")
@click.option("--time-span", "time_span", type=FiniteFloat(min=0), default=None, metavar="S",
              help="Spread the rows evenly over S seconds and write a t column.")
@click.option("--temp-profile", "temp_profile", default=None, metavar="T|T0:T1|T0:T1:TAU", callback=_temp_profile,
              help="Write a temp column: constant, linear ramp over the run, or warm-up from T0 "
                   "towards T1 with time constant TAU s.")
@click.option("--load-values", "load_values", default=None, metavar="L1,L2,...",
              help="Measure the set once per load value and write a load column.")
@context_option(help="A constant context column, e.g. temp=21.5. Repeatable.")
def simulate(machine, grid_step, n_random, static, tables, step, output, seed, no_noise, volume,
             tool_vectors, approach, repeats, time_span, temp_profile, load_values, context):
    """Measure a virtual machine: tracker points or interferometer tables.

    MACHINE is a machine definition (JSON, "format": "postproc machine"; see
    docs/virtual-machine.md). Choose one of --grid, --random, --static-set or
    --tables. Point files carry X,Y,Z, the measured mx,my,mz (machine forward model
    plus tracker noise), tool vectors, approach directions and any context asked for;
    they are read back by 'postproc fit' like any instrument's file. --seed makes the
    noise reproducible.

    Example:

    \b
        postproc simulate calibrations/s500.machine.json --static-set --repeats 12 -o six.csv
        postproc simulate calibrations/s500.machine.json --tables --step 2 -o tables.csv
    """
    import numpy as np

    from postproc.calibration.measurements import format_measurements
    from postproc.fileio import atomic_write_text
    from postproc.simulate import load_machine
    from postproc.simulate.points import (
        grid_points,
        measurement_plan,
        random_points,
        simulate_plan,
        static_set,
    )

    chosen = [name for name, on in (("--grid", grid_step is not None), ("--random", n_random is not None),
                                    ("--static-set", static), ("--tables", tables)) if on]
    if len(chosen) != 1:
        raise click.UsageError("choose exactly one of --grid, --random, --static-set, --tables"
                               + (f" (got {', '.join(chosen)})" if chosen else ""))
    mach = load_machine(machine)
    rng = np.random.default_rng(seed)
    vol = _parse_volume(volume) if volume else mach.volume_mm.tolist()
    comments = [f"simulated by postproc from machine {mach.name!r} ({machine})",
                f"seed: {seed}", f"noise: {'off' if no_noise else 'on'}"]

    if tables:
        from postproc.calibration.tables import squareness_path_for, write_tables
        from postproc.simulate.tables import simulate_tables

        tabs, sq = simulate_tables(mach, step, rng, noise=not no_noise, context=context)
        sq_path = squareness_path_for(output)
        write_tables(output, sq_path, tabs, sq, comments=comments + [f"step: {step:g} mm"])
        click.echo(f"wrote {output} ({sum(len(x) for x in tabs.position_mm.values())} rows) and {sq_path}",
                   err=True)
        return

    if grid_step is not None:
        points = grid_points(vol, _parse_floats(grid_step, "--grid"))
        comments.append(f"grid step: {grid_step} mm")
    elif n_random is not None:
        points = random_points(vol, n_random, rng)
    else:
        points = static_set(vol)
    plan = measurement_plan(
        points,
        tool_vectors=[parse_vector(t, "--tool-vector") for t in tool_vectors] or None,
        approach=approach,
        repeats=repeats,
        time_span_s=time_span,
        temp_profile=temp_profile,
        load_values=_parse_floats(load_values, "--load-values") if load_values else None,
        context=context,
    )
    meas = simulate_plan(mach, plan, rng, noise=not no_noise)
    atomic_write_text(output, format_measurements(meas, comments=comments))
    click.echo(f"wrote {output}: {len(meas)} rows ({len(points)} points)", err=True)
