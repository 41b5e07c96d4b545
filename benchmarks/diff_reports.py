"""`diff`'s reports on a broad set of pairs, recorded once and checked again later.

Pairs: every program of samples/ and of ../shared/corpus (at most --max-lines lines),
each corrected (as benchmarks/corpus_speed.py places it, in the dialect of its source)
with calibrations/s500_static.json, calibrations/s500_parametric.json and the identity,
and with s500_static.json and ``cycles="expand"`` too (programs correct refuses are left
out). For each pair the three reports of ``postproc diff`` (text, ``--all``, ``--json``),
or the error it ends with, are kept. The pairs the diff tests build
(tests/test_diff.py and the other tests calling ``compare_programs``) are captured while
those tests run (pytest with this module as a plugin; ``--no-tests`` leaves them out),
their inputs kept, and their reports (``DiffReport.to_dict()``, or the error) kept too;
a report is compared with the temporary folder its pair was written to left out.

  --record DIR   correct the programs into DIR/pairs, capture the test pairs into
                 DIR/tests, and write every report into DIR/reports.json
  --reports DIR  only compute DIR/reports.json again (DIR's pairs and tests as they are)
  --check DIR    compute the reports of DIR's pairs again and compare them with
                 DIR/reports.json: prints how many were compared and how many differ

The reports are made by the postproc package imported: the checkout first on PYTHONPATH,
else this one (PYTHONPATH=/other/checkout python benchmarks/diff_reports.py --reports DIR
records another checkout's).

Usage: python benchmarks/diff_reports.py --record DIR [--max-lines N] [--no-tests]
       python benchmarks/diff_reports.py --check DIR
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import pickle
import re
import subprocess
import sys
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# (appended: a checkout named first on PYTHONPATH is the one whose reports are made)
sys.path.append(str(ROOT))
sys.path.append(str(ROOT / "benchmarks"))

# the tests whose pairs are captured (those that call compare_programs or run diff)
TESTS = ["tests/test_diff.py", "tests/test_cli_columns.py", "tests/test_cli_hints.py",
         "tests/test_cli_setup_options.py", "tests/test_correct_start.py", "tests/test_dialect.py",
         "tests/test_dialect_sinumerik.py", "tests/test_dialect_sinumerik_cycles.py", "tests/test_dialect_vars.py",
         "tests/test_split_words.py", "tests/test_readme_walkthrough.py"]
CAPTURE_ENV = "POSTPROC_DIFF_CAPTURE"


# -- capturing the tests' pairs (this module as a pytest plugin) -----------------------
def pytest_configure(config) -> None:
    out = os.environ.get(CAPTURE_ENV)
    if not out:
        return
    from postproc.gcode import compare

    real = compare.compare_programs
    seen = [0]

    def capture(original, corrected, setup=None, progress=None, keep=None, **kwargs):
        args = []
        for src in (original, corrected):
            if isinstance(src, str) and "\n" not in src and os.path.exists(src) or isinstance(src, os.PathLike):
                args.append(("file", Path(src).read_bytes(), Path(src).name))
            else:
                args.append(("text", src, None))
        seen[0] += 1
        name = f"{os.environ.get('PYTEST_CURRENT_TEST', 'test').split(' ')[0]}#{seen[0]}"
        record = {"name": name, "args": args, "setup": setup, "keep": keep, "kwargs": kwargs,
                  "chunk_lines": compare.__dict__.get("CHUNK_LINES")}
        try:
            with open(Path(out) / f"{seen[0]:05d}.pkl", "wb") as fh:
                pickle.dump(record, fh)
        except Exception:  # noqa: BLE001 - a pair that does not pickle is left out
            pass
        return real(original, corrected, setup, progress, keep, **kwargs)

    compare.compare_programs = capture


def _replay(record: dict, tmp: Path) -> str:
    from postproc.gcode import compare

    default_chunk = getattr(compare, "CHUNK_LINES", None)
    srcs = []
    for k, (kind, data, name) in enumerate(record["args"]):
        if kind == "file":
            d = tmp / str(k)
            d.mkdir(exist_ok=True)
            (d / name).write_bytes(data)
            srcs.append(str(d / name))
        else:
            srcs.append(data)
    if record.get("chunk_lines") and hasattr(compare, "CHUNK_LINES"):
        compare.CHUNK_LINES = record["chunk_lines"]  # as small as the test made it
    kwargs = dict(record["kwargs"])
    reading = {k: kwargs.pop(k) for k in ("dialect", "subroutine_path", "limits", "cycles") if k in kwargs}
    if reading and "options" in inspect.signature(compare.compare_programs).parameters:
        # (how the program is read, given as the options correct was given)
        from postproc.gcode.options import CorrectOptions

        if "subroutine_path" in reading:
            reading["subroutine_path"] = tuple(reading["subroutine_path"])
        if reading.get("limits") is None:
            reading.pop("limits", None)
        kwargs["options"] = CorrectOptions(**reading)
    else:
        kwargs.update(reading)
    try:
        rep = compare.compare_programs(srcs[0], srcs[1], record["setup"], None, record["keep"], **kwargs)
    except Exception as exc:  # noqa: BLE001 - the error is the report
        return f"error {type(exc).__name__}: {exc}"
    finally:
        if default_chunk is not None:
            compare.CHUNK_LINES = default_chunk
    if record["keep"] is None:
        d = rep.to_dict()
    else:
        d = {"largest": [(m.lineno, m.lineno_corrected, m.delta_mm) for m in rep.largest(record["keep"])],
             "axis": rep.axis_stats(), "moves": rep.moves, "n_moved": rep.n_moved,
             "lines": (rep.lines_original, rep.lines_corrected, rep.lines_unchanged, rep.lines_inserted,
                       rep.lines_rewritten), "header": rep.header}
    for k in ("original", "corrected"):
        d.pop(k, None)
    return json.dumps(d, sort_keys=True)


# -- the corrected programs ------------------------------------------------------------
def _programs(max_lines: int) -> list[tuple[Path, str]]:
    from corpus_speed import CORPUS, dialect_of

    out = [(p, "generic") for p in sorted((ROOT / "samples").iterdir()) if p.suffix.lower() in (".nc", ".ngc")]
    if CORPUS.exists():
        exts = {".nc", ".ngc", ".gcode", ".tap", ".cnc", ".txt", ".mpf", ".spf", ".min", ".eia"}
        for p in sorted(CORPUS.rglob("*")):
            if p.is_file() and p.suffix.lower() in exts:
                with open(p, "rb") as fh:
                    if sum(1 for _ in fh) <= max_lines:
                        out.append((p, dialect_of(p)))
    return out


def _make_pairs(d: Path, max_lines: int) -> list[dict]:
    from corpus_speed import setup

    from postproc.calfile import load_calibration
    from postproc.engine.identity import IdentityEngine
    from postproc.gcode.pipeline import CorrectOptions, correct_file

    cals = [("static", load_calibration(ROOT / "calibrations" / "s500_static.json"), "auto"),
            ("parametric", load_calibration(ROOT / "calibrations" / "s500_parametric.json"), "auto"),
            ("identity", IdentityEngine(((-1e4, -1e4, -1e4), (1e4, 1e4, 1e4))), "auto"),
            ("static-expand", load_calibration(ROOT / "calibrations" / "s500_static.json"), "expand")]
    (d / "pairs").mkdir(parents=True, exist_ok=True)
    pairs = []
    for path, dialect in _programs(max_lines):
        for name, cal, cycles in cals:
            engine = cal if isinstance(cal, IdentityEngine) else cal.engine
            out = d / "pairs" / f"{len(pairs):04d}{path.suffix}"
            try:
                correct_file(path, out, engine, setup(),
                             CorrectOptions(extrapolate="linear", dialect=dialect, cycles=cycles))
            except Exception as exc:  # noqa: BLE001 - refused (PostprocError or not): no pair
                out.unlink(missing_ok=True)
                print(f"skip {path.name} {name}: {str(exc).splitlines()[0][:80] if str(exc) else type(exc)}")
                continue
            pairs.append({"original": str(path), "corrected": str(out), "dialect": dialect, "calibration": name})
    (d / "pairs.json").write_text(json.dumps(pairs, indent=1))
    return pairs


def _cli_reports(pair: dict) -> dict[str, str]:
    from click.testing import CliRunner

    from postproc.cli import main

    out = {}
    base = ["diff", pair["original"], pair["corrected"], "--dialect", pair["dialect"]]
    for variant, extra in (("text", []), ("all", ["--all"]), ("json", ["--json"])):
        r = CliRunner().invoke(main, [*base, *extra])
        text = r.output if r.exception is None or isinstance(r.exception, SystemExit) else (
            r.output + "".join(traceback.format_exception(r.exception)))
        out[variant] = f"exit {r.exit_code}\n{text}"
    return out


def _reports(d: Path) -> dict[str, str]:
    import tempfile

    reports: dict[str, str] = {}
    for k, pair in enumerate(json.loads((d / "pairs.json").read_text())):
        for variant, text in _cli_reports(pair).items():
            reports[f"pair {k} {Path(pair['original']).name} {pair['calibration']} {variant}"] = text
    tests = sorted((d / "tests").glob("*.pkl")) if (d / "tests").exists() else []
    for p in tests:
        with open(p, "rb") as fh:
            record = pickle.load(fh)
        with tempfile.TemporaryDirectory() as tmp:
            reports[f"test {p.stem} {record['name']}"] = _replay(record, Path(tmp))
    return reports


def _same_place(report: str) -> str:
    """``report`` with the temporary folder its replayed pair was written to left out."""
    return re.sub(r"/tmp/tmp[\w]+/", "<tmp>/", report)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--record", type=Path)
    g.add_argument("--reports", type=Path)
    g.add_argument("--check", type=Path)
    ap.add_argument("--max-lines", type=int, default=60_000)
    ap.add_argument("--no-tests", action="store_true", help="do not capture the tests' pairs")
    args = ap.parse_args()
    if args.record or args.reports:
        d = args.record or args.reports
        d.mkdir(parents=True, exist_ok=True)
        if args.record:
            _make_pairs(d, args.max_lines)
        if args.record and not args.no_tests:
            (d / "tests").mkdir(exist_ok=True)
            path = os.pathsep.join(p for p in (os.environ.get("PYTHONPATH"), str(ROOT), str(ROOT / "benchmarks")) if p)
            env = dict(os.environ, **{CAPTURE_ENV: str(d / "tests"), "PYTHONPATH": path})
            subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-p", "diff_reports", "-x",
                            "--no-header", "-p", "no:cacheprovider", *TESTS], cwd=ROOT, env=env, check=False)
        reports = _reports(d)
        (d / "reports.json").write_text(json.dumps(reports, indent=0, sort_keys=True))
        print(f"{len(reports)} reports recorded in {d / 'reports.json'}")
        return 0
    d = args.check
    before = json.loads((d / "reports.json").read_text())
    after = _reports(d)
    differ = [k for k in before if k not in after or _same_place(after[k]) != _same_place(before[k])]
    missing = [k for k in after if k not in before]
    for k in differ:
        print(f"DIFFERS: {k}")
    print(f"{len(before)} reports compared, {len(differ)} differ, {len(missing)} not recorded before")
    return 1 if differ or missing else 0


if __name__ == "__main__":
    sys.exit(main())
