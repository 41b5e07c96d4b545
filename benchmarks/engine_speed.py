"""Speed of the parametric engine's inverse and forward model: the one-interpolant-per-axis
evaluation (tests/parametric_reference.py, what the engine did before the stacked
evaluation) against the engine, per point, by call size.

For each call size (1, 10, 100, 1k, 10k, 100k points) a batch of calls (500 calls, or
20k points, or one call) on random targets inside the calibrated volume, tool vectors up
to 150 mm long, is timed after one untimed call, in a fresh process per implementation
and repeat
(so that neither inherits the other's heap), the two alternating; the table gives the
median CPU time (user + system) per point of each and their ratio. ``mix`` replays the
call sizes `postproc correct` asks on a CAM program, a twentieth of them (gencam 100k
asks about 760 calls of 14..700 points and 250 calls of 1k..7k points). The answers
are checked bit-identical first.

    python benchmarks/engine_speed.py [-c CAL] [--repeats 5] [--options order=second,...]

The whole command, before/after (paired runs, CPU time of the child processes)::

    python ../shared/bench/gencam.py 100000 /tmp/g100k.nc 1
    python benchmarks/engine_speed.py --command OLD_CHECKOUT [--program /tmp/g100k.nc]

runs, alternately in OLD_CHECKOUT and here,

    python -c "from postproc.cli import main; main()" correct /tmp/g100k.nc \\
        -c calibrations/s500_parametric.json --offset G54=X0,Y0,Z100 --home G28=X0,Y0,Z200 \\
        --tool-length 1=0 ... --tool-length 20=0 -o OUT
"""

from __future__ import annotations

import argparse
import json
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

from postproc.calfile import load_calibration  # noqa: E402
from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM  # noqa: E402

SIZES = (1, 10, 100, 1000, 10_000, 100_000)
# (calls, low, high): call sizes log-uniform in [low, high], as `correct` asks them
MIX = ((38, 14, 700), (12, 1000, 7000))


def mix_sizes(rng: np.random.Generator) -> list[int]:
    out: list[int] = []
    for calls, lo, hi in MIX:
        out += np.exp(rng.uniform(np.log(lo), np.log(hi), calls)).astype(int).tolist()
    return out


def rows_of_work(engine) -> list[tuple[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]]:
    """(label, [(targets p, tool vectors r, commands q)] per call), the same in every process."""
    rng = np.random.default_rng(0)
    lo, hi = engine.volume_mm
    table = [(str(n), [n] * max(1, min(500, 20_000 // n))) for n in SIZES] + [("mix", mix_sizes(rng))]
    out = []
    for label, sizes in table:
        work = []
        for n in sizes:
            p = rng.uniform(lo + 5, hi - 5, (n, 3))
            r = np.zeros((n, 3))
            r[:, 2] = -rng.uniform(0, 150, n)
            r[:, :2] = rng.uniform(-20, 20, (n, 2))
            work.append((p, r, p - r))
        out.append((label, work))
    return out


def load_engine(args):
    engine = load_calibration(args.calibration).engine
    if args.options:
        engine = engine.with_options(**dict(kv.split("=", 1) for kv in args.options.split(",")))
    return engine


def worker(args) -> None:
    """Time one implementation over all rows; print {label: {kind: s per point}} as JSON."""
    engine = load_engine(args)
    ref = ReferenceParametric(engine)
    if args.worker == "ref":
        def inverse(p, r):
            return ref.inverse(p, r, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
        forward = ref.forward
    else:
        inverse, forward = engine.inverse, engine.forward
    result: dict[str, dict[str, float]] = {}
    for label, work in rows_of_work(engine):
        points = sum(len(p) for p, _, _ in work)
        result[label] = {}
        for kind in ("inverse", "forward"):
            p, r, q = work[0]
            inverse(p, r) if kind == "inverse" else forward(q, r)  # warm-up
            t0 = time.process_time()
            for p, r, q in work:
                if kind == "inverse":
                    inverse(p, r)
                else:
                    forward(q, r)
            result[label][kind] = (time.process_time() - t0) / points
    print(json.dumps(result))


def check_same(engine) -> None:
    ref = ReferenceParametric(engine)
    for _, work in rows_of_work(engine):
        for p, r, q in work[:2]:
            a = engine.inverse(p, r)
            b = ref.inverse(p, r, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
            assert np.array_equal(a.q, b.q)
            assert np.array_equal(a.residual_mm, b.residual_mm)
            assert np.array_equal(engine.forward(q, r), ref.forward(q, r))


def engine_table(args) -> None:
    engine = load_engine(args)
    print(f"engine: order {engine.order}, {engine.interpolation}, extrapolate {engine.extrapolate}")
    check_same(engine)
    print("answers bit-identical on the first calls of every row")
    runs: dict[str, list[dict]] = {"ref": [], "new": []}
    base = [sys.executable, __file__, "-c", args.calibration, "--options", args.options]
    for i in range(args.repeats):
        for impl in (("ref", "new") if i % 2 == 0 else ("new", "ref")):
            out = subprocess.run(base + ["--worker", impl], check=True, capture_output=True, text=True).stdout
            runs[impl].append(json.loads(out))
        print(f"repeat {i + 1} of {args.repeats} done", file=sys.stderr, flush=True)
    print(f"{'call size':>10} {'kind':>8} {'ref us/pt':>10} {'new us/pt':>10} {'ratio':>7}   (medians of {args.repeats})")
    for label in runs["ref"][0]:
        for kind in ("inverse", "forward"):
            a = statistics.median(r[label][kind] for r in runs["ref"])
            b = statistics.median(r[label][kind] for r in runs["new"])
            print(f"{label:>10} {kind:>8} {a * 1e6:10.3f} {b * 1e6:10.3f} {a / b:7.2f}")


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
    times: dict[str, list[float]] = {"old": [], "new": []}
    outs = {"old": "/tmp/engine_speed_old.nc", "new": "/tmp/engine_speed_new.nc"}
    checkouts = {"old": old, "new": REPO}
    for i in range(repeats):
        for side in (("old", "new") if i % 2 == 0 else ("new", "old")):
            times[side].append(child_cpu(command(checkouts[side], program, outs[side]), checkouts[side]))
        same = Path(outs["old"]).read_bytes() == Path(outs["new"]).read_bytes()
        print(f"run {i + 1}: old {times['old'][-1]:.2f} s, new {times['new'][-1]:.2f} s CPU, "
              f"outputs {'identical' if same else 'DIFFER'}", flush=True)
    a, b = statistics.median(times["old"]), statistics.median(times["new"])
    print(f"correct CPU median of {repeats}: old {a:.2f} s, new {b:.2f} s, saved {a - b:.2f} s ({a / b:.2f}x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-c", "--calibration", default=str(REPO / "calibrations/s500_parametric.json"))
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--options", default="", help="engine options, e.g. order=second,extrapolate=linear")
    ap.add_argument("--command", metavar="OLD_CHECKOUT", help="time `correct` here against this checkout")
    ap.add_argument("--program", default="/tmp/g100k.nc")
    ap.add_argument("--worker", choices=("ref", "new"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args)
    elif args.command:
        command_table(Path(args.command).resolve(), args.program, args.repeats)
    else:
        engine_table(args)


if __name__ == "__main__":
    main()
