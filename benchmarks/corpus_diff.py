"""`diff` on the corpus's real programs and their corrected versions.

Corrects every program of ../shared/corpus (real/, linuxcnc/, pygcode-linuxcnc/; at most
--max-lines lines) with each calibration given (default: calibrations/s500_static.json
and calibrations/s500_parametric.json), placed in the calibrated volume as
benchmarks/corpus_speed.py places it, in the dialect of its source, then compares the
two with ``compare_programs`` in the same dialect, and prints per pair: lines, the
seconds `diff` took, moves, lines inserted, the largest moved block, and the verdict:

  ok       every block paired;
  SUSPECT  paired, but a block moved by more than --suspect-mm (the corrections of the
           S500 calibrations stay below 0.5 mm: a larger one is a line paired with
           another move's line);
  FAIL     diff refused the pair (a move without counterpart, a line that differs, a
           program it cannot read);
  skip     correct refused the program.

A program correct refuses for a canned cycle the correction tilts is corrected again
with ``cycles="expand"`` (its cycles written as moves; marked "cycles" in the list).
Programs correct expands (subprograms, loops, parameters) are compared expanded.

Slowest pairs first. Exit code 1 if any pair is SUSPECT or FAIL. ``--json OUT`` saves
the rows. The gencam benchmark (benchmarks/throughput.py) measures diff's speed on a
synthetic CAM program; this one checks its pairing on real ones: moves shorter than the
change of the correction over the move before them, programs without anchor lines for
tens of thousands of lines, every move with its own N word.

Usage: python benchmarks/corpus_diff.py [--calibration FILE ...] [--only SUBSTRING]
                                        [--max-lines N] [--suspect-mm MM] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from corpus_speed import CORPUS, dialect_of, programs, setup  # noqa: E402

from postproc.calfile import load_calibration  # noqa: E402
from postproc.errors import PostprocError  # noqa: E402
from postproc.gcode.compare import compare_programs  # noqa: E402
from postproc.gcode.pipeline import CorrectOptions, correct_file  # noqa: E402

DEFAULT_CALIBRATIONS = [ROOT / "calibrations" / "s500_static.json", ROOT / "calibrations" / "s500_parametric.json"]
def run(path: Path, lines: int, cal_name: str, engine, suspect_mm: float, tmp: Path) -> dict:
    dialect = dialect_of(path)
    row: dict = {"program": str(path.relative_to(CORPUS)), "calibration": cal_name, "lines": lines}
    out = tmp / "out.nc"
    try:
        try:
            correct_file(path, out, engine, setup(), CorrectOptions(extrapolate="linear", dialect=dialect))
        except PostprocError as exc:
            if "--cycles expand" not in str(exc):
                raise
            correct_file(path, out, engine, setup(), CorrectOptions(extrapolate="linear", dialect=dialect,
                                                                    cycles="expand"))
            row["cycles"] = True
    except PostprocError as exc:
        row.update(verdict="skip", reason="correct: " + str(exc).splitlines()[0][:100])
        return row
    t0 = time.perf_counter()
    try:
        rep = compare_programs(path, out, keep=1, options=CorrectOptions(dialect=dialect))
    except PostprocError as exc:
        row.update(verdict="FAIL", reason="diff: " + str(exc).splitlines()[0][-110:])
        return row
    row["seconds"] = time.perf_counter() - t0
    largest = rep.largest(1)
    row.update(moves=rep.moves, inserted=rep.lines_inserted,
               largest_um=largest[0].size_mm * 1000 if largest else 0.0)
    row["verdict"] = "SUSPECT" if row["largest_um"] > suspect_mm * 1000 else "ok"
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calibration", action="append", help="calibration file (repeatable)")
    ap.add_argument("--only", default="", help="only programs whose path contains this")
    ap.add_argument("--max-lines", type=int, default=40_000)
    ap.add_argument("--suspect-mm", type=float, default=1.0)
    ap.add_argument("--json", dest="json_out", help="save the rows as JSON")
    args = ap.parse_args()
    if not CORPUS.is_dir():
        print(f"no corpus at {CORPUS}", file=sys.stderr)
        return 1
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for cal in args.calibration or DEFAULT_CALIBRATIONS:
            engine = load_calibration(cal).engine
            for path, n in programs(0, args.only):
                if n <= args.max_lines:
                    rows.append(run(path, n, Path(cal).name, engine, args.suspect_mm, Path(tmp)))
    done = sorted((r for r in rows if "seconds" in r), key=lambda r: -r["seconds"])
    print(f"{'s':>7} {'lines':>7} {'moves':>7} {'inserted':>8} {'largest um':>10}  verdict  calibration  program")
    for r in done:
        print(f"{r['seconds']:7.2f} {r['lines']:7,} {r['moves']:7,} {r['inserted']:8,} {r['largest_um']:10.1f}  "
              f"{r['verdict']:7}  {r['calibration']}  {r['program']}{'  (cycles)' if r.get('cycles') else ''}")
    for r in rows:
        if "seconds" not in r:
            print(f"  {r['verdict']:7}  {r['calibration']}  {r['program']}: {r['reason']}")
    count = {v: sum(r["verdict"] == v for r in rows) for v in ("ok", "SUSPECT", "FAIL", "skip")}
    print(f"{len(rows)} pairs: " + ", ".join(f"{n} {v}" for v, n in count.items())
          + f" ({sum(bool(r.get('cycles')) for r in rows)} with their cycles written as moves)"
          + f"; diff took {sum(r.get('seconds', 0.0) for r in rows):.1f} s in all")
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=1))
    return 1 if count["SUSPECT"] or count["FAIL"] else 0


if __name__ == "__main__":
    sys.exit(main())
