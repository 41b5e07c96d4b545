"""Output size and path deviation of corrected programs with arcs.

    python benchmarks/arc_output.py [PROGRAM[@X,Y,Z] ...]

Each program (default: samples/pocket.nc and a 3,000-line gencam program when
../shared/bench exists) is corrected with calibrations/s500_parametric.json at the
default tolerance and run on calibrations/s500.machine.json through verify. ``@X,Y,Z``
gives the G54 offset. Prints lines in/out, growth, arcs kept/split/linearised, the
two-sided max deviation before and after correction and the time taken.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).parents[1]
sys.path.insert(0, str(ROOT))

from postproc.calfile import load_calibration  # noqa: E402
from postproc.gcode import emit  # noqa: E402
from postproc.gcode.path import Setup  # noqa: E402
from postproc.gcode.pipeline import CorrectOptions, correct_text  # noqa: E402
from postproc.simulate.machine import load_machine  # noqa: E402
from postproc.simulate.program import verify_program  # noqa: E402

TOOLS = {t: 50.0 + t for t in range(1, 100)}


def main(args: list[str]) -> None:
    cal = load_calibration(ROOT / "calibrations" / "s500_parametric.json")
    machine = load_machine(ROOT / "calibrations" / "s500.machine.json")
    progs = [(a.split("@")[0], a.split("@")[1] if "@" in a else None) for a in args]
    tmp = Path(tempfile.mkdtemp())
    if not progs:
        progs = [(str(ROOT / "samples" / "pocket.nc"), None)]
        gencam = ROOT.parent / "shared" / "bench" / "gencam.py"
        if gencam.is_file():
            raw = tmp / "cam_raw.nc"
            subprocess.run([sys.executable, str(gencam), "3000", str(raw), "7"], check=True, capture_output=True)
            # O-words and G28 are refused: drop them
            keep = [ln for ln in raw.read_text().splitlines(keepends=True) if not ln.startswith(("O", "G28"))]
            (tmp / "cam3000.nc").write_text("".join(keep))
            progs.append((str(tmp / "cam3000.nc"), "10,10,100"))
    print("| program | lines in | lines out (without header) | growth | arcs kept / split / linearised | "
          "max before | max after | model error | time |")
    print("|---|---|---|---|---|---|---|---|---|")
    for prog, off in progs:
        offsets = {"G54": tuple(float(v) for v in off.split(","))} if off else {}
        setup = Setup(offsets=offsets, tool_lengths=TOOLS)
        text = Path(prog).read_text(encoding="utf-8", errors="surrogateescape")
        t = time.perf_counter()
        out, rep = correct_text(text, cal.engine, setup, CorrectOptions(extrapolate="clamp"))
        dt = time.perf_counter() - t
        fixed = tmp / "fixed.nc"
        fixed.write_text(out)
        args_setup = {"offsets": offsets, "tool_lengths": TOOLS}
        before, after = verify_program(prog, machine, [], args_setup, corrected=fixed).runs
        split = getattr(rep, "arcs_split", 0)
        # the program's own lines (the header carries the setup, 99 tool lengths here)
        body = rep.lines_out - len(emit.split_header(out)[0])
        print(f"| {Path(prog).name} | {rep.lines_in:,} | {body:,} | {body / rep.lines_in:.2f}x | "
              f"{rep.arcs_kept} / {split} / {rep.arcs_linearised} | {before.max_mm * 1000:.2f} um | "
              f"{after.max_mm * 1000:.2f} um | {model_error(prog, machine, cal.engine, setup) * 1000:.2f} um | "
              f"{dt:.2f} s |")


def model_error(prog: str, machine, engine, setup: Setup) -> float:
    """How far the calibration's exact correction of the nominal path lands from it on the
    machine (feed moves): what no emitted program can beat."""
    import numpy as np

    from postproc.gcode.path import program_path

    nom = program_path(prog, setup, max_step_mm=0.05)
    q = nom.points_mm - nom.tool_mm
    ideal = q + np.asarray(engine.correction(nom.points_mm, nom.tool_mm, nom.context).q)
    actual = machine.forward(ideal, nom.tool_mm, nom.context)
    return float(np.linalg.norm(actual - nom.points_mm, axis=1)[~nom.rapid].max())


if __name__ == "__main__":
    main(sys.argv[1:])
