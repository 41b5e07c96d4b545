"""Which engine class and which fitter serve each ``--method`` name.

Entries are import paths so that ``postproc correct`` imports only the engine it uses.
"""

from __future__ import annotations

import importlib

from postproc.errors import CalibrationError

#: method name -> "module:EngineClass"
ENGINES = {
    "static": "postproc.engine.static:StaticEngine",
    "interval": "postproc.engine.interval:IntervalEngine",
    "grid": "postproc.engine.grid:GridEngine",
    "parametric": "postproc.engine.parametric:ParametricEngine",
    "identity": "postproc.engine.identity:IdentityEngine",
}

#: method name -> "module:function" fitting an engine from point measurements.
#: A fitter is called as ``fit(measurements: list[Measurements], **options) -> FitResult``.
FITTERS = {
    "static": "postproc.engine.static:fit",
    "interval": "postproc.engine.interval:fit",
    "grid": "postproc.engine.grid:fit",
    "parametric": "postproc.engine.parametric_fit:fit",
}


def _load(spec: str):
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)


def engine_class(method: str):
    try:
        spec = ENGINES[method]
    except KeyError:
        raise CalibrationError(
            f"unknown calibration method {method!r}",
            hint=f"known methods: {', '.join(sorted(ENGINES))}",
        ) from None
    return _load(spec)


def fitter(method: str):
    try:
        spec = FITTERS[method]
    except KeyError:
        raise CalibrationError(
            f"no fitter for method {method!r}", hint=f"choose one of: {', '.join(sorted(FITTERS))}"
        ) from None
    return _load(spec)
