"""Pin today's outputs of `correct`, and check that they stay as pinned.

Every program of ../shared/corpus (real/, linuxcnc/, pygcode-linuxcnc/; the suffixes
tests/conftest.py lists), every program of samples/, every golden case of tests/cases and
the gencam benchmark program of 100,000 lines, seed 42 (../shared/bench/gencam.py, made
afresh in a temporary folder), is corrected in this process (two worker processes at most) with each of these
calibrations, with the options the tests and benchmarks that use them use:

- ``identity``: IdentityEngine over +-1e5 mm, conftest.corpus_setup(path), default
  options (tests/test_correct_roundtrip.py, the identity round trip);
- ``scale``: a machine that moves k = 1.0002 times what it is told (StaticEngine k*I),
  every offset, tool length and G28/G30 position zero, dialect linuxcnc, cycles expand
  (tests/test_oracle_scale.py);
- ``s500_static``, ``s500_parametric``: calibrations/s500_*.json, the program placed in
  the calibrated volume as benchmarks/corpus_speed.py's setup() places it, in the dialect
  of its source, --extrapolate linear; a program refused for a canned cycle the
  correction tilts is corrected again with cycles expand, as benchmarks/corpus_diff.py
  does (recorded as ``"cycles": "expand"``); the gencam program with the setup of
  benchmarks/throughput.py (G54 at Z100, G28 at Z200, tools 1..20 of length 0), without
  extrapolation, as the throughput runs correct it;
- ``own`` (golden cases only): the case's own flags and calibration, through the CLI
  in-process, as tests/test_correct_cases.py runs it.

Per case (key ``<where>/<program>|<calibration>``, where is ``corpus/...``, ``samples/``,
``cases/`` or ``bench/``) the manifest holds the sha256 and line count of the output bytes, or for
a refusal the exit code and the first line of the message (without its place, which
names a path); and, for every output, LinuxCNC's rs274 on it (tools 1..99 of zero
length): whether it accepted the program, its motion count, and the sha256 of its
canonical calls (or the first line of its error). The header's version word is written
as ``VERSION`` before hashing, so that a version bump alone changes no pin.

``--write DIR`` records DIR/manifest.json (with ``--only``, updates those keys of it); ``--check`` (against tests/data/pinned/ unless
given DIR) prints every key whose outcome changed, old -> new, and exits 1 if any did,
3 if an output under the identity or scale calibration did (those must never change;
they are listed apart). Keys in one manifest only are listed too (a program added or
removed). ``--only SUBSTRING`` limits the run to keys containing it (``--check`` then compares only those).
``--no-rs274`` leaves the oracle out (its entries are not compared).

Usage: python benchmarks/pin_outputs.py --write tests/data/pinned/
       python benchmarks/pin_outputs.py --check [DIR] [--only SUBSTRING] [-j 2]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402

from postproc.errors import EXIT_INTERNAL, PostprocError  # noqa: E402

CORPUS = ROOT.parent / "shared" / "corpus"
SAMPLES = ROOT / "samples"
CASES = ROOT / "tests" / "cases"
DEFAULT_DIR = ROOT / "tests" / "data" / "pinned"
MANIFEST = "manifest.json"
CALIBRATIONS = ("identity", "scale", "s500_static", "s500_parametric")
#: calibrations whose outputs must never change
FROZEN = frozenset({"identity", "scale"})
SCALE_K = 1.0002  # tests/test_oracle_scale.py K
OFFSET_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")
_VERSION_LINE = re.compile(r"^(\s*\(POSTPROC )\S+( CORRECTED\))", re.MULTILINE | re.IGNORECASE)
#: tool table given to rs274: tools 1..99, zero length and diameter (test_oracle_scale.TOOLS)
RS274_TOOLS = "".join(f"T{t} P{t} Z0 D0 ;\n" for t in range(1, 100))


# -- what is run -------------------------------------------------------------------------
GENCAM = ROOT.parent / "shared" / "bench" / "gencam.py"
GENCAM_LINES, GENCAM_SEED = 100_000, 42
GENCAM_KEY = f"bench/gencam-{GENCAM_LINES}-seed{GENCAM_SEED}.nc"


def make_gencam(folder: Path) -> Path | None:
    """The gencam program written into ``folder`` (None without ../shared/bench)."""
    if not GENCAM.is_file():
        return None
    out = folder / Path(GENCAM_KEY).name
    subprocess.run([sys.executable, str(GENCAM), str(GENCAM_LINES), str(out), str(GENCAM_SEED)], check=True,
                   stdout=subprocess.DEVNULL)
    return out


def programs(corpus: bool = True, gencam: Path | None = None) -> list[tuple[str, Path]]:
    """(key prefix, path) of every program pinned: golden cases, samples, the corpus, then
    the gencam program when ``gencam`` (its path) is given."""
    from conftest import CORPUS_EXTS, corpus_files

    out = [(f"cases/{p.name}", p) for p in sorted(CASES.glob("*.nc"))]
    out += [(f"samples/{p.relative_to(SAMPLES)}", p) for p in sorted(SAMPLES.rglob("*"))
            if p.is_file() and p.suffix.lower() in CORPUS_EXTS]
    if corpus:
        out += [(f"corpus/{p.relative_to(CORPUS)}", p) for p in corpus_files()]
    if gencam is not None:
        out.append((GENCAM_KEY, gencam))
    return out


def jobs_for(items: list[tuple[str, Path]]) -> list[tuple[str, str, str]]:
    """(key, path, calibration) of every case of ``items``."""
    out = []
    for rel, path in items:
        cals = (("own",) if rel.startswith("cases/") else ()) + CALIBRATIONS
        out += [(f"{rel}|{cal}", str(path), cal) for cal in cals]
    return out


def _engine(cal: str):
    """(engine, calibration name, sha256) for a calibration name; cached per process."""
    if cal not in _ENGINES:
        from postproc.calfile import load_calibration
        from postproc.engine.identity import IdentityEngine
        from postproc.engine.static import StaticEngine

        if cal == "identity":
            from conftest import BIG
            _ENGINES[cal] = (IdentityEngine(BIG), "identity", "0" * 64)
        elif cal == "scale":
            _ENGINES[cal] = (StaticEngine(SCALE_K * np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3]),
                             "scale", "0" * 64)
        else:
            c = load_calibration(ROOT / "calibrations" / f"{cal}.json")
            _ENGINES[cal] = (c.engine, c.name, c.sha256)
    return _ENGINES[cal]


_ENGINES: dict = {}


def _scale_setup():
    from postproc.gcode.path import Setup
    return Setup(offsets={n: (0.0, 0.0, 0.0) for n in OFFSET_NAMES}, tool_lengths={t: 0.0 for t in range(100)},
                 home={"G28": {"X": 0.0, "Y": 0.0, "Z": 0.0}, "G30": {"X": 0.0, "Y": 0.0, "Z": 0.0}})


def _gencam_setup():
    """benchmarks/throughput.py's SETUP: every move inside the S500 volume."""
    from postproc.gcode.path import Setup
    return Setup(offsets={"G54": (0.0, 0.0, 100.0)}, tool_lengths={t: 0.0 for t in range(1, 21)},
                 home={"G28": {"X": 0.0, "Y": 0.0, "Z": 200.0}})


