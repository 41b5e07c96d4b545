"""A base engine plus physical effects: ``forward = base.forward + sum of displacements``.

The inverse solves ``base.forward(q) + D(q) = p*`` by a fixed-point iteration around
the base inverse, ``q_{k+1} = base.inverse(p* - D(q_k))``; it converges because the
effects' displacements change by far less than the step in q (|dD/dq| << 1), and it
stops when ``|F(q) - p*| < SOLVER_TOL_MM``.

Context: effects read their columns from ``context`` (``dirx/diry/dirz`` from the
pipeline, ``t``, ``temp``, ``load``... from ``--context NAME=VALUE``). A missing
value raises MissingSetupError naming the ``--context`` to give.
"""

from __future__ import annotations

import numpy as np

from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM
from postproc.effects.base import Effect, context_hint
from postproc.effects.registry import effect_from_dict
from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.errors import CalibrationError, MissingSetupError

# The fixed point has stopped when a step moves q by less than this: a tenth of the
# solver tolerance, so a residual left above the tolerance is the base inverse's own.
STALL_STEP_MM = 0.1 * SOLVER_TOL_MM


class ComposedEngine(Engine):
    """``base`` with ``effects``; serialises as the base model (effects go in "effects")."""

    affine = False

    def __init__(self, base: Engine, effects: list[Effect]) -> None:
        super().__init__(base.volume_mm)
        self.base = base
        self.effects = list(effects)
        self.method = base.method  # the calibration file's method is the base's
        # the base's solver stands for the inverse: the fixed point only adds the effects
        self.solver = base.solver
        self.accept_residual_mm = base.accept_residual_mm

    @property
    def needs(self) -> tuple[str, ...]:
        out: list[str] = []
        for e in self.effects:
            out += [c for c in e.needs if c not in out]
        return tuple(out)

    def effects_dicts(self) -> list[dict]:
        return [e.to_dict() for e in self.effects]

    def with_extrapolation(self, mode: str) -> Engine:
        return type(self)(self.base.with_extrapolation(mode), self.effects)

    def check_context(self, names) -> None:
        """Refuse early, before a program is processed, when a needed value is missing."""
        names = set(names or ())
        for e in self.effects:
            for c in e.needs:
                if c not in names:
                    raise MissingSetupError(
                        f"the calibration's effect {e.name} needs the context value {c!r}, which was not given",
                        hint=context_hint(c),
                    )

    def displacement(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        rr = check_tool_vectors(r, len(q))
        d = np.zeros_like(q)
        for e in self.effects:
            d += e.displacement(q, rr, context)
        return d

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        rr = check_tool_vectors(r, len(q))
        return self.base.forward(q, rr, context) + self.displacement(q, rr, context)

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        rr = check_tool_vectors(r, len(p))
        res = self.base.inverse(p, rr, context)
        q = res.q
        iters = np.zeros(len(p), dtype=int)
        resid = np.linalg.norm(self.forward(q, rr, context) - p, axis=1)
        todo = resid >= SOLVER_TOL_MM
        for _ in range(SOLVER_MAX_ITER):
            if not todo.any():
                break
            sub = _subset_context(context, todo, len(p))
            d = self.displacement(q[todo], rr[todo], sub)
            q_new = self.base.inverse(p[todo] - d, rr[todo], sub).q
            step = np.linalg.norm(q_new - q[todo], axis=1)
            q[todo] = q_new
            iters[todo] += 1
            resid[todo] = np.linalg.norm(self.forward(q[todo], rr[todo], sub) - p[todo], axis=1)
            # done when on target, or when the fixed point stopped moving (what is left is
            # the base inverse's own residual, reported as it is)
            idx = np.flatnonzero(todo)
            todo[idx[(resid[idx] < SOLVER_TOL_MM) | (step < STALL_STEP_MM)]] = False
        return InverseResult(q, resid, iters)

    def model_to_dict(self) -> dict:
        return self.base.model_to_dict()

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> Engine:
        raise CalibrationError("a composed engine is loaded as its base method plus \"effects\"")


def _subset_context(context, mask: np.ndarray, n: int):
    if context is None:
        return None
    out = {}
    for k, v in context.items():
        a = np.asarray(v)
        out[k] = a[mask] if a.ndim == 1 and a.shape[0] == n else v
    return out


#: Value of every context column the effect needs when its config is checked (a valid
#: approach direction, time, temperature and load alike): only the config is under test.
CHECK_CONTEXT_VALUE = 1.0

_CONFIG_HINT = ("an effect's config holds the settings its fit found (pitch_mm, tau_s, center_mm, "
                "half_travel_mm, reference...); refit with 'postproc fit --effect NAME' or correct the file")


def check_config(effect: Effect, volume_mm=None) -> None:
    """Evaluate ``effect`` once, at the corners and centre of ``volume_mm``, so that a
    config it cannot work with (a ``periodic`` without ``pitch_mm``, ``tau_s <= 0`` ...)
    is refused when a calibration or machine is loaded, not when it is first used.

    Raises CalibrationError naming the effect (the caller adds the file).
    """
    vol = np.asarray(volume_mm if volume_mm is not None else np.zeros((2, 3)), dtype=float)
    if vol.shape != (2, 3) or not np.all(np.isfinite(vol)):
        vol = np.zeros((2, 3))
    q = np.vstack([vol, vol.mean(axis=0)])
    ctx = {c: np.full(len(q), CHECK_CONTEXT_VALUE) for c in effect.needs}
    try:
        B = np.asarray(effect.basis(q, np.zeros_like(q), ctx), dtype=float)
    except CalibrationError as exc:
        name = effect.name
        msg = exc.message if name in exc.message else f"effect {name}: {exc.message}"
        raise CalibrationError(msg, hint=exc.hint or _CONFIG_HINT) from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as exc:
        raise CalibrationError(f"effect {effect.name}: config {effect.config} cannot be used "
                               f"({type(exc).__name__}: {exc})", hint=_CONFIG_HINT) from None
    if B.shape != (len(q), 3, len(effect.param_names)) or not np.all(np.isfinite(B)):
        raise CalibrationError(f"effect {effect.name}: config {effect.config} does not give a finite "
                               "displacement in the calibrated volume", hint=_CONFIG_HINT)


def compose(engine: Engine, effects_dicts) -> Engine:
    """Wrap ``engine`` so that forward adds the effects' displacements.

    Each effect is built and its config checked (:func:`check_config`) here, so a wrong
    one is reported on loading.
    """
    effects = [e if isinstance(e, Effect) else effect_from_dict(e) for e in (effects_dicts or [])]
    if not effects:
        return engine
    for e in effects:
        check_config(e, engine.volume_mm)
    return ComposedEngine(engine, effects)
