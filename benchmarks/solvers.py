"""Inverse solvers of the parametric engine: iterations, residual, speed, in one run.

Machine: ``synthetic_tables(seed)`` (seed-000 magnitudes, 315 mm cube). Points:
random targets whose ideal command lies in the cube, a 100 mm vertical tool.
Baselines measured in the same run: the uncorrected error (command p - r) and the
speed of one forward evaluation. Also the seed's control points (Table 1) with
Sum|Delta| before and after each solver, as in seed 000, Table 5.

    python benchmarks/solvers.py [--points 10000] [--seed 0] [--order first|second|exact]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from postproc.engine.parametric import ParametricEngine
from postproc.simulate.s500 import SEED_CONTROL_POINTS_MM, synthetic_tables

TOOL = np.array([0.0, 0.0, -100.0])


def timed(fn, repeat=3):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--order", default="first", choices=["first", "second", "exact"])
    args = ap.parse_args()

    tables, sq = synthetic_tables(args.seed)
    engine = ParametricEngine(tables, sq, order=args.order)
    rng = np.random.default_rng(args.seed + 1)
    n = args.points
    p = rng.uniform(0, 315, (n, 3)) + TOOL
    r = np.tile(TOOL, (n, 1))

    _, t_fwd = timed(lambda: engine.forward(p - r, r))
    before = np.linalg.norm(engine.forward(p - r, r) - p, axis=1)
    print(f"machine: synthetic_tables({args.seed}), order {args.order}, {n} random targets, tool {TOOL.tolist()}")
    print(f"baseline: uncorrected |error| median {np.median(before) * 1000:.1f} um, max {before.max() * 1000:.1f} um; "
          f"forward model {n / t_fwd:,.0f} points/s")
    print(f"{'solver':>8} {'iter median':>11} {'iter max':>8} {'resid median':>14} {'resid max':>14} {'points/s':>12}")
    for solver in ("newton", "astatic"):
        res, t = timed(lambda s=solver: engine.inverse(p, r, solver=s))
        check = np.linalg.norm(engine.forward(res.q, r) - p, axis=1)
        assert np.allclose(check, res.residual_mm)
        print(f"{solver:>8} {np.median(res.iterations):11.0f} {res.iterations.max():8d} "
              f"{np.median(res.residual_mm) * 1000:11.3g} um {res.residual_mm.max() * 1000:11.3g} um "
              f"{n / t:12,.0f}")

    cp = np.array(SEED_CONTROL_POINTS_MM, dtype=float) + TOOL
    cr = np.tile(TOOL, (len(cp), 1))
    d_n = np.linalg.norm(engine.forward(cp - cr, cr) - cp, axis=1)
    print("\nseed 000 Table 1 control points (gauge point at the control point, tool 100 mm down):")
    print(f"{'x/y/z':>12} {'Delta_n':>9} {'newton':>9} {'astatic':>9}   (mm)")
    cols = {s: engine.inverse(cp, cr, solver=s).residual_mm for s in ("newton", "astatic")}
    for i, c in enumerate(SEED_CONTROL_POINTS_MM):
        print(f"{'/'.join(map(str, c)):>12} {d_n[i]:9.3f} {cols['newton'][i]:9.6f} {cols['astatic'][i]:9.4f}")
    print(f"{'Sum':>12} {d_n.sum():9.3f} {cols['newton'].sum():9.6f} {cols['astatic'].sum():9.4f}")
    for s in ("newton", "astatic"):
        print(f"{s}: Sum|Delta| {100 * (1 - cols[s].sum() / d_n.sum()):.1f} % below uncorrected")

    m = min(n, 2000)
    print(f"\nastatic settings (first {m} targets): residual median / max (um), iterations median")
    for u, K, dt in ((1.0, 1.5, 0.1), (2.0, 1.5, 0.1), (5.0, 1.5, 0.1), (10.0, 1.5, 0.1),
                     (2.0, 1.0, 0.1), (2.0, 3.0, 0.1), (2.0, 1.5, 0.5)):
        eng = engine.with_options(astatic={"grid_step_mm": u, "gain": K, "time_step": dt})
        res = eng.inverse(p[:m], r[:m], solver="astatic")
        print(f"  u={u:4g} mm K={K:3g} l={dt:3g}: {np.median(res.residual_mm) * 1000:7.2f} / "
              f"{res.residual_mm.max() * 1000:7.2f}   {np.median(res.iterations):4.0f}")


if __name__ == "__main__":
    main()