def _correct(path: Path, cal: str, out: Path) -> dict:
    """Correct ``path`` into ``out`` as the calibration's tests do; the record's extras."""
    from postproc.gcode.pipeline import CorrectOptions, correct_file

    engine, name, sha = _engine(cal)
    kw = dict(calibration_name=name, calibration_sha256=sha)
    if cal == "identity":
        from conftest import corpus_setup
        correct_file(path, out, engine, corpus_setup(path), CorrectOptions(), **kw)
        return {}
    if cal == "scale":
        correct_file(path, out, engine, _scale_setup(), CorrectOptions(dialect="linuxcnc", cycles="expand"), **kw)
        return {}
    if path.name == Path(GENCAM_KEY).name:
        correct_file(path, out, engine, _gencam_setup(), CorrectOptions(), **kw)
        return {}
    from corpus_speed import setup as volume_setup
    dialect = _dialect(path)
    try:
        correct_file(path, out, engine, volume_setup(), CorrectOptions(extrapolate="linear", dialect=dialect), **kw)
        return {}
    except PostprocError as exc:
        if "--cycles expand" not in str(exc):
            raise
    correct_file(path, out, engine, volume_setup(), CorrectOptions(extrapolate="linear", dialect=dialect,
                                                                   cycles="expand"), **kw)
    return {"cycles": "expand"}


def _dialect(path: Path) -> str:
    """The dialect of a corpus program's source (corpus_speed.dialect_of); generic elsewhere."""
    from corpus_speed import dialect_of
    try:
        return dialect_of(path)
    except ValueError:  # not under the corpus
        return "generic"


