"""postproc fit: make a calibration from measurements or axis error tables."""

from __future__ import annotations

import click

from postproc.cli.options import FINITE_FLOAT, FiniteFloat, parse_vector

#: Options of one tangential method: option name -> the method it belongs to.
METHOD_OPTIONS = {"--border-blend": "interval", "--grid-model": "grid", "--fill-missing": "grid"}


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("-m", "--method", type=click.Choice(["static", "interval", "grid", "parametric"]),
              default=None, help="Model to fit. Default: parametric for axis error tables, static for points.")
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="Calibration file to write (JSON text), whatever its name.")
@click.option("--name", default=None, help="Calibration name recorded in corrected programs (default: output stem).")
@click.option("--squareness", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Squareness file for axis error tables (default: TABLES_squareness.csv if present).")
@click.option("--intervals", default=None, metavar="SPEC",
              help="Interval method: partition, e.g. 'X=0,100,200,315;Y=3;Z=2' (edges, or a count per axis).")
@click.option("--border-blend", "border_blend", type=FiniteFloat(min=0), default=None, metavar="MM",
              help="Interval method: width of the zone blending neighbouring cells at each border "
                   "(default 1 mm; 0: the seed's pure piecewise model).")
@click.option("--step", default=None, metavar="MM",
              help="Grid method: grid step u1,u2,u3 in mm (default: the lattice step of the data).")
@click.option("--screw-pitch", "screw_pitch", multiple=True, metavar="AXIS=P",
              help="Declared lead-screw pitch (mm) of an axis, to warn about grid steps that alias it.")
@click.option("--grid-model", "grid_model", type=click.Choice(["trilinear", "cell"]), default=None,
              help="Grid method: trilinear tangent field (default, continuous) or the seed's "
                   "piecewise-affine cells.")
@click.option("--fill-missing", "fill_missing", is_flag=True, default=None,
              help="Grid method: fill lattice nodes without measurements from their neighbours "
                   "(listed as a warning) instead of refusing the grid.")
@click.option("--knot-spacing", "knot_spacing", type=FINITE_FLOAT, default=None, metavar="MM",
              help="Parametric identification: B-spline knot spacing (default: from the data).")
@click.option("--order", type=click.Choice(["first", "second", "exact"]), default=None,
              help="Parametric: forward-model order stored in the calibration (default: first).")
@click.option("--solver", type=click.Choice(["newton", "astatic"]), default=None,
              help="Parametric: inverse solver stored in the calibration (default: newton).")
@click.option("--tool-vector", "tool_vector", default=None, metavar="X,Y,Z",
              help="Tool vector (mm) for rows that have no tx,ty,tz columns.")
@click.option("--effect", "effects", multiple=True, metavar="NAME",
              help="Add a physical effect to the model, named as 'postproc check' prints it "
                   "(e.g. backlash:X, periodic:Y, thermal:t, load:load). Repeatable.")
@click.option("--base", "base_path", type=click.Path(exists=True, dir_okay=False), default=None, metavar="CAL",
              help="Keep this calibration (tables, grid, static ...) as it is and add the --effect terms, "
                   "fitted to its residual on the point FILES (what 'postproc check --fixed' suggests).")
@click.option("--register/--no-register", "register", default=None,
              help="Fit a 6-DOF registration of the measurement frame as a nuisance (reported, not "
                   "stored). Default: on with --base, off otherwise.")
@click.option("--max-correction", "max_correction", type=FiniteFloat(min=0), default=1.0, show_default=True,
              metavar="MM", help="Refuse to write a calibration whose correction anywhere in its volume "
                                 "exceeds this (an undetermined fit).")
def fit(files, method, output, name, squareness, intervals, border_blend, step, screw_pitch, grid_model,
        fill_missing, knot_spacing, order, solver, tool_vector, effects, base_path, register, max_correction):
    """Fit a calibration from point measurements or axis error tables.

    FILES are formats.md CSV files: point measurements (several files are fitted
    together), or axis error tables with their squareness file, and/or ISO 230-2
    interferometer runs. A tables file may give only the components measured
    (missing ones are zero, and reported). Runs give each axis's positioning error
    (the mean bidirectional deviation) and a backlash effect with the reversal
    values B_i along the axis. The calibration is written to OUTPUT atomically; a
    summary of the fit (residual, rank, undetermined parameters) is printed.

    Example:

    \b
        postproc fit samples/tracker_6points.csv --method static -o my_static.json
        postproc fit grid15.csv -m interval --intervals 'X=3;Y=3;Z=2' --border-blend 0 -o interval.json
        postproc fit grid15.csv -m grid --grid-model cell --fill-missing -o grid.json
        postproc fit --base tables_cal.json tracker.csv --effect backlash:Y -o tables_backlash.json
        postproc fit samples/iso230_runs_x.csv -o x_runs.json
    """
    from postproc.calibration.calfile import save_calibration
    from postproc.calibration.measurements import read_measurement_files
    from postproc.calibration.sniff import sniff
    from postproc.engine.registry import fitter
    from postproc.errors import CalibrationError, MeasurementError

    kinds = ["tables" if k == "isg" else k for k in (sniff(f) for f in files)]
    if base_path is not None:
        _fit_base(base_path, files, kinds, method, output, name, tool_vector, effects, register, max_correction)
        return
    options = {
        "intervals": intervals,
        "border_blend_mm": border_blend,
        "step": step,
        "screw_pitch": list(screw_pitch) or None,
        "model": grid_model,
        "fill_missing": fill_missing,
        "knot_spacing": knot_spacing,
        "order": order,
        "solver": solver,
    }
    options = {k: v for k, v in options.items() if v is not None}
    given = {"--border-blend": border_blend, "--grid-model": grid_model, "--fill-missing": fill_missing}
    if ("tables" in kinds or "runs" in kinds) and kinds.count("squareness") == 1 and squareness is None:
        # A squareness file given among FILES is taken as --squareness.
        squareness = files[kinds.index("squareness")]
        files = tuple(f for f, k in zip(files, kinds, strict=True) if k != "squareness")
        kinds = [k for k in kinds if k != "squareness"]
    if "tables" in kinds or "runs" in kinds:
        if "measurements" in kinds:
            what = "axis error tables" if "tables" in kinds else "interferometer runs"
            raise MeasurementError(f"{what} cannot be fitted together with point files",
                                   path=files[kinds.index("measurements")])
        if "squareness" in kinds:
            raise MeasurementError("more than one squareness file", path=files[kinds.index("squareness")],
                                   hint="give one squareness file (among FILES or with --squareness)")
        if method not in (None, "parametric"):
            raise click.UsageError("axis error tables make a parametric calibration; drop --method or use parametric")
        _check_method_options("parametric", given)
        if effects:
            raise click.UsageError("--effect is fitted from point measurements, not axis error tables; "
                                   "fit the tables alone, then 'postproc check POINTS -c CAL --fixed' tells "
                                   "which effect the points show")
        from postproc.metrology.tables_fit import fit_tables

        result = fit_tables([f for f, k in zip(files, kinds, strict=True) if k == "tables"], squareness=squareness,
                            runs=[f for f, k in zip(files, kinds, strict=True) if k == "runs"], **options)
    else:
        method = method or "static"
        if (order or solver) and method != "parametric":
            raise click.UsageError("--order and --solver apply to the parametric method only")
        _check_method_options(method, given)
        r = parse_vector(tool_vector, "--tool-vector") if tool_vector is not None else None
        data = read_measurement_files(files, r)
        try:
            if effects or register:
                from postproc.diagnose.refit import fit_with_effects

                result = fit_with_effects(method, data, list(effects), register=bool(register), **options)
            else:
                result = fitter(method)(data, **options)
        except CalibrationError as exc:
            if border_blend is not None and "border blend" in exc.message:
                # The blend is checked against the partition, known only once fitted.
                raise click.UsageError(f"--border-blend {border_blend:g}: {exc.message}") from None
            raise
    for line in result.report:
        click.echo(line, err=True)
    if len(result.residuals_mm):  # tables are taken as measured: there is no fit residual
        click.echo(
            f"fit residual: RMS {result.rms_mm * 1000:.2f} um, max {result.max_mm * 1000:.2f} um "
            f"over {len(result.residuals_mm)} points",
            err=True,
        )
    if len(result.residuals_mm):
        from postproc.diagnose.refit import refuse_large_correction

        refuse_large_correction(result.engine, data, max_correction, output)
    save_calibration(output, result.engine, name=name, effects=result.effects, fit=result.info)
    click.echo(f"wrote {output}", err=True)


def _fit_base(base_path, files, kinds, method, output, name, tool_vector, effects, register, max_correction):
    """``fit --base CAL POINTS... --effect NAME``: effects added to a calibration kept as it is."""
    from postproc.calibration.calfile import load_calibration, save_calibration
    from postproc.calibration.measurements import read_measurement_files
    from postproc.diagnose.refit import extend_calibration, refuse_large_correction
    from postproc.errors import MeasurementError

    if method is not None:
        raise click.UsageError("--base keeps the calibration's own method; drop --method")
    if not effects:
        raise click.UsageError("--base adds effects: name at least one --effect (as 'postproc check --fixed' "
                               "suggests)")
    bad = [f for f, k in zip(files, kinds, strict=True) if k != "measurements"]
    if bad:
        raise MeasurementError("--base fits effects from point measurements; this is not a point file",
                               path=bad[0])
    cal = load_calibration(base_path)
    r = parse_vector(tool_vector, "--tool-vector") if tool_vector is not None else None
    data = read_measurement_files(files, r)
    result = extend_calibration(cal, data, list(effects), register=True if register is None else register)
    for line in result.report:
        click.echo(line, err=True)
    click.echo(f"fit residual: RMS {result.rms_mm * 1000:.2f} um, max {result.max_mm * 1000:.2f} um "
               f"over {len(result.residuals_mm)} points", err=True)
    refuse_large_correction(result.engine, data, max_correction, output)
    save_calibration(output, result.engine, name=name, effects=result.effects, fit=result.info)
    click.echo(f"wrote {output}", err=True)


def _check_method_options(method: str, given: dict) -> None:
    """A usage error for an option of another method (``given``: option name -> value or None)."""
    for opt, value in given.items():
        if value is not None and METHOD_OPTIONS[opt] != method:
            raise click.UsageError(f"{opt} applies to the {METHOD_OPTIONS[opt]} method only "
                                   f"(this fit is {method}); add --method {METHOD_OPTIONS[opt]} or drop {opt}")
