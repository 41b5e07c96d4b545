"""CPU time of ``sample_program`` on one program, this tree against another, alternating.

Each run is a child process of its tree (``PYTHONPATH``) that samples the program once
to warm up and then once timed (``time.process_time``: CPU time of the sampling
alone, the import and warm-up left out), with the benchmark setup (G54 at Z100, G28
home, tool lengths T1..T20: what ``gencam.py`` programs need):

    python benchmarks/path_speed.py --base OTHER_TREE [--step MM] [--chord MM] [--repeats 3] PROGRAM

Prints each run's time and the median of each tree.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
from postproc.gcode.path import Setup, sample_program
prog, kw = sys.argv[1], json.loads(sys.argv[2])
setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}},
              tool_lengths={t: 0.0 for t in range(1, 21)})
sample_program(prog, setup, **kw)
t0 = time.process_time()
pp = sample_program(prog, setup, **kw)
print(json.dumps({"cpu": time.process_time() - t0, "samples": len(pp)}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, type=Path, help="the other tree")
    ap.add_argument("--step", type=float, default=None, help="step_mm (default: none)")
    ap.add_argument("--chord", type=float, default=None, help="chord_mm (default: none)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("program")
    args = ap.parse_args()
    kw = {k: v for k, v in (("step_mm", args.step), ("chord_mm", args.chord)) if v is not None}
    times: dict[str, list[float]] = {"base": [], "this": []}
    for k in range(args.repeats):
        for name, tree in (("base", args.base), ("this", REPO)):
            env = dict(os.environ, PYTHONPATH=str(tree))
            res = subprocess.run([sys.executable, "-c", CHILD, args.program, json.dumps(kw)], capture_output=True,
                                 text=True, env=env, cwd=tree, check=True)
            got = json.loads(res.stdout)
            times[name].append(got["cpu"])
            print(f"run {k + 1} {name}: {got['cpu']:.3f} s CPU ({got['samples']:,} samples)", flush=True)
    b, t = statistics.median(times["base"]), statistics.median(times["this"])
    print(f"median of {args.repeats}: base {b:.3f} s, this {t:.3f} s ({b / t:.2f}x)")


if __name__ == "__main__":
    main()
