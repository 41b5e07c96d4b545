"""postproc iso230: ISO 230-2:2014 evaluation of bidirectional interferometer runs."""

from __future__ import annotations

import click

from postproc.cli.options import FiniteFloat
from postproc.metrology.iso230_env import UncertaintyInputs


@click.command()
@click.argument("runs_file", metavar="RUNS", type=click.Path(exists=True, dir_okay=False))
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Write the ISO 230-2 plot as CARTO and XCal-View draw it (PNG): mean deviation +- 2s per "
                   "target and direction, the mean bidirectional line, A, E, R and B annotated.")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as one JSON object (mm).")
@click.option("--alpha", "alpha", type=FiniteFloat(min=0), default=UncertaintyInputs.alpha_um_per_m_k,
              show_default=True, metavar="UM_PER_M_K",
              help="Expansion coefficient of the machine's scale: the normal-temperature correction and the "
                   "uncertainty budget.")
@click.option("--alpha-u", "alpha_u", type=FiniteFloat(min=0), default=UncertaintyInputs.alpha_u_um_per_m_k,
              show_default=True, metavar="UM_PER_M_K", help="Half-width of the expansion coefficient's uncertainty.")
@click.option("--laser-u", "laser_u", type=FiniteFloat(min=0), default=UncertaintyInputs.laser_u_um_per_m,
              show_default=True, metavar="UM_PER_M",
              help="Expanded (k = 2) uncertainty of the interferometer per metre of travel.")
@click.option("--temp-u", "temp_u", type=FiniteFloat(min=0), default=UncertaintyInputs.temp_u_k, show_default=True,
              metavar="K", help="Expanded (k = 2) uncertainty of the machine temperature reading (material_temp).")
@click.option("--no-temperature-correction", "no_temp_correction", is_flag=True,
              help="Do not correct the deviations to 20 C with material_temp (the report says so).")
def iso230(runs_file, plot_path, as_json, alpha, alpha_u, laser_u, temp_u, no_temp_correction):
    """Evaluate bidirectional positioning runs as ISO 230-2:2014 does.

    RUNS is a formats.md runs file (axis,target,run,direction,deviation). Per target:
    the mean unidirectional deviations, the reversal value B_i, the estimators s_i
    and the repeatabilities R_i+, R_i-, R_i. Per axis: A, A+, A-, E, E+, E-, M, R,
    R+, R-, B and the mean reversal; runs in one direction only get that direction's
    A, E and R. The text report is in um, --json in mm. Every reading counts, as the
    standard asks; readings beyond the outlier rule that check and fit use are listed
    as suspicious. The report gives the temperatures (ISO 230-2 4.2: temp, the air;
    material_temp, the machine, which corrects the deviations to 20 C unless
    --no-temperature-correction), or says that the file has none, and the expanded
    uncertainty of each figure (ISO/TR 230-9, k = 2) with its budget.
    Warnings (stderr) say where the runs fall short of the standard: fewer than 5
    runs per direction, too few targets, evenly spaced targets, targets visited
    out of order (checked when the file gives the time t).

    Example:

    \b
        postproc iso230 samples/iso230_runs_x.csv
        postproc iso230 samples/iso230_runs_x.csv --json --plot x_iso230.png
    """
    import json

    from postproc.metrology.iso230 import evaluate, format_results, results_json
    from postproc.metrology.runs import read_runs

    inputs = UncertaintyInputs(alpha, alpha_u, laser_u, temp_u)
    results = evaluate(read_runs(runs_file), inputs=inputs, correct_temperature=not no_temp_correction)
    if as_json:
        for r in results.values():
            for w in r.warnings:
                click.echo(f"warning: {w}", err=True)
            for o in r.suspicious:
                click.echo(f"suspicious (kept): {o.describe()}", err=True)
        click.echo(json.dumps(results_json(results), indent=2))
    else:
        click.echo("\n".join(format_results(results, inputs)))
    if plot_path:
        import matplotlib

        matplotlib.use("Agg")
        from postproc.metrology.iso230 import plot_results

        plot_results(results, plot_path)
        click.echo(f"wrote {plot_path}", err=True)
