"""``postproc fit ... --effect NAME``: a calibration with physical effects added.

The base method is fitted jointly with the effects where it is linear in its
parameters (static) and through the fitter's linear response otherwise (see :mod:`postproc.diagnose.models`).
The result's engine is the base engine composed with the fitted effects; the
calibration file stores the base model and the effects (``FitResult.effects``).
"""

from __future__ import annotations

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.diagnose.models import Fitted, Fixed, base_model
from postproc.effects import effect_from_dict, get_effect
from postproc.effects.composed import ComposedEngine
from postproc.engine.base import FitResult
from postproc.errors import CalibrationError, MeasurementError

#: Default of ``fit --max-correction`` (mm): machine-tool geometric errors are tens of
#: micrometres; a correction of a millimetre somewhere in the volume is a fit gone wrong
#: (an undetermined parameter), not a machine.
MAX_CORRECTION_MM = 1.0
# Points per axis of the lattice over the calibrated volume where the correction is
# evaluated (besides the measured points themselves).
CORRECTION_LATTICE = 7


def effect_list(effect_names) -> list[str]:
    """A repeated --effect counts once, except ``periodic:AXIS``: a second one is a second
    pitch on the same axis (found on the residual of the first)."""
    out: list[str] = []
    for n in effect_names:
        if n not in out or n.startswith("periodic:"):
            out.append(n)
    return out


def check_effects_testable(ds: Dataset, effects) -> None:
    """Refuse effects the data cannot determine, naming the column or variation missing."""
    for e in effects:
        why = e.untestable_reason(ds.q, ds.r, ds.ctx)
        if why:
            miss = e.missing(ds.ctx)
            hint = (f"measure with a {', '.join(miss)} column (see the formats section)" if miss
                    else "measure with that variable varied, or drop the effect")
            raise MeasurementError(f"effect {e.name} cannot be fitted from this data: {why}",
                                   path=",".join(ds.paths), hint=hint)


def _effect_lines(fitted: Fitted) -> list[str]:
    out = []
    if fitted.guard is not None:
        out += fitted.guard.lines()
    for e in fitted.effects:
        out.append(f"effect {e.name}: {e.describe()}")
        u = getattr(e, "uncertainty", None)
        if u:
            out.append("  k=2 uncertainty: " + ", ".join(
                (f"{k} undetermined" if not np.isfinite(v) else
                 f"{k} +- {v * 1000:.2f} um" if k.endswith("_mm") else f"{k} +- {v:.3g}") for k, v in u.items()))
        out.append(f"  {e.meaning}; {e.compensable_reason}")
    if fitted.frame is not None:
        if fitted.frame.absorbed:
            out.append("measurement frame: held by the base model itself (no separate registration)")
        else:
            out.append(f"measurement frame registered (not stored): {fitted.frame.describe(fitted.engine.volume_mm)}")
    return out


def _info(ds: Dataset, resid: np.ndarray, fitted: Fitted) -> dict:
    info = {
        "n_points": len(ds), "rms_mm": float(np.sqrt(np.mean(np.sum(resid**2, axis=1)))),
        "max_mm": float(np.max(np.linalg.norm(resid, axis=1))),
        "sources": list(ds.paths), "effects": [e.name for e in fitted.effects],
    }
    notes = column_notes(ds, fitted.effects)
    if notes:
        info["notes"] = notes
    if fitted.guard is not None:
        info["conditioning"] = fitted.guard.to_json()
    if fitted.frame is not None and not fitted.frame.absorbed:
        info["registration"] = fitted.frame.to_json(fitted.engine.volume_mm)
    return info


def column_notes(ds: Dataset, effects) -> list[str]:
    """The calibration's notes: each effect fitted on a context column that was sparse,
    gappy or sample-and-hold (:func:`postproc.diagnose.data.screen_columns`)."""
    out = []
    for n in ds.column_notes:
        users = [e.name for e in effects if n["column"] in e.needs]
        if users:
            out.append(f"{', '.join(users)} depend(s) on {n['message']}")
    return out


