"""The diagnosis matrix: `postproc check` on campaigns it has never seen, with a known truth.

Every campaign is measured on the virtual machine (:mod:`postproc.diagnose.vm`: the
S500-like machine without its lead-screw terms, Student-t tracker noise of 5 um sigma,
a tracker frame of its own) in one of eight shapes, with hidden effects added to the
machine as effect records or, for errors outside the catalogue, as displacement
functions written here (never the candidate effects' own formulas). Each is checked
against the parametric calibration fitted from the same machine's interferometer tables
(`--fixed`, as a user re-checks a tables calibration) unless the case says otherwise.

Printed: case / truth / verdict / suggestion / cross-validated RMS over the noise floor
(random folds before -> after the suggestions; the worst held-out split after: slabs,
blocks, load steps; for model-too-stiff, the finer model's), then, with
``--clean N``, the false-alarm rate over N seeds of each of the eight clean shapes
(N = 5: 40 campaigns; a false alarm is any suggestion).

Run:  python benchmarks/diagnose_matrix.py [--clean 5] [--seed 300] [--only WORD]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from postproc.calfile import calibration_from_dict, calibration_to_dict
from postproc.diagnose import vm

TRAVEL = 315.0


def eff(name, params, **config):
    return {"name": name, "config": config, "params": params}


# -- displacements outside the catalogue ------------------------------------------------

def bump(axis: int, centre: float, width: float, size_mm: float, along: int | None = None):
    """A local bump of the ``axis`` component, Gaussian in the position along ``along``."""
    along = axis if along is None else along

    def f(q, r, ctx):
        out = np.zeros_like(q)
        out[:, axis] = size_mm * np.exp(-0.5 * ((q[:, along] - centre) / width) ** 2)
        return out
    return f


def roll_xy(k_rad: float):
    """Roll of the carriage (about X) growing with X and Y together, acting through the
    tool vector: angle k (X/L)(Y/L), rotation of r about the X axis."""
    def f(q, r, ctx):
        a = k_rad * (q[:, 0] / TRAVEL) * (q[:, 1] / TRAVEL)
        out = np.zeros_like(q)
        out[:, 1] = -a * r[:, 2]
        out[:, 2] = a * r[:, 1]
        return out
    return f


def two_frames(offset_mm):
    """The tracker moved (a re-set-up) halfway through the campaign."""
    def f(q, r, ctx):
        out = np.zeros_like(q)
        out[len(q) // 2:] += offset_mm
        return out
    return f


# -- context columns -------------------------------------------------------------------

def warm_temp(t, rng):
    return 23.0 + (20.0 - 23.0) * np.exp(-t / 2400.0) + rng.normal(0, 0.02, len(t))


def ramp_temp(t, rng):
    return 20.0 + 4.0 * t / 7200.0 + rng.normal(0, 0.02, len(t))


def sparse(fn, keep: int):
    """A column logged in ``keep`` rows only (empty elsewhere)."""
    def g(t, rng):
        v = fn(t, rng)
        out = np.full(len(t), np.nan)
        idx = np.sort(rng.choice(len(t), keep, replace=False))
        out[idx] = v[idx]
        return v, out
    return g


def held(fn, every_s: float):
    """A column logged by sample and hold every ``every_s`` seconds."""
    def g(t, rng):
        v = fn(t, rng)
        k = np.floor(t / every_s)
        first = np.searchsorted(k, k)  # the first row of each logging interval
        return v, v[first]
    return g


def load_steps(t, rng):
    return np.repeat([0.0, 250.0, 500.0], -(-len(t) // 3))[:len(t)][rng.permutation(len(t))]


# -- the cases -------------------------------------------------------------------------

def cases():
    """(name, truth, shape, machine effects, options for vm.campaign, options for check)."""
    out = [(f"clean {s}", "nothing", s, [], {}, {}) for s in vm.SHAPES]
    out += [
        ("backlash X", "backlash:X +12 um", "random", [eff("backlash:X", {"b_mm": 0.012})], {}, {}),
        ("lost motion Y, raster dir=0", "backlash:Y -10 um", "raster", [eff("backlash:Y", {"b_mm": -0.010})], {}, {}),
        ("lead screw X 10 mm", "periodic:X 6 um @ 10 mm", "random",
         [eff("periodic:X", {"cos_mm": 0.006, "sin_mm": 0.0}, pitch_mm=10.0)], {"n": 90}, {}),
        ("lead screw Y 80 mm", "periodic:Y 7 um @ 80 mm", "random",
         [eff("periodic:Y", {"cos_mm": 0.004, "sin_mm": -0.0057}, pitch_mm=80.0)], {"n": 90}, {}),
        ("lead screw Z 80 mm on lines", "periodic:Z 7 um @ 80 mm", "lines",
         [eff("periodic:Z", {"cos_mm": 0.007, "sin_mm": 0.0}, pitch_mm=80.0)], {}, {}),
        ("warm-up", "thermal:t 4/15 um (Y/Z), 40 min", "random",
         [eff("thermal:t", {"dx_mm": 0.0, "dy_mm": 0.004, "dz_mm": 0.015}, tau_s=2400.0)], {}, {}),
        ("scale Y 40 ppm", "scale:Y 40 ppm", "random", [eff("scale:Y", {"scale": 4e-5})], {}, {}),
        ("straightness X bow", "straightness:X bow 12 um in Z", "planes",
         [eff("straightness:X", {"bow_y_mm": 0.0, "s_y_mm": 0.0, "bow_z_mm": 0.012, "s_z_mm": 0.0},
              center_mm=157.5, half_travel_mm=157.5)], {}, {}),
        ("positioning Z S-shape on lines", "positioning:Z S 10 um", "lines",
         [eff("positioning:Z", {"bow_mm": 0.0, "s_mm": 0.010}, center_mm=157.5, half_travel_mm=157.5)], {}, {}),
        ("squareness XY 40 urad", "squareness:XY 40 urad", "diagonals",
         [eff("squareness:XY", {"EC0Y_rad": 4e-5})], {}, {}),
        ("Abbe: pitch growing with X", "abbe:X", "tools",
         [eff("abbe:X", {"wx_rad_per_mm": 0.0, "wy_rad_per_mm": 2e-7, "wz_rad_per_mm": 0.0})], {}, {}),
        ("constant tilt (Abbe)", "abbe:tilt 60 urad", "tools",
         [eff("abbe:tilt", {"wx_rad": 6e-5, "wy_rad": 0.0, "wz_rad": 0.0})], {}, {}),
        ("load (constant deflection)", "load:load 20 um / 500", "logged",
         [eff("load:load", {"cx_mm_per_unit": 0.0, "cy_mm_per_unit": 0.0, "cz_mm_per_unit": -4e-5})],
         {"context": {"load": load_steps}}, {}),
        ("temperature growth", "thermal:temp 8 um/C in Z", "random",
         [eff("thermal:temp", {"kx_mm_per_C": 0.0, "ky_mm_per_C": 0.0, "kz_mm_per_C": 0.008})],
         {"context": {"temp": warm_temp}}, {}),
        ("sparse temperature (5 of 240 rows)", "thermal:temp 8 um/C in Z", "random",
         [eff("thermal:temp", {"kx_mm_per_C": 0.0, "ky_mm_per_C": 0.0, "kz_mm_per_C": 0.008})],
         {"context": {"temp": sparse(warm_temp, 5)}}, {}),
        ("sample-and-hold temperature (20 min)", "expansion:temp 12 ppm/C in X", "random",
         [eff("expansion:temp", {"ax_per_C": 1.2e-5, "ay_per_C": 0.0, "az_per_C": 0.0})],
         {"context": {"temp": held(ramp_temp, 1200.0)}}, {}),
        ("two at once: backlash + warm-up", "backlash:X 12 um + thermal:t 15 um Z", "random",
         [eff("backlash:X", {"b_mm": 0.012}),
          eff("thermal:t", {"dx_mm": 0.0, "dy_mm": 0.0, "dz_mm": 0.015}, tau_s=2400.0)], {"n": 80}, {}),
        ("two at once: screw + bow", "periodic:Y 16 mm 6 um + straightness:X bow 12 um", "random",
         [eff("periodic:Y", {"cos_mm": 0.006, "sin_mm": 0.0}, pitch_mm=16.0),
          eff("straightness:X", {"bow_y_mm": 0.012, "s_y_mm": 0.0, "bow_z_mm": 0.0, "s_z_mm": 0.0},
              center_mm=157.5, half_travel_mm=157.5)], {"n": 90}, {}),
        ("two at once: backlash Z + load", "backlash:Z -10 um + load:load", "logged",
         [eff("backlash:Z", {"b_mm": -0.010}),
          eff("load:load", {"cx_mm_per_unit": 0.0, "cy_mm_per_unit": 3e-5, "cz_mm_per_unit": 0.0})],
         {"context": {"load": load_steps}}, {}),
        ("local bump 15 um in X", "bump X at 240 mm (outside catalogue)", "random", [],
         {"n": 90, "extra": bump(0, 240.0, 20.0, 0.015)}, {}),
        ("local bump 15 um in Z along Y", "bump Z at Y 60 mm (outside catalogue)", "random", [],
         {"n": 90, "extra": bump(2, 60.0, 20.0, 0.015, along=1)}, {}),
        ("XY-dependent roll", "roll EA = k X Y, 150 urad at the far corner (outside catalogue)", "tools", [],
         {"extra": roll_xy(1.5e-4)}, {}),
        ("load x position", "ram along Y sagging under its load: 20 um at 500 and full extension (beam)",
         "logged", [], {"context": {"load": load_steps},
                        "extra": vm.ram_sag(0.020, 1, load_column="load", load_max=500.0)}, {}),
        ("load x position, larger", "the same ram, 50 um at 500 and full extension (beam)", "logged", [],
         {"context": {"load": load_steps}, "extra": vm.ram_sag(0.050, 1, load_column="load", load_max=500.0)}, {}),
        ("machine repeatability 4 um", "per-visit scatter (no model can remove it)", "random", [],
         {"visit_sigma_mm": 0.004}, {}),
        ("tracker moved halfway", "frame jump 15 um (nuisance, not the machine)", "random", [],
         {"extra": two_frames([0.0, 0.015, 0.0])}, {}),
        ("static calibration refitted", "s500 bows (static too stiff)", "random", [], {"n": 120},
         {"cal": "static"}),
        ("parametric refitted: lost motion, raster dir=0", "backlash:Y -12 um", "raster",
         [eff("backlash:Y", {"b_mm": -0.012})], {}, {"cal": "parametric"}),
        ("parametric refitted: warm-up", "thermal:t 15 um Z, 40 min", "random",
         [eff("thermal:t", {"dx_mm": 0.0, "dy_mm": 0.0, "dz_mm": 0.015}, tau_s=2400.0)], {"n": 120},
         {"cal": "parametric"}),
        ("parametric refitted: spindle tilt", "abbe:tilt 80 urad", "tools",
         [eff("abbe:tilt", {"wx_rad": 8e-5, "wy_rad": 0.0, "wz_rad": 0.0})], {"n": 80}, {"cal": "parametric"}),
        ("parametric refitted on a 45 mm raster", "s500 bows and waviness, 8 positions per axis", "raster", [],
         {}, {"cal": "parametric"}),
        # added after the cases above, so that those keep their seeds (seed + index)
        ("ram sag under its head", "ram along Y sagging 30 um at full extension (beam, outside catalogue)",
         "random", [], {"extra": vm.ram_sag(0.030, 1)}, {}),
        ("tracker moved at 60 %", "frame jump 10 um + 20 urad, rigid (nuisance, not the machine)", "random", [],
         {"moved": (0.6, 0.010, 2e-5)}, {}),
    ]
    return out


def refitted_calibration(method: str, meas):
    from postproc.engine.registry import fitter

    res = fitter(method)([meas])
    data = calibration_to_dict(res.engine, name=method, fit=res.info)
    return calibration_from_dict(data, path=f"{method}.json")


def run_case(case, seed: int):
    name, truth, shape, effects, opts, check_opts = case
    mach = vm.machine_with(effects) if effects else None
    opts = dict(opts)
    if name.startswith("parametric refitted"):
        meas = vm.campaign("raster", seed, machine=mach, **opts)
    else:
        meas = vm.campaign(shape, seed, machine=mach, **opts)
    check_opts = dict(check_opts)
    cal = None
    if "cal" in check_opts:
        cal = refitted_calibration(check_opts.pop("cal"), meas)
        check_opts["fixed"] = False
    return vm.check_campaign(meas, cal, **check_opts)


def row(res) -> tuple[str, str, str]:
    sug = ", ".join(s["effect"] for s in res.suggestions) or "none"
    rk, floor, v = res.ranking, res.noise.rms_mm, res.verdict_info
    if rk is None or not floor or v is None:
        return str(res.verdict), sug, "-"
    after = rk.final_cv_rms_mm / floor
    spatial = f"; held-out splits {v.spatial_ratio:.2f}" if v.spatial_ratio is not None else ""
    if v.name == "model-too-stiff":
        finer = ", ".join(v.details.get("finer_effects") or []) or "none"
        sug += f" (on the finer model: {finer})"
        spatial += f"; finer model {max(v.details['finer_random_ratio'], v.details['finer_spatial_ratio']):.2f}"
    return v.name, sug, f"{rk.base_cv_rms_mm / floor:.2f} -> {after:.2f}{spatial}"


def clean(n_seeds: int, seed0: int) -> None:
    """False alarms on clean campaigns: a suggestion, and a verdict other than consistent
    (with the ratio it would have needed at the Gaussian 1.15, for the heavy-tailed ones)."""
    from postproc.diagnose.verdict import CONSISTENT_RATIO

    false, total, t0 = 0, 0, time.perf_counter()
    not_consistent, gaussian_rule, heavy = 0, 0, 0
    per_shape = {}
    for s in vm.SHAPES:
        for k in range(n_seeds):
            res = vm.check_campaign(vm.campaign(s, seed0 + 1000 + k), max_selected=1, offer_empirical=False)
            hit = bool(res.suggestions)
            false += hit
            total += 1
            per_shape[s] = per_shape.get(s, 0) + hit
            v = res.verdict_info
            heavy += bool(res.noise.heavy_tailed)
            worst = max(v.random_ratio, v.spatial_ratio or 0.0) if v is not None else float("nan")
            gaussian_rule += bool(hit or not worst <= CONSISTENT_RATIO)
            if res.verdict != "consistent":
                not_consistent += 1
                print(f"  not consistent: {s} seed {seed0 + 1000 + k}: {res.verdict} ({v.evidence if v else ''})",
                      flush=True)
            if hit:
                print(f"  false suggestion: {s} seed {seed0 + 1000 + k}: "
                      + ", ".join(f"{x['effect']} (p = {x['p_value']:.2g})" for x in res.suggestions), flush=True)
    dt = (time.perf_counter() - t0) / max(total, 1)
    print(f"false-alarm rate: {false} of {total} clean campaigns ({false / total:.1%}) got a suggestion "
          f"({', '.join(f'{s} {v}' for s, v in per_shape.items())}); {dt:.1f} s per check")
    print(f"verdicts: {total - not_consistent} of {total} consistent ({not_consistent} not); "
          f"{heavy} flagged heavy-tailed; with the Gaussian 1.15 for all, {gaussian_rule} would not be")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--clean", type=int, default=0, help="seeds per clean shape for the false-alarm rate")
    ap.add_argument("--seed", type=int, default=300)
    ap.add_argument("--only", default=None, help="run only the cases whose name holds this word")
    ap.add_argument("--no-cases", action="store_true")
    args = ap.parse_args()
    if not args.no_cases:
        print("| case | truth | verdict | suggestion | CV RMS / floor (random folds: before -> after; "
              "worst held-out split after) |")
        print("|---|---|---|---|---|")
        for i, case in enumerate(cases()):
            if args.only and args.only not in case[0]:
                continue
            t0 = time.perf_counter()
            res = run_case(case, args.seed + i)
            v, sug, ratio = row(res)
            print(f"| {case[0]} | {case[1]} | {v} | {sug} | {ratio} |", flush=True)
            if res.verdict_info is not None and args.only:
                print(f"    evidence: {res.verdict_info.evidence} ({time.perf_counter() - t0:.1f} s)")
    if args.clean:
        clean(args.clean, args.seed)


if __name__ == "__main__":
    main()
