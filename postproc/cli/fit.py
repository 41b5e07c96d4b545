"""postproc fit: make a calibration from measurements or axis error tables."""

from __future__ import annotations

import click

from postproc.cli.options import FINITE_FLOAT, FiniteFloat, parse_vector

#: prefix of the parameter names of the method options (kept apart from the command's own)
_PREFIX = "method_option_"


def _method_option(opt) -> click.Option:
    """The click option of a registry :class:`postproc.engine.registry.FitOption`."""
    attrs: dict = {"help": opt.help, "default": None, "metavar": opt.metavar}
    if opt.type == "float":
        attrs["type"] = FINITE_FLOAT if opt.minimum is None else FiniteFloat(min=opt.minimum)
    elif opt.type == "choice":
        attrs["type"] = click.Choice(list(opt.choices))
    elif opt.type == "flag":
        attrs["is_flag"] = True
    if opt.multiple:
        attrs["multiple"] = True
    return click.Option([opt.flag, _PREFIX + opt.keyword], **attrs)


class MethodOptionsCommand(click.Command):
    """A command whose --method choices and method options are read from
    :mod:`postproc.engine.registry` when it is used: they go after the parameter
    named ``after`` (a method registered later is taken without a change here)."""

    def __init__(self, *args, after: str, **kwargs) -> None:
        self._after = after
        self._cache: tuple = ((), [])
        super().__init__(*args, **kwargs)

    @property
    def params(self) -> list[click.Parameter]:
        from postproc.engine import registry

        key = tuple((name, id(m)) for name, m in registry.METHODS.items())
        if self._cache[0] != key:
            method = click.Option(
                ["-m", "--method"], type=click.Choice(registry.fit_methods()), default=None,
                help=f"Model to fit. Default: {' or '.join(registry.tables_methods())} for axis error tables, "
                     f"{registry.DEFAULT_POINTS_METHOD} for points.")
            options = [_method_option(opt) for opt, _methods in registry.fit_options().values()]
            at = next(k for k, p in enumerate(self._static) if p.name == self._after) + 1
            self._cache = (key, [*self._static[:1], method, *self._static[1:at], *options, *self._static[at:]])
        return self._cache[1]

    @params.setter
    def params(self, value: list[click.Parameter]) -> None:
        self._static = list(value)
        self._cache = ((), [])


