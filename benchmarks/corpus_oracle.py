"""LinuxCNC's own interpreter as the oracle on the long corpus programs.

tests/test_oracle_scale.py runs every corpus program of up to MAX_LINES (10,000) lines
through rs274; this script runs the longer ones: every program of ../shared/corpus
(real/, linuxcnc/, pygcode-linuxcnc/; .nc .ngc .tap .gcode) with more than MAX_LINES
lines, corrected in the linuxcnc dialect with --cycles expand, in three cases:

- ``scale``: the uniform-scale machine of test_oracle_scale (StaticEngine, k = 1.0002,
  every work offset, tool length and G28/G30 position zero, so program and machine
  coordinates coincide). Checked as the test checks it: rs274 accepts the corrected
  program; every canonical end point of the original over k lies on the corrected path,
  and the two paths (arcs drawn as LinuxCNC draws them) are within the tolerance plus
  rs274's rounding of each other, both ways.
- ``static`` and ``parametric``: calibrations/s500_static.json and s500_parametric.json,
  the program placed in the calibrated volume as benchmarks/corpus_speed.py's setup()
  does (every work offset at X150 Y150 Z150, tool lengths 0, the start and the G28/G30
  positions at X150 Y150 Z300, --extrapolate linear); rs274 gets the same offsets and
  stored positions as parameters and starts from the same point (a G53 G0 line put before
  the program's first line, or after a leading %, in both runs). Checked: rs274 accepts
  the corrected program, and the corrected path as rs274 gives it, run on the
  calibration's forward model (linearly extrapolated, tool offset zero), lies within
  tolerance + model error + rs274's rounding of the original's path as rs274 gives it,
  both ways. Arcs are sampled every 0.02 mm; straight feeds every 0.5 mm for the
  parametric model (the static one is affine: their ends suffice); traverses are
  compared by their end points only (the corrector moves a rapid's end, not its way
  there). The model error is how far the calibration's exact correction of the
  original's feed points lands from them on the same forward model.

Paths are compared in mm. rs274 prints 4 decimals in the program's units: its rounding
adds 0.2 um to a bound (as in the test), 5.08 um for a program in inches (G20), whose
check is correspondingly coarser (the test compares such programs in inches against
the mm tolerance). The scale case's paths start at the end of the first motion (where
the machine came from is unknown), as in the test. The calibrated cases' start at the
start position: the points there before the machine leaves it are not compared (it sits
there uncorrected), the way from there is.

A case is SKIP when rs274 refuses the original, the original makes splines (rs274
prints no NURBS geometry) or correct refuses the program (with its message); FAIL when
rs274 refuses the corrected program or a distance exceeds its bound. Prints one row per
program and case: lines, the result with the largest distance and its bound (um; or the
reason), and the seconds taken by rs274 on the original, correct, rs274 on the output
and the check. Exits 1 when a case fails. ``--json OUT`` saves the rows (with the model
error).

Usage: python benchmarks/corpus_oracle.py [--only SUBSTRING] [--cases scale,static,parametric]
                                          [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

from conftest import corpus_files, polyline_distance  # noqa: E402
from corpus_speed import ABOVE, OFFSETS  # noqa: E402
from corpus_speed import setup as calibrated_setup  # noqa: E402
from oracle import RS274, machine_path, run_rs274, uses_inches, uses_nurbs  # noqa: E402
from test_oracle_scale import MAX_LINES, TOOLS, K  # noqa: E402
from test_oracle_scale import _setup as scale_setup  # noqa: E402

from postproc.calfile import load_calibration  # noqa: E402
from postproc.engine.static import StaticEngine  # noqa: E402
from postproc.errors import PostprocError  # noqa: E402
from postproc.gcode.pipeline import CorrectOptions, correct_text  # noqa: E402

CORPUS = ROOT.parent / "shared" / "corpus"
SOURCES = ("real", "linuxcnc", "pygcode-linuxcnc")
CASES = ("scale", "static", "parametric")
CALIBRATIONS = {"static": ROOT / "calibrations" / "s500_static.json",
                "parametric": ROOT / "calibrations" / "s500_parametric.json"}
ROUNDING = 2e-4  # rs274 prints 4 decimals: 0.09 um on each side (as in test_oracle_scale)
INCH_ROUNDING = ROUNDING * 25.4  # the same in inches: 2.2 um on each side
LINE_STEP = 0.5  # sampling of straight feeds on a non-affine forward model (mm)
RS274_TIMEOUT = 1800.0
# rs274's parameter file holds lengths in inches: (G54..G59.3 offsets, G28, G30)
_INCH = 25.4
_G5X_PARAM = [5221 + 20 * i for i in range(len(OFFSETS))]
_HOME_PARAM = {"G28": 5161, "G30": 5181}


def programs(only: str) -> list[tuple[Path, int]]:
    out = []
    for p in corpus_files(SOURCES):
        if only not in str(p.relative_to(CORPUS)):
            continue
        n = p.read_bytes().count(b"\n")  # as the test counts lines
        if n > MAX_LINES:
            out.append((p, n))
    return out


def calibrated_params() -> dict[int, float]:
    """rs274's parameters for corpus_speed's setup(): G54 selected, every offset, G28/G30."""
    s = calibrated_setup()
    params = {5220: 1.0}
    for name, base in zip(OFFSETS, _G5X_PARAM, strict=True):
        off = s.offsets[name]
        vals = [off[a] for a in "XYZ"] if isinstance(off, dict) else list(off)
        params.update({base + j: vals[j] / _INCH for j in range(3)})
    for name, base in _HOME_PARAM.items():
        params.update({base + j: s.home[name][a] / _INCH for j, a in enumerate("XYZ")})
    return params


def from_start(text: str) -> str:
    """``text`` with a move to corpus_speed's start position before its first line (after
    a leading % line)."""
    line = f"G53 G0 X{ABOVE['X']:g} Y{ABOVE['Y']:g} Z{ABOVE['Z']:g}\n"
    first, sep, rest = text.partition("\n")
    if first.strip() == "%":
        return first + sep + line + rest
    return line + text


class Oracle:
    """rs274 runs of one program's original, cached per setup."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.cache: dict[str, tuple] = {}

    def run(self, text: str, calibrated: bool, line_step: float | None):
        """(rs274's result, end points, dense path, traverse ends, how many of the path's
        first points are at the start position, before the machine leaves it)."""
        if not calibrated:
            res = run_rs274(text, tools=TOOLS, timeout=RS274_TIMEOUT)
            return (res, *machine_path(res, line_step, mm=True), 0)
        res = run_rs274(from_start(text), tools=TOOLS, params=calibrated_params(), timeout=RS274_TIMEOUT)
        ends, dense, rapid = machine_path(res, line_step, mm=True)  # starts at the start position
        start = np.array([ABOVE[a] for a in "XYZ"])
        still = np.linalg.norm(dense - start, axis=1) <= rounding(res)
        lead = int(np.argmin(still)) if not still.all() else len(still)
        return res, ends[1:], dense, rapid, lead

    def original(self, calibrated: bool, line_step: float | None):
        key = f"{calibrated}/{line_step}"
        if key not in self.cache:
            t0 = time.perf_counter()
            got = self.run(self.text, calibrated, line_step)
            self.cache[key] = (*got, time.perf_counter() - t0)
        return self.cache[key]