def _correct_own(name: str, out: Path) -> None:
    """A golden case with its own flags, through the CLI in-process (test_correct_cases)."""
    from click.testing import CliRunner

    from postproc.cli import main

    f = CASES / f"{name}.flags"
    args = shlex.split(f.read_text()) if f.exists() else []
    if "-c" not in args:
        args += ["-c", "demo_static.json"]
    cwd = os.getcwd()
    os.chdir(CASES)
    try:
        r = CliRunner().invoke(main, ["correct", f"{name}.nc", *args, "-o", str(out)])
    finally:
        os.chdir(cwd)
    if r.exit_code:
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        raise _Refused(r.exit_code, lines[0] if lines else "")


class _Refused(Exception):
    def __init__(self, code: int, first: str) -> None:
        super().__init__(first)
        self.code, self.first = code, first


def normalised(raw: bytes) -> bytes:
    """The output with the header's version word written as VERSION."""
    text = raw.decode("utf-8", errors="surrogateescape")
    return _VERSION_LINE.sub(r"\1VERSION\2", text, count=1).encode("utf-8", errors="surrogateescape")


def run_case(job: tuple[str, str, str], rs274: bool = True) -> tuple[str, dict, float]:
    """(key, record, seconds) of one case."""
    key, path, cal = job
    t0 = time.perf_counter()
    rec: dict = {}
    with tempfile.TemporaryDirectory(prefix="pin-") as tmp:
        out = Path(tmp) / "out.ngc"
        try:
            if cal == "own":
                _correct_own(Path(path).stem, out)
            else:
                rec.update(_correct(Path(path), cal, out))
        except _Refused as exc:
            rec = {"exit": exc.code, "error": exc.first}
        except PostprocError as exc:
            where = f"line {exc.lineno}: " if exc.lineno is not None else ""
            rec = {"exit": exc.exit_code, "error": where + (exc.message.splitlines() or [""])[0]}
        except Exception as exc:  # a bug in postproc: pinned too, so that a fix shows
            rec = {"exit": EXIT_INTERNAL, "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
        else:
            raw = normalised(out.read_bytes())
            rec["sha256"] = hashlib.sha256(raw).hexdigest()
            rec["lines"] = raw.count(b"\n")
            if rs274:
                rec["rs274"] = _rs274(raw)
    return key, rec, time.perf_counter() - t0


#: runs of rs274 on an output it refuses before the refusal is pinned: a refusal that does
#: not repeat is not the program's (rs274 keeps its tool table in memory shared by every
#: rs274 on the machine: another one running at the same time, outside tests/oracle.py's
#: lock, once made it refuse gencam's "T18" as "not found in the tool table")
RS274_REFUSAL_RUNS = 3


def _rs274(raw: bytes) -> dict:
    from oracle import RS274, run_rs274
    if RS274 is None:
        return {"absent": True}
    for attempt in range(RS274_REFUSAL_RUNS):
        if attempt:
            time.sleep(0.2 * attempt)
        res = run_rs274(raw.decode("utf-8", errors="surrogateescape"), tools=RS274_TOOLS)
        if res.ok:
            break
    if not res.ok:
        return {"ok": False, "error": (res.error.splitlines() or [""])[0][:160]}
    return {"ok": True, "motions": len(res.motions),
            "sha256": hashlib.sha256("\n".join(res.calls).encode()).hexdigest()}


def _run_case_rs274(job):
    return run_case(job, True)


def _run_case_plain(job):
    return run_case(job, False)


def run_all(jobs: list[tuple[str, str, str]], processes: int = 2, rs274: bool = True,
            progress=None) -> tuple[dict, dict]:
    """({key: record}, {key: seconds}) of ``jobs``, in ``processes`` processes (at most 2)."""
    fn = _run_case_rs274 if rs274 else _run_case_plain
    # the slowest first, so that two processes end together: largest files first
    order = sorted(jobs, key=lambda j: (-Path(j[1]).stat().st_size, j[0]))
    records, seconds = {}, {}
    if processes <= 1:
        results = map(fn, order)
        pool = None
    else:
        pool = multiprocessing.get_context("fork").Pool(min(processes, 2), maxtasksperchild=50)
        results = pool.imap_unordered(fn, order)
    try:
        for n, (key, rec, s) in enumerate(results, 1):
            records[key], seconds[key] = rec, s
            if progress:
                progress(n, len(order), key, s)
    finally:
        if pool is not None:
            pool.close()
            pool.join()
    return dict(sorted(records.items())), seconds


# -- the manifest --------------------------------------------------------------------------
def write_manifest(directory: Path, records: dict) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / MANIFEST
    # one key a line: a change shows as a one-line diff
    body = ",\n".join(f"{json.dumps(k)}: {json.dumps(v, sort_keys=True)}" for k, v in sorted(records.items()))
    path.write_text("{\n" + body + "\n}\n")
    return path


def read_manifest(directory: Path) -> dict:
    return json.loads((directory / MANIFEST).read_text())


def calibration_of(key: str) -> str:
    return key.rsplit("|", 1)[1]


def compare(old: dict, new: dict, rs274: bool = True) -> list[tuple[str, str, str]]:
    """(key, old, new) of every key whose outcome differs (present in one only included)."""
    def view(rec):
        if rec is None:
            return "absent"
        rec = dict(rec)
        if not rs274:
            rec.pop("rs274", None)
        return json.dumps(rec, sort_keys=True)

    out = []
    for key in sorted(set(old) | set(new)):
        a, b = view(old.get(key)), view(new.get(key))
        if a != b:
            out.append((key, a, b))
    return out


def report(changes: list[tuple[str, str, str]], out=sys.stdout) -> None:
    frozen = [c for c in changes if calibration_of(c[0]) in FROZEN]
    other = [c for c in changes if calibration_of(c[0]) not in FROZEN]
    if frozen:
        print(f"{len(frozen)} IDENTITY/SCALE output(s) changed (never allowed):", file=out)
        for key, a, b in frozen:
            print(f"  {key}\n    old {a}\n    new {b}", file=out)
    if other:
        print(f"{len(other)} other output(s) changed (allowed only where the arc fit picks another exact "
              f"arc within the same bounds; list each in the closing note):", file=out)
        for key, a, b in other:
            print(f"  {key}\n    old {a}\n    new {b}", file=out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", metavar="DIR", help="record the manifest into DIR")
    mode.add_argument("--check", metavar="DIR", nargs="?", const=str(DEFAULT_DIR),
                      help=f"compare with DIR's manifest (default {DEFAULT_DIR.relative_to(ROOT)})")
    ap.add_argument("--only", default="", help="only keys containing this")
    ap.add_argument("-j", "--processes", type=int, default=2, help="worker processes (at most 2)")
    ap.add_argument("--no-rs274", action="store_true", help="leave LinuxCNC's rs274 out")
    ap.add_argument("--times", metavar="JSON", help="save the seconds each case took")
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args(argv)
    if not CORPUS.is_dir():
        print(f"warning: no corpus at {CORPUS}: golden cases and samples only", file=sys.stderr)
    tmp = tempfile.TemporaryDirectory(prefix="pin-gencam-")
    gencam = make_gencam(Path(tmp.name)) \
        if any(args.only in f"{GENCAM_KEY}|{c}" for c in CALIBRATIONS) else None
    jobs = [j for j in jobs_for(programs(gencam=gencam)) if args.only in j[0]]
    rs274 = not args.no_rs274 and shutil.which("rs274") is not None
    if not rs274 and not args.no_rs274:
        print("warning: rs274 not found: the oracle is not run", file=sys.stderr)

    def progress(n, total, key, s):
        if not args.quiet and (s > 5 or n % 100 == 0 or n == total):
            print(f"[{n}/{total}] {s:6.1f} s {key}", file=sys.stderr)

    t0 = time.perf_counter()
    records, seconds = run_all(jobs, args.processes, rs274, progress)
    wall = time.perf_counter() - t0
    if args.times:
        Path(args.times).write_text(json.dumps(dict(sorted(seconds.items(), key=lambda kv: -kv[1])), indent=1))
    refused = sum("exit" in r for r in records.values())
    checked = sum("rs274" in r for r in records.values())
    accepted = sum(r.get("rs274", {}).get("ok", False) for r in records.values())
    summary = (f"{len(records)} cases ({len(records) - refused} corrected, {refused} refused; rs274 ran "
               f"{checked}, accepted {accepted}) in {wall:.1f} s")
    tmp.cleanup()
    if args.write:
        if args.only and (Path(args.write) / MANIFEST).exists():
            records = {**read_manifest(Path(args.write)), **records}
        path = write_manifest(Path(args.write), records)
        print(f"{summary}; written to {path}")
        return 0
    old = read_manifest(Path(args.check))
    if args.only:
        old = {k: v for k, v in old.items() if args.only in k}
    if not CORPUS.is_dir():
        old = {k: v for k, v in old.items() if not k.startswith("corpus/")}
    if gencam is None:
        old = {k: v for k, v in old.items() if not k.startswith("bench/")}
    changes = compare(old, records, rs274)
    report(changes)
    print(f"{summary}; {len(changes)} changed against {Path(args.check) / MANIFEST}")
    if any(calibration_of(key) in FROZEN for key, _, _ in changes):
        return 3
    return 1 if changes else 0


if __name__ == "__main__":
    sys.exit(main())
