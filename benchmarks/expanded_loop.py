"""CPU time of ``correct`` on a program that must be expanded, for two source trees, in pairs.

The program is a LinuxCNC ``o100 while`` loop of ``--passes`` passes, each writing four
moves (G1, G1, G2, G0) whose words are parameter arithmetic: ``4 x passes`` lines once
expanded, plain after substitution. Each run is a child process of
:mod:`paired` (``compare_trees``, ``run_once``: the tree's own code and calibration, ``correct_file``
alone timed, ``-j 1``, G54 at Z100); the outputs of the two trees are compared byte
for byte.

Usage: python benchmarks/expanded_loop.py BASE_TREE [NEW_TREE] [--passes N] [--repeats R]
                                          [--cal static,parametric]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from paired import ROOT, compare_trees  # noqa: E402


def loop_program(passes: int) -> str:
    """The loop: a 100-pass row of slots, rows 0.5 mm apart (inside the S500 volume)."""
    return f"""G21 G17 G90 G94
G54
T1 M6
G43 H1
S12000 M3
G0 X0 Y0 Z5
G1 Z-1 F300
#1 = 0
#2 = 5
o100 while [#1 LT {passes}]
  #3 = [#1 MOD 100 * 0.5]
  #4 = [FIX[#1 / 100] * 0.4]
  G1 X[#3] Y[#4] F600
  G1 X[#3 + #2] Y[#4]
  G2 X[#3 + #2] Y[#4 + 2] I0 J1
  G0 X[#3] Y[#4 + 2]
  #1 = [#1 + 1]
o100 endwhile
G0 Z20
M5
M30
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("base", type=Path, help="the tree measured first in each pair")
    ap.add_argument("new", type=Path, nargs="?", default=ROOT, help="the other tree (default: this one)")
    ap.add_argument("--passes", type=int, default=20_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cal", default="static", help="s500_<name>.json calibrations, comma-separated")
    args = ap.parse_args(argv)
    base, new = args.base.resolve(), args.new.resolve()
    lines = 4 * args.passes
    with tempfile.TemporaryDirectory(prefix="postproc-loop-") as tmp:
        program = Path(tmp) / "loop.ngc"
        program.write_text(loop_program(args.passes))
        print(f"base {base}\nnew  {new}\nloop of {args.passes:,} passes ({lines:,} lines expanded), "
              f"{args.repeats} pairs, -j 1")
        compare_trees(base, new, program, lines, args.cal.split(","), args.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