def rounding(*runs) -> float:
    """What rs274's printing (4 decimals) can add to a distance between two of its paths."""
    return INCH_ROUNDING if any(uses_inches(r) for r in runs) else ROUNDING


def check_scale(ref_ends, ref_path, got_path, rnd: float) -> tuple[float, float]:
    """(largest distance, bound) of test_oracle_scale's three checks."""
    tol = CorrectOptions().tolerance_mm + rnd
    target = ref_path / K
    worst = max(polyline_distance(ref_ends / K, got_path).max(), polyline_distance(got_path, target).max(),
                polyline_distance(target, got_path).max())
    return float(worst), tol


def check_calibrated(engine, ref_path, ref_rapid, ref_lead, got_path, got_lead,
                     rnd: float) -> tuple[float, float, float]:
    """(largest distance, bound, model error): the corrected path on the forward model
    against the original's, both ways. The paths' first ``*_lead`` points are at the start
    position (the machine sits there uncorrected): not compared, though the original's way
    from the start is."""
    actual = engine.forward(got_path[got_lead:])
    ref_points = ref_path[ref_lead:]
    feed = ref_points[~ref_rapid[ref_lead:]]
    ideal = feed + np.asarray(engine.correction(feed).q)
    model = float(np.linalg.norm(engine.forward(ideal) - feed, axis=1).max()) if len(feed) else 0.0
    worst = max(polyline_distance(actual, ref_path).max(), polyline_distance(ref_points, actual).max())
    return float(worst), CorrectOptions().tolerance_mm + model + rnd, model


