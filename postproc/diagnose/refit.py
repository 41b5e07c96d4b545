"""``postproc fit ... --effect NAME``: a calibration with physical effects added.

The base method is fitted jointly with the effects where it is linear in its
parameters (static) and through the fitter's linear response otherwise (see :mod:`postproc.diagnose.models`).
The result's engine is the base engine composed with the fitted effects; the
calibration file stores the base model and the effects (``FitResult.effects``).
"""

from __future__ import annotations

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.diagnose.models import base_model
from postproc.effects import get_effect
from postproc.effects.composed import ComposedEngine
from postproc.engine.base import FitResult
from postproc.errors import MeasurementError


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


def fit_with_effects(method: str, data, effect_names, **options) -> FitResult:
    """Fit ``method`` on the measurements ``data`` together with the named effects."""
    ds = Dataset.from_measurements(data)
    names = list(dict.fromkeys(effect_names))  # a repeated --effect counts once
    effects = [get_effect(n) for n in names]
    check_effects_testable(ds, effects)
    model = base_model(method, options)
    prepared = model.prepare(ds, effects)
    fitted = model.fit(ds, prepared)
    resid = ds.m - fitted.predict(ds)
    engine = ComposedEngine(fitted.engine, fitted.effects)
    result = FitResult(engine=engine, residuals_mm=resid)
    rms = float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))
    result.report = [f"{method} fit with {len(effects)} effect(s) on {len(ds)} points ({model.description})"]
    result.report += fitted.report
    for e in fitted.effects:
        result.report.append(f"effect {e.name}: {e.describe()}")
        result.report.append(f"  {e.meaning}; {e.compensable_reason}")
    result.info = {
        "n_points": len(ds), "rms_mm": rms, "max_mm": float(np.max(np.linalg.norm(resid, axis=1))),
        "sources": list(ds.paths), "effects": [e.name for e in fitted.effects],
    }
    result.effects = [e.to_dict() for e in fitted.effects]
    return result
