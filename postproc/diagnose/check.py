"""``postproc check``: hold a calibration against measurements.

Residuals of the calibration as it is (measured - model), a noise floor, a
cross-validated refit of its method (so a flexible model cannot hide a misfit),
where the residual sits (points, regions, approach directions, time, context), and
which physical effect would explain it (:mod:`postproc.diagnose.rank`).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from postproc.diagnose.campaign import campaign_warnings
from postproc.diagnose.crossval import DEFAULT_FOLDS, make_folds
from postproc.diagnose.data import Dataset
from postproc.diagnose.frame import FrameFit
from postproc.diagnose.jump import FrameJump, frame_jump
from postproc.diagnose.models import BaseModel, Fixed, base_model
from postproc.diagnose.noise import NoiseFloor, noise_floor
from postproc.diagnose.rank import (
    MAX_SELECTED,
    SIGNIFICANCE_P,
    Candidate,
    Ranking,
    empirical_offer,
    rank_effects,
)
from postproc.diagnose.robust import Screening, screen
from postproc.diagnose.verdict import Verdict, judge
from postproc.diagnose.where import components, where_it_fails
from postproc.effects import candidate_names, effect_from_dict, get_effect
from postproc.effects.composed import ComposedEngine
from postproc.engine.registry import fit_methods, fold_options, option_flag, refit_options
from postproc.errors import MeasurementError, MissingSetupError, PostprocError

# Points beyond the calibrated volume by more than this (mm) are outside it.
OUTSIDE_TOLERANCE_MM = 1e-3



@dataclass
class CheckResult:
    cal_path: str
    method: str
    files: list[str]
    ds: Dataset
    resid: np.ndarray  # measured - calibration (as it is)
    summary: dict
    noise: NoiseFloor
    where: dict
    ranking: Ranking | None
    cv_note: str = ""
    existing: list[str] = field(default_factory=list)
    fit_options: dict = field(default_factory=dict)
    fixed: bool = False
    register: bool = False
    frame: FrameFit | None = None
    volume_mm: np.ndarray | None = None
    resid_registered: np.ndarray | None = None  # measured - model after the registration alone
    screening: Screening | None = None  # duplicates and outliers excluded
    outside: list[str] = field(default_factory=list)  # rows outside the calibrated volume
    outside_excluded: bool = False
    warnings: list[dict] = field(default_factory=list)  # campaign diagnostics
    empirical: dict | None = None  # the last-resort empirical field, when the verdict is unexplained
    from_other_data: bool = False  # the calibration was not fitted on these files
    recorded: dict | None = None  # what 'fit --base' held fixed, read from the file (then used)
    refitted_effects: list = field(default_factory=list)  # effects of the file refitted on every fold
    verdict_info: Verdict | None = None  # judged on random and spatial held-out points
    jump: FrameJump | None = None  # a step of the measurement frame in time (the tracker moved)

    @property
    def suggestions(self) -> list[dict]:
        if self.ranking is None:
            return []
        out, names = [], list(self.existing)
        for c in self.ranking.selected:
            names.append(c.name)
            eff = c.effect
            out.append({
                "effect": c.name,
                "explained": c.explained,
                "rms_after_mm": c.rms_after_mm,
                "p_value": c.p_value,
                "parameters": dict(eff.params) if eff else {},
                "parameters_u_k2": dict(getattr(eff, "uncertainty", {}) or {}) if eff else {},
                "config": dict(eff.config) if eff else {},
                "description": eff.describe() if eff else "",
                "meaning": c.meaning,
                "compensable": eff.compensable_reason if eff else "",
                "command": self.fit_command(names),
            })
        return out

    @property
    def verdict(self) -> str | None:
        """"consistent", "missing-effect", "model-too-stiff", "campaign-limited" or
        "unexplained", judged on random and spatial held-out points
        (:mod:`postproc.diagnose.verdict`); None without a noise floor or a cross-validation."""
        return self.verdict_info.name if self.verdict_info is not None else None

    @property
    def extends(self) -> bool:
        """Suggestions keep the calibration and add effects to it (``fit --base``): the
        calibration is held as it is (--fixed) or its method cannot be refitted from points."""
        return self.fixed or self.method not in fit_methods()

    def fit_command(self, names: list[str]) -> str | None:
        stem = Path(self.cal_path).stem if self.cal_path else "calibration"
        added = [n for n in names if n not in self.existing]
        out = f"{stem}_{'_'.join(n.replace(':', '_') for n in added)}.json"
        if self.extends:
            if not self.cal_path:
                return None
            args = ["postproc", "fit", "--base", self.cal_path, *self.files]
            if not self.register:
                args.append("--no-register")
            for n in added:
                args += ["--effect", n]
            return shlex.join([*args, "-o", out])
        args = ["postproc", "fit", *self.files, "--method", self.method]
        for key, value in self.fit_options.items():
            args += [option_flag(key), str(value)]
        for n in names:
            args += ["--effect", n]
        return shlex.join([*args, "-o", out])

    def to_json(self) -> dict:
        rk = self.ranking
        return {
            "calibration": self.cal_path,
            "method": self.method,
            "effects_in_calibration": list(self.existing),
            "n_points": len(self.ds),
            "rms_mm": self.summary["rms_mm"],
            "max_mm": self.summary["max_mm"],
            "rms_xyz_mm": self.summary["rms_xyz_mm"],
            "max_xyz_mm": self.summary["max_xyz_mm"],
            "noise_floor_mm": self.noise.rms_mm,
            "noise_floor_source": self.noise.source,
            "noise_floor_robust_mm": self.noise.robust_rms_mm,
            "noise_excess_kurtosis": self.noise.kurtosis,
            "noise_heavy_tailed": self.noise.heavy_tailed,
            "cv_folds": rk.folds if rk else 0,
            "cv_rms_mm": rk.base_cv_rms_mm if rk else None,
            "cv_rms_after_mm": rk.final_cv_rms_mm if rk else None,
            "cv_note": self.cv_note,
            "verdict": self.verdict,
            "verdict_evidence": self.verdict_info.evidence if self.verdict_info else None,
            "verdict_detail": self.verdict_info.to_json() if self.verdict_info else None,
            "conditioning": rk.final_guard.to_json() if rk and rk.final_guard is not None else None,
            "calibration_from_other_data": self.from_other_data,
            "cv_ratio_to_floor": (rk.final_cv_rms_mm / self.noise.rms_mm) if rk and self.noise.rms_mm else None,
            "registration": (None if self.frame is None else
                             {"absorbed_by_model": True} if self.frame.absorbed else
                             self.frame.to_json(self.volume_mm)),
            "significance_p": SIGNIFICANCE_P,
            "suggestions": self.suggestions,
            "candidates": [
                {"effect": c.name, "status": c.status, "explained": c.explained,
                 "rms_after_mm": c.rms_after_mm, "p_value": c.p_value, "reason": c.reason,
                 "round": c.round}
                for c in ((rk.rounds[-1] if rk.rounds else []) + rk.untestable + rk.in_model)
            ] if rk else [],
            "where": self.where,
            "screening": self.screening.to_json() if self.screening else None,
            "outside_volume": {"rows": list(self.outside), "excluded": self.outside_excluded},
            "warnings": list(self.warnings),
            "empirical": self.empirical,
            "fixed_from_file": self.recorded,
            "frame_jump": self.jump.to_json() if self.jump is not None else None,
        }


def json_safe(obj):
    """Plain JSON data: numpy scalars to Python, NaN/inf to null."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def measured_residual(engine, ds: Dataset) -> np.ndarray:
    try:
        return ds.m - engine.forward(ds.q, ds.r, ds.ctx)
    except MissingSetupError as exc:
        raise MeasurementError(
            f"the measurements lack a column the calibration needs: {exc.message}",
            path=",".join(ds.paths),
            hint="measure with that column (dirx/diry/dirz, t, temp, load ...) or check a calibration without the effect",
        ) from None


