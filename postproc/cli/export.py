"""postproc export: compensation tables for controllers from a parametric calibration."""

from __future__ import annotations

import math
from pathlib import Path

import click

from postproc.cli.options import FiniteFloat
from postproc.metrology.controllers.formats import (
    FORMATS,
    SETTING_OPTIONS,
    Settings,
    TableFormat,
    readers_of,
)


def _check_outliers(cal, cal_path: str, keep: bool) -> None:
    """Refuse a calibration fitted from runs that used a reading beyond the outlier rule
    (postproc.metrology.outliers) unless ``keep``; say which readings fit left out."""
    from postproc.metrology.outliers import runs_outliers_used

    used, excluded, notes = runs_outliers_used(cal, cal_path)
    for line in notes:
        click.echo(line, err=True)
    for o in excluded:
        click.echo(f"excluded by fit (not in the calibration): {o}", err=True)
    if used and not keep:
        from postproc.errors import CalibrationError

        raise CalibrationError(
            f"the calibration was fitted from a reading beyond the outlier rule: {used[0]}"
            + (f" (and {len(used) - 1} more)" if len(used) > 1 else ""),
            path=cal_path,
            hint="refit without it ('postproc fit RUNS -o CAL' leaves such readings out), or give --keep-outliers "
                 "to put it in the controller table all the same")
    for o in used:
        click.echo(f"warning: kept (--keep-outliers): {o}", err=True)


def _settings(fmt: TableFormat, given: dict, cal_name: str) -> Settings:
    """The settings of ``export``'s options, checked: each one given must be read by the
    format (a setting another format reads is refused, not ignored), --reference a
    finite number of mm by axis, --return + or - by axis."""
    unread = fmt.unread({k for k, v in given.items() if v not in (None, ())})
    if unread:
        readers = readers_of(unread[0])
        raise click.UsageError(f"{SETTING_OPTIONS[unread[0]]} is a setting of {' and '.join(readers) or 'no format'} "
                               f"tables; drop it for --format {fmt.name}")
    refs_mm = {}
    for a, v in _axis_map(given["reference"], "--reference").items():
        try:
            refs_mm[a] = float(v)
        except ValueError:
            refs_mm[a] = math.nan
        if not math.isfinite(refs_mm[a]):
            raise click.BadParameter(f"{a}={v}: the reference must be a finite number of mm, e.g. X=300",
                                     param_hint="--reference")
    returns = {}
    for a, v in _axis_map(given["return"], "--return").items():
        if v not in ("+", "-"):
            raise click.BadParameter(f"{a}={v}: the return direction is + or -", param_hint="--return")
        returns[a] = 1 if v == "+" else -1
    du = given["detection_unit"]
    return Settings(step_mm=given["step"], reference_mm=refs_mm, return_direction=returns,
                    parameters=given["parameters"], detection_unit_mm=None if du is None else du / 1000.0,
                    comp_type=int(given["comp_type"] or 0), axis_names=_axis_map(given["axis_names"], "--axis-name"),
                    name=cal_name)


def _axis_map(values, what: str) -> dict[str, str]:
    out = {}
    for item in values:
        axis, sep, value = item.partition("=")
        if not sep or axis.strip().upper() not in ("X", "Y", "Z") or not value.strip():
            raise click.BadParameter(f"{item!r} is not AXIS=VALUE (e.g. X=300)", param_hint=what)
        out[axis.strip().upper()] = value.strip()
    return out


@click.command()
@click.argument("cal_path", metavar="CAL", type=click.Path(exists=True, dir_okay=False))
@click.option("-f", "--format", "fmt", required=True, type=click.Choice(list(FORMATS)),
              help="Controller table to write.")
@click.option("-o", "--output", "output", required=True, type=click.Path(),
              help="Output: a directory for linuxcnc (one file per joint), else the file to write.")
@click.option("--axis", "axes", multiple=True, type=click.Choice(["X", "Y", "Z"]),
              help="Axis to export (repeatable). Default: every axis the calibration measured.")
@click.option("--comp-type", "comp_type", type=click.Choice(["0", "1"]), default=None,
              help="LinuxCNC COMP_FILE_TYPE: 0 actual positions (the default), 1 trims (nominal - actual).")
@click.option("--step", type=FiniteFloat(min=0), default=None, metavar="MM",
              help="Table spacing (fanuc, siemens; linuxcnc: resample instead of the calibration's own "
                   "positions). Default: the smallest spacing of the calibration's positions.")
@click.option("--reference", "reference", multiple=True, metavar="AXIS=MM",
              help="Fanuc, siemens (required for each axis): machine position of the reference point; the "
                   "table is zero there.")
@click.option("--return", "return_direction", multiple=True, metavar="AXIS=+|-",
              help="Fanuc (required for each axis): direction of the reference position return (1006#5 ZMI: "
                   "0 is +, 1 is -). A reference the return cannot reach (the lower end with +) is refused.")
@click.option("--parameters", "parameters", type=click.Path(exists=True, dir_okay=False), default=None,
              metavar="TAPE", help="Fanuc: the control's parameter tape; 1240 (reference position, detection "
                                   "units) and 1006#5 (return direction) of each axis, unless --reference/--return "
                                   "give them.")