def fit_with_effects(method: str, data, effect_names, register: bool = False, **options) -> FitResult:
    """Fit ``method`` on the measurements ``data`` together with the named effects
    (and a registration of the measurement frame when ``register``)."""
    ds = Dataset.from_measurements(data)
    names = effect_list(effect_names)
    effects = [get_effect(n) for n in names]
    check_effects_testable(ds, effects)
    model = base_model(method, options, register=register)
    prepared = model.prepare(ds, effects)
    fitted = model.fit(ds, prepared)
    resid = ds.m - fitted.predict(ds)
    engine = ComposedEngine(fitted.engine, fitted.effects)
    result = FitResult(engine=engine, residuals_mm=resid)
    result.report = [f"{method} fit with {len(effects)} effect(s) on {len(ds)} points ({model.description})"]
    result.report += fitted.report
    result.report += _effect_lines(fitted)
    result.info = _info(ds, resid, fitted)
    result.report += [f"note: {n}" for n in result.info.get("notes", [])]
    result.effects = [e.to_dict() for e in fitted.effects]
    return result


def extend_calibration(cal, data, effect_names, register: bool = True) -> FitResult:
    """``fit --base CAL``: the calibration ``cal`` held as it is (its base and its effects),
    the named effects fitted to its residual on ``data`` (with a registration of the
    measurement frame when ``register``); the result is the same base with the effects added.

    This is exactly the model ``check --fixed`` ranks, so the figure it promises is the
    one this fit delivers."""
    ds = Dataset.from_measurements(data)
    existing = [effect_from_dict(d) for d in (cal.effects or [])]
    held = {e.name for e in existing}
    names = effect_list(effect_names)
    again = [n for n in names if n in held and not n.startswith("periodic:")]
    if again:
        raise CalibrationError(f"{cal.path}: effect(s) {', '.join(again)} already in the calibration",
                               hint="name only effects to add; refit the calibration to change existing ones")
    effects = [get_effect(n) for n in names]
    check_effects_testable(ds, effects)
    base_engine = cal.engine.base if isinstance(cal.engine, ComposedEngine) else cal.engine
    model = Fixed(cal.engine, "fit --base: the calibration as it is", register)
    prepared = model.prepare(ds, effects)
    fitted = model.fit(ds, prepared)
    resid = ds.m - fitted.predict(ds)
    all_effects = [*existing, *fitted.effects]
    engine = ComposedEngine(base_engine, all_effects) if all_effects else base_engine
    result = FitResult(engine=engine, residuals_mm=resid)
    result.report = [f"{cal.method} calibration {cal.path} kept as it is; {len(effects)} effect(s) added, "
                     f"fitted on {len(ds)} points ({model.description})"]
    result.report += _effect_lines(fitted)
    result.info = _info(ds, resid, fitted)
    result.report += [f"note: {n}" for n in result.info.get("notes", [])]
    result.info["effects"] = [e.name for e in all_effects]
    _raw_check(result, cal, ds, effects, engine, register, base_engine, existing)
    result.info["base"] = {"path": cal.path, "method": cal.method, "fit": dict(cal.fit or {})}
    result.info["fixed"] = fixed_record(cal, existing, fitted.effects, register)
    result.effects = [e.to_dict() for e in all_effects]
    return result


def _raw_rms(engine, ds: Dataset) -> float:
    return float(np.sqrt(np.mean(np.sum((ds.m - engine.forward(ds.q, ds.r, ds.ctx)) ** 2, axis=1))))


