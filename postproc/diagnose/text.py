"""The readable ``postproc check`` report (lines of text; the CLI prints them)."""

from __future__ import annotations

import numpy as np

from postproc.diagnose.check import CheckResult
from postproc.diagnose.rank import SIGNIFICANCE_P
from postproc.effects.base import AXES

# After the suggested effects, a cross-validated RMS above this many times the noise
# floor means the model's form is wrong, not just incomplete.
FAR_ABOVE_FLOOR = 2.0

# The calibration as it is fits the points this much worse than its method refitted
# on held-out folds: it no longer describes the machine these points measured.
WORSE_THAN_REFIT = 1.2

# A reversal between +1 and -1 approaches larger than this many standard errors is
# marked as a finding (3 sigma: one false mark in ~700 clean axes).
REVERSAL_FLAG_SIGMAS = 3.0


def rms_of(resid) -> float:
    return float(np.sqrt(np.mean(np.sum(np.asarray(resid) ** 2, axis=1)))) if len(resid) else 0.0


def um(v: float) -> str:
    return f"{v * 1000:.2f}"


def vec_um(v, signed: bool = True) -> str:
    fmt = "{:+.2f}" if signed else "{:.2f}"
    return " ".join(f"{a.lower()} {fmt.format(x * 1000)}" for a, x in zip(AXES, v, strict=True))


def vec_g(v) -> str:
    return " ".join(f"{a.lower()} {x:+.3g}" for a, x in zip(AXES, v, strict=True))


def format_report(res: CheckResult) -> list[str]:
    s, nf, rk = res.summary, res.noise, res.ranking
    eff = f", effects {', '.join(res.existing)}" if res.existing else ""
    out = [f"check of {res.cal_path} ({res.method}{eff}) against {len(res.ds)} points "
           f"from {', '.join(res.files)}"]
    out.append(f"residual (measured - model): RMS {um(s['rms_mm'])} um, max {um(s['max_mm'])} um")
    out.append(f"  per axis RMS (um): {vec_um(s['rms_xyz_mm'], False)};  mean: {vec_um(s['mean_xyz_mm'])}")
    # a floor from repeats or a declared sigma has its RMS (and a declared one its sigma)
    if nf.source == "repeats" and nf.rms_mm is not None:
        out.append(f"noise floor: {um(nf.rms_mm)} um (3D RMS from repeated points, {nf.dof} degrees of freedom)")
        if nf.heavy_tailed and nf.robust_rms_mm is not None:
            out.append(f"  heavy-tailed noise: excess kurtosis {nf.kurtosis:.1f} of the repeat deviations, robust "
                       f"floor (Qn) {um(nf.robust_rms_mm)} um; the floor is less certain than its degrees of "
                       "freedom say, and the verdict allows for it")
    elif nf.source == "declared" and nf.rms_mm is not None and nf.sigma_mm is not None:
        meas = f"; repeats say {um(nf.measured_rms_mm)} um" if nf.measured_rms_mm else ""
        out.append(f"noise floor: {um(nf.rms_mm)} um (3D RMS of the declared sigma {um(nf.sigma_mm[0])} um{meas})")
    else:
        out.append("noise floor: unknown (no repeated points; give --sigma MM, the instrument's sigma per axis)")
    if res.recorded is not None:
        rec = res.recorded
        added = ", ".join(rec.get("fitted_effects") or []) or "none"
        out.append(f"made by 'fit --base {rec.get('base')}': held fixed as recorded in the file "
                   f"({'; '.join(rec.get('held') or [])}), refitted on every training fold: {added} "
                   "(--no-fixed refits the whole method)")
    if res.frame is not None:
        if res.frame.absorbed:
            out.append("measurement frame: its registration is held by the model itself (origin and axes)")
        else:
            beside = " (fitted beside the suggested effects)" if res.ranking and res.ranking.selected else ""
            out.append(f"measurement frame registered (a nuisance of the measurement, not a machine error){beside}: "
                       f"{res.frame.describe(res.volume_mm)}")
            if res.resid_registered is not None:
                out.append(f"  residual after the registration alone: RMS {um(rms_of(res.resid_registered))} um")
    if rk is not None:
        ratio = f" = {rk.base_cv_rms_mm / nf.rms_mm:.2f} x the noise floor" if nf.rms_mm else ""
        out.append(f"cross-validated RMS: {um(rk.base_cv_rms_mm)} um{ratio} ({res.cv_note})")
        if not res.fixed and res.from_other_data:
            out.append("  this calibration came from other data: its method is refitted here on these points; "
                       "'postproc check ... --fixed' keeps it as it is and suggests 'postproc fit --base' "
                       "to add effects to it")
        if rk.final_guard is not None and rk.final_guard.undetermined:
            out.append("  " + rk.final_guard.lines()[1])
        if not res.fixed and s["rms_mm"] > WORSE_THAN_REFIT * rk.base_cv_rms_mm:
            out.append(f"  the calibration fits these points worse ({um(s['rms_mm'])} um) than its method refitted "
                       "to them: the machine changed since it was calibrated, or the calibration came from "
                       "other data; --fixed ranks the effects on the calibration as it is")
    else:
        out.append(res.cv_note)
    out += _screening(res)
    if res.warnings:
        out += ["", "what this campaign cannot show:"] + [f"  {w['message']}" for w in res.warnings]
    out += ["", "where it fails:"] + _where(res)
    out += [""] + _ranking(res)
    out += ["", *_verdict(res)]
    if res.empirical:
        e, floor = res.empirical, res.noise.rms_mm
        ratio = f" = {e['cv_rms_after_mm'] / floor:.2f} x the floor" if floor else ""
        out.append(f"  last resort, an empirical correction ({e['effect']}: {e['description']}): "
                   f"cross-validated RMS {um(e['cv_rms_before_mm'])} -> {um(e['cv_rms_after_mm'])} um{ratio}; "
                   "it names no cause and holds only inside that extent")
        if e.get("command"):
            out.append(f"  add it: {e['command']}")
    return out


