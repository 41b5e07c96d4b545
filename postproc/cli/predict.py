"""postproc predict: machined surfaces and feature errors from a serial-chain machine model."""

from __future__ import annotations

import json

import click
import numpy as np

from postproc.cli.options import FINITE_FLOAT, parse_context, parse_vector


def _use_agg() -> None:
    """Draw off-screen: the command writes files and never opens a window."""
    import matplotlib

    matplotlib.use("Agg")


def _save_figure(ax, path: str) -> None:
    """Save the figure of ``ax`` atomically (temporary file beside it, then rename)."""
    from postproc.fileio import save_figure

    save_figure(np.ravel(ax)[0].figure, path, dpi=110)


def _require_plotting(option: str = "--plot") -> None:
    from postproc.fileio import require_matplotlib

    require_matplotlib(option)


def _echo_json(data) -> None:
    click.echo(json.dumps(data, indent=2))


def _fmt_um(mm: float) -> str:
    return f"{mm * 1e3:8.3f} um"


@click.group()
def predict() -> None:
    """Predict machined surfaces and feature errors from a machine chain.

    A machine is a chain of modules from the workpiece to the tool (4x4 matrices:
    constant geometry, axis motion, small-angle errors, frames from three points,
    planes inside tolerance fields). An operation file names the machine and what
    is cut. See docs/predict.md for both file formats.

    Example:

    \b
        postproc predict bore samples/predict/bore_50H7.operation.json
    """


@predict.command()
@click.argument("operation", type=click.Path(exists=True, dir_okay=False))
@click.option("--runout", "runout", type=FINITE_FLOAT, default=None, metavar="RAD",
              help="Spindle runout: angular amplitude A (rad). Default: the operation's value.")
