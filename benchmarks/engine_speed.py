"""Speed of the parametric engine's inverse and forward model: the one-interpolant-per-axis
evaluation (tests/parametric_reference.py, what the engine did before the stacked
evaluation) against the engine, per point, by call size.

For each call size (1, 10, 100, 1k, 10k, 100k points) a batch of calls on random targets
inside the calibrated volume (tool vectors of up to 150 mm) is timed with the reference
and with the engine, alternately, ``--repeats`` times; the table gives the median CPU
time per point of each and their ratio. The two answers are checked to be bit-identical
on the way. ``mix`` replays the call sizes `postproc correct` asks on a CAM program
(gencam 100k: about 760 calls of 14..700 points and 250 of 1k..7k points).

    python benchmarks/engine_speed.py [-c CAL] [--repeats 7] [--options order=second,...]

The whole command, before/after (run from each checkout's root, paired)::

    python ../shared/bench/gencam.py 100000 /tmp/g100k.nc 1
    python -c "from postproc.cli import main; main()" correct /tmp/g100k.nc \\
        -c calibrations/s500_parametric.json --offset G54=X0,Y0,Z100 --home G28=X0,Y0,Z200 \\
        --tool-length 1=0 ... --tool-length 20=0 -o /tmp/out.nc

(`--command OLD_CHECKOUT` runs that command here and in OLD_CHECKOUT alternately and
prints the CPU times of the child processes.)
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from parametric_reference import ReferenceParametric  # noqa: E402

from postproc.calibration.calfile import load_calibration  # noqa: E402
from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM  # noqa: E402

SIZES = (1, 10, 100, 1000, 10_000, 100_000)
# (calls, low, high): call sizes log-uniform in [low, high], as `correct` asks them
MIX = ((760, 14, 700), (250, 1000, 7000))


def mix_sizes(rng: np.random.Generator) -> list[int]:
    out: list[int] = []
    for calls, lo, hi in MIX:
        out += np.exp(rng.uniform(np.log(lo), np.log(hi), calls)).astype(int).tolist()
    return out


def batches(engine, sizes: list[int], rng: np.random.Generator):
    lo, hi = engine.volume_mm
    out = []
    for n in sizes:
        p = rng.uniform(lo + 5, hi - 5, (n, 3))
        r = np.zeros((n, 3))
        r[:, 2] = -rng.uniform(0, 150, n)
        r[:, :2] = rng.uniform(-20, 20, (n, 2))
        q = p - r
        out.append((p, r, q))
    return out


def cpu() -> float:
    return time.process_time()


def time_pair(engine, ref, work, kind: str, repeats: int) -> tuple[float, float]:
    def run_new():
        for p, r, q in work:
            if kind == "inverse":
                engine.inverse(p, r)
            else:
                engine.forward(q, r)

    def run_ref():
        for p, r, q in work:
            if kind == "inverse":
                ref.inverse(p, r, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
            else:
                ref.forward(q, r)

    t_new, t_ref = [], []
    for _ in range(repeats):
        for fn, acc in ((run_ref, t_ref), (run_new, t_new)):
            t0 = cpu()
            fn()
            acc.append(cpu() - t0)
    return statistics.median(t_ref), statistics.median(t_new)


def check_same(engine, ref, work) -> None:
    for p, r, q in work[:3]:
        a = engine.inverse(p, r)
        b = ref.inverse(p, r, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
        assert np.array_equal(a.q, b.q)
        assert np.array_equal(a.residual_mm, b.residual_mm)
        assert np.array_equal(engine.forward(q, r), ref.forward(q, r))


def engine_table(engine, repeats: int) -> None:
    ref = ReferenceParametric(engine)
    rng = np.random.default_rng(0)
    print(f"{'call size':>10} {'kind':>8} {'ref us/pt':>10} {'new us/pt':>10} {'ratio':>7}")
    rows = [(str(n), [n] * max(1, 20_000 // n)) for n in SIZES] + [("mix", mix_sizes(rng))]
    for label, sizes in rows:
        work = batches(engine, sizes, rng)
        check_same(engine, ref, work)
        points = sum(sizes)
        for kind in ("inverse", "forward"):
            reps = repeats if points * len(SIZES) < 2_000_000 else max(3, repeats // 2)
            t_ref, t_new = time_pair(engine, ref, work, kind, reps)
            print(f"{label:>10} {kind:>8} {t_ref / points * 1e6:10.3f} {t_new / points * 1e6:10.3f} "
                  f"{t_ref / t_new:7.2f}", flush=True)


def command(checkout: Path, program: str, out: str) -> list[str]:
    args = [sys.executable, "-c", "from postproc.cli import main; main()", "correct", program,
            "-c", str(checkout / "calibrations/s500_parametric.json"),
            "--offset", "G54=X0,Y0,Z100", "--home", "G28=X0,Y0,Z200", "-o", out]
    for t in range(1, 21):
        args += ["--tool-length", f"{t}=0"]
    return args


def child_cpu(args: list[str], cwd: Path) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = dict(os.environ, PYTHONPATH=str(cwd))
    subprocess.run(args, cwd=cwd, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def command_table(old: Path, program: str, repeats: int) -> None:
    t_old, t_new = [], []
    for i in range(repeats):
        for checkout, acc in ((old, t_old), (REPO, t_new)):
            acc.append(child_cpu(command(checkout, program, f"/tmp/engine_speed_{id(acc)}.nc"), checkout))
        print(f"run {i + 1}: old {t_old[-1]:.2f} s, new {t_new[-1]:.2f} s CPU", flush=True)
    a, b = statistics.median(t_old), statistics.median(t_new)
    print(f"correct CPU median: old {a:.2f} s, new {b:.2f} s, saved {a - b:.2f} s ({a / b:.2f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-c", "--calibration", default=str(REPO / "calibrations/s500_parametric.json"))
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--options", default="", help="engine options, e.g. order=second,extrapolate=linear")
    ap.add_argument("--command", metavar="OLD_CHECKOUT", help="time `correct` here against this checkout")
    ap.add_argument("--program", default="/tmp/g100k.nc")
    args = ap.parse_args()
    if args.command:
        command_table(Path(args.command).resolve(), args.program, args.repeats)
        return
    engine = load_calibration(args.calibration).engine
    if args.options:
        engine = engine.with_options(**dict(kv.split("=", 1) for kv in args.options.split(",")))
    print(f"engine: order {engine.order}, {engine.interpolation}, extrapolate {engine.extrapolate}")
    engine_table(engine, args.repeats)


if __name__ == "__main__":
    main()