def run_case(path: Path, lines: int, case: str, oracle: Oracle, engines: dict) -> dict:
    row: dict = {"program": str(path.relative_to(CORPUS)), "case": case, "lines": lines}
    calibrated = case != "scale"
    line_step = LINE_STEP if case == "parametric" else None
    res, ref_ends, ref_path, ref_rapid, ref_lead, row["rs274_s"] = oracle.original(calibrated, line_step)
    if not res.ok or not len(ref_ends):
        row.update(result="SKIP", reason="rs274 refuses the original: " + (res.error.splitlines() or ["no motion"])[0])
        return row
    if uses_nurbs(res):
        row.update(result="SKIP", reason="the original makes splines (NURBS_FEED): rs274 prints no geometry")
        return row
    if calibrated:
        engine = engines[case]
        setup = calibrated_setup()
        opts = CorrectOptions(dialect="linuxcnc", cycles="expand", extrapolate="linear")
    else:
        engine = StaticEngine(K * np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
        setup = scale_setup()
        opts = CorrectOptions(dialect="linuxcnc", cycles="expand")
    t0 = time.perf_counter()
    try:
        out, _ = correct_text(oracle.text, engine, setup, opts, path=str(path))
    except PostprocError as exc:
        row.update(result="SKIP", reason="correct refuses: " + exc.message.splitlines()[0],
                   correct_s=time.perf_counter() - t0)
        return row
    row["correct_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    res2, _, got_path, _, got_lead = oracle.run(out, calibrated, line_step)
    row["rs274_out_s"] = time.perf_counter() - t0
    if not res2.ok:
        row.update(result="FAIL", reason="rs274 refuses the corrected program: " + res2.error.replace("\n", " | ")[:300])
        return row
    t0 = time.perf_counter()
    if calibrated:
        worst, bound, model = check_calibrated(engines["forward_" + case], ref_path, ref_rapid, ref_lead,
                                               got_path, got_lead, rounding(res, res2))
        row["model_error_um"] = model * 1e3
    else:
        worst, bound = check_scale(ref_ends, ref_path, got_path, rounding(res, res2))
    row["check_s"] = time.perf_counter() - t0
    row.update(max_um=worst * 1e3, bound_um=bound * 1e3, result="PASS" if worst <= bound else "FAIL")
    if worst > bound:
        row["reason"] = f"path {worst * 1e3:.2f} um from the original's, bound {bound * 1e3:.2f} um"
    return row


def _fmt(row: dict) -> str:
    def sec(key: str) -> str:
        return f"{row[key]:10.1f}" if key in row else f"{'':10}"

    figures = f"{row['max_um']:7.3f} {row['bound_um']:7.3f}" if "max_um" in row else f"{'':15}"
    text = f"{row['case']:10} {row['lines']:7,} {row['result']:4} {figures}" + \
        "".join(sec(k) for k in ("rs274_s", "correct_s", "rs274_out_s", "check_s")) + f"  {row['program']}"
    return text + (f"\n{'':29}{row['reason']}" if "reason" in row else "")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", default="", help="only programs whose path contains this")
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated, of " + ", ".join(CASES))
    ap.add_argument("--json", dest="json_out", help="save the rows as JSON")
    args = ap.parse_args()
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    if bad := [c for c in cases if c not in CASES]:
        ap.error(f"unknown case(s) {', '.join(bad)}: choose from {', '.join(CASES)}")
    if RS274 is None:
        print("rs274 (LinuxCNC's interpreter, linuxcnc-uspace) is not installed", file=sys.stderr)
        return 1
    if not CORPUS.is_dir():
        print(f"no corpus at {CORPUS}", file=sys.stderr)
        return 1
    engines: dict = {}
    for case in cases:
        if case in CALIBRATIONS:
            engines[case] = load_calibration(CALIBRATIONS[case]).engine
            engines["forward_" + case] = engines[case].with_extrapolation("linear")
    progs = programs(args.only)
    print(f"{len(progs)} corpus programs of more than {MAX_LINES:,} lines; cases {', '.join(cases)}; "
          f"max and bound in um, times in s")
    print(f"{'case':10} {'lines':>7} {'':4} {'max':>7} {'bound':>7}{'rs274':>10}{'correct':>10}{'rs274 out':>10}"
          f"{'check':>10}  program")
    rows = []
    t_all = time.perf_counter()
    for path, n in progs:
        oracle = Oracle(path.read_bytes().decode("utf-8", errors="surrogateescape"))
        for case in cases:
            row = run_case(path, n, case, oracle, engines)
            rows.append(row)
            print(_fmt(row), flush=True)
    counts = {k: sum(r["result"] == k for r in rows) for k in ("PASS", "FAIL", "SKIP")}
    print(f"{counts['PASS']} pass, {counts['FAIL']} fail, {counts['SKIP']} skipped; "
          f"{time.perf_counter() - t_all:.0f} s in all")
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=1))
    return 1 if counts["FAIL"] else 0


if __name__ == "__main__":
    sys.exit(main())
