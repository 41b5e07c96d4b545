"""postproc iso230: ISO 230-2:2014 evaluation of bidirectional interferometer runs."""

from __future__ import annotations

import click


@click.command()
@click.argument("runs_file", metavar="RUNS", type=click.Path(exists=True, dir_okay=False))
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Write the mean deviation +- 2s per direction against position (PNG), "
                   "with A, E, R and B in the legend.")
@click.option("--json", "as_json", is_flag=True, help="Print the figures as one JSON object (mm).")
def iso230(runs_file, plot_path, as_json):
    """Evaluate bidirectional positioning runs as ISO 230-2:2014 does.

    RUNS is a formats.md runs file (axis,target,run,direction,deviation). Per target:
    the mean unidirectional deviations, the reversal value B_i, the estimators s_i
    and the repeatabilities R_i+, R_i-, R_i. Per axis: A, A+, A-, E, E+, E-, M, R,
    R+, R-, B and the mean reversal. The text report is in um, --json in mm.
    Warnings (stderr) say where the runs fall short of the standard: fewer than 5
    runs per direction, too few targets, evenly spaced targets, targets visited
    out of order.

    Example:

    \b
        postproc iso230 samples/iso230_runs_x.csv
        postproc iso230 samples/iso230_runs_x.csv --json --plot x_iso230.png
    """
    import json

    from postproc.metrology.iso230 import evaluate, format_results, results_json
    from postproc.metrology.runs import read_runs

    results = evaluate(read_runs(runs_file))
    if as_json:
        for r in results.values():
            for w in r.warnings:
                click.echo(f"warning: {w}", err=True)
        click.echo(json.dumps(results_json(results), indent=2))
    else:
        click.echo("\n".join(format_results(results)))
    if plot_path:
        import matplotlib

        matplotlib.use("Agg")
        from postproc.metrology.iso230 import plot_results

        plot_results(results, plot_path)
        click.echo(f"wrote {plot_path}", err=True)