def outside_volume(engine, ds: Dataset) -> np.ndarray:
    """(N,) True for rows whose commanded point lies outside the calibrated volume (beyond
    OUTSIDE_TOLERANCE_MM): there the calibration extrapolates."""
    vol = np.asarray(engine.volume_mm, dtype=float)
    return np.any((ds.q < vol[0] - OUTSIDE_TOLERANCE_MM) | (ds.q > vol[1] + OUTSIDE_TOLERANCE_MM), axis=1)


def _registered(engine, ds_all: Dataset, keep: np.ndarray, resid_all: np.ndarray) -> np.ndarray:
    """The residual after the measurement frame's registration on the points ``keep``
    (six at least), or as it is when that registration cannot be fitted."""
    if keep.sum() < 6:
        return resid_all
    try:
        fr = Fixed(engine, "registration", True).fit(ds_all.subset(keep), []).frame
    except PostprocError:
        return resid_all
    return resid_all if fr is None else resid_all - fr.displacement(ds_all.q, ds_all.r)


def _in_time(name: str) -> bool:
    """An effect that changes with time or temperature only (a warm-up): a step of the frame
    is tested against such a drift, never on its residual (fitted to a step, it hides it)."""
    needs = get_effect(name).needs
    return any(c == "t" or c.startswith("temp") for c in needs)