def _screening(res: CheckResult) -> list[str]:
    sc = res.screening
    if sc is None or (not sc.duplicates and not sc.outliers):
        return []
    out = []
    if sc.duplicates:
        out.append(f"duplicated rows (one shot written twice; kept once): {len(sc.duplicates)}: "
                   + ", ".join(d["place"] for d in sc.duplicates[:8]) + (" ..." if len(sc.duplicates) > 8 else ""))
    if sc.outliers:
        out.append(f"outliers excluded from the analysis: {len(sc.outliers)} (the outlier rule of "
                   "postproc.metrology.outliers, family-wise 0.1 %; the suggested 'fit' leaves them out too)")
        for o in sc.outliers[:10]:
            out.append(f"  {o['place']}  residual {vec_um(o['residual_mm'])} um: {o['reason']}")
        if len(sc.outliers) > 10:
            out.append(f"  ... and {len(sc.outliers) - 10} more (see --json)")
    return out


def _verdict(res: CheckResult) -> list[str]:
    """The verdict with its evidence in one line (and the finer model's fit command)."""
    v, rk = res.verdict_info, res.ranking
    if v is None:
        return ["verdict: none (no noise floor to compare with: give --sigma or measure repeated points)"
                if rk is not None else "verdict: none (no cross-validation)"]
    out = [f"verdict: {v.name}: {v.evidence}"]
    if v.details.get("finer_command"):
        out.append(f"  refit with the finer model: {v.details['finer_command']}")
    return out


def _where(res: CheckResult) -> list[str]:
    w = res.where
    out = ["  worst points:"]
    for p in w["worst"]:
        q = p["q_mm"]
        out.append(f"    {p['place']}  X {q[0]:.3f} Y {q[1]:.3f} Z {q[2]:.3f}  "
                   f"residual {vec_um(p['residual_mm'])} um (|{um(p['norm_mm'])}| um)")
    out.append("  by region (RMS um in quarters of each axis's travel):")
    for a, bins in w["by_region"].items():
        worst = max(bins, key=lambda b: b["rms_mm"])
        cells = " | ".join(f"{b['from']:.0f}..{b['to']:.0f}: {um(b['rms_mm'])}" for b in bins)
        out.append(f"    {a}: {cells}   (worst {worst['from']:.0f}..{worst['to']:.0f} mm)")
    if w["by_direction"]:
        out.append("  by approach direction (mean residual along the axis):")
        for a, d in w["by_direction"].items():
            flag = ("  <- reversal error" if abs(d["reversal_mm"]) > REVERSAL_FLAG_SIGMAS * d["stderr_mm"]
                    else "")
            out.append(f"    {a}: +1 {um(d['mean_plus_mm'])} um, -1 {um(d['mean_minus_mm'])} um: "
                       f"difference {um(d['reversal_mm'])} +- {um(d['stderr_mm'])} um{flag}")
    else:
        out.append("  by approach direction: no dirx/diry/dirz columns")
    if w.get("by_tool"):
        out.append("  by tool vector (mean residual um, RMS um, n points):")
        for b in w["by_tool"]:
            t = b["tool_mm"]
            out.append(f"    tool {t[0]:g},{t[1]:g},{t[2]:g} mm: {vec_um(b['mean_xyz_mm'])}; RMS {um(b['rms_mm'])}  "
                       f"(n {b['n']})")
    if w["along_time"]:
        out.append("  along time t (mean residual um per quarter of the campaign, n points):")
        for b in w["along_time"]:
            out.append(f"    t {b['from']:.0f}..{b['to']:.0f} s: {vec_um(b['mean_xyz_mm'])}  (n {b['n']})")
    for name, c in w["context"].items():
        r = c["correlation_xyz"]
        flag = "  <- correlated" if c["flagged"] else ""
        out.append(f"  against {name}: slope (um per unit) {vec_g(np.asarray(c['slope_xyz_mm_per_unit']) * 1000)}; "
                   f"correlation {' '.join(f'{v:+.2f}' for v in r)}{flag}")
    return out


