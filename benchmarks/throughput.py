"""Throughput and peak memory of reading/writing, tokenizing and correcting a big program.

Makes a program of N lines (default 1,000,000: straight moves with some feed changes
and small arcs, as CAM output looks), then runs each case in its own child process
(median of --repeats runs) and prints lines/s and the child's peak RSS:

  (a) read and write the file unchanged (the floor: Python line I/O);
  (b) our tokenizer: lex every line and write tokens_to_src (byte-identical);
  (b') the fast line scanner that the interpreter uses on plain lines;
  (c) ``postproc correct`` with a static calibration, end to end.

Usage: python benchmarks/throughput.py [--lines N] [--repeats R] [--calibration FILE]
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys, time
case, src, dst, cal = sys.argv[1:5]
t0 = time.perf_counter()
if case == "copy":
    with open(src, encoding="utf-8", newline="") as fi, open(dst, "w", encoding="utf-8", newline="") as fo:
        for line in fi:
            fo.write(line)
elif case == "lex":
    from postproc.gcode.lexer import lex, tokens_to_src
    with open(src, encoding="utf-8", newline="") as fi, open(dst, "w", encoding="utf-8", newline="") as fo:
        for line in fi:
            fo.write(tokens_to_src(lex(line)))
elif case == "scan":
    from postproc.gcode.lexer import lex, scan_words
    with open(src, encoding="utf-8", newline="") as fi, open(dst, "w", encoding="utf-8", newline="") as fo:
        for line in fi:
            if scan_words(line) is None:
                lex(line)
            fo.write(line)
elif case == "correct":
    from postproc.cli import main
    code = main(["correct", src, "-c", cal, "-o", dst], standalone_mode=False)
    if code:
        sys.exit(f"postproc correct failed with exit code {code}")
dt = time.perf_counter() - t0
ru = resource.getrusage(resource.RUSAGE_SELF)
print(json.dumps({"seconds": dt, "cpu_seconds": ru.ru_utime + ru.ru_stime, "peak_mb": ru.ru_maxrss / 1024.0}))
"""


def make_program(path: Path, n: int, seed: int = 0) -> None:
    rng = random.Random(seed)
    x, y = 150.0, 150.0
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write("%\n(throughput benchmark program)\nG21 G90 G17 G94\nG0 Z80.0\nG0 X150.0 Y150.0\nG1 Z60.0 F500\n")
        written = 6
        after_arc = False
        while written < n - 2:
            r = rng.random()
            if r < 0.01:  # a small arc (radius 2 mm), ending where it starts a quarter further
                cx, cy = x - 2.0, y
                fh.write(f"G3 X{cx:.4f} Y{cy + 2.0:.4f} I-2.0 J0.0\n")
                x, y = cx, cy + 2.0
                after_arc = True
            elif r < 0.05:
                fh.write(f"G1 X{x:.4f} Y{y:.4f} Z{rng.uniform(55, 65):.4f} F{rng.choice([600, 800, 1200])}\n")
                after_arc = False
            else:
                x = min(max(x + rng.uniform(-1.5, 1.5), 20.0), 290.0)
                y = min(max(y + rng.uniform(-1.5, 1.5), 20.0), 290.0)
                plain = rng.random() < 0.5 and not after_arc
                fh.write(f"X{x:.4f} Y{y:.4f}\n" if plain else f"G1 X{x:.4f} Y{y:.4f}\n")
                after_arc = False
            written += 1
        fh.write("G0 Z80.0\nM30\n%\n")


def run_case(case: str, src: Path, dst: Path, cal: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, case, str(src), str(dst), cal],
                         capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--calibration", default=str(ROOT / "calibrations" / "s500_static.json"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "big.nc"
        t0 = time.perf_counter()
        make_program(src, args.lines)
        n = sum(1 for _ in open(src, encoding="utf-8", newline=""))
        print(f"program: {n:,} lines, {src.stat().st_size / 1e6:.1f} MB (made in {time.perf_counter() - t0:.1f} s)")
        print(f"calibration: {args.calibration}")
        results = {}
        for case, label in (("copy", "(a) read+write unchanged"), ("lex", "(b) tokenizer pass-through"),
                            ("scan", "(b') fast scanner pass-through"), ("correct", "(c) postproc correct")):
            runs = [run_case(case, src, Path(tmp) / f"out_{case}.nc", args.calibration)
                    for _ in range(args.repeats)]
            secs = statistics.median(r["seconds"] for r in runs)
            cpu = statistics.median(r["cpu_seconds"] for r in runs)
            peak = max(r["peak_mb"] for r in runs)
            results[case] = n / secs
            print(f"{label:34s} {n / secs:12,.0f} lines/s   peak RSS {peak:7.1f} MB   "
                  f"(median of {args.repeats}: {secs:.2f} s wall, {cpu:.2f} s CPU)")
        print(f"ratio (c)/(b)  = {results['correct'] / results['lex']:.2f}   (target >= 0.3)")
        print(f"ratio (c)/(b') = {results['correct'] / results['scan']:.2f}")
        print(f"ratio (c)/(a)  = {results['correct'] / results['copy']:.3f}")


if __name__ == "__main__":
    main()