@click.option("--heights", type=int, default=None, help="Number of edge heights sampled (default: the operation's).")
@click.option("--windows", type=int, default=40, show_default=True, help="Cutting windows (edge passes) sampled.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write colour maps of the wall without and with runout to this PNG.")
@click.option("--plot-trace", "plot_trace", type=click.Path(dir_okay=False), default=None,
              help="Write the trace of the edge tip near the wall (cutting windows and air) to this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
def trace(operation, runout, heights, windows, plot, plot_trace, as_json):
    """Trace of a flank-milling cutter and the wall it leaves (seed 002).

    The edge trace r_s(t, p) = M(t) r_e(p) is sampled only in the cutting windows
    (time scale of formula 4); the wall is the envelope of the passes. Prints the
    cusp height along the feed (against R - sqrt(R^2 - (f/2)^2)) and the form of the
    wall without and with spindle runout.

    Example:

    \b
        postproc predict trace samples/predict/flank_5mm.operation.json --plot wall.png --plot-trace arcs.png
    """
    from postproc.errors import PostprocError
    from postproc.predict.operation import load_operation
    from postproc.predict.trace import flank_surface, plot_flank, plot_trace_near_wall, with_runout

    if plot or plot_trace:
        _require_plotting("--plot" if plot else "--plot-trace")
    op = load_operation(operation)
    if op.kind != "flank":
        raise PostprocError(f"predict trace needs a flank operation, got {op.kind!r}", path=operation,
                            hint="use predict bore or predict tolerance for this file")
    prm = op.params
    cutter = prm["cutter"]
    amp = prm["runout_rad"] if runout is None else runout
    n_h = heights or prm["heights"]
    if n_h < 2 or windows < 5:
        raise click.BadParameter("need at least 2 heights and 5 windows")
    top = cutter.length_mm if cutter.kind != "ball" else cutter.d_mm / 2
    p = np.linspace(0.0, top, n_h)
    kw = {"rpm": prm["rpm"], "feed_mm_min": prm["feed_mm_min"], "heights_mm": p, "windows": windows,
          "context": op.context}
    cases = {"no runout": flank_surface(op.chain, cutter, **kw)}
    if amp:
        edge_rpm = prm["rpm"] * cutter.flutes
        chain = with_runout(op.chain, amp, edge_rpm, cutter.flutes, prm["runout_phase_rad"])
        cases[f"runout A = {amp:g} rad"] = flank_surface(chain, cutter, **kw)
    fz = cases["no runout"].feed_per_edge_mm
    r = cutter.d_mm / 2
    expected = r - np.sqrt(r * r - (fz / 2) ** 2)
    out = {
        "operation": op.name,
        "feed_per_edge_mm": fz,
        "cutting_time_s": cases["no runout"].t_m_s,
        "cusp_formula_mm": expected,
        "cases": {
            name: {
                "cusp_median_mm": float(np.median(s.cusp_mm)),
                "cusp_max_mm": float(np.max(s.cusp_mm)),
                "form_mm": s.form_mm,
                "deepest_mm": float(max(0.0, -np.min(s.excess_mm))),
                "highest_mm": float(np.max(s.excess_mm)),
            }
            for name, s in cases.items()
        },
    }
    if plot or plot_trace:
        _use_agg()
    if plot:
        _save_figure(plot_flank(cases), plot)
    if plot_trace:
        _save_figure(plot_trace_near_wall(op.chain, cutter, rpm=prm["rpm"], feed_mm_min=prm["feed_mm_min"],
                                          context=op.context), plot_trace)
    if as_json:
        _echo_json(out)
        return
    click.echo(f"{op.name or op.path}: {cutter.kind} cutter d = {cutter.d_mm:g} mm, {cutter.flutes} flute(s), "
               f"{prm['rpm']:g} rpm, feed {prm['feed_mm_min']:g} mm/min")
    click.echo(f"feed per edge {fz * 1e3:.4f} um, edge in the cut {out['cutting_time_s'] * 1e6:.4f} us per pass")
    click.echo(f"cusp height R - sqrt(R^2 - (f/2)^2) = {expected * 1e6:.4f} nm")
    for name, c in out["cases"].items():
        click.echo(f"  {name}: cusp {c['cusp_median_mm'] * 1e6:.4f} nm (median over heights), "
                   f"wall form {c['form_mm'] * 1e3:.4f} um, cut up to {c['deepest_mm'] * 1e3:.4f} um too deep")
    if plot:
        click.echo(f"wrote {plot}")
    if plot_trace:
        click.echo(f"wrote {plot_trace}")


MACHINE_OPTION = click.option(
    "--machine", "machine", type=click.Path(exists=True, dir_okay=False), default=None, metavar="CHAIN",
    help="Chain file of the machine to use instead of the operation's \"machine\" (e.g. one from predict init).")


SET_OPTION = click.option(
    "--set", "values", multiple=True, metavar="NAME=VALUE",
    help="A context variable (axis position X, Y, Z, t, a load ...) in place of the operation's. Repeatable.")


def _load(operation, machine=None, values=()):
    """The operation (with --machine's chain), its context updated by --set."""
    from postproc.predict.operation import load_operation

    op = load_operation(operation, machine)
    op.context.update(dict(parse_context(v) for v in values))
    return op


def _load_bore(operation, machine=None, values=()):
    from postproc.errors import PostprocError

    op = _load(operation, machine, values)
    if op.kind != "bore":
        raise PostprocError(f"predict bore needs a bore operation, got {op.kind!r}", path=operation)
    return op


CHECK_HELP = ("Exit with status 6 when the tolerance (and the diameter limits) are not held: in the worst "
              "case over the fields, or by the single prediction of a chain without random variables.")


def _finish_check(check: bool, verdict: dict) -> None:
    """With --check, a tolerance that is not held is exit status 6 (after the report)."""
    if check and not verdict["held"]:
        from postproc.errors import EXIT_NOT_HELD

        click.get_current_context().exit(EXIT_NOT_HELD)


@predict.command()
@click.argument("operation", type=click.Path(exists=True, dir_okay=False))
@click.option("-n", "n", type=click.IntRange(min=2), default=None, help="Monte-Carlo size (default: the operation's).")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="Random seed (default: the operation's).")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write the section (errors magnified) and the centre scatter to this PNG.")
@click.option("--magnify", type=FINITE_FLOAT, default=100.0, show_default=True, help="Error magnification in the plot.")
@MACHINE_OPTION
@SET_OPTION
@click.option("--check", "check", is_flag=True, help=CHECK_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
def bore(operation, n, seed, plot, magnify, machine, values, check, as_json):
    """Position error of a bored hole's centre (seed 004 example).

    The eight tool-tip positions of the seed's table 4 (and the axis point) go
    through the chain; the section's least-squares circle gives the centre. Prints
    the centre with every random variable mid-field, the worst case over the corners
    of the tolerance fields and clearances, and the Monte-Carlo distribution with the
    probability of meeting the +- tolerances. A chain without random variables gives
    its single prediction (the worst case is that prediction, no Monte Carlo).

    With --check the exit status is the verdict: 0 when the centre (and the diameter,
    if the operation gives limits) is within tolerance, 6 when not.

    Example:

    \b
        postproc predict bore samples/predict/bore_50H7.operation.json -n 20000 --plot bore.png
    """
    from postproc.predict import bore as bore_mod
    from postproc.predict.analysis import predict_bore

    if plot:
        _require_plotting()
    op = _load_bore(operation, machine, values)
    report = predict_bore(op, n=n, seed=seed)
    mid, worst, worst_sec, dist, verdict = report.mid, report.worst, report.worst_section, report.dist, report.verdict
    tol = op.params["tolerance_mm"]
    out = report.to_dict()
    if plot:
        _use_agg()
        _save_figure(bore_mod.plot_bore(op, mid, worst_sec, dist, magnify), plot)
    if as_json:
        _echo_json(out)
        _finish_check(check, verdict)
        return
    names = list(worst.names)
    click.echo(f"{op.name or op.path}: d = {op.params['diameter_mm']:g} mm, overhang "
               f"{op.params['overhang_mm']:g} mm, tolerance +-{tol[0]:g} ({names[0]}) +-{tol[1]:g} ({names[1]}) mm")
    what = "single prediction (no random variable varies)" if dist is None else "variables mid-field"
    click.echo(f"{what}: centre error {names[0]} {_fmt_um(mid.error_mm[0])}, "
               f"{names[1]} {_fmt_um(mid.error_mm[1])}; section diameter {mid.diameter_mm:.4f} mm, "
               f"roundness {mid.roundness_mm * 1e3:.3f} um")
    if "diameter_limits_mm" in op.params:
        lo_d, hi_d = op.params["diameter_limits_mm"]
        ok = lo_d <= mid.diameter_mm <= hi_d
        click.echo(f"diameter {mid.diameter_mm:.4f} mm is {'within' if ok else 'OUTSIDE'} "
                   f"{lo_d:.4f}..{hi_d:.4f} mm")
    if dist is None:
        for i, name in enumerate(names):
            click.echo(f"{name}: {'within' if worst.max_abs_mm[i] <= tol[i] else 'OUTSIDE'} +-{tol[i]:g} mm")
        click.echo("the tolerance is " + ("met" if worst.within else "NOT met") + " (deterministic chain)")
    else:
        for i, name in enumerate(names):
            click.echo(f"worst case {name}: {_fmt_um(worst.min_mm[i])} .. {_fmt_um(worst.max_mm[i])}  "
                       f"({'within' if worst.max_abs_mm[i] <= tol[i] else 'OUTSIDE'} +-{tol[i]:g} mm)")
        lo, hi = dist.p_within_ci95
        for i, name in enumerate(names):
            click.echo(f"Monte Carlo {name}: mean {_fmt_um(dist.mean_mm[i])}, std {_fmt_um(dist.std_mm[i])}, "
                       f"range {_fmt_um(dist.samples_mm[:, i].min())} .. {_fmt_um(dist.samples_mm[:, i].max())}")
        click.echo(f"P(centre within tolerance) = {dist.p_within:.5f} (95 % {lo:.5f}..{hi:.5f}), "
                   f"n = {len(dist.samples_mm)}, seed {dist.seed}")
        click.echo("the tolerance is " + ("met in the worst case" if worst.within else
                                          "NOT met in the worst case"))
    if check:
        click.echo(f"check: {'held' if verdict['held'] else 'NOT held'} ({verdict['basis']})")
    if plot:
        click.echo(f"wrote {plot}")
    _finish_check(check, verdict)


@predict.command("tolerance")
@click.argument("operation", type=click.Path(exists=True, dir_okay=False))
@click.option("-n", "n", type=click.IntRange(min=2), default=None, help="Monte-Carlo size (default: the operation's).")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="Random seed (default: the operation's).")
@click.option("--worst-case", "worst_only", is_flag=True, help="Only the worst case over the field corners.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None,
              help="Write histograms of the error components to this PNG.")
