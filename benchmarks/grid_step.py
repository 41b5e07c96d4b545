"""Quasi-differential method: error after correction against the tracker grid step.

For each grid step the virtual machine is measured on a tracker lattice over its
volume (--shots per node, the machine's tracker noise), the grid calibration is fitted
(its warnings are flagged: "<10" step under 10 mm, "alias" step a multiple of the
declared lead-screw pitch), and targets are corrected and run through the noise-free
machine: the error left is the calibration's own. Two columns separate the causes:
a noise-free grid (interpolation and aliasing only) and the measured grid.

Targets: the seed's Table 1 control points (sum of Delta, as in the seed) and
--random random points inside the volume. Baseline in the same run: uncorrected and
static (six points).

Run:  python benchmarks/grid_step.py [--machine PATH|test] [--steps 5,10,15,20,30,45]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from table1 import load  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machine", default=str(ROOT / "calibrations" / "s500.machine.json"))
    ap.add_argument("--steps", default="5,10,15,20,30,45,12.5,16,22.5")
    ap.add_argument("--shots", type=int, default=12, help="tracker shots per node (seed: 12)")
    ap.add_argument("--screw-pitch", default="X=10;Y=10;Z=10",
                    help="declared lead-screw pitches (S500-like machine: 10 mm)")
    ap.add_argument("--random", type=int, default=5000)
    ap.add_argument("--grid-offset", type=float, default=0.0,
                    help="start the lattice this far (mm) from the low corner on every axis, which "
                         "moves the phase at which the nodes sample the lead-screw error")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    from postproc.engine import grid, static
    from postproc.simulate import grid_points, measurement_plan, simulate_plan, static_set
    from postproc.simulate.control import read_control_points

    machine, label = load(args.machine)
    vol = machine.volume_mm
    rng = np.random.default_rng(args.seed)
    ctx1 = {"dirx": 1.0, "diry": 1.0, "dirz": 1.0}

    def run(q):
        return machine.forward(q, None, {k: np.full(len(q), v) for k, v in ctx1.items()})

    steps = [float(s) for s in args.steps.split(",")]
    lo = vol[0] + args.grid_offset
    # Every lattice covers lo .. lo + step * floor(travel / step); targets are drawn in
    # the part all of them cover, so no grid is judged on extrapolation.
    hi = lo + np.min([s * np.floor((vol[1] - lo) / s + 1e-9) for s in steps], axis=0)
    table1 = read_control_points(ROOT / "samples" / "s500_control_points.csv").targets
    targets = rng.uniform(lo, hi, (args.random, 3))

    def errors(engine):
        out = []
        for p in (table1, targets):
            res = engine.inverse(p, None, ctx1)
            out.append(np.linalg.norm(run(res.q) - p, axis=1))
        return out

    base_t1 = np.linalg.norm(run(table1) - table1, axis=1)
    base_rnd = np.linalg.norm(run(targets) - targets, axis=1)
    six = simulate_plan(machine, measurement_plan(static_set(vol), repeats=12), rng)
    st_t1, st_rnd = errors(static.fit([six]).engine)

    print(f"machine: {label}; {args.shots} shots per node; lead-screw pitch declared {args.screw_pitch}")
    print(f"lattices from {lo.tolist()} mm; targets: seed Table 1 (10 points, sum of Delta) and "
          f"{args.random} random points in {lo.tolist()}..{hi.tolist()} mm (covered by every lattice)")
    print("error = |machine(inverse(p)) - p| without tracker noise")
    print()
    head = (f"{'step mm':>7}  {'nodes':>7}  {'flags':<9}  {'noise-free grid':^19}  "
            f"{'measured grid':^19}  {'Table 1':^17}  {'fit s':>5}")
    sub = (f"{'':7}  {'':7}  {'':9}  {'mean um':>9} {'max um':>9}  {'mean um':>9} {'max um':>9}  "
           f"{'sum mm':>7} {'impr.':>9}  {'':5}")
    print(head)
    print(sub)
    print(f"{'none':>7}  {'':7}  {'':9}  {base_rnd.mean() * 1000:9.1f} {base_rnd.max() * 1000:9.1f}  "
          f"{'':19}  {base_t1.sum():7.3f} {'':9}")
    print(f"{'static':>7}  {6:7d}  {'':9}  {'':19}  {st_rnd.mean() * 1000:9.1f} {st_rnd.max() * 1000:9.1f}  "
          f"{st_t1.sum():7.3f} {100 * (1 - st_t1.sum() / base_t1.sum()):7.1f} %")
    for step in steps:
        q = grid_points([lo, vol[1]], step)
        clean = simulate_plan(machine, measurement_plan(q), rng, noise=False)
        t0 = time.perf_counter()
        noisy = simulate_plan(machine, measurement_plan(q, repeats=args.shots), rng)
        fit_noisy = grid.fit([noisy], step=step, screw_pitch=[args.screw_pitch])
        fit_s = time.perf_counter() - t0
        fit_clean = grid.fit([clean], step=step)
        flags = []
        if any("under 10 mm" in line for line in fit_noisy.report):
            flags.append("<10")
        if any("lead-screw" in line for line in fit_noisy.report):
            flags.append("alias")
        _, c_rnd = errors(fit_clean.engine)
        n_t1, n_rnd = errors(fit_noisy.engine)
        nodes = int(np.prod(fit_noisy.engine.shape))
        print(f"{step:7g}  {nodes:7d}  {','.join(flags):<9}  {c_rnd.mean() * 1000:9.2f} {c_rnd.max() * 1000:9.2f}  "
              f"{n_rnd.mean() * 1000:9.2f} {n_rnd.max() * 1000:9.2f}  {n_t1.sum():7.3f} "
              f"{100 * (1 - n_t1.sum() / base_t1.sum()):7.1f} %  {fit_s:5.1f}")


if __name__ == "__main__":
    main()