@click.command(cls=MethodOptionsCommand, after="squareness")
@click.argument("files", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="Calibration file to write (JSON text), whatever its name.")
@click.option("--name", default=None, help="Calibration name recorded in corrected programs (default: output stem).")
@click.option("--squareness", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Squareness file for axis error tables (default: TABLES_squareness.csv if present).")
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
@click.option("--keep-outliers", "keep_outliers", is_flag=True,
              help="Fit every reading, also those beyond the outlier rule that 'check' excludes (listed, and "
                   "recorded in the calibration: 'export' then refuses it without --keep-outliers).")
def fit(files, method, output, name, squareness, tool_vector, effects, base_path, register, max_correction,
        keep_outliers, **method_options):
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
    from postproc.calfile import save_calibration
    from postproc.calibration.measurements import read_measurement_files
    from postproc.calibration.sniff import sniff
    from postproc.engine import registry
    from postproc.errors import CalibrationError, MeasurementError

    kinds = ["tables" if k == "isg" else k for k in (sniff(f) for f in files)]
    given = _given(method_options)
    if base_path is not None:
        if given:
            raise click.UsageError(f"--base keeps the calibration as it is; drop {', '.join(given)}")
        _fit_base(base_path, files, kinds, method, output, name, tool_vector, effects, register, max_correction,
                  keep_outliers)
        return
    options = {opt.keyword: value for flag, (opt, value) in given.items()}
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
        table_methods = " or ".join(registry.tables_methods())
        if method is not None and method not in registry.tables_methods():
            raise click.UsageError(f"axis error tables make a {table_methods} calibration; drop --method or use "
                                   f"{table_methods}")
        method = method or registry.tables_methods()[0]
        _check_method_options(method, given, tables=True)
        if effects:
            raise click.UsageError("--effect is fitted from point measurements, not axis error tables; "
                                   "fit the tables alone, then 'postproc check POINTS -c CAL --fixed' tells "
                                   "which effect the points show")
        from postproc.metrology.tables_fit import tables_fitter

        result = tables_fitter(method)(
            [f for f, k in zip(files, kinds, strict=True) if k == "tables"], squareness=squareness,
            runs=[f for f, k in zip(files, kinds, strict=True) if k == "runs"], keep_outliers=keep_outliers,
            **options)
    else:
        method = method or registry.DEFAULT_POINTS_METHOD
        _check_method_options(method, given)
        r = parse_vector(tool_vector, "--tool-vector") if tool_vector is not None else None
        data = read_measurement_files(files, r)
        try:
            result, data = _fit_points(method, data, effects, register, options, keep_outliers)
        except CalibrationError as exc:
            for flag, (opt, value) in given.items():
                if opt.error_phrase and opt.error_phrase in exc.message:
                    # Such a value is checked against the data, known only once fitted.
                    shown = f"{value:g}" if isinstance(value, float) else str(value)
                    raise click.UsageError(f"{flag} {shown}: {exc.message}") from None
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


def _fit_base(base_path, files, kinds, method, output, name, tool_vector, effects, register, max_correction,
              keep_outliers=False):
    """``fit --base CAL POINTS... --effect NAME``: effects added to a calibration kept as it is."""
    from postproc.calfile import load_calibration, save_calibration
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
    register = True if register is None else register
    # as 'check --fixed' screens: against the calibration as it is, the frame registered
    found = _points_outliers(data, cal.engine, register=register)
    if found and not keep_outliers:
        data = _without(data, found)
    result = extend_calibration(cal, data, list(effects), register=register)
    _record_outliers(result, found, keep_outliers)
    for line in result.report:
        click.echo(line, err=True)
    click.echo(f"fit residual: RMS {result.rms_mm * 1000:.2f} um, max {result.max_mm * 1000:.2f} um "
               f"over {len(result.residuals_mm)} points", err=True)
    refuse_large_correction(result.engine, data, max_correction, output)
    save_calibration(output, result.engine, name=name, effects=result.effects, fit=result.info)
    click.echo(f"wrote {output}", err=True)


def _fit_points(method, data, effects, register, options, keep_outliers):
    """Fit the point files ``data``; points beyond the outlier rule (screened as 'check'
    screens, on the first fit's residual) are left out and the fit made again, unless
    ``keep_outliers``. Returns the result and the data it was fitted to."""
    from postproc.engine import registry

    def run_fit(data):
        if effects or register:
            from postproc.diagnose.refit import fit_with_effects

            return fit_with_effects(method, data, list(effects), register=bool(register), **options)
        return registry.fitter(method)(data, **options)

    result = run_fit(data)
    found = _points_outliers(data, result.engine, resid=result.residuals_mm)
    if found and not keep_outliers:
        data = _without(data, found)
        result = run_fit(data)
    _record_outliers(result, found, keep_outliers)
    return result, data


def _points_outliers(data, engine, *, register: bool = False, resid=None) -> list[dict]:
    """Points of measurement files ``data`` beyond the rule, screened as ``check`` screens
    them (:func:`postproc.diagnose.robust.screen`: repeat groups against their other
    shots, single shots by their residual against ``engine``, or ``resid`` (N, 3) when
    given, e.g. a fit's own residual), with the measurement frame registered first when
    ``register``. Each: ``row`` (over the files in order), ``place`` (file:line),
    ``residual_mm`` and ``why``."""
    import numpy as np

    from postproc.diagnose.check import measured_residual
    from postproc.diagnose.data import Dataset
    from postproc.diagnose.robust import screen
    from postproc.errors import PostprocError

    ds = Dataset.from_measurements(data)
    if resid is None or len(resid) != len(ds):
        resid = measured_residual(engine, ds)
        if register and len(ds) >= 6:  # a 6-DOF registration needs six points, as in check
            from postproc.diagnose.models import Fixed

            try:
                frame = Fixed(engine, "registration", True).fit(ds, []).frame
                resid = resid - frame.displacement(ds.q, ds.r) if frame is not None else resid
            except PostprocError:
                pass
    sc = screen(ds, np.asarray(resid, dtype=float))
    return [{"row": int(o["row"]), "place": o["place"], "residual_mm": o["residual_mm"], "why": o["reason"]}
            for o in sc.outliers]


def _without(data, found):
    """The measurement files without the rows of ``found`` (points_outliers entries)."""
    out = []
    start = 0
    for meas in data:
        rows = [o["row"] - start for o in found if start <= o["row"] < start + len(meas)]
        out.append(meas.without_rows(rows) if rows else meas)
        start += len(meas)
    return out


def _record_outliers(result, found, kept: bool) -> None:
    """List the points beyond the outlier rule in the report and the calibration's fit
    information (left out, or kept with --keep-outliers)."""
    from postproc.metrology.outliers import RULE

    if found:
        what = "kept (--keep-outliers)" if kept else "excluded from the fit (as 'check' excludes them)"
        result.report.append(f"{len(found)} point(s) beyond the outlier rule {what}:")
        result.report += [f"  {o['place']}: residual ({', '.join(f'{v * 1000:+.1f}' for v in o['residual_mm'])}) um: "
                          f"{o['why']}" for o in found]
    result.info = dict(result.info or {})
    rows = [{k: v for k, v in o.items() if k != "row"} for o in found]
    result.info["outliers"] = {"rule": RULE, "excluded": [] if kept else rows, "kept": rows if kept else []}


def _given(method_options: dict) -> dict:
    """The method options given on the command line: flag -> (FitOption, value); a
    repeatable option's values as a list."""
    from postproc.engine.registry import fit_options

    given = {}
    for flag, (opt, _methods) in fit_options().items():
        value = method_options.get(_PREFIX + opt.keyword)
        if value is None or value == () or value is False:
            continue
        given[flag] = (opt, list(value) if opt.multiple else value)
    return given


def _check_method_options(method: str, given: dict, tables: bool = False) -> None:
    """A usage error for a method option the fit's method does not take (``given``: flag ->
    (FitOption, value)); ``tables``: the fit is made from axis error tables."""
    from postproc.engine.registry import fit_options

    declared = fit_options()
    for flag, (opt, _value) in given.items():
        methods = declared[flag][1]
        if method not in methods:
            names = " and ".join(methods)
            raise click.UsageError(f"{flag} applies to the {names} method{'s' if len(methods) > 1 else ''} only "
                                   f"(this fit is {method}); add --method {methods[0]} or drop {flag}")
        if tables and not opt.tables:
            raise click.UsageError(f"{flag} applies to {method} fits from point measurements, not to axis "
                                   f"error tables; drop {flag}")