@MACHINE_OPTION
@SET_OPTION
@click.option("--check", "check", is_flag=True, help=CHECK_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print the figures as JSON.")
def tolerance_cmd(operation, n, seed, worst_only, plot, machine, values, check, as_json):
    """Distribution of a feature's position error over the chain's random variables.

    The random variables of the machine file (corner heights of planes inside
    tolerance fields, positions inside joint clearances) are drawn n times
    (reproducible for a seed); the feature is a bore centre or, for a "point"
    operation, one tool point. Prints mean, std, range and P(within +- tolerance),
    and the worst case over the corners of the variables' box. A chain without
    random variables gives its single prediction. --check: exit status 6 when the
    tolerance is not held.

    Example:

    \b
        postproc predict tolerance samples/predict/bore_50H7.operation.json -n 50000 --seed 2
    """
    if plot:
        _require_plotting()
    from postproc.predict import tolerance
    from postproc.predict.analysis import analyse_feature

    op = _load(operation, machine, values)
    report = analyse_feature(op, n=n, seed=seed, monte_carlo=not worst_only)
    worst, dist, verdict, deterministic = report.worst, report.dist, report.verdict, report.deterministic
    names, tol = worst.names, op.params["tolerance_mm"]
    out = report.to_dict()
    if plot:
        if dist is None:
            raise click.UsageError("--plot needs the Monte Carlo (drop --worst-case; a chain without random "
                                   "variables has none)")
        _use_agg()
        _save_figure(tolerance.plot_histograms(dist, worst), plot)
    if as_json:
        _echo_json(out)
        _finish_check(check, verdict)
        return
    for i, name in enumerate(names):
        if deterministic:
            line = f"{name}: error {_fmt_um(worst.max_mm[i])} (tolerance +-{tol[i]:g} mm)"
        else:
            line = (f"{name}: worst case {_fmt_um(worst.min_mm[i])} .. {_fmt_um(worst.max_mm[i])} "
                    f"(tolerance +-{tol[i]:g} mm)")
        if dist is not None:
            line += f"; mean {_fmt_um(dist.mean_mm[i])}, std {_fmt_um(dist.std_mm[i])}"
        click.echo(line)
    if dist is not None:
        lo, hi = dist.p_within_ci95
        click.echo(f"P(within tolerance) = {dist.p_within:.5f} (95 % {lo:.5f}..{hi:.5f}), "
                   f"n = {len(dist.samples_mm)}, seed {dist.seed}")
    if deterministic:
        click.echo("single prediction (no random variable varies): " + ("within tolerance" if worst.within
                                                                  else "OUTSIDE tolerance"))
    else:
        click.echo("worst case: " + ("within tolerance" if worst.within else "OUTSIDE tolerance"))
    if op.kind == "bore" and verdict["diameter_within"] is not None:
        lo_d, hi_d = verdict["diameter_range_mm"]
        click.echo(f"diameter {lo_d:.4f}..{hi_d:.4f} mm: {'within' if verdict['diameter_within'] else 'OUTSIDE'} "
                   "its limits")
    if check:
        click.echo(f"check: {'held' if verdict['held'] else 'NOT held'} ({verdict['basis']})")
    if plot:
        click.echo(f"wrote {plot}")
    _finish_check(check, verdict)


@predict.command()
@click.argument("chain_file", type=click.Path(exists=True, dir_okay=False))
@click.option("--set", "values", multiple=True, metavar="NAME=VALUE",
              help="A variable (axis position, t, rpm, random variable). Repeatable.")
@click.option("--tool", "tool", default="0,0,0", show_default=True, metavar="X,Y,Z",
              help="Point in the tool frame (mm).")
def point(chain_file, values, tool):
    """Tool point of a chain in the workpiece frame, and the chain matrix.

    Random variables that are not set take their mid-field value.

    Example:

    \b
        postproc predict point samples/predict/mc12.machine.json --set X=0 --set S=90 --tool 100,25,0
    """
    from postproc.predict import tolerance
    from postproc.predict.operation import load_chain

    chain = load_chain(chain_file)
    env = {**tolerance.nominal(chain.random), **dict(parse_context(v) for v in values)}
    m = chain.matrix(env)
    p = chain.transform(parse_vector(tool, "--tool"), env)
    click.echo("point: " + " ".join(f"{v:.6f}" for v in np.ravel(p)))
    click.echo("matrix:")
    for row in np.asarray(m).reshape(4, 4):
        click.echo("  " + " ".join(f"{v:12.8f}" for v in row))


@predict.command("chain")
@click.argument("tables", type=click.Path(exists=True, dir_okay=False))
@click.option("--squareness", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Squareness file (default: TABLES_squareness.csv if present).")
@click.option("--order", type=click.Choice(["exact", "small"]), default="exact", show_default=True,
              help="Angular error matrix: finite rotation or seed 002's small-angle matrix.")
@click.option("--angular", type=click.Choice(["summed", "per-axis"]), default="summed", show_default=True,
              help="One matrix of the summed angles (the 21-parameter model) or one per axis.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Chain file to write.")
def chain_cmd(tables, squareness, order, angular, output):
    """Write axis error tables (formats.md) as a chain description file.

    The chain reproduces the 21-parameter model: tool point = q + rho(q) + R r.

    Example:

    \b
        postproc predict chain tables.csv --squareness tables_squareness.csv -o machine.chain.json
    """
    from postproc.calfile import atomic_write_text
    from postproc.calibration.tables import read_squareness, read_tables, squareness_path_for
    from postproc.predict.parametric_chain import chain_from_tables

    tab = read_tables(tables)
    sq_path = squareness or (squareness_path_for(tables) if squareness_path_for(tables).exists() else None)
    sq = read_squareness(sq_path) if sq_path else None
    chain = chain_from_tables(tab, sq, order=order, angular=angular)
    atomic_write_text(output, json.dumps(chain.to_dict(), indent=1) + "\n")
    click.echo(f"wrote {output}: {len(chain.modules)} modules, variables {', '.join(sorted(chain.variables()))}")


@predict.command("init")
@click.option("--layout", required=True, type=click.Choice(["vertical-mill", "horizontal-boring"]),
              help="Machine layout: 3-axis vertical mill, or horizontal boring machine (seed 004).")
@click.option("-c", "--calibration", "calibration", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Calibration made by fit: the chain takes its measured error instead of zero axis errors.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="Chain file to write.")
def init(layout, calibration, output):
    """Write a starting chain file with the common modules of a machine layout.

    Every module and element carries a "comment" (JSON has no comments; the chain
    format keeps "comment" and "_comment" keys as text) saying what it stands for and
    what to fill in. With --calibration the axes' error elements give way to the
    calibration's measured error at the commanded X, Y, Z (the path is written
    relative to the chain file; X, Y, Z default to the middle of its volume).

    Example:

    \b
        postproc predict init --layout vertical-mill -c calibrations/s500_parametric.json -o s500.chain.json
    """
    import os
    from pathlib import Path

    from postproc.calfile import load_calibration
    from postproc.fileio import atomic_write_text
    from postproc.predict.chain import chain_from_dict
    from postproc.predict.layouts import layout_chain

    centre = (0.0, 0.0, 0.0)
    rel = None
    needs: tuple[str, ...] = ()
    if calibration is not None:
        engine = load_calibration(calibration).engine
        centre = tuple(engine.volume_mm.mean(axis=0))
        needs = tuple(engine.needs)
        out_dir = Path(output).resolve().parent
        rel = Path(os.path.relpath(Path(calibration).resolve(), out_dir)).as_posix()
    data = layout_chain(layout, rel, centre, needs)
    chain = chain_from_dict(data, base_dir=Path(output).resolve().parent)  # what predict will read
    atomic_write_text(output, json.dumps(data, indent=2) + "\n")
    click.echo(f"wrote {output}: {layout}, {len(chain.modules)} modules, variables "
               f"{', '.join(sorted(chain.variables()))}")
