"""CPU time of ``correct`` (one process, ``-j 1``) for two source trees, run in pairs.

On a machine shared with other work the wall time and even the CPU time of one run
drift from minute to minute; a change is measured by running the two trees one after
the other, ``--repeats`` times, and comparing the medians (and the median of the
pairs' ratios). Each run is a child process that imports ``postproc`` from its tree
(``PYTHONPATH``), loads the calibration, and reports the process CPU time of
``correct_file`` alone (not the import, not the calibration). The outputs of the two
trees are compared byte for byte.

The program is made by ``../shared/bench/gencam.py N OUT SEED`` (as in
``throughput.py``).

Usage: python benchmarks/paired.py BASE_TREE [NEW_TREE] [--lines N] [--seed S]
                                   [--repeats R] [--cal static,parametric]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GENCAM = ROOT.parent / "shared" / "bench" / "gencam.py"

# The child: correct one program with the tree's own code and calibration file.
_CHILD = """
import json, sys, time
tree, program, cal_name, out = sys.argv[1:5]
import postproc
from postproc.calfile import load_calibration
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_file
if not postproc.__file__.startswith(tree):
    raise SystemExit(f"postproc imported from {postproc.__file__}, not {tree}")
cal = load_calibration(f"{tree}/calibrations/{cal_name}")
setup = Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={t: 0.0 for t in range(1, 21)},
              home={"G28": (0.0, 0.0, 200.0)})
t = time.process_time()
correct_file(program, out, cal.engine, setup, CorrectOptions(processes=1))
print(json.dumps({"cpu": time.process_time() - t}))
"""


def run_once(tree: Path, program: Path, cal: str, out: Path) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree))
    res = subprocess.run([sys.executable, "-c", _CHILD, str(tree), str(program), cal, str(out)],
                         env=env, cwd=tree, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        raise SystemExit(f"{tree}: {res.stderr.strip()}")
    return float(json.loads(res.stdout.strip().splitlines()[-1])["cpu"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("base", type=Path, help="the tree measured first in each pair")
    ap.add_argument("new", type=Path, nargs="?", default=ROOT, help="the other tree (default: this one)")
    ap.add_argument("--lines", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--cal", default="static,parametric", help="s500_<name>.json calibrations, comma-separated")
    args = ap.parse_args(argv)
    base, new = args.base.resolve(), args.new.resolve()
    with tempfile.TemporaryDirectory(prefix="postproc-paired-") as tmp:
        program = Path(tmp) / "program.ngc"
        subprocess.run([sys.executable, str(GENCAM), str(args.lines), str(program), str(args.seed)], check=True,
                       capture_output=True)
        print(f"base {base}\nnew  {new}\ngencam {args.lines:,} lines, seed {args.seed}, {args.repeats} pairs, -j 1")
        compare_trees(base, new, program, args.lines, args.cal.split(","), args.repeats)
    return 0


def compare_trees(base: Path, new: Path, program: Path, lines: int, cals: list[str], repeats: int) -> None:
    """Run ``correct`` on ``program`` (``lines`` lines) with each calibration
    ``s500_<name>.json``, ``repeats`` pairs of the two trees, and print each tree's median
    CPU time and rate, their ratio, the median of the pairs' ratios, the runs, and whether
    the outputs are identical (written beside ``program``)."""
    for name in cals:
        cal = f"s500_{name}.json"
        times: dict[str, list[float]] = {"base": [], "new": []}
        outs = {"base": program.parent / "base.nc", "new": program.parent / "new.nc"}
        for _ in range(repeats):
            times["base"].append(run_once(base, program, cal, outs["base"]))
            times["new"].append(run_once(new, program, cal, outs["new"]))
        same = filecmp.cmp(outs["base"], outs["new"], shallow=False)
        mb, mn = statistics.median(times["base"]), statistics.median(times["new"])
        ratio = statistics.median(b / n for b, n in zip(times["base"], times["new"], strict=True))
        print(f"{name:11s} base {mb:6.2f} s ({lines / mb:8,.0f} lines/s)  new {mn:6.2f} s "
              f"({lines / mn:8,.0f} lines/s)  base/new {mb / mn:.3f} (median of pairs {ratio:.3f})  "
              f"outputs {'identical' if same else 'DIFFER'}")
        print(f"{'':11s} base runs {' '.join(f'{t:.2f}' for t in times['base'])}; "
              f"new runs {' '.join(f'{t:.2f}' for t in times['new'])}")


if __name__ == "__main__":
    raise SystemExit(main())
