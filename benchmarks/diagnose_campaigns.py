"""`postproc check` on campaigns as they are really measured, and its false alarms on clean data.

Campaigns are made with the virtual machine (calibrations/s500.machine.json, 5 um tracker
noise per axis) and checked against the S500 interferometer-table calibration
(calibrations/s500_parametric.json, `--fixed`), or, for the clean synthetic baseline, with
a static calibration refitted under cross-validation.

Part 1 (``--clean N``): false alarms on clean data, N seeds per setting:
  - "tracker/tables --fixed": 60 random points x 2 approaches x 2 shots, t over 3 h;
  - "synthetic/static": the diagnose_detection baseline (70 points x 3 shots, tool
    vectors, t, temp, load, humidity), static calibration refitted.
Reported: data sets with any suggestion, data sets with a verdict other than consistent
(where the code gives one), rows excluded as outliers.

Part 2 (``--cases``): the table of case / truth / verdict / suggestion / CV RMS over floor.

Runs against whatever ``postproc`` is on the path, so the same script measures a baseline:
    PYTHONPATH=/path/to/old/tree python benchmarks/diagnose_campaigns.py --clean 20
    python benchmarks/diagnose_campaigns.py --clean 20 --cases
"""

from __future__ import annotations

import argparse
import inspect
import time
from pathlib import Path

import numpy as np

from postproc.calfile import (
    calibration_from_dict,
    calibration_to_dict,
    load_calibration,
)
from postproc.calibration.measurements import Measurements
from postproc.diagnose.check import run_check
from postproc.diagnose.vm import serpentine
from postproc.simulate import Machine, load_machine, measurement_plan, random_points, simulate_plan

ROOT = Path(__file__).parents[1]
MACHINE = ROOT / "calibrations" / "s500.machine.json"
TABLES_CAL = ROOT / "calibrations" / "s500_parametric.json"
CONSISTENT = 1.15


def check(cal, meas, fixed, **kw):
    params = inspect.signature(run_check).parameters
    kw = {k: v for k, v in kw.items() if k in params}
    return run_check(cal, [meas], [meas.path or "data.csv"], fixed=fixed, **kw)


def verdict(res) -> str:
    v = getattr(res, "verdict", None)
    if v is not None or not hasattr(res, "noise"):
        return v or "-"
    rk, floor = res.ranking, res.noise.rms_mm
    if rk is None or not floor:
        return "-"
    final = rk.final_cv_rms_mm if rk.selected else rk.base_cv_rms_mm
    if final > CONSISTENT * floor:
        return "unexplained*"
    return "missing-effect*" if rk.selected else "consistent*"


def machine_with(effects):
    base = load_machine(MACHINE)
    return Machine(base.geometry, effects=effects, noise=base.noise)


def tracker(rng, n=60, machine=None, tools=((0, 0, -100),), repeats=2):
    mach = machine or load_machine(MACHINE)
    plan = measurement_plan(random_points(mach.volume_mm, n, rng), tool_vectors=list(tools),
                            approach="both", repeats=repeats, time_span_s=3 * 3600)
    meas = simulate_plan(mach, plan, rng)
    meas.path, meas.linenos = "campaign.csv", np.arange(len(meas.q)) + 4
    return meas


def raster(machine, rng, step=35.0, repeats=2, zs=(0.0, 157.5, 315.0)):
    """Serpentine raster; the file records dir 0 for axes that did not move."""
    q, recorded = serpentine(step, zs)
    state = recorded.copy()
    for j in range(1, len(state)):
        state[j] = np.where(recorded[j] != 0, recorded[j], state[j - 1])
    q, recorded, state = (np.repeat(a, repeats, axis=0) for a in (q, recorded, state))
    recorded[1::repeats] = 0
    t = np.linspace(0, 3 * 3600, len(q))
    r = np.tile([0.0, 0.0, -100.0], (len(q), 1))
    m = machine.forward(q, r, {"dirx": state[:, 0], "diry": state[:, 1], "dirz": state[:, 2], "t": t})
    m = m + rng.normal(0, machine.noise.tracker_mm, q.shape)
    return Measurements(q=q, m=m, r=r, direction=recorded, context={"t": t}, path="raster.csv",
                        linenos=np.arange(len(q)) + 4)


def rotation(axis, angle):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def describe(res) -> tuple[str, str, str]:
    sug = ", ".join(s["effect"] for s in res.suggestions) or "none"
    floor = res.noise.rms_mm
    rk = res.ranking
    if rk is None or not floor:
        return verdict(res), sug, "-"
    final = rk.final_cv_rms_mm if rk.selected else rk.base_cv_rms_mm
    extra = ""
    emp = getattr(res, "empirical", None)
    if emp:
        extra = f" (empirical {emp['cv_rms_after_mm'] / floor:.2f})"
    return verdict(res), sug, f"{rk.base_cv_rms_mm / floor:.2f} -> {final / floor:.2f}{extra}"


