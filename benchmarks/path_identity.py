"""Whether two trees of postproc sample the same programs into the same arrays, bit for bit.

Each program is sampled by ``postproc.gcode.path.sample_program`` under each case (the
setups, dialects and samplings below) by a child process of each tree; a case's record
is the sha256 of every array of the path (points, tool vector, lines, rapid flags,
each context array, with its dtype and shape), or the error it raised (class, message,
file, line, column, hint). The records of the two trees are compared:

    python benchmarks/path_identity.py --base OTHER_TREE [--gencam N:SEED ...] PROGRAM_OR_DIR...

``OTHER_TREE``: a checkout of the code to compare with (its compiled modules beside its
sources, as in this tree). Directories are searched for G-code files. ``--gencam``
adds a program made by ``gencam.py`` (the shared benchmark generator), read with the
benchmark setup (G54, G28 home, tool lengths T1..T20).

Prints one line per program that differs, then the counts: cases checked, identical
arrays, the same error on both sides, and differing; exits 1 if any differs.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GENCAM = REPO.parent / "shared" / "bench" / "gencam.py"
SUFFIXES = {".nc", ".ngc", ".tap", ".gcode", ".cnc", ".iso", ".mpf", ".txt", ".out", ".spf"}

# (name, keyword arguments of sample_program)
SAMPLINGS = [
    ("step0.5", {"step_mm": 0.5}),  # program_path, verify's run step
    ("chord", {"chord_mm": 1e-5}),  # verify's nominal path
    ("step+chord", {"step_mm": 0.5, "chord_mm": 1e-5}),  # verify's actual path samples
    ("ends", {}),  # each move's end alone
    ("step0.5-2M", {"step_mm": 0.5, "max_samples": 2_000_000}),  # past the default bound
]
# and for gencam programs (long): steps and a chord that stay under the default bound
GENCAM_SAMPLINGS = [("step5", {"step_mm": 5.0}), ("step20", {"step_mm": 20.0}), ("chord1e-3", {"chord_mm": 1e-3})]
# a dialect for the programs of a corpus folder, besides the generic one
FOLDER_DIALECT = {"haas_kiely": "haas", "fanuc_sim": "fanuc", "lagun_linuxcnc": "linuxcnc", "linuxcnc": "linuxcnc",
                  "pygcode-linuxcnc": "linuxcnc", "ugs": "grbl", "cncjs": "grbl"}

CHILD = r"""
import hashlib, json, sys
from postproc.gcode.path import Setup, sample_program

def setups():
    offsets = {n: (0.0, 0.0, 0.0) for n in ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"]}
    return {
        "none": Setup(),
        "corpus": Setup(offsets=offsets, tool_lengths={t: 50.0 + t for t in range(100)}),
        "corpus-start": Setup(offsets=offsets, tool_lengths={t: 50.0 + t for t in range(100)},
                              start={"X": 1.0, "Y": 2.0, "Z": 150.0}, context={"temp": 21.5}),
        "bench": Setup(offsets={"G54": (0.0, 0.0, 100.0)}, home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}},
                       tool_lengths={t: 0.0 for t in range(1, 21)}),
    }

def digest(pp):
    arrays = [("points_mm", pp.points_mm), ("tool_mm", pp.tool_mm), ("lineno", pp.lineno), ("rapid", pp.rapid)]
    arrays += [("context." + k, v) for k, v in pp.context.items()]
    out = {}
    for name, a in arrays:
        h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
        out[name] = h.hexdigest()
    out["n"] = len(pp.points_mm)
    return out

cases = json.load(sys.stdin)
S = setups()
records = []
for prog, setup, dialect, kw in cases:
    try:
        rec = digest(sample_program(prog, S[setup], dialect=dialect, **kw))
    except Exception as exc:
        rec = {"error": type(exc).__name__, "message": str(exc), "path": getattr(exc, "path", None),
               "lineno": getattr(exc, "lineno", None), "col": getattr(exc, "col", None),
               "hint": getattr(exc, "hint", None)}
    records.append(rec)
json.dump(records, sys.stdout)
"""


def programs(args: list[str]) -> list[Path]:
    out: list[Path] = []
    for a in args:
        p = Path(a)
        if p.is_dir():
            out += sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in SUFFIXES)
        else:
            out.append(p)
    return out


def cases_of(prog: Path, setups: list[str], samplings=SAMPLINGS) -> list[tuple[str, str, str, dict]]:
    dialects = ["generic"]
    for part in prog.parts:
        d = FOLDER_DIALECT.get(part)
        if d and d not in dialects:
            dialects.append(d)
    return [(str(prog), s, d, kw) for s in setups for d in dialects for _name, kw in samplings]


def run(tree: Path, cases: list) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=str(tree))
    res = subprocess.run([sys.executable, "-c", CHILD], input=json.dumps(cases), capture_output=True, text=True,
                         env=env, cwd=tree, check=False)
    if res.returncode != 0:
        raise SystemExit(f"the child of {tree} failed:\n{res.stderr}")
    return json.loads(res.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", required=True, type=Path, help="the other tree")
    ap.add_argument("--gencam", action="append", default=[], help="N:SEED, a gencam.py program (repeatable)")
    ap.add_argument("--generator", type=Path, default=GENCAM, help=f"gencam.py (default {GENCAM})")
    ap.add_argument("sources", nargs="*")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        jobs: list[tuple[Path, list]] = []
        for p in programs(args.sources):
            setups = ["none", "corpus", "corpus-start"]
            jobs.append((p, cases_of(p, setups)))
        for spec in args.gencam:
            n, seed = spec.split(":")
            out = Path(tmp) / f"gencam_{n}_{seed}.nc"
            subprocess.run([sys.executable, str(args.generator), n, str(out), seed], check=True, capture_output=True)
            jobs.append((out, cases_of(out, ["bench"], SAMPLINGS + GENCAM_SAMPLINGS)))
        counts = {"cases": 0, "identical": 0, "same error": 0, "differ": 0}
        programs_seen = all_errors = 0
        errors: dict[str, int] = {}
        for prog, cases in jobs:
            base, mine = run(args.base, cases), run(REPO, cases)
            programs_seen += 1
            all_errors += all("error" in a for a in base)
            for case, a, b in zip(cases, base, mine, strict=True):
                if "error" in a:
                    errors[a["error"]] = errors.get(a["error"], 0) + 1
                counts["cases"] += 1
                if a != b:
                    counts["differ"] += 1
                    what = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
                    print(f"DIFFERS {prog} setup={case[1]} dialect={case[2]} {case[3]}: {', '.join(what)}"
                          f" (base {a.get('n', a.get('error'))}, this {b.get('n', b.get('error'))})")
                elif "error" in a:
                    counts["same error"] += 1
                else:
                    counts["identical"] += 1
            sys.stdout.flush()
        print(f"programs: {programs_seen} ({all_errors} refused in every case); cases: {counts['cases']}, "
              f"identical arrays: {counts['identical']}, same error: {counts['same error']}, "
              f"differ: {counts['differ']}")
        print("errors of the base: " + ", ".join(f"{k} {v}" for k, v in sorted(errors.items())))
    sys.exit(1 if counts["differ"] else 0)


if __name__ == "__main__":
    main()