def _raw_check(result: FitResult, cal, ds: Dataset, effects, engine, register: bool, base_engine,
               existing) -> None:
    """The written calibration against its base on the raw data (no registration), in the
    report and ``fit.raw_rms_mm``. With a registration, the frame may take what an effect
    describes: a ram's sag has an offset and a tilt, which look like a tracker set up
    elsewhere, so the effect is stored without them and the file can be worse than its base
    on the raw points. Then a warning gives both figures and the one without the
    registration (``--no-register``: for a frame that is the machine's own, or did not move)."""
    before, after = _raw_rms(cal.engine, ds), _raw_rms(engine, ds)
    raw = {"input_mm": before, "written_mm": after}
    if register and effects and after > before:
        model = Fixed(cal.engine, "fit --base --no-register", False)
        alt = model.fit(ds, model.prepare(ds, effects))
        alt_engine = ComposedEngine(base_engine, [*existing, *alt.effects])
        raw["without_registration_mm"] = _raw_rms(alt_engine, ds)
        message = (f"on the raw points (no registration) the written calibration is worse than its base: RMS "
                   f"{before * 1000:.2f} -> {after * 1000:.2f} um. The registration (not stored) took part of what "
                   "the effects describe (an offset or a tilt that grows with an axis, as a ram's sag has, looks "
                   "like a tracker set up elsewhere). If the measurement frame is the machine's own (the tracker "
                   "registered to the machine, or not moved since the base was measured), fit with --no-register: "
                   f"{raw['without_registration_mm'] * 1000:.2f} um on the raw points")
        result.report.append(f"warning: {message}")
        result.info.setdefault("warnings", []).append(message)
    else:
        result.report.append(f"raw points (no registration): RMS {before * 1000:.2f} um with the base, "
                             f"{after * 1000:.2f} um with the written calibration")
    result.info["raw_rms_mm"] = raw


def fixed_record(cal, held_effects, added_effects, register: bool) -> dict:
    """What ``fit --base`` held fixed and what it fitted: read back by ``check``, which
    re-checks such a calibration the same way (the base held, the added effects refitted)."""
    return {
        "by": "fit --base",
        "base": cal.path,
        "method": cal.method,
        "held": [f"the {cal.method} model (all its parameters)"] + [f"effect {e.name}" for e in held_effects],
        "held_effects": [e.name for e in held_effects],
        "fitted_effects": [e.name for e in added_effects],
        "register": bool(register),
    }


def recorded_fixed(cal) -> dict | None:
    """The record of what ``fit --base`` held fixed (:func:`fixed_record`), also for files
    written before the record existed (their ``fit.base``); None for other calibrations."""
    fit = cal.fit or {}
    if isinstance(fit.get("fixed"), dict):
        return fit["fixed"]
    base = fit.get("base")
    if not isinstance(base, dict):
        return None
    held = list((base.get("fit") or {}).get("effects") or [])
    names = [d.get("name") for d in (cal.effects or [])]
    return {"by": "fit --base", "base": base.get("path"), "method": base.get("method", cal.method),
            "held": [f"the {cal.method} model (all its parameters)"] + [f"effect {n}" for n in held],
            "held_effects": held, "fitted_effects": names[len(held):], "register": True}


def max_correction(engine, data=None) -> tuple[float, np.ndarray]:
    """Largest |correction| (mm) of ``engine`` (forward(q, r) - q - r) over a lattice of its
    volume and the measured points, with the measurements' tool vectors and context
    (cycled over the lattice). Returns (size, where: the commanded point)."""
    vol = np.asarray(engine.volume_mm, dtype=float)
    axes = [np.linspace(vol[0, j], vol[1, j], CORRECTION_LATTICE) for j in range(3)]
    lattice = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    qs, rs, ctx = [lattice], [np.zeros_like(lattice)], {}
    if data:
        ds = Dataset.from_measurements(data)
        idx = np.arange(len(lattice)) % len(ds)
        qs.append(ds.q)
        rs = [ds.r[idx], ds.r]
        ctx = {k: np.concatenate([v[idx], v]) for k, v in ds.ctx.items()}
    q, r = np.vstack(qs), np.vstack(rs)
    dev = np.linalg.norm(engine.forward(q, r, ctx) - q - r, axis=1)
    i = int(np.argmax(dev))
    return float(dev[i]), q[i]


def refuse_large_correction(engine, data, limit_mm: float, output: str) -> None:
    """The guard of ``fit --max-correction``: a calibration that corrects by more than
    ``limit_mm`` anywhere in its volume is not written."""
    size, where = max_correction(engine, data)
    if size > limit_mm:
        raise CalibrationError(
            f"the fitted calibration corrects by {size:.4f} mm at X {where[0]:.1f} Y {where[1]:.1f} "
            f"Z {where[2]:.1f}, more than --max-correction {limit_mm:g} mm; {output} was not written",
            hint="an undetermined parameter usually makes this (see the conditioning lines above): "
                 "drop an effect, measure more points, or raise --max-correction if the machine "
                 "really is that far off")
