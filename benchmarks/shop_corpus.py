"""How far `postproc correct` gets with the shop-program corpus (tests/data/shop).

Corrects every program under tests/data/shop/<dialect>/ (sinumerik, g41, fadal, okuma) with
calibrations/s500_static.json, through the command line as a user would run it, one process
per file, with ``--dialect`` chosen by folder (sinumerik / fadal / okuma; the default,
generic, for g41). When this version of postproc has no such ``--dialect`` the file runs in
the default dialect and the table says so. Every piece of setup is given (work offsets
G54-G59, tool lengths 0-99, start position, G28/G30 positions) and ``--extrapolate clamp``
keeps targets outside the calibrated volume from hiding what the corpus is about: the
constructs the programs use. A refusal is counted under its first line, without the
file and line it names.

Prints a table by source (repository) and dialect folder: files, corrected, refused, other
(internal error, usage error or timeout), then the refusals grouped by construct, most
frequent first.

Usage: python benchmarks/shop_corpus.py [--corpus DIR] [--calibration FILE] [--timeout S]
"""

from __future__ import annotations

import argparse
import collections
import csv
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ["sinumerik", "g41", "fadal", "okuma"]
#: the --dialect each folder asks for; None: the default dialect (generic)
WANTED = {"sinumerik": "sinumerik", "fadal": "fadal", "okuma": "okuma", "g41": None}
SETUP = ([a for w in ("G54", "G55", "G56", "G57", "G58", "G59") for a in ("--offset", f"{w}=X150,Y150,Z50")]
         + [a for t in range(100) for a in ("--tool-length", f"{t}=100")]
         + ["--start", "X150,Y150,Z300", "--home", "G28=X150,Y150,Z300", "--home", "G30=X150,Y150,Z300",
            "--extrapolate", "clamp"]
         # a 3 mm cutter for the programs with cutter radius compensation (G41/G42), when the
         # checkout has the option (older checkouts refuse G41/G42 whatever is given)
         + (["--tool-diameter", "3"] if "--tool-diameter" in subprocess.run(
             [sys.executable, "-m", "postproc", "correct", "--help"], capture_output=True, text=True,
             cwd=ROOT).stdout else []))
_LOCATION = re.compile(r"^(?:postproc: )?(?:error: )?(?:[^\s:]+(?::\d+){1,2}: )?")


def postproc_cmd() -> list[str]:
    return [sys.executable, "-m", "postproc"]


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + (os.pathsep + e["PYTHONPATH"] if e.get("PYTHONPATH") else "")
    return e


def available_dialects() -> set[str]:
    """The --dialect choices of this version's `correct` (from its --help)."""
    out = subprocess.run(postproc_cmd() + ["correct", "--help"], capture_output=True, text=True, env=env(),
                         cwd=ROOT).stdout
    m = re.search(r"--dialect\s+\[([^\]]+)\]", out)
    return {d.strip().lower() for d in re.sub(r"\s+", "", m.group(1)).split("|")} if m else {"generic"}


def load_sources(corpus: Path) -> dict[str, dict]:
    with open(corpus / "SOURCES.csv", newline="") as fh:
        return {row["file"]: row for row in csv.DictReader(fh)}


def construct_of(stderr: str) -> str:
    """The refusal's first line without the 'postproc: error: file:line:col:' in front."""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    first = next((ln for ln in lines if "error" in ln.lower()), lines[0] if lines else "(no message)")
    return _LOCATION.sub("", first.strip())[:110]


