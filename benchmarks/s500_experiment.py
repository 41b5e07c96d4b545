"""Seed 000's experiments (Tables 1 and 5) repeated on the S500-like virtual machine.

Simulates the measurements (six-point static set and a 15 mm tracker grid, 12 shots
per point; interferometer tables every 2 mm), fits the static, interval,
quasi-differential (grid) and parametric calibrations from them, and runs the
seed's control points uncorrected and corrected with each, measured by a simulated
tracker (12 shots averaged). Prints both tables with the seed's own sums beside
them, and how long each step took.

    python benchmarks/s500_experiment.py [--out DIR] [--seed N] [--machine FILE]

With a machine that has time- or load-dependent effects (e.g.
calibrations/s500_warm.machine.json) the campaign is timed: the six points in the
first 10 minutes, the grid over the next 4 hours, the control points 6 hours after
the start, all without load and approaching every point moving +.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from postproc.calfile import load_calibration, save_calibration
from postproc.calibration.tables import write_tables
from postproc.engine.registry import fitter
from postproc.metrology.tables_fit import fit_tables
from postproc.simulate import grid_points, load_machine, measurement_plan, simulate_plan, static_set
from postproc.simulate.control import control_experiment, format_control_report, read_control_points
from postproc.simulate.tables import simulate_tables

REPO = Path(__file__).resolve().parents[1]
MACHINE = REPO / "calibrations" / "s500.machine.json"
TABLE1 = REPO / "samples" / "s500_control_points.csv"
TABLE5 = REPO / "samples" / "s500_control_points_table5.csv"
SEED_TABLE1 = {"uncorrected": 3.100, "static": 1.579, "interval": 1.177, "grid": 0.866}
SEED_TABLE5 = {"uncorrected": 2.098, "grid": 0.679, "parametric (KMTPP)": 0.208}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="keep the simulated files and calibrations here")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--machine", default=str(MACHINE), help="machine definition (default: the S500-like one)")
    args = ap.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="s500_"))
    out.mkdir(parents=True, exist_ok=True)
    machine = load_machine(args.machine)
    timed = {"t", "load"} & set(getattr(machine.model, "needs", []))

    def plan(points, start_s: float, span_s: float):
        if not timed:
            return measurement_plan(points, repeats=12)
        p = measurement_plan(points, repeats=12, time_span_s=span_s, context={"load": 0.0})
        p.context["t"] = p.context["t"] + start_s
        return p
    rng = np.random.default_rng(args.seed)
    clock = {}

    t0 = time.perf_counter()
    six = simulate_plan(machine, plan(static_set(machine.volume_mm), 0.0, 600.0), rng)
    grid = simulate_plan(machine, plan(grid_points(machine.volume_mm, 15.0), 600.0, 4 * 3600.0), rng)
    tables, squareness = simulate_tables(machine, 2.0, rng, context={"t": 0.0, "load": 0.0} if timed else None)
    write_tables(out / "tables.csv", out / "tables_squareness.csv", tables, squareness)
    clock["simulate (6 pts, 15 mm grid x 12 shots, 2 mm tables)"] = time.perf_counter() - t0

    cals = {}
    for name, method, data, opts in (("static", "static", six, {}),
                                     ("interval", "interval", grid, {}),
                                     ("grid", "grid", grid, {"step": "15"})):
        t0 = time.perf_counter()
        res = fitter(method)([data], **opts)
        save_calibration(out / f"{name}.json", res.engine, name=name, fit=res.info)
        cals[name] = load_calibration(out / f"{name}.json").engine
        clock[f"fit {name} ({len(data)} rows)"] = time.perf_counter() - t0
    for name, opts in (("parametric", {}), ("parametric (KMTPP)", {"solver": "astatic"})):
        t0 = time.perf_counter()
        res = fit_tables([str(out / "tables.csv")], **opts)
        save_calibration(out / f"{name.split()[0]}_{opts.get('solver', 'newton')}.json", res.engine, name=name)
        cals[name] = res.engine
        clock[f"fit {name}"] = time.perf_counter() - t0

    for title, path, names, seed_sums in (
        ("Table 1", TABLE1, ["static", "interval", "grid", "parametric"], SEED_TABLE1),
        ("Table 5", TABLE5, ["grid", "parametric", "parametric (KMTPP)"], SEED_TABLE5),
    ):
        t0 = time.perf_counter()
        targets = read_control_points(path).targets
        ctx = {"t": 6 * 3600.0, "load": 0.0} if timed else None
        rep = control_experiment(machine, targets, [(n, cals[n]) for n in names], context=ctx, rng=rng, shots=12)
        clock[f"control points, {title}"] = time.perf_counter() - t0
        print(f"\n{title} on machine {machine.name} (D in mm, tracker 12 shots averaged)")
        print(format_control_report(rep), end="")
        seed = ", ".join(f"{k} {v:.3f}" for k, v in seed_sums.items())
        print(f"seed 000 sums on the real S500: {seed}")
        for note in rep.notes:
            print(f"note: {note}")
    print(f"\nfiles in {out}")
    for k, v in clock.items():
        print(f"  {v:7.2f} s  {k}")


if __name__ == "__main__":
    main()