def cases(seed: int):
    tables = load_calibration(TABLES_CAL)
    out = []

    rng = np.random.default_rng(seed)
    meas = tracker(rng, 70)
    meas.m = meas.m @ rotation([0, 0, 1], 20e-6).T + [0.005, 0, 0]
    out.append(("frame offset 5 um + rotation 20 urad", "no machine effect", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 1)
    meas = raster(machine_with([{"name": "backlash:Y", "params": {"b_mm": 0.015}}]), rng)
    out.append(("raster with dir=0 rows", "backlash:Y 15 um", check(tables, meas, True, max_selected=2)))

    rng = np.random.default_rng(seed + 2)
    meas = tracker(rng, 60, machine=machine_with([{"name": "backlash:X", "params": {"b_mm": 0.012}}]))
    meas.m[17] += [0.2, -0.05, 0.1]
    out.append(("200 um glitch in a repeat group", "backlash:X 12 um", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 3)
    meas = tracker(rng, 60)
    dup = np.arange(0, 60, 2)
    for name in ("q", "m", "r", "direction"):
        setattr(meas, name, np.vstack([getattr(meas, name), getattr(meas, name)[dup]]))
    meas.context = {k: np.concatenate([v, v[dup]]) for k, v in meas.context.items()}
    meas.linenos = np.arange(len(meas.q)) + 4
    out.append(("30 duplicated rows", "nothing", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 4)
    warm = machine_with([{"name": "thermal:t", "config": {"tau_s": 2400.0},
                          "params": {"dx_mm": 0.012, "dy_mm": -0.006, "dz_mm": 0.02}}])
    meas = raster(warm, rng)
    out.append(("raster during a warm-up", "thermal:t 12/-6/20 um", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 5)
    grid = machine_with([{"name": "periodic:X", "config": {"pitch_mm": 10.0},
                          "params": {"cos_mm": 0.008, "sin_mm": 0.0}}])
    meas = raster(grid, rng, step=20.0, repeats=2, zs=(0.0, 315.0))
    out.append(("regular 20 mm grid, 10 mm pitch", "periodic:X 8 um @ 10 mm", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 6)
    two = machine_with([
        {"name": "periodic:Y", "config": {"pitch_mm": 16.0}, "params": {"cos_mm": 0.006, "sin_mm": 0.0}},
        {"name": "periodic:Y", "config": {"pitch_mm": 5.3}, "params": {"cos_mm": 0.0, "sin_mm": 0.005}}])
    meas = simulate_plan(two, measurement_plan(random_points(two.volume_mm, 150, rng),
                                               tool_vectors=[(0, 0, -100)], repeats=2), rng)
    meas.path = "pitch.csv"
    out.append(("two pitches on Y", "periodic:Y 16 mm + 5.3 mm", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 7)
    meas = tracker(rng, 80)
    u = meas.q / 315.0
    meas.m[:, 2] += 0.24 * np.prod(u - 0.5, axis=1)
    meas.m[:, 0] += 0.030 * np.sin(np.pi * u[:, 1]) * np.sin(np.pi * u[:, 2])
    out.append(("axis coupling outside the catalogue", "xyz coupling (none in catalogue)", check(tables, meas, True)))

    rng = np.random.default_rng(seed + 8)
    meas = tracker(rng, 60, tools=((0, 0, -100), (0, 0, -200)), repeats=2)
    meas.m[meas.r[:, 2] == -200, 2] -= 0.030
    out.append(("tool-length error 30 um (2nd tool)", "tool length (none in catalogue)", check(tables, meas, True)))
    return out


def clean(n_seeds: int) -> None:
    tables = load_calibration(TABLES_CAL)
    for setting in ("tracker/tables --fixed", "synthetic/static"):
        sugg = not_consistent = outliers = 0
        t0 = time.perf_counter()
        for s in range(n_seeds):
            if setting.startswith("tracker"):
                res = check(tables, tracker(np.random.default_rng(5000 + s)), True)
            else:
                from postproc.diagnose.synthetic import make_data
                from postproc.engine.static import fit as static_fit

                meas = make_data([], seed=1000 + s)[0]
                eng = static_fit([meas]).engine
                cal = calibration_from_dict(calibration_to_dict(eng, name="s", fit={}), path="static.json")
                res = check(cal, meas, False)
            sugg += bool(res.suggestions)
            not_consistent += verdict(res).rstrip("*") not in ("consistent",)
            sc = getattr(res, "screening", None)
            outliers += len(sc.outliers) if sc is not None else 0
        dt = (time.perf_counter() - t0) / n_seeds
        print(f"clean {setting}: {n_seeds} data sets, with a suggestion {sugg} ({sugg / n_seeds:.0%}), "
              f"verdict not consistent {not_consistent}, rows flagged as outliers {outliers}; "
              f"{dt:.1f} s per check", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clean", type=int, default=0, help="seeds of clean data per setting")
    ap.add_argument("--cases", action="store_true", help="print the table of campaign cases")
    ap.add_argument("--seed", type=int, default=100)
    args = ap.parse_args()
    if args.clean:
        clean(args.clean)
    if args.cases:
        print("| case | truth | verdict | suggestion | CV RMS / floor (before -> after suggestions) |")
        print("|---|---|---|---|---|")
        for name, truth, res in cases(args.seed):
            v, sug, ratio = describe(res)
            print(f"| {name} | {truth} | {v} | {sug} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