def _jump(model: BaseModel, ds: Dataset, effects: list) -> FrameJump | None:
    """A step of the measurement frame in time (:mod:`postproc.diagnose.jump`), on the
    residual of the model with the calibration's own effects and the suggested ones that
    depend on the position or the approach (a reversal or a lead screw measured along the
    time order of a raster is a step in time too), not the warm-ups: the test compares the
    step with a drift itself."""
    try:
        fitted = model.fit(ds, model.prepare(ds, [effect_from_dict(e.to_dict()) for e in effects]))
    except PostprocError:
        return None
    return frame_jump(ds, ds.m - fitted.predict(ds))


def run_check(cal, data, files: list[str], *, sigma_mm: float | None = None, folds: int = DEFAULT_FOLDS,
              candidates: list[str] | None = None, max_selected: int = MAX_SELECTED,
              fixed: bool | None = None, register: bool | None = None, offer_empirical: bool = True) -> CheckResult:
    """Check calibration ``cal`` (a loaded Calibration) against measurements ``data``.

    ``fixed``: hold the calibration (with its effects) as it is and rank effects on its
    residual, instead of refitting its method on the training folds.
    ``register``: fit a 6-DOF registration of the measurement frame as a nuisance
    (default: on with ``fixed``, off otherwise). ``offer_empirical``: when the verdict is
    "unexplained", size the empirical field (one more cross-validation).

    Duplicated rows and outliers (:mod:`postproc.diagnose.robust`) are excluded first,
    and, with ``fixed``, points outside the calibrated volume (the calibration would be
    extrapolated there); all are listed in the result.
    """
    from postproc.diagnose.refit import recorded_fixed

    record = recorded_fixed(cal) if fixed is None else None
    if record is not None:
        register = bool(record.get("register", True)) if register is None else bool(register)
    fixed = bool(fixed) or record is not None
    register = fixed if register is None else bool(register)
    ds_all = Dataset.from_measurements(data)
    engine = cal.engine
    base_engine = engine.base if isinstance(engine, ComposedEngine) else engine
    existing = [effect_from_dict(d) for d in (cal.effects or [])]
    resid_all = measured_residual(engine, ds_all)
    refitted: list = []  # effects 'fit --base' added: refitted on every training fold
    model: BaseModel
    if record is not None:
        added = set(record.get("fitted_effects") or [])
        held = [e for e in existing if e.name not in added]
        refitted = [e for e in existing if e.name in added]
        held_engine = ComposedEngine(base_engine, held) if held else base_engine
        model = Fixed(held_engine, "recorded by fit --base: its base held as it is, the effects it added "
                      "refitted on every training fold", register)
    elif fixed:
        model = Fixed(engine, "--fixed: the calibration as it is, effects fitted to its residual", register)
    else:
        # The method's options for a training fold (a grid fold fills lattice nodes left
        # without points from their neighbours).
        options = refit_options(base_engine)
        cv_options = {**options, **fold_options(cal.method)}
        model = base_model(cal.method, cv_options, engine=base_engine, register=register)
    options = refit_options(base_engine)
    keep = np.ones(len(ds_all), dtype=bool)
    outside = outside_volume(engine, ds_all)
    if fixed and outside.any() and not outside.all():
        keep &= ~outside
    screening_resid = _registered(engine, ds_all, keep, resid_all) if fixed and register else resid_all
    screening = screen(ds_all.subset(keep), screening_resid[keep])
    idx = np.nonzero(keep)[0][screening.keep]
    ds, resid = ds_all.subset(idx), resid_all[idx]
    noise = noise_floor(ds, sigma_mm)
    where = where_it_fails(ds, resid)
    ranking, note = None, ""
    frame, resid_registered = None, None
    try:
        groups = ds.repeat_groups()
        fold_masks = make_folds(groups, folds)
        names = candidates if candidates is not None else candidate_names(ds.ctx)
        if record is not None:
            ranking = rank_effects(model, ds, refitted, names, fold_masks, max_selected=max_selected)
            kept = [e for e in existing if e not in refitted]
            ranking.in_model[:0] = [Candidate(e.name, "in model", "held as in the base calibration") for e in kept]
        elif fixed:
            held_names = {e.name for e in existing}
            ranking = rank_effects(model, ds, [], [n for n in names if n not in held_names], fold_masks,
                                   max_selected=max_selected)
            ranking.in_model[:0] = [Candidate(e.name, "in model", "already in the calibration") for e in existing]
        else:
            ranking = rank_effects(model, ds, existing, names, fold_masks, max_selected=max_selected)
        note = f"{len(fold_masks)} folds; {model.description}"
        if register:
            frame = model.fit(ds, model.prepare(ds, existing) if not fixed else
                              model.prepare(ds, refitted)).frame
            if fixed and frame is not None and not frame.absorbed:
                resid_registered = resid - frame.displacement(ds.q, ds.r)
                where = where_it_fails(ds, resid_registered)
            if ranking.selected and ranking.final_frame is not None:
                frame = ranking.final_frame  # reported as fitted beside the suggested effects
    except PostprocError as exc:
        note = f"cross-validation not possible: {exc.message}"
    res = CheckResult(cal.path or "", cal.method, list(files), ds, resid, components(resid), noise, where,
                      ranking, note, [e.name for e in existing], options, fixed, register, frame,
                      np.asarray(engine.volume_mm, dtype=float), resid_registered)
    res.screening = screening
    res.recorded = record
    sources = [Path(p).name for p in (cal.fit or {}).get("sources", [])]
    res.from_other_data = bool(cal.fit and (cal.fit.get("kind") == "axis error tables"
                                            or (sources and sorted(sources) != sorted(Path(f).name for f in files))))
    res.outside = [ds_all.place(int(i)) for i in np.nonzero(outside)[0]]
    res.outside_excluded = bool(fixed and outside.any() and not outside.all())
    res.warnings = campaign_warnings(ds, cal, data, res)
    res.refitted_effects = refitted if fixed else existing
    if ranking is not None:
        res.jump = _jump(model, ds, [*res.refitted_effects,
                                     *(get_effect(c.name) for c in ranking.selected if not _in_time(c.name))])
        res.verdict_info = judge(res, model, groups, fold_masks)
    if offer_empirical and ranking is not None and res.verdict == "unexplained":
        try:
            offer = empirical_offer(model, ds, ranking, refitted if fixed else existing, fold_masks)
        except PostprocError:
            offer = None
        if offer is not None:
            offer["command"] = res.fit_command([*res.existing, *(c.name for c in ranking.selected),
                                                offer["effect"]])
            res.empirical = offer
    return res