def _ranking(res: CheckResult) -> list[str]:
    rk = res.ranking
    if rk is None:
        return ["missing effects: not ranked (no cross-validation)"]
    out = [f"missing effects (each added to the model and cross-validated; significant at p < {SIGNIFICANCE_P:g}):"]
    sug = res.suggestions
    last = rk.rounds[-1] if rk.rounds else []
    if not sug and any(c.status == "significant" for c in last):
        out.append("  none added (--max-effects 0); significant candidates, best first:")
        out += [f"    {c.name}: explains {c.explained * 100:.1f} % (p = {c.p_value:.2g})"
                for c in last if c.status == "significant"]
    elif not sug:
        out.append("  none: no candidate effect explains the residual significantly")
    for i, (c, sgg) in enumerate(zip(rk.selected, sug, strict=True), 1):
        after = "" if c.rms_after_mm is None else f"RMS after {um(c.rms_after_mm)} um "  # set when selected
        out.append(f"  {i}. {c.name}: explains {c.explained * 100:.1f} % of the residual variance, "
                   f"{after}(p = {c.p_value:.1g})")
        out.append(f"     {sgg['description']}")
        out.append(f"     {sgg['meaning']}; {sgg['compensable']}")
        if sgg["parameters_u_k2"]:
            out.append("     k=2 uncertainty: " + ", ".join(
                (f"{k} undetermined" if not np.isfinite(v) else
                 f"{k} +- {v * 1000:.2f} um" if k.endswith("_mm") else f"{k} +- {v:.3g}")
                for k, v in sgg["parameters_u_k2"].items()))
        keeps = " (keeps the calibration, adds the effect)" if res.extends else ""
        out.append(f"     add it{keeps}: {sgg['command']}" if sgg["command"] else
                   f"     the {res.method} method cannot be refitted from points: add it to a static fit")
    if last and sug:
        nxt = next((c for c in last if c.status == "significant"), last[0])
        if nxt.status == "significant":
            out.append(f"  stopped at {len(sug)} effects (--max-effects); next: {nxt.name} explains "
                       f"{nxt.explained * 100:.1f} % (p = {nxt.p_value:.2g})")
        else:
            why = f"; {nxt.reason}" if nxt.reason else ""
            out.append(f"  next best, not suggested: {nxt.name} explains {nxt.explained * 100:.1f} % "
                       f"(p = {nxt.p_value:.2g}{why})")
            if nxt.effect is not None and nxt.reason:
                out.append(f"     {nxt.effect.describe()}")
    elif last:
        out.append("  best tried: " + ", ".join(
            f"{c.name} {c.explained * 100:+.1f} % (p = {c.p_value:.2g})" for c in last[:3]))
    if sug and res.noise.rms_mm:
        ratio = rk.final_cv_rms_mm / res.noise.rms_mm
        out.append(f"  with all suggestions: cross-validated RMS {um(rk.final_cv_rms_mm)} um = "
                   f"{ratio:.2f} x the noise floor")
        if ratio > FAR_ABOVE_FLOOR:
            out.append("  still far above the noise floor: the errors are not a few missing effects but "
                       "the shape of the axes; fit a more flexible method (interval, grid, or parametric "
                       "from axis error tables) and check it")
    if rk.untestable:
        out.append("untestable with this data:")
        out += [f"  {c.name}: {c.reason}" for c in rk.untestable]
    if rk.in_model:
        out.append("already in the model: " + ", ".join(c.name for c in rk.in_model))
    return out

