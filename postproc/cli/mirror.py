"""postproc mirror: corrections for mirror milling of waffle-grid shells (seed 003)."""

from __future__ import annotations

import math
from pathlib import Path

import click

from postproc.cli.options import (
    FINITE_FLOAT,
    FiniteFloat,
    correction_options,
    program_setup_options,
)
from postproc.errors import PostprocError


def _direction(ctx, param, value):
    from postproc.mirror.maps import parse_direction

    try:
        return parse_direction(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None


def _pair(text: str, what: str) -> tuple[float, float]:
    try:
        a, b = (float(p) for p in text.split(","))
        if not (math.isfinite(a) and math.isfinite(b)):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{what} must be two numbers A,B, got {text!r}") from None
    return a, b


THINNER = click.option(
    "--thinner-direction", "thinner", default="+Y", show_default=True, callback=_direction, metavar="[+|-]AXIS",
    help="Axis motion that cuts deeper (leaves a thinner wall): the spindle axis with the sign that "
         "points into the wall. +Y matches the seed's Y_c = Y_p + K.")


@click.group()
def mirror() -> None:
    """Mirror milling of waffle shells: K_dist, feedback self-tuning, dead-band model.

    Maps are CSV files '# postproc correction map v1' with columns B,Z,value (or any
    one or two of X,Y,Z,A,B,C); 'postproc correct --map FILE' adds them to a program.
    See docs/mirror.md for units, signs and a worked example.

    Example:

        postproc mirror kdist samples/mirror/backwall_sensor.csv --cutter-radius 10 --diameter 2000 -o kdist.csv
    """


@mirror.command()
@click.argument("sensor", type=click.Path(exists=True, dir_okay=False))
@click.option("--cutter-radius", "radius", type=FINITE_FLOAT, required=True, metavar="MM", help="Cutter radius R (mm).")
@click.option("--diameter", type=FINITE_FLOAT, required=True, metavar="MM", help="Blank (shell) diameter D (mm).")
@click.option("--segment-deg", "segment", type=FINITE_FLOAT, default=5.0, show_default=True, metavar="DEG",
              help="Length in B of each least-squares segment.")
@click.option("--z-bin", "z_bin", type=FINITE_FLOAT, default=None, metavar="MM",
              help="Group sensor rows into Z bins of this height (for sweeps not at constant Z).")
@click.option("--model", type=click.Choice(["signed", "overcut"]), default="signed", show_default=True,
              help="signed: E = R*360/(pi D)*tan(alpha) as in the seed; overcut: E = -R|slope| "
                   "(flat end mill envelope, always thinner).")
@THINNER
@click.option("--units", type=click.Choice(["mm", "um"]), default="mm", show_default=True,
              help="Units of the values written to the map.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="K_dist map to write.")
def kdist(sensor, radius, diameter, segment, z_bin, model, thinner, units, output):
    """Disturbance correction K_dist from a back-wall sensor sweep (formulas 1-4).

    SENSOR is a CSV with columns B (table angle, degrees), Z (mm) and V (sensor
    signal, mm; '# units: length=um' for micrometres). V is fitted by least squares
    against B on segments of --segment-deg in each row of constant Z; each
    segment's slope k (mm/deg) gives tan(alpha) = k * 360 / (pi D) and the thickness
    error E = R * tan(alpha). The map [B, Z, E] is written with E as the value
    (positive: the wall comes out thicker, cut deeper), applied along the spindle
    axis given by --thinner-direction.

    Example:

        postproc mirror kdist samples/mirror/backwall_sensor.csv --cutter-radius 10 --diameter 2000 --segment-deg 2 -o kdist.csv
    """
    import numpy as np

    from postproc.mirror.kdist import fit_kdist, kdist_comments, read_sensor
    from postproc.mirror.maps import save_map

    axis, sign = thinner
    res = fit_kdist(read_sensor(sensor), cutter_radius_mm=radius, diameter_mm=diameter, segment_deg=segment,
                    z_bin_mm=z_bin, model=model, apply_axis=axis, sign=sign)
    save_map(output, res.kmap, comments=kdist_comments(res, sensor), units=units)
    e = np.array([s.e_mm for s in res.segments]) * 1e3
    k = np.array([s.k_mm_per_deg for s in res.segments])
    rms = max(s.rms_mm for s in res.segments) * 1e3
    rows = len({s.z_mm for s in res.segments})
    click.echo(f"{len(res.segments)} segments of {segment:g} deg in {rows} row(s); "
               f"slope k {k.min():+.5f}..{k.max():+.5f} mm/deg, "
               f"tan(alpha) {k.min() * 360 / (np.pi * diameter):+.6f}..{k.max() * 360 / (np.pi * diameter):+.6f}")
    click.echo(f"K_dist = E: {e.min():+.2f}..{e.max():+.2f} um (R={radius:g} mm, D={diameter:g} mm, {model}); "
               f"worst line-fit rms {rms:.2f} um")
    click.echo(f"wrote {output} ({len(res.kmap.values_mm)} nodes, {'regular' if res.kmap.regular else 'scattered'} "
               f"over {','.join(res.kmap.coords)}, applied along {'+' if sign > 0 else '-'}{axis})")


@mirror.command()
@click.argument("semi", type=click.Path(exists=True, dir_okay=False))
@click.option("--t-ref", "t_ref", type=FINITE_FLOAT, required=True, metavar="MM", help="Nominal wall thickness T_ref.")
@click.option("--allowance", type=FiniteFloat(min=0), required=True, metavar="MM", help="Semi-finish allowance b.")
@click.option("--origin", default="0,0", show_default=True, metavar="B0,Z0",
              help="Pocket origin: the map is written in pocket-local B-B0, Z-Z0.")
@THINNER
@click.option("--smooth", type=int, default=1, show_default=True, metavar="N",
              help="Average each K_fb node with its neighbours along B (odd N nodes per row); 1 = none.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="K_fb map to write.")
def kfb(semi, t_ref, allowance, origin, thinner, smooth, output):
    """Feedback correction K_fb = T - T_ref - b from one semi-finish thickness map (formula 7).

    SEMI is the ultrasonic thickness map B,Z,T measured after a semi-finish pass
    that left the allowance b. The map is written in pocket-local coordinates and
    can be added to the finish program with 'postproc correct --map'.

    Example:

        postproc mirror kfb samples/mirror/P01_semi.csv --t-ref 2.0 --allowance 0.3 --origin 3,100 -o kfb.csv
    """
    from postproc.mirror.feedback import kfb_map, read_thickness
    from postproc.mirror.maps import save_map

    axis, sign = thinner
    b0, z0 = _pair(origin, "--origin")
    thk = read_thickness(semi)
    m = kfb_map(thk, t_ref=t_ref, allowance=allowance, b0=b0, z0=z0, apply_axis=axis, sign=sign, smooth=smooth)
    save_map(output, m, comments=[f"kfb: T - T_ref - b, T_ref={t_ref:g} mm, b={allowance:g} mm, "
                                  f"origin B0={b0:g} Z0={z0:g}", f"source: {Path(semi).name}"])
    click.echo(f"K_fb {m.values_mm.min() * 1e3:+.2f}..{m.values_mm.max() * 1e3:+.2f} um at {len(m.values_mm)} "
               f"nodes; wrote {output}")


@mirror.command()
@click.argument("plan", type=click.Path(exists=True))
@click.option("-c", "--calibration", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Geometric calibration applied first (a calibration of method identity for none, e.g. samples/mirror/shell_identity.json).")
@click.option("--program", "template", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Pocket program in pocket-local coordinates (B as programmed = B - B0).")
@click.option("--t-ref", "t_ref", type=FINITE_FLOAT, required=True, metavar="MM", help="Nominal wall thickness T_ref.")
@click.option("--band", required=True, metavar="TMIN,TMAX", help="Signal band [T_min, T_max] (mm).")
@click.option("--allowance", type=FiniteFloat(min=0), required=True, metavar="MM", help="Semi-finish allowance b.")
@click.option("--kdist", "kdist_path", type=click.Path(exists=True, dir_okay=False), default=None,
              help="K_dist map (machine B, Z) added to every pass (formula 11).")
@THINNER
@click.option("--smooth", type=int, default=1, show_default=True, metavar="N",
              help="Average each K_fb node with its neighbours along B (odd N nodes per row); 1 = none.")
@click.option("--clamp", is_flag=True, help="Hold the edge value for program points outside a map "
                                            "(default: refuse).")
@program_setup_options
@correction_options
@click.option("-o", "--output-dir", "outdir", required=True, type=click.Path(file_okay=False),
              help="Directory for the programs and maps of the next pocket.")
def pockets(plan, calibration, template, t_ref, band, allowance, kdist_path, thinner, smooth, clamp, reading, setup,
            correcting, outdir):
    """Pocket-to-pocket self-tuning: which correction each pocket gets (formulas 7-11).

    PLAN is a CSV '# postproc mirror plan v1' with columns pocket,B0,Z0,semi,finish
    (or a directory holding plan.csv): each pocket's origin and the thickness maps
    (B,Z,T files) measured after its semi-finish and finish passes so far, empty
    when not measured. The history is replayed: the first pocket gets a semi-finish
    pass; K_fb = T_semi - T_ref - b is reused while each finished pocket stays
    inside [T_min, T_max]; after a pocket leaves the band the next one gets a new
    semi-finish pass. For the next pocket to machine, the corrected program is
    written to OUTPUT_DIR (geometric calibration first, then the maps added along
    the spindle axis): <pocket>_semi.nc (allowance b, plus K_dist) or
    <pocket>_finish.nc (K_fb, plus K_dist), with the correction map used. The setup
    options are those of 'postproc correct' (e.g. --tool-vector 0,150,0 for a spindle
    along +Y).

    Example:

        postproc mirror pockets samples/mirror/plan.csv -c samples/mirror/shell_static.json --program samples/mirror/pocket.nc --t-ref 2.0 --band 1.98,2.02 --allowance 0.3 --kdist samples/mirror/kdist.csv -o next/
    """
    from postproc.mirror.feedback import Band, pocket_corrections, read_plan, self_tune
    from postproc.mirror.maps import load_map

    axis, sign = thinner
    t_min, t_max = _pair(band, "--band")
    bnd = Band(t_ref, t_min, t_max)
    plan_path = str(Path(plan) / "plan.csv") if Path(plan).is_dir() else str(plan)
    pks = read_plan(plan)
    decisions = self_tune(pks, bnd, allowance, plan_path)
    outside = "clamp" if clamp else "refuse"
    kd = load_map(kdist_path, outside=outside) if kdist_path else None
    click.echo(f"{'pocket':8} {'pass':12} {'K_fb from':10} {'finish T error (um)':28} decision")
    for d in decisions:
        kind = "semi+finish" if d.semi_pass else "finish"
        stats = (f"mean {d.finish_stats['mean_um']:+6.1f} max|.| {d.finish_stats['max_abs_um']:5.1f}"
                 if d.finish_stats else "not measured")
        band_txt = "" if d.band_ok is None else ("in band" if d.band_ok else "OUT OF BAND")
        click.echo(f"{d.pocket.name:8} {kind:12} {d.k_from or '-':10} {stats:28} {band_txt or d.reason}")
        if d.band_ok is False:
            click.echo(f"{'':8} {d.band_note}")
    last = decisions[-1]
    if not last.next:
        click.echo("all pockets of the plan are finished")
        return
    semi_corr, fin_corr = pocket_corrections(last, {p.name: p for p in pks}, band=bnd, allowance=allowance,
                                             apply_axis=axis, sign=sign, kdist=kd, outside=outside,
                                             smooth=smooth)
    corr = fin_corr if fin_corr is not None else semi_corr
    kind = "finish" if fin_corr is not None else "semi"
    out = Path(outdir)
    target = out / f"{last.pocket.name}_{kind}.nc"
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        summary = _correct_program(template, calibration, setup, corr, target, reading, correcting)
    except BaseException:
        if created and not any(out.iterdir()):
            out.rmdir()  # leave nothing behind: the directory was made for this job
        raise
    click.echo(f"next: pocket {last.pocket.name}: {last.next}")
    click.echo(f"wrote {target} ({summary})")
    if fin_corr is not None:
        _save_parts(fin_corr, out, last.pocket.name)


def _save_parts(corr, out: Path, name: str) -> None:
    from postproc.mirror.maps import CorrectionMap, save_map

    for part in corr.parts:
        if isinstance(part, CorrectionMap):
            target = out / f"{name}_{part.name.split('@')[0]}.csv"
            save_map(target, part, comments=[f"{part.name}: pocket-local coordinates of pocket {name}"])
            click.echo(f"wrote {target}")


def _correct_program(template, calibration, setup, corr, target: Path, reading, correcting: dict) -> str:
    """Correct the template with the calibration, ``corr`` added; write ``target`` atomically."""
    from postproc.calfile import load_calibration
    from postproc.gcode.path import program_path
    from postproc.gcode.pipeline import CorrectOptions, correct_file
    from postproc.gcode.places import file_of
    from postproc.gcode.recognise import dialect_of_file

    cal = load_calibration(calibration)
    # How the template is read, once for the check and the correction both: the dialect
    # (generic: Sinumerik by its header, as correct, diff and verify choose it), the
    # subprogram folders and the bounds on the work, so that the check cannot read the
    # template otherwise than the correction does, nor run unbounded where it is bounded.
    given = {**reading.correct_options(), "dialect": dialect_of_file(str(template), reading.dialect)}
    # Evaluate the maps on the program's points first, so that a point outside a map
    # is refused naming its line in the template.
    # A point of a subprogram's file (the template read expanded) is named in that file.
    pp = program_path(template, setup, dialect=given["dialect"], subroutine_path=given["subroutine_path"],
                      limits=given["limits"])
    try:
        corr.delta(pp.points_mm, {**pp.context, "lineno": pp.lineno})
    except PostprocError as exc:
        at = exc.point_index
        raise exc.at(path=str(template) if at is None else file_of(pp.files, at, str(template))) from None
    options = CorrectOptions(added=[corr], **correcting, **given)
    report = correct_file(template, target, cal.engine, setup, options, calibration_name=cal.name,
                          calibration_sha256=cal.sha256)
    return (f"{report.moves} moves, {report.words_changed} words changed, "
            f"largest correction {report.max_correction_mm * 1e3:.1f} um")


@mirror.command()
@click.argument("sensor", type=click.Path(exists=True, dir_okay=False))
@click.option("--gap", type=FINITE_FLOAT, required=True, metavar="MM", help="Width of the elastic gap (dead band).")
@click.option("--drive-tau", "tau", type=FiniteFloat(min=0), default=0.0, show_default=True, metavar="S",
              help="Time constant of the tracking drive (needs a t column); 0: ideal drive.")
@click.option("--correction", "correction", type=click.Path(exists=True, dir_okay=False), default=None,
              help="Correction map (B,Z or B) to test: the residual E - K is reported.")
@click.option("--learn", "learn", type=click.Path(dir_okay=False), default=None,
              help="Write the simulated error E at the sensor points as a map (to test with --correction).")
@click.option("--plot", type=click.Path(dir_okay=False), default=None, help="PNG of the signals (needs matplotlib).")
@click.option("-o", "--output", type=click.Path(dir_okay=False), default=None,
              help="CSV trace: B,Z,V,V_gap,W,E(,K,residual).")
def deadband(sensor, gap, tau, correction, learn, plot, output):
    """Dead-band model of the copying chain: the plateau at table reversal.

    SENSOR holds the ideal back-wall signal along the path, in path order: columns
    B (deg), Z (mm), V (mm), optional t (s). V goes through a backlash block of
    width --gap, then the drive; the thickness error is E = V - W. Each reversal of
    the table shows a plateau, during which the input travels exactly the gap, and
    E steps from +gap/2 to -gap/2.

    Example:

        postproc mirror deadband samples/mirror/zigzag_sensor.csv --gap 0.02 --plot deadband.png
    """
    import numpy as np

    if plot:
        from postproc.fileio import require_matplotlib

        require_matplotlib("--plot")
    from postproc.calibration.csvfile import read_csv
    from postproc.mirror.deadband import plot_deadband, simulate
    from postproc.mirror.kdist import read_sensor
    from postproc.mirror.maps import CorrectionMap, load_map, save_map

    data = read_sensor(sensor)
    table = read_csv(sensor)
    t = table.numeric("t") if table.has("t") else None
    if tau > 0 and t is None:
        raise click.UsageError("--drive-tau needs a t column (seconds) in SENSOR")
    k = None
    if correction:
        m = load_map(correction)
        coords = np.column_stack([data.b_deg if c == "B" else data.z_mm for c in m.coords])
        if any(c not in ("B", "Z") for c in m.coords):
            raise click.UsageError("--correction: the map must be over B or B,Z")
        k = m.values_at(coords, data.linenos)
    res = simulate(data.v_mm, gap, t_s=t, tau_s=tau, b_deg=data.b_deg, correction_mm=k)
    click.echo(f"{len(data.v_mm)} samples, {len(res.reversals)} reversal(s) of the signal, gap {gap * 1e3:g} um")
    for p in res.plateaus:
        click.echo(f"  plateau at line {int(table.linenos[p.start])}: B {p.b_start:.3f} -> {p.b_end:.3f} deg, "
                   f"input travel {p.input_travel_mm * 1e3:.2f} um")
    click.echo(f"thickness error E = V - W: {res.error_mm.min() * 1e3:+.2f}..{res.error_mm.max() * 1e3:+.2f} um")
    if k is not None:
        r = res.residual_mm
        click.echo(f"with {correction}: residual {r.min() * 1e3:+.2f}..{r.max() * 1e3:+.2f} um "
                   f"(rms {np.sqrt(np.mean(r**2)) * 1e3:.2f} um, was {np.sqrt(np.mean(res.error_mm**2)) * 1e3:.2f})")
    if learn:
        nodes = np.column_stack([data.b_deg, data.z_mm])
        m = CorrectionMap("deadband", ("B", "Z"), nodes, res.error_mm)
        save_map(learn, m, comments=[f"deadband: E = V - W along {Path(sensor).name}, gap {gap:g} mm"])
        click.echo(f"wrote {learn}")
    if output:
        from postproc.calfile import atomic_write_text

        head = "B,Z,V,V_gap,W,E" + (",K,residual" if k is not None else "")
        lines = ["# deadband trace (mm)", head]
        for i in range(len(data.v_mm)):
            cells = [data.b_deg[i], data.z_mm[i], res.v_ideal[i], res.v_model[i], res.w[i], res.error_mm[i]]
            if k is not None:
                cells += [k[i], res.residual_mm[i]]
            lines.append(",".join(f"{c:.6f}" for c in cells))
        atomic_write_text(output, "\n".join(lines) + "\n")
        click.echo(f"wrote {output}")
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        from postproc.fileio import save_figure

        ax = plot_deadband(res, x=t, xlabel="t, s" if t is not None else "sample")
        save_figure(ax[0].figure, plot, dpi=120)
        click.echo(f"wrote {plot}")


@mirror.command()
@click.argument("directory", type=click.Path(file_okay=False))
@click.option("--seed", type=click.IntRange(min=0), default=3, show_default=True, help="Seed of the synthetic noise.")
def synth(directory, seed):
    """Write a synthetic shell data set: sensor sweep, pocket program, plan, first maps.

    The shell (D 2000 mm, 12 pockets every 6 deg, T_ref 2.0 mm, allowance 0.3 mm)
    has a tilted back wall, a drift of 8 um per pocket and a within-pocket error
    pattern; the files are what a campaign starts with: backwall_sensor.csv,
    pocket.nc, plan.csv with the first pocket's semi-finish map, and
    zigzag_sensor.csv for the dead-band model.

    Example:

        postproc mirror synth shell_demo/
    """
    from postproc.mirror.synthetic import write_sample_set

    for path in write_sample_set(Path(directory), seed=seed):
        click.echo(f"wrote {path}")
