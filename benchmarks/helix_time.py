"""CPU time of `postproc correct` on a helix of many turns, per checkout.

A helix G2 of radius 20 mm descending about 1 mm a turn (``helix_program``), placed at
G54 X150 Y150 Z150 in the volume of calibrations/s500_parametric.json, along which the
correction varies: the fit cuts it into about eight exact arcs a turn
(:class:`postproc.gcode.arcfit.MoveFit`). For each checkout given (a folder holding a
``postproc`` package) and each number of turns, `python -m postproc correct ... -j 1` is
run --repeats times in a child process with PYTHONPATH set to the checkout, and the
median of the child's CPU seconds (user + system) is printed with the sha256 of the
output (equal sums: the checkouts write the same bytes).

Usage: python benchmarks/helix_time.py CHECKOUT [CHECKOUT ...] [--turns 10 20 40 80]
                                       [--repeats 3] [--json OUT]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CALIBRATION = ROOT / "calibrations" / "s500_parametric.json"
OFFSET = "G54=X150,Y150,Z150"


def helix_program(turns: int) -> str:
    """A helix of ``turns`` full turns (P word) about X0 Y0, radius 20 mm, from Z-1 to Z-turns."""
    return (f"G21 G90 G17\nG0 X20 Y0 Z0\nG1 Z-1 F500\n"
            f"G2 X20 Y0 I-20 J0 Z-{turns} P{turns} F500\nM2\n")


def imported_from(checkout: Path, cwd: Path) -> str:
    """Where a child process with PYTHONPATH set to ``checkout`` imports postproc from."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    cmd = [sys.executable, "-P", "-c", "import postproc; print(postproc.__file__)"]
    return subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def correct_cpu(checkout: Path, src: Path, out: Path) -> float:
    """CPU seconds (user + system) of one `postproc correct` of ``src`` in a child process
    (run in the folder of ``src``, without the current folder on its path: the package
    imported is the checkout's)."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    cmd = [sys.executable, "-P", "-m", "postproc", "correct", str(src), "-c", str(CALIBRATION),
           "--offset", OFFSET, "-j", "1", "-o", str(out)]
    proc = subprocess.Popen(cmd, env=env, cwd=src.parent, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _pid, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode() if proc.stderr is not None else ""
    if proc.stderr is not None:
        proc.stderr.close()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{checkout}: correct failed on {src.name}:\n{err}")
    return usage.ru_utime + usage.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkouts", nargs="+", type=Path)
    ap.add_argument("--turns", nargs="+", type=int, default=[10, 20, 40, 80])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for checkout in args.checkouts:
            print(f"{checkout}: postproc from {imported_from(checkout.resolve(), Path(tmp))}", flush=True)
        for turns in args.turns:
            src = Path(tmp) / f"helix{turns}.ngc"
            src.write_text(helix_program(turns))
            for checkout in args.checkouts:
                out = Path(tmp) / f"out{turns}.ngc"
                times = [correct_cpu(checkout.resolve(), src, out) for _ in range(args.repeats)]
                digest = hashlib.sha256(out.read_bytes()).hexdigest()
                row = {"checkout": str(checkout), "turns": turns, "cpu_s": statistics.median(times),
                       "times": times, "sha256": digest}
                rows.append(row)
                print(f"{turns:4d} turns  {statistics.median(times):8.2f} s CPU (median of {args.repeats})"
                      f"  sha256 {digest[:16]}  {checkout}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