def run_one(path: Path, dialect: str | None, calibration: Path, out: Path, timeout: float,
            extra: list[str] | None = None) -> tuple[str, str]:
    """('corrected'|'refused'|'crashed'|'usage error'|'timeout', the first line of the refusal).
    Exit 1 is postproc's internal error (a bug), 2 a command line this version does not take."""
    cmd = postproc_cmd() + ["correct", str(path), "-c", str(calibration), "-o", str(out), "-j", "1", *SETUP,
                            *(extra or [])]
    if dialect:
        cmd += ["--dialect", dialect]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, env=env(), cwd=ROOT, timeout=timeout,
                             errors="replace")
    except subprocess.TimeoutExpired:
        return "timeout", f"no answer in {timeout:.0f} s"
    if res.returncode == 0:
        return "corrected", ""
    status = {1: "crashed", 2: "usage error"}.get(res.returncode, "refused")
    return status, construct_of(res.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", type=Path, default=ROOT / "tests" / "data" / "shop")
    ap.add_argument("--calibration", type=Path, default=ROOT / "calibrations" / "s500_static.json")
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per file")
    ap.add_argument("--tolerance", default=None, help="--tolerance given to every correct (mm) [postproc's default]")
    args = ap.parse_args(argv)
    extra = ["--tolerance", args.tolerance] if args.tolerance else []

    sources = load_sources(args.corpus)
    have = available_dialects()
    t0 = time.perf_counter()
    # (source, folder) -> counters and refusal constructs
    table: dict[tuple[str, str], dict] = {}
    per_file: list[tuple[str, str, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for folder in FOLDERS:
            files = sorted(p for p in (args.corpus / folder).glob("*") if p.is_file()) \
                if (args.corpus / folder).is_dir() else []
            wanted = WANTED[folder]
            dialect = wanted if wanted is None or wanted in have else None
            used = dialect or "generic"
            if wanted and dialect is None:
                used = f"generic (no --dialect {wanted} yet)"
            if not files:
                table[("(none)", folder)] = {"dialect": used, "files": 0, "status": collections.Counter(),
                                             "why": collections.Counter()}
            for path in files:
                rel = f"{folder}/{path.name}"
                source = sources.get(rel, {}).get("repository", "(not in SOURCES.csv)")
                row = table.setdefault((source, folder), {"dialect": used, "files": 0,
                                                          "status": collections.Counter(),
                                                          "why": collections.Counter()})
                status, why = run_one(path, dialect, args.calibration, Path(tmp) / path.name, args.timeout, extra)
                row["files"] += 1
                per_file.append((rel, status, why))
                row["status"][status] += 1
                if why:
                    row["why"][f"{status}: {why}"] += 1
    elapsed = time.perf_counter() - t0

    head = ["source", "folder", "dialect", "files", "corrected", "refused", "other"]
    rows = []
    for (source, folder), r in table.items():
        st = r["status"]
        rows.append([source, folder, r["dialect"], str(r["files"]), str(st["corrected"]),
                     str(st["refused"]), str(st["crashed"] + st["usage error"] + st["timeout"])])
    tot = [sum(int(r[i]) for r in rows) for i in (3, 4, 5, 6)]
    rows.append(["total", "", "", *map(str, tot)])
    widths = [max(len(x[i]) for x in [head] + rows) for i in range(len(head))]

    def fmt(cells: list[str]) -> str:
        return "  ".join(c.ljust(w) if i < 3 else c.rjust(w)
                         for i, (c, w) in enumerate(zip(cells, widths, strict=True)))

    print(f"Shop corpus {args.corpus.relative_to(ROOT) if args.corpus.is_relative_to(ROOT) else args.corpus}, "
          f"calibration {args.calibration.name}, --dialect choices here: {', '.join(sorted(have))}")
    print(fmt(head))
    print(fmt(["-" * w for w in widths]))
    for r in rows[:-1]:
        print(fmt(r))
    print(fmt(["-" * w for w in widths]))
    print(fmt(rows[-1]))
    print()
    print("Refused, by construct (first line of the refusal, file and line left out):")
    for (source, folder), r in table.items():
        if not r["why"]:
            continue
        print(f"  {source} [{folder}, {r['dialect']}]")
        for why, n in sorted(r["why"].items(), key=lambda kv: (-kv[1], kv[0])):
            print(f"    {n:3d}  {why}")
    overall = collections.Counter()
    for r in table.values():
        for why, n in r["why"].items():
            overall[why.split(": ", 1)[1] if ": " in why else why] += n
    print()
    print("All folders together:")
    for why, n in sorted(overall.items(), key=lambda kv: (-kv[1], kv[0])):
        print(f"  {n:3d}  {why}")
    print()
    print("Per file:")
    for rel, status, why in per_file:
        print(f"  {status:<10} {rel}" + (f"  -- {why}" if why else ""))
    print(f"\n({sum(r['files'] for r in table.values())} files in {elapsed:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
