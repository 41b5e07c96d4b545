"""postproc export: compensation tables for controllers from a parametric calibration."""

from __future__ import annotations

import click

from postproc.cli.options import FiniteFloat


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
@click.option("-f", "--format", "fmt", required=True, type=click.Choice(["linuxcnc", "fanuc", "siemens", "beckhoff"]),
              help="Controller table to write.")
@click.option("-o", "--output", "output", required=True, type=click.Path(),
              help="Output: a directory for linuxcnc (one file per joint), else the file to write.")
@click.option("--axis", "axes", multiple=True, type=click.Choice(["X", "Y", "Z"]),
              help="Axis to export (repeatable). Default: every axis the calibration measured.")
@click.option("--comp-type", "comp_type", type=click.Choice(["0", "1"]), default="0", show_default=True,
              help="LinuxCNC COMP_FILE_TYPE: 0 actual positions, 1 trims (nominal - actual).")
@click.option("--step", type=FiniteFloat(min=0), default=None, metavar="MM",
              help="Table spacing (fanuc, siemens; linuxcnc: resample instead of the calibration's own "
                   "positions). Default: the smallest spacing of the calibration's positions.")
@click.option("--reference", "reference", multiple=True, metavar="AXIS=MM",
              help="Fanuc: machine position of the reference point (default: the axis's lower end).")
@click.option("--return-direction", "return_direction", type=click.Choice(["+", "-"]), default="+",
              show_default=True, help="Fanuc: direction of the reference position return.")
@click.option("--detection-unit", "detection_unit", type=FiniteFloat(min=0, min_open=True), default=1.0, show_default=True,
              metavar="UM", help="Fanuc: detection unit in um (pitch data and interval are counted in it).")
@click.option("--axis-name", "axis_names", multiple=True, metavar="AXIS=NAME",
              help="Controller name of an axis: LinuxCNC joint number (default X=0,Y=1,Z=2), Fanuc axis "
                   "number (1,2,3), Siemens machine axis (X1,Y1,Z1).")
@click.option("--remainder", type=click.Path(dir_okay=False), default=None, metavar="CAL_OUT",
              help="Also write the calibration without what the table compensates, for 'postproc correct' "
                   "while the controller holds the table (each error compensated once).")
def export(cal_path, fmt, output, axes, comp_type, step, reference, return_direction, detection_unit,
           axis_names, remainder):
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
    siemens   $AA_ENC_COMP part program (LEC): one table for both directions, the mean
              positioning error; the reversal stays in the program correction.
    beckhoff  TF5280 ISG CSV: all six component errors of each axis (read back by 'fit');
              squareness and backlash stay in the program correction.

    Example:

    \b
        postproc fit samples/iso230_runs_x.csv -o x_runs.json
        postproc export x_runs.json --format linuxcnc -o comp/ --remainder x_rest.json
        postproc export x_runs.json --format fanuc --step 25 --reference X=0 -o pitch.txt
        postproc export calibrations/s500_parametric.json --format siemens --step 5 -o enc_comp.spf
    """
    import json
    from pathlib import Path

    from postproc.calfile import calibration_from_dict, load_calibration
    from postproc.fileio import atomic_write_text, atomic_write_texts
    from postproc.metrology.controllers.axis import AxisErrors, default_step
    from postproc.metrology.controllers.base import axis_order, remainder_dict

    cal = load_calibration(cal_path)
    names = _axis_map(axis_names, "--axis-name")
    refs = {a: v for a, v in _axis_map(reference, "--reference").items()}
    try:
        refs_mm = {a: float(v) for a, v in refs.items()}
    except ValueError:
        raise click.BadParameter("the reference must be a number of mm, e.g. X=300", param_hint="--reference") from None
    chosen = [AxisErrors(cal, a) for a in axis_order(axes or "XYZ")]
    if not axes:
        chosen = [e for e in chosen if e.measured]
    if not chosen:
        raise click.UsageError("the calibration measured no axis: nothing to export (name one with --axis)")
    if fmt == "linuxcnc":
        from postproc.metrology.controllers.linuxcnc import export_linuxcnc

        result = export_linuxcnc(chosen, comp_type=int(comp_type), step=step, joints=names)
    elif fmt == "fanuc":
        from postproc.metrology.controllers.fanuc import export_fanuc

        du = detection_unit / 1000.0
        interval = step if step is not None else max(du, round(min(default_step(e) for e in chosen) / du) * du)
        result = export_fanuc(chosen, interval_mm=interval, detection_unit_mm=du, reference_mm=refs_mm,
                              return_direction=1 if return_direction == "+" else -1, axis_numbers=names)
    elif fmt == "siemens":
        from postproc.metrology.controllers.siemens import export_siemens

        result = export_siemens(chosen, step=step or min(default_step(e) for e in chosen), axis_names=names)
    else:
        from postproc.metrology.controllers.beckhoff import export_beckhoff

        result = export_beckhoff(chosen, name=cal.name)
    if fmt == "linuxcnc":
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
