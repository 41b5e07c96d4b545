"""How long verify PROGRAM takes on a long program, against the time to sample its path.

Writes a raster program of about N lines over the S500-like machine's cube (passes
of 1 mm G1 segments, 2 mm apart, joined by half-circle arcs, as CAM output looks),
then times (wall, and CPU of this process in brackets), in the same run:

- baseline: ``program_path`` sampling the program at the verify step (0.5 mm);
- the nominal path (move ends, arcs as 10 nm chords) and the nearest-segment query of
  the uncorrected run;
- the full ``verify_program`` with a static calibration (in-process correction included).

    python benchmarks/verify_speed.py [--lines N]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from postproc.calfile import load_calibration
from postproc.gcode.path import Setup, program_path
from postproc.simulate import load_machine
from postproc.simulate.program import verify_program
from postproc.simulate.verify import RUN_STEP_MM, evaluate_run, nominal_path, nominal_polyline

REPO = Path(__file__).resolve().parents[1]


def raster(n_lines: int) -> str:
    rows = ["%", "G21 G90 G17 G94", "G0 Z60", "G0 X20 Y20", "G1 Z50 F500"]
    y, step, x0, x1, seg = 20.0, 2.0, 20.0, 120.0, 1.0
    forward = True
    while len(rows) < n_lines:
        xs = np.arange(x0 + seg, x1 + seg / 2, seg)
        for x in (xs if forward else (x0 + x1 - xs)):
            rows.append(f"G1 X{x:.3f} F1500")
        cx = x1 if forward else x0
        rows.append(f"G{3 if forward else 2} X{cx:.3f} Y{y + step:.3f} I0 J{step / 2:.4f}")
        y += step
        forward = not forward
        if y > 290:
            y = 20.0
            rows.append(f"G1 Y{y:.3f}")
    rows += ["G0 Z60", "M30", "%"]
    return "\n".join(rows) + "\n"


class _Clock:
    """Wall and CPU time since the last lap."""

    def __init__(self) -> None:
        self.wall, self.cpu = time.perf_counter(), time.process_time()

    def lap(self) -> str:
        wall, cpu = time.perf_counter(), time.process_time()
        text = f"{wall - self.wall:7.2f} s ({cpu - self.cpu:.2f} s CPU)"
        self.wall, self.cpu = wall, cpu
        return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=20000)
    args = ap.parse_args()
    machine = load_machine(REPO / "calibrations" / "s500.machine.json")
    cal = load_calibration(REPO / "calibrations" / "s500_static.json")
    with tempfile.TemporaryDirectory() as d:
        prog = Path(d) / "raster.nc"
        prog.write_text(raster(args.lines))
        clock = _Clock()
        path = program_path(str(prog), Setup(), max_step_mm=RUN_STEP_MM)
        t_base = clock.lap()
        nominal = nominal_path(str(prog), Setup())
        poly = nominal_polyline(nominal)
        t_nom = clock.lap()
        run = evaluate_run("uncorrected", machine, path, poly, nominal.lineno)
        t_run = clock.lap()
        rep = verify_program(prog, machine, [cal], {})
        t_all = clock.lap()
    print(f"program: {args.lines} lines, {len(path)} samples at {RUN_STEP_MM} mm, "
          f"{len(nominal)} nominal points")
    print(f"  baseline program_path ({RUN_STEP_MM} mm)        {t_base}")
    print(f"  nominal path + polyline index        {t_nom}")
    print(f"  one run: machine + nearest segment   {t_run}  (max {run.max_mm * 1000:.1f} um)")
    print(f"  verify_program, static, with correction {t_all}  "
          f"(after: max {rep.runs[1].max_mm * 1000:.1f} um)")


if __name__ == "__main__":
    main()
