"""Effect detection by `postproc check`: how often each hidden effect is found, against
its size, and how often clean data get a false suggestion.

For each effect and size (visible RMS in units of the per-axis noise sigma: the part
of the displacement the static model cannot absorb) and each seed, synthetic tracker
data (70 points x 3 shots, varied tool vectors, approach directions, t, temp, load,
humidity) are ranked with 5-fold cross-validation. Reported: the fraction of seeds
where the hidden effect is the first suggestion, the mean cross-validated RMS after
the suggestions over the noise floor, and the time per check. Baseline in the same
run: the same data checked with no effect hidden (false suggestions per data set, and
the fraction of candidate p-values below each level: an honest test gives about the
level itself or less), and the time of the plain static fit.

Run:  python benchmarks/diagnose_detection.py [--seeds 10] [--sizes 1,2,3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from postproc.diagnose.crossval import make_folds
from postproc.diagnose.data import Dataset
from postproc.diagnose.models import Fixed, LinearStatic
from postproc.diagnose.noise import noise_floor
from postproc.diagnose.rank import rank_effects
from postproc.diagnose.synthetic import NEEDS_IDENTITY_BASE, SPECS, identity_machine, make_data
from postproc.effects import candidate_names
from postproc.engine.static import fit as static_fit


def check(meas, base):
    ds = Dataset.from_measurements([meas])
    model = LinearStatic() if base == "static" else Fixed(identity_machine(), "benchmark")
    folds = make_folds(ds.repeat_groups(), 5)
    rk = rank_effects(model, ds, [], candidate_names(ds.ctx), folds, max_selected=3)
    return rk, noise_floor(ds).rms_mm


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--sizes", default="1,2,3")
    args = ap.parse_args()
    sizes = [float(s) for s in args.sizes.split(",")]
    seeds = range(1000, 1000 + args.seeds)

    t0 = time.perf_counter()
    false_sugg, pvals = [], []
    for s in seeds:
        rk, _ = check(make_data([], seed=s)[0], "static")
        false_sugg.append(len(rk.selected))
        pvals += [c.p_value for c in rk.rounds[0]]
    t_clean = (time.perf_counter() - t0) / len(seeds)
    pvals = np.asarray(pvals)
    t0 = time.perf_counter()
    for s in seeds:
        static_fit([make_data([], seed=s)[0]])
    t_fit = (time.perf_counter() - t0) / len(seeds)
    print(f"baseline: clean data, {len(seeds)} seeds: false suggestions {sum(false_sugg)} "
          f"({np.mean(false_sugg):.2f} per data set); check {t_clean:.2f} s, static fit {t_fit * 1000:.1f} ms")
    print(f"null calibration: {len(pvals)} candidate tests on clean data, fraction of p below "
          + ", ".join(f"{a:g}: {np.mean(pvals < a):.4f}" for a in (0.05, 0.01, 0.001, 0.0001)))
    print(f"{'effect':18s}" + "".join(f"  size {z:g}: found  rms/floor" for z in sizes))
    for name in sorted(SPECS):
        base = "identity" if name in NEEDS_IDENTITY_BASE else "static"
        row = f"{name:18s}"
        for z in sizes:
            found, ratio = 0, []
            for s in seeds:
                rk, floor = check(make_data([(SPECS[name], z)], base=base, seed=s)[0], base)
                found += bool(rk.selected) and rk.selected[0].name == name
                ratio.append(rk.final_cv_rms_mm / floor)
            row += f"  {found / len(seeds):>11.0%}  {np.mean(ratio):9.3f}"
        print(row, flush=True)


if __name__ == "__main__":
    main()
