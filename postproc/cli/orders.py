"""postproc orders: first against second order of the parametric model (seed 000, Tables 3-4)."""

from __future__ import annotations

import json

import click

from postproc.cli.options import FINITE_FLOAT, parse_vector


@click.command()
@click.option("-c", "--calibration", "calibration", required=True, type=click.Path(exists=True, dir_okay=False),
              help="A parametric calibration (from axis error tables or 'fit --method parametric').")
@click.option("--points", "points", type=click.Path(exists=True, dir_okay=False), default=None,
              help="CSV with X,Y,Z columns: commanded points (formats.md layout, '# units: length=mm|um').")
@click.option("--point", "point", multiple=True, metavar="X,Y,Z",
              help="A commanded point in mm (repeatable). Default: the six points of seed 000, Table 3.")
@click.option("--tool-vector", "tool_vector", default="0,0,-100", show_default=True, metavar="X,Y,Z",
              help="Tool vector r (mm) from the gauge point to the functional point.")
@click.option("-k", "k", type=FINITE_FLOAT, default=1000.0, show_default=True,
              help="Factor applied to every angular error for the second comparison (seed 000, Table 4).")
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON.")
def orders(calibration, points, point, tool_vector, k, as_json):
    """Compare the first- and second-order volumetric error at chosen points.

    For each commanded point: |delta| of the first-order model (formula 3), the
    second-order bounds |delta+| and |delta-| (formula 4 with the interval terms all
    + or all -), and their relative differences |delta+- - delta| / |delta| in %;
    then the same with the angular errors multiplied by K. When the differences stay
    around 1e-5 % the first order is enough (seed 000, Table 3); when they reach
    percents (Table 4, k = 1000) the second order matters.

    Example:

        postproc orders -c s500_tables.json --point 60,50,50 --point 200,200,140 -k 1000
    """
    import numpy as np

    from postproc.calfile import load_calibration
    from postproc.engine.parametric import ParametricEngine
    from postproc.engine.parametric_orders import SEED_ORDER_POINTS_MM, compare_orders
    from postproc.errors import CalibrationError

    cal = load_calibration(calibration)
    engine = cal.engine
    while not isinstance(engine, ParametricEngine) and hasattr(engine, "base"):
        engine = engine.base
    if not isinstance(engine, ParametricEngine):
        raise CalibrationError(
            f"{cal.method!r} calibration: orders compares the orders of the parametric model",
            path=calibration, hint="make a parametric calibration: postproc fit TABLES.csv -o CAL",
        )
    if points is not None and point:
        raise click.UsageError("give --points or --point, not both")
    if points is not None:
        from postproc.simulate.control import read_control_points

        q = read_control_points(points).targets
    elif point:
        q = np.array([parse_vector(p, "--point") for p in point])
    else:
        q = np.array(SEED_ORDER_POINTS_MM, dtype=float)
    r = np.array(parse_vector(tool_vector, "--tool-vector"))
    outside = ~engine.inside(q)
    real = compare_orders(engine, q, r, 1.0)
    scaled = compare_orders(engine, q, r, k)
    if as_json:
        out = {
            "calibration": cal.name,
            "tool_vector_mm": r.tolist(),
            "k": k,
            "points": [
                {"q_mm": qi.tolist(), "outside_volume": bool(o), "measured": a, "scaled": b}
                for qi, o, a, b in zip(q, outside, real.rows(), scaled.rows(), strict=True)
            ],
        }
        click.echo(json.dumps(out, indent=2))
        return
    click.echo(f"calibration {cal.name}; tool vector r = {r[0]:g},{r[1]:g},{r[2]:g} mm")
    for comp in (real, scaled):
        click.echo("")
        click.echo(f"k = {comp.k:g}" + (" (measured angular errors)" if comp.k == 1 else
                                        " (angular errors multiplied by k)"))
        click.echo(f"{'X/Y/Z (mm)':>22}  {'delta+ um':>14}  {'delta- um':>14}  {'delta um':>14}"
                   f"  {'delta+/delta %':>14}  {'delta-/delta %':>14}")
        for i, row in enumerate(comp.rows()):
            label = "/".join(f"{v:g}" for v in q[i]) + ("*" if outside[i] else "")
            click.echo(f"{label:>22}  {row['delta_plus_um']:14.6f}  {row['delta_minus_um']:14.6f}  "
                       f"{row['delta_um']:14.6f}  {row['rel_plus_pct']:14.3g}  {row['rel_minus_pct']:14.3g}")
    if outside.any():
        click.echo("* outside the calibrated volume: the error functions are held at their end values",
                   err=True)
