"""The corpus corrected with calibrations/s500_parametric.json, LinuxCNC's rs274 on input and output.

Every program whose input rs274 accepts and that postproc corrects must give an output
rs274 accepts; the script lists any that does not.

Input/output rs274 setup: tests/test_oracle_scale.py (tools 1..99 of zero length, no
parameters, program text passed as is); refusals retried up to 3 times as
benchmarks/pin_outputs.py's _rs274 does. Correction: pin_outputs._correct for the
s500_parametric key (corpus_speed.setup(), source dialect, --extrapolate linear, retry with
cycles expand when refused for it).

Usage: python3 benchmarks/corpus_rs274.py [-j 2] [--out results.jsonl]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

CORPUS = ROOT.parent / "shared" / "corpus"
SOURCES = ("real", "linuxcnc", "pygcode-linuxcnc")
MAX_LINES = 20_000
CAL = "s500_parametric"

def rs274(text: str) -> tuple[bool, str, int]:
    """rs274's verdict, as benchmarks/pin_outputs.py runs it (its tool table, its retries)."""
    from pin_outputs import _rs274

    res = _rs274(text.encode("utf-8", errors="surrogateescape"))
    return bool(res.get("ok")), res.get("error", ""), res.get("motions", 0)


def correct(path: Path) -> tuple[str, dict]:
    """The corrected text, as benchmarks/pin_outputs.py corrects the s500_parametric key."""
    import tempfile

    from pin_outputs import _correct, _dialect

    with tempfile.TemporaryDirectory(prefix="corpus-rs274-") as tmp:
        out = Path(tmp) / "out.ngc"
        extra = _correct(path, CAL, out)
        return out.read_bytes().decode("utf-8", errors="surrogateescape"), {"dialect": _dialect(path), **extra}


def run_one(job) -> dict:
    rel, lines = job
    path = CORPUS / rel
    t0 = time.perf_counter()
    rec: dict = {"program": rel, "lines": lines}
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    ok, err, nmo = rs274(text)
    rec["input_ok"] = ok
    rec["input_motions"] = nmo
    if not ok:
        rec["status"] = "input refused"
        rec["input_error"] = (err.splitlines() or [""])[0][:200]
        rec["seconds"] = time.perf_counter() - t0
        return rec
    from postproc.errors import PostprocError
    try:
        out, extra = correct(path)
        rec.update(extra)
    except PostprocError as exc:
        where = f"line {exc.lineno}: " if exc.lineno is not None else ""
        rec["status"] = "postproc refused"
        rec["refusal"] = where + (exc.message.splitlines() or [""])[0]
        rec["seconds"] = time.perf_counter() - t0
        return rec
    except Exception as exc:  # noqa: BLE001
        rec["status"] = "postproc crashed"
        rec["refusal"] = f"{type(exc).__name__}: {(str(exc).splitlines() or [''])[0]}"
        rec["seconds"] = time.perf_counter() - t0
        return rec
    rec["output_lines"] = out.count("\n")
    ok2, err2, nmo2 = rs274(out)
    rec["output_ok"] = ok2
    rec["output_motions"] = nmo2
    rec["status"] = "output accepted" if ok2 else "OUTPUT REFUSED"
    if not ok2:
        rec["output_error"] = err2.replace("\n", " | ")[:500]
    rec["seconds"] = time.perf_counter() - t0
    return rec


def programs():
    jobs, skipped = [], []
    from conftest import corpus_files

    for p in corpus_files(SOURCES):
        n = p.read_bytes().count(b"\n")
        rel = str(p.relative_to(CORPUS))
        (skipped if n > MAX_LINES else jobs).append((rel, n))
    jobs.sort(key=lambda j: (j[1], j[0]))
    return jobs, skipped


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("-j", type=int, default=2)
    ap.add_argument("--out", default="corpus_rs274.jsonl")
    ap.add_argument("--min-lines", type=int, default=0, help="supplementary runs: only programs over this")
    ap.add_argument("--max-lines", type=int, default=20_000)
    args = ap.parse_args()
    globals()["MAX_LINES"] = args.max_lines
    jobs, skipped = programs()
    jobs = [j for j in jobs if j[1] > args.min_lines]
    print(f"{len(jobs)} runs, {len(skipped)} programs skipped (> {MAX_LINES:,} lines): "
          + ", ".join(f"{r} ({n:,})" for r, n in skipped), flush=True)
    t0 = time.perf_counter()
    rows = []
    with open(args.out, "w") as fh, multiprocessing.get_context("fork").Pool(min(args.j, 2), maxtasksperchild=20) as pool:
        for rec in pool.imap_unordered(run_one, jobs):
            rows.append(rec)
            fh.write(json.dumps(rec) + "\n")
            fh.flush()
            print(f"[{len(rows)}/{len(jobs)}] {rec['seconds']:6.1f}s {rec['status']:17} {rec['program']}",
                  flush=True)
    wall = time.perf_counter() - t0
    report(rows, skipped, wall)
    return 0


def report(rows, skipped, wall):
    n = len(rows)
    inp = [r for r in rows if r["input_ok"]]
    corr = [r for r in inp if r["status"] in ("output accepted", "OUTPUT REFUSED")]
    acc = [r for r in corr if r["output_ok"]]
    bad = [r for r in corr if not r["output_ok"]]
    refused = [r for r in inp if r["status"] in ("postproc refused", "postproc crashed")]
    print()
    print(f"{'programs':>10} {'input ok':>10} {'corrected':>10} {'output ok':>10} {'OUTPUT REFUSED':>15}")
    print(f"{n:>10} {len(inp):>10} {len(corr):>10} {len(acc):>10} {len(bad):>15}")
    print(f"input refused by rs274: {n - len(inp)}; postproc refused (of inputs rs274 accepts): {len(refused)}; "
          f"skipped for size: {len(skipped)}; wall {wall:.0f} s")
    print("\nFAILURES (input accepted, corrected, output refused by rs274):" if bad else "\nFAILURES: none")
    for r in sorted(bad, key=lambda r: r["program"]):
        print(f"  {r['program']} ({r['lines']} lines, {r.get('dialect')}, cycles {r.get('cycles', 'as is')}): "
              f"{r['output_error']}")
    print("\npostproc refusals:")
    for r in sorted(refused, key=lambda r: r["program"]):
        print(f"  {r['program']}: {r['refusal']}")
    print("\ninput refused by rs274:")
    for r in sorted((r for r in rows if not r["input_ok"]), key=lambda r: r["program"]):
        print(f"  {r['program']}: {r['input_error']}")
    print("\nStar_Trek.tap:")
    for r in rows:
        if Path(r["program"]).name == "Star_Trek.tap":
            print(f"  {json.dumps(r)}")


if __name__ == "__main__":
    sys.exit(main())
