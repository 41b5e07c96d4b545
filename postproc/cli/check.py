"""postproc check: hold a calibration against measurements; say where and why it fails."""

from __future__ import annotations

import click

from postproc.cli.options import FINITE_FLOAT


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("-c", "--calibration", "cal_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Calibration file to check.")
@click.option("--sigma", type=FINITE_FLOAT, default=None, metavar="MM",
              help="Instrument noise, standard deviation per axis in mm (default: from repeated points).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@click.option("--plot", "plot_dir", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="Write PNG plots (residual vectors, residual vs each variable, periodograms, before/after).")
@click.option("--folds", type=click.IntRange(2, 50), default=5, show_default=True,
              help="Cross-validation folds (repeated points stay together).")
@click.option("--max-effects", "max_effects", type=click.IntRange(0, 10), default=4, show_default=True,
              help="Most effects the greedy search adds (0: rank candidates, add none).")
@click.option("--fixed/--no-fixed", "fixed", default=None,
              help="Hold the calibration as it is (no refit of its method): rank effects on its own "
                   "residual. For checking a calibration made from other data (e.g. axis error tables). "
                   "Default: as recorded by 'fit --base' (its base held, the effects it added refitted), "
                   "else off.")
@click.option("--tool-vector", "tool_vector", default=None, metavar="X,Y,Z",
              help="Tool vector (mm) for rows that have no tx,ty,tz columns.")
@click.option("--register/--no-register", "register", default=None,
              help="Fit a 6-DOF registration of the measurement frame (translation and rotation) as a "
                   "nuisance, reported with its size, never as an effect. Default: on with --fixed.")
def check(files, cal_path, sigma, as_json, plot_dir, folds, max_effects, fixed, tool_vector, register):
    """Check a calibration against measurements: residuals, noise floor, where it
    fails and which physical effect is missing.

    FILES are formats.md point measurements (not necessarily those the calibration
    was fitted on). The report gives the residual (measured - model) RMS and max per
    axis, a noise floor from repeated points (or --sigma), a cross-validated RMS
    (the calibration's method refitted on K-1 folds, tested on the held-out one),
    the worst points with their file line, the residual by region, approach
    direction, time and every context column, and candidate effects (backlash,
    lead-screw periodic error, thermal drift, load, Abbe, straightness...) ranked by
    the residual variance they explain under cross-validation, each significant one
    with the 'postproc fit ... --effect NAME' command that adds it.

    Example:

    \b
        postproc fit samples/walkthrough_points.csv --method static -o walkthrough_static.json
        postproc check samples/walkthrough_points.csv -c walkthrough_static.json
        postproc check warm_points.csv -c s500_param.json --fixed --plot plots
    """
    import json

    from postproc.calfile import load_calibration
    from postproc.calibration.measurements import read_measurement_files
    from postproc.cli.options import parse_vector
    from postproc.diagnose.check import json_safe, run_check
    from postproc.diagnose.text import format_report

    if sigma is not None and not sigma > 0:
        raise click.BadParameter("must be a positive length in mm", param_hint="--sigma")
    if plot_dir:
        from pathlib import Path

        from postproc.fileio import require_matplotlib

        if Path(plot_dir).suffix.lower() in (".png", ".svg", ".pdf", ".jpg", ".jpeg") and not Path(plot_dir).is_dir():
            raise click.BadParameter(f"{plot_dir!r} looks like a file name: check writes several plots, "
                                     "give the directory to write them in (it is created)", param_hint="--plot")
        require_matplotlib("--plot")
    cal = load_calibration(cal_path)
    r = parse_vector(tool_vector, "--tool-vector") if tool_vector is not None else None
    data = read_measurement_files(files, r)
    res = run_check(cal, data, list(files), sigma_mm=sigma, folds=folds, max_selected=max_effects,
                    fixed=fixed, register=register)
    if plot_dir:
        from postproc.diagnose.plots import write_plots

        written = write_plots(res, plot_dir)
        click.echo(f"wrote {len(written)} plots in {plot_dir}", err=True)
    if as_json:
        click.echo(json.dumps(json_safe(res.to_json()), indent=2))
    else:
        click.echo("\n".join(format_report(res)))
