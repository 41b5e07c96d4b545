"""Share of real programs corrected, by source, and every refusal by construct.

Corrects each program of ../shared/corpus (real/, linuxcnc/, pygcode-linuxcnc/) with an
identity calibration and every piece of setup given (all work offsets zero, every tool
length, the stored G28/G30 positions), in the dialect of its source, and checks that the
output is byte-identical to the input apart from the header. Prints a table by source
and the refusals grouped by the construct their message names.

With ``--calibration FILE`` (e.g. calibrations/s500_static.json) each program is
corrected with that calibration instead, and a program is counted corrected when the
correction runs to its end (its bytes are expected to change).

Usage: python benchmarks/corpus_survey.py [--corpus DIR] [--calibration FILE] [--json]
"""

from __future__ import annotations

import argparse
import collections
import csv
import json
import re
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from postproc.engine.identity import IdentityEngine  # noqa: E402
from postproc.errors import PostprocError  # noqa: E402
from postproc.gcode import emit  # noqa: E402
from postproc.gcode.path import Setup  # noqa: E402
from postproc.gcode.pipeline import CorrectOptions, correct_text  # noqa: E402

EXTS = {".nc", ".ngc", ".tap", ".gcode", ".cnc", ".txt"}
BIG = [[-1e5] * 3, [1e5] * 3]
DIALECT_BY_SOURCE = {"fanuc_sim": "fanuc", "haas_kiely": "haas", "lagun_linuxcnc": "linuxcnc",
                     "linuxcnc": "linuxcnc", "cncjs": "grbl", "ugs": "grbl"}


def setup_for(path: Path) -> Setup:
    offsets = {n: (0.0, 0.0, 0.0) for n in ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"]}
    kw = dict(offsets=offsets, tool_lengths={t: 50.0 + t for t in range(100)})
    try:
        return Setup(**kw, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 0.0}, "G30": {"X": 0.0, "Y": 0.0, "Z": 0.0}},
                     start={"Z": 150.0})
    except TypeError:  # older versions: no stored positions
        return Setup(**kw, start={"Z": 150.0})


def options_for(dialect: str) -> CorrectOptions:
    try:
        return CorrectOptions(dialect=dialect)
    except TypeError:
        return CorrectOptions()


def construct_of(message: str) -> str:
    m = re.match(r"[^:]*(?::\d+)*: (.*)", message)
    text = (m.group(1) if m else message).split("\n")[0]
    text = re.sub(r"\d+(\.\d+)?", "N", text)
    return text[:90]


def survey(corpus: Path, calibration: str | None = None):
    engine = None
    if calibration:
        from postproc.calfile import load_calibration

        engine = load_calibration(calibration).engine
    sources = {}
    real = corpus / "real"
    if (real / "SOURCES.csv").exists():
        with open(real / "SOURCES.csv", newline="") as fh:
            for row in csv.DictReader(fh):
                sources[str(real / row["file"])] = row["source"]
    rows = []
    for path in sorted(p for p in corpus.rglob("*") if p.suffix.lower() in EXTS and p.is_file()):
        source = sources.get(str(path), path.parent.name)
        dialect = DIALECT_BY_SOURCE.get(source, "generic")
        text = path.read_bytes().decode("utf-8", errors="surrogateescape")
        t0 = time.perf_counter()
        try:
            out, rep = correct_text(text, engine or IdentityEngine(BIG), setup_for(path), options_for(dialect),
                                    path=str(path))
            body = "".join(ln for ln in out.splitlines(keepends=True) if not emit.is_header(ln))
            if engine is not None:
                status = "expanded" if getattr(rep, "expanded", False) else "identical"  # corrected
            elif getattr(rep, "expanded", False):
                status = "expanded"  # flat: subprograms, loops and parameters written out
            else:
                status = "identical" if body.lstrip("\ufeff") == text.lstrip("\ufeff") else "changed"
            reason = ""
        except PostprocError as exc:
            status, reason = "refused", construct_of(str(exc))
        except Exception as exc:  # noqa: BLE001  a bug: reported as such
            status, reason = "internal error", f"{type(exc).__name__}: {exc}"[:90]
        rows.append({"source": source, "file": str(path.relative_to(corpus)), "dialect": dialect,
                     "status": status, "reason": reason, "seconds": time.perf_counter() - t0})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--corpus", default=str(ROOT.parent / "shared" / "corpus"))
    ap.add_argument("--calibration", default=None, help="correct with this calibration (default: identity)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = survey(Path(args.corpus), args.calibration)
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    by = collections.defaultdict(collections.Counter)
    for r in rows:
        by[r["source"]][r["status"]] += 1
    print(f"{'source':22} {'files':>5} {'identical':>9} {'expanded':>8} {'changed':>7} {'refused':>7} "
          f"{'internal':>8}")
    tot = collections.Counter()
    for src in sorted(by):
        c = by[src]
        tot.update(c)
        n = sum(c.values())
        print(f"{src:22} {n:5d} {c['identical']:9d} {c['expanded']:8d} {c['changed']:7d} {c['refused']:7d} "
              f"{c['internal error']:8d}")
    n = sum(tot.values())
    done = tot["identical"] + tot["expanded"]
    print(f"{'all':22} {n:5d} {tot['identical']:9d} {tot['expanded']:8d} {tot['changed']:7d} {tot['refused']:7d} "
          f"{tot['internal error']:8d}   ({100.0 * done / max(n, 1):.0f} % corrected: identical apart from the "
          "header, or expanded)")
    reasons = collections.Counter(r["reason"] for r in rows if r["status"] in ("refused", "internal error"))
    print("\nrefusals by construct:")
    for reason, k in reasons.most_common():
        print(f"  {k:4d}  {reason}")
    changed = [r["file"] for r in rows if r["status"] == "changed"]
    if changed:
        print("\nchanged under identity (should be byte-identical):")
        for f in changed:
            print("  ", f)


if __name__ == "__main__":
    main()
