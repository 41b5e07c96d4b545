"""Time the split-arc fitting of the G-code writer alone, on pieces recorded from a run.

``capture``: run ``postproc correct`` on a program and record every call of the
writer's ``arcfit.MoveFit.piece`` (its move, plan, arguments, the engine subdivisions it asks for and the
segments it returns) in a pickle. ``run``: replay the recorded calls with the
checkout's emitter, check that every call returns the recorded segments and print the
median wall and CPU time of the replays (``--repeats``). Paired A/B: record once, then replay with
each checkout (``PYTHONPATH=CHECKOUT``).

  python benchmarks/arcfit_replay.py capture PROGRAM CALIBRATION OUT.pkl [correct options...]
  python benchmarks/arcfit_replay.py run OUT.pkl [--repeats R] [--limit N]   (N: the first N pieces)
"""

from __future__ import annotations

import pickle
import statistics
import sys
import time
from typing import Any

import numpy as np


def _plain(seg: Any) -> Any:
    """A segment as comparable plain data (a dict or a record with slots)."""
    if isinstance(seg, dict):
        d = dict(seg)
    else:
        d = {k: getattr(seg, k) for k in type(seg).__slots__ if getattr(seg, k, None) is not None}
    if not d.get("takeup"):
        d.pop("takeup", None)
    if isinstance(d.get("spec"), dict):
        d["spec"] = {k: v for k, v in d["spec"].items() if k != "replace"}
    d["qe"] = [float(v) for v in d["qe"]]
    return repr(sorted(d.items()))


def capture(program: str, calibration: str, out: str, extra: list[str]) -> None:
    from click.testing import CliRunner

    from postproc.cli import main
    from postproc.gcode import arcfit

    calls: list[tuple] = []
    orig = arcfit.MoveFit.piece

    def wrapped(self, s, Q, nom, bulge, qe, final):
        subs: list = []
        writer = self.w
        sub0 = writer.subdivision

        def rec(*a, **k):
            r = sub0(*a, **k)
            subs.append(r)
            return r

        writer.subdivision = rec
        try:
            res = orig(self, s, Q, nom, bulge, qe, final)
        finally:
            del writer.subdivision
        plan = self.plan
        keep = {k: plan[k] for k in ("nsweep", "mismatch", "whole", "curve") if k in plan}
        calls.append(((self.mv, keep, s, Q, nom, bulge, list(qe), final, self.d, self.budget), subs,
                      [_plain(x) for x in res]))
        return res

    arcfit.MoveFit.piece = wrapped
    r = CliRunner().invoke(main, ["correct", program, "-c", calibration, "-o", "/dev/null", *extra])
    if r.exit_code != 0:
        raise SystemExit(r.output)
    with open(out, "wb") as f:
        pickle.dump(calls, f)
    print(f"{len(calls)} pieces recorded in {out}")


def run(path: str, repeats: int, limit: int | None = None) -> None:
    from postproc.gcode.arcfit import MoveFit
    from postproc.gcode.emitter import EmitterMixin

    class Replay(EmitterMixin):
        def __init__(self) -> None:
            self.subs: list = []

        def subdivision(self, *a, **k):
            return self.subs.pop(0)

    with open(path, "rb") as f:
        calls = pickle.load(f)[:limit]
    arcs = sum(1 for c in calls if c[0][0].arc is not None)
    times, cpu = [], []
    for rep in range(repeats):
        obj = Replay()
        bad = 0
        t0, c0 = time.perf_counter(), time.process_time()
        results = []
        for args, subs, _want in calls:
            obj.subs = list(subs)
            mv, plan, s, Q, nom, bulge, qe, final, d, budget = args
            results.append(MoveFit(obj, mv, plan, d, budget).piece(s, Q, nom, bulge, qe, final))
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        if rep == 0:
            for (_a, _s, want), got in zip(calls, results, strict=True):
                if [_plain(x) for x in got] != want:
                    bad += 1
            print(f"{len(calls)} pieces ({arcs} of arcs): {bad} differ from the recording")
    print(f"replay: median {statistics.median(times):.3f} s wall, {statistics.median(cpu):.3f} s cpu "
          f"over {repeats} (min {min(times):.3f} wall, {min(cpu):.3f} cpu)")


if __name__ == "__main__":
    np.seterr(all="ignore")
    if sys.argv[1] == "capture":
        capture(sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5:])
    else:
        reps = int(sys.argv[sys.argv.index("--repeats") + 1]) if "--repeats" in sys.argv else 3
        lim = int(sys.argv[sys.argv.index("--limit") + 1]) if "--limit" in sys.argv else None
        run(sys.argv[2], reps, lim)
