"""Speed of `correct` on the real programs of the corpus, slowest first.

Corrects each program of ../shared/corpus with at least --min-lines lines (real/,
linuxcnc/, pygcode-linuxcnc/) with a calibration, in the dialect of its source, the
program placed in the calibrated volume (every work offset at X150 Y150 Z150, every tool
length 0, the start and the G28/G30 positions 150 mm above, points outside the volume
extrapolated linearly), and prints per program: lines, the median wall time of
--repeats runs in this process, lines per second, and what the output holds (arcs kept,
split into several arcs, linearised; R-form arcs in the input), slowest first. A program
the corrector refuses is listed with the reason. ``--json OUT`` saves the rows.

The gencam benchmark (benchmarks/throughput.py) measures a synthetic CAM program; this
one shows which real programs are slow and why: arcs that one exact arc cannot follow
(fitted piece by piece) and R-form arcs (fitted one by one by the general planner) cost
far more than plain moves and centre-word arcs, which are planned and written in bulk.

Usage: python benchmarks/corpus_speed.py [--calibration FILE] [--min-lines N]
                                         [--only SUBSTRING] [--repeats R] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from corpus_survey import DIALECT_BY_SOURCE, EXTS  # noqa: E402

from postproc.calfile import load_calibration  # noqa: E402
from postproc.errors import PostprocError  # noqa: E402
from postproc.gcode.path import Setup  # noqa: E402
from postproc.gcode.pipeline import CorrectOptions, correct_file  # noqa: E402

CORPUS = ROOT.parent / "shared" / "corpus"
OFFSETS = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
CENTRE = {"X": 150.0, "Y": 150.0, "Z": 150.0}
ABOVE = {"X": 150.0, "Y": 150.0, "Z": 300.0}
_R_ARC = re.compile(r"[Rr][ \t]*[+-]?(?:\d|\.\d)")


def setup() -> Setup:
    return Setup(offsets={n: dict(CENTRE) for n in OFFSETS}, tool_lengths={t: 0.0 for t in range(100)},
                 start=dict(ABOVE), home={"G28": dict(ABOVE), "G30": dict(ABOVE)})


def programs(min_lines: int, only: str) -> list[tuple[Path, int]]:
    out = []
    for p in sorted(CORPUS.rglob("*")):
        if not p.is_file() or p.suffix.lower() not in EXTS or only not in str(p):
            continue
        with open(p, "rb") as fh:
            n = sum(1 for _ in fh)
        if n >= min_lines:
            out.append((p, n))
    return out


def dialect_of(path: Path) -> str:
    """The dialect of a corpus program's source (real/SOURCE/..., or the set's folder)."""
    parts = path.relative_to(CORPUS).parts
    return DIALECT_BY_SOURCE.get(parts[1] if parts[0] == "real" else parts[0], "generic")


def run(path: Path, lines: int, engine, repeats: int) -> dict:
    opts = CorrectOptions(extrapolate="linear", dialect=dialect_of(path))
    row: dict = {"program": str(path.relative_to(CORPUS)), "lines": lines}
    text = path.read_text(encoding="utf-8", errors="replace")
    row["r_arcs"] = sum(1 for line in text.splitlines() if _R_ARC.search(line.split("(")[0].split(";")[0]))
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            t0 = time.perf_counter()
            try:
                rep = correct_file(path, Path(tmp) / "out.nc", engine, setup(), opts)
            except PostprocError as exc:
                row["refused"] = str(exc).splitlines()[0][:120]
                return row
            times.append(time.perf_counter() - t0)
    row["seconds"] = statistics.median(times)
    row["lines_per_s"] = lines / row["seconds"]
    row.update(arcs_kept=rep.arcs_kept, arcs_split=rep.arcs_split, arcs_linearised=rep.arcs_linearised,
               lines_inserted=rep.lines_inserted)
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calibration", default=str(ROOT / "calibrations" / "s500_static.json"))
    ap.add_argument("--min-lines", type=int, default=3000)
    ap.add_argument("--only", default="", help="only programs whose path contains this")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--json", dest="json_out", help="save the rows as JSON")
    args = ap.parse_args()
    if not CORPUS.is_dir():
        print(f"no corpus at {CORPUS}", file=sys.stderr)
        return 1
    engine = load_calibration(args.calibration).engine
    rows = [run(p, n, engine, args.repeats) for p, n in programs(args.min_lines, args.only)]
    done = sorted((r for r in rows if "seconds" in r), key=lambda r: r["lines_per_s"])
    print(f"calibration {Path(args.calibration).name}; {len(done)} programs of {args.min_lines} lines or more "
          f"corrected, {len(rows) - len(done)} refused; median of {args.repeats} run(s)")
    print(f"{'lines/s':>9} {'lines':>7} {'s':>7} {'kept':>6} {'split':>6} {'lin.':>5} {'R arcs':>6}  program")
    for r in done:
        print(f"{r['lines_per_s']:9,.0f} {r['lines']:7,} {r['seconds']:7.2f} {r['arcs_kept']:6,} {r['arcs_split']:6,} "
              f"{r['arcs_linearised']:5,} {r['r_arcs']:6,}  {r['program']}")
    for r in rows:
        if "refused" in r:
            print(f"  refused: {r['program']}: {r['refused']}")
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
