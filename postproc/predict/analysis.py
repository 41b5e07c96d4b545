"""Whole analyses of an operation, as the commands report them.

- :func:`predict_bore`: the bore's section with the variables mid-field, the worst
  case over the corners of the fields, the Monte Carlo, and the verdict;
- :func:`analyse_feature`: worst case (and Monte Carlo) of a bore centre or a tool
  point, and the verdict.

A chain whose random variables cannot vary (none, none used, fields of no width) is
deterministic: its single prediction is the worst case and there is no Monte Carlo.
The verdict (``held``) is what ``--check`` turns into the exit status.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from postproc.errors import PostprocError
from postproc.predict import bore, tolerance
from postproc.predict.bore import is_deterministic
from postproc.predict.operation import Operation

__all__ = ["BoreReport", "FeatureReport", "analyse_feature", "error_function", "is_deterministic", "predict_bore"]


def error_function(op: Operation):
    """``(component names, fn)``: the feature error (n, d) of a bore or point operation."""
    if op.kind == "bore":
        return bore.component_names(op), lambda env: bore.centre_errors(op, env)
    if op.kind == "point":
        r = op.params["tool_point_mm"]

        def fn(env):
            full = {**op.context, **{k: np.asarray(v, dtype=float) for k, v in env.items()}}
            return op.chain.transform(r, full) - op.params["nominal_mm"]

        return ["X", "Y", "Z"], fn
    raise PostprocError(f"a tolerance analysis needs a bore or point operation, got {op.kind!r}", path=op.path)


def _verdict(op: Operation, worst: tolerance.WorstCase, deterministic: bool) -> dict:
    basis = "single prediction" if deterministic else "worst case"
    if op.kind != "bore":
        return {"held": worst.within, "basis": basis, "within": worst.within}
    return bore.verdict(op, worst, bore.diameter_range(op))


@dataclass
class FeatureReport:
    """Worst case (and Monte Carlo) of a feature error, and the verdict."""

    op: Operation
    deterministic: bool
    worst: tolerance.WorstCase
    dist: tolerance.Distribution | None
    verdict: dict

    def to_dict(self) -> dict:
        out = {"operation": self.op.name, "deterministic": self.deterministic, "worst_case": self.worst.to_dict()}
        if self.dist is not None:
            out["monte_carlo"] = self.dist.to_dict()
        out["verdict"] = self.verdict
        return out


def analyse_feature(op: Operation, n: int | None = None, seed: int | None = None,
                    monte_carlo: bool = True) -> FeatureReport:
    """Worst case over the corners of the fields (the single prediction of a deterministic
    chain) and, unless ``monte_carlo`` is false or the chain is deterministic, the Monte Carlo."""
    names, fn = error_function(op)
    tol = op.params["tolerance_mm"]
    random = op.chain.random
    deterministic = is_deterministic(op)
    if deterministic:
        worst = tolerance.single(fn, tolerance.nominal(random), tolerance_mm=tol, names=names)
    else:
        worst = tolerance.worst_case(fn, random, tolerance_mm=tol, names=names)
    dist = None
    if monte_carlo and not deterministic:
        dist = tolerance.monte_carlo(fn, random, n=n or op.params["n"],
                                     seed=op.params["seed"] if seed is None else seed, tolerance_mm=tol, names=names)
    return FeatureReport(op, deterministic, worst, dist, _verdict(op, worst, deterministic))


@dataclass
class BoreReport:
    """Everything ``predict bore`` reports about one bore operation."""

    op: Operation
    mid: bore.Section
    worst: tolerance.WorstCase
    worst_values: dict
    worst_section: bore.Section
    dist: tolerance.Distribution | None
    verdict: dict

    @property
    def deterministic(self) -> bool:
        return self.dist is None

    def to_dict(self) -> dict:
        op, mid, ws = self.op, self.mid, self.worst_section
        out = {
            "operation": op.name,
            "deterministic": self.deterministic,
            "nominal_centre_mm": op.params["nominal_centre_mm"].tolist(),
            "mid_field": {"centre_mm": mid.centre_mm.tolist(), "error_mm": mid.error_mm.tolist(),
                          "axis_point_mm": mid.axis_point_mm.tolist(), "diameter_mm": mid.diameter_mm,
                          "roundness_mm": mid.roundness_mm},
            "worst_section": {"values": self.worst_values, "error_mm": ws.error_mm.tolist(),
                              "diameter_mm": ws.diameter_mm, "roundness_mm": ws.roundness_mm},
            "worst_case": self.worst.to_dict(),
            "monte_carlo": None if self.dist is None else self.dist.to_dict(),
            "verdict": self.verdict,
        }
        if "diameter_limits_mm" in op.params:
            lo, hi = op.params["diameter_limits_mm"]
            out["mid_field"]["diameter_within_limits"] = bool(lo <= mid.diameter_mm <= hi)
        return out


def predict_bore(op: Operation, n: int | None = None, seed: int | None = None) -> BoreReport:
    """The bore's mid-field section, worst case, Monte Carlo (unless deterministic) and verdict."""
    mid = bore.evaluate_section(op, tolerance.nominal(op.chain.random))
    dist, worst = bore.analyse(op, n=n, seed=seed)
    k = int(np.argmax(worst.max_abs_mm / op.params["tolerance_mm"]))
    worst_section = bore.evaluate_section(op, worst.corner[k])
    verdict = bore.verdict(op, worst, bore.diameter_range(op))
    return BoreReport(op, mid, worst, worst.corner[k], worst_section, dist, verdict)