@click.option("--detection-unit", "detection_unit", type=FiniteFloat(min=0, min_open=True), default=None,
              metavar="UM", help="Fanuc: detection unit in um (pitch data and interval are counted in it); "
                                 "default 1.")
@click.option("--axis-name", "axis_names", multiple=True, metavar="AXIS=NAME",
              help="Controller name of an axis: LinuxCNC joint number (default X=0,Y=1,Z=2), Fanuc axis "
                   "number (1,2,3), Siemens machine axis (X1,Y1,Z1).")
@click.option("--remainder", type=click.Path(dir_okay=False), default=None, metavar="CAL_OUT",
              help="Also write the calibration without what the table compensates, for 'postproc correct' "
                   "while the controller holds the table (each error compensated once).")
@click.option("--keep-outliers", "keep_outliers", is_flag=True,
              help="Export a calibration fitted from runs that hold a reading beyond the outlier rule "
                   "(refused otherwise; the reading is named).")
def export(cal_path, fmt, output, axes, comp_type, step, reference, return_direction, parameters, detection_unit,
           axis_names, remainder, keep_outliers):
    """Write a controller's compensation table from a parametric calibration.

    A pitch or axis table holds the positioning of an axis along its own travel only
    (and, bidirectional, its reversal): straightness, angles acting through the
    tool, squareness and other effects are volumetric and stay in the program
    correction. --remainder writes that rest as a calibration: correct programs with
    it, not with CAL, while the table is active, or every error is compensated twice.

    \b
    linuxcnc  one file per joint: 'nominal forward reverse' triplets, COMP_FILE_TYPE 0
              or 1, at most 256; set [JOINT_n] BACKLASH = 0 (a COMP_FILE holds the reversal).
    fanuc     bidirectional pitch error compensation as a parameter tape (3620-3627 and
              the pitch data N10000+n), equidistant points from the reference point,
              values in detection units; set 3605#0 = 1 and the backlash 1851 to 0.
              Needs --reference and --return (or --parameters): no sign is assumed.
    siemens   $AA_ENC_COMP part program (LEC): one table for both directions, the mean
              positioning error, zero at --reference; the reversal stays in the program
              correction.
    beckhoff  TF5280 ISG CSV: all six component errors of each axis (read back by 'fit');
              squareness and backlash stay in the program correction; the comment lines
              say how to set negate and alternative_model.

    Every table is read back by a model of its controller (LinuxCNC's loader, Fanuc's
    pitch summation, Siemens' interpolation, the ISG CSV reader) and must give the
    calibration's correction at every table point, both directions, within the
    table's resolution; otherwise nothing is written. A calibration fitted from runs
    with a reading beyond the outlier rule is refused unless --keep-outliers.

    Example:

    \b
        postproc fit samples/iso230_runs_x.csv -o x_runs.json
        postproc export x_runs.json --format linuxcnc -o comp/ --remainder x_rest.json
        postproc export x_runs.json --format fanuc --step 25 --reference X=0 --return X=- -o pitch.txt
        postproc export calibrations/s500_parametric.json --format siemens --step 5 \\
            --reference X=0 --reference Y=0 --reference Z=0 -o enc_comp.spf
    """
    import json

    from postproc.calfile import calibration_from_dict, load_calibration
    from postproc.fileio import atomic_write_text, atomic_write_texts
    from postproc.metrology.controllers.axis import AxisErrors
    from postproc.metrology.controllers.base import axis_order, remainder_dict

    cal = load_calibration(cal_path)
    _check_outliers(cal, cal_path, keep_outliers)
    table = FORMATS[fmt]
    settings = _settings(table, {"step": step, "reference": reference, "return": return_direction,
                                 "parameters": parameters, "detection_unit": detection_unit, "comp_type": comp_type,
                                 "axis_names": axis_names}, cal.name)
    chosen = [AxisErrors(cal, a) for a in axis_order(axes or "XYZ")]
    if not axes:
        chosen = [e for e in chosen if e.measured]
    if not chosen:
        raise click.UsageError("the calibration measured no axis: nothing to export (name one with --axis)")
    result = table.build(chosen, settings)
    if table.folder:
        out_dir = Path(output)
        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_texts({out_dir / name: text for name, text in result.files.items()})
        written = [str(out_dir / name) for name in result.files]
    else:
        (text,) = result.files.values()
        atomic_write_text(output, text)
        written = [output]
    for line in result.notes:
        click.echo(line, err=True)
    others = sorted({n for e in chosen for n in e.other_effects if not n.startswith("backlash:")})
    if others:
        click.echo(f"not in the table (position-independent or volumetric): {', '.join(others)}", err=True)
    if remainder:
        data = json.loads(Path(cal_path).read_text(encoding="utf-8-sig"))
        rest = remainder_dict(data, result)
        calibration_from_dict(rest, path=remainder)  # the remainder must load as any calibration
        atomic_write_text(remainder, json.dumps(rest, indent=2) + "\n")
        written.append(remainder)
        click.echo(f"remainder for 'postproc correct' (without what the table holds): {remainder}", err=True)
    else:
        click.echo("correct programs with --remainder's calibration, not with the full one, while the table "
                   "is active: otherwise the positioning is compensated twice", err=True)
    click.echo(f"wrote {', '.join(written)}", err=True)
