"""A base model (the calibration's method) fitted jointly with effects.

Three ways, chosen by the method:

- ``LinearStatic``: the static model ``p = r_O1 + G q + r`` is linear in its 12
  parameters, so base and effects are one least-squares problem (exact joint fit).
- ``Refit``: any other method with a point fitter (interval, grid, parametric):
  the joint fit through the fitter's response. For a fitter that is linear in the
  measured values (least squares: interval, grid, parametric B-splines) the base
  residual operator ``R(m) = m - P(m)`` is linear, so the effect parameters solve
  ``min |R(m) - sum_k theta_k R(B_k)|``, with ``R(B_k)`` read from one extra fit of
  ``m + s B_k`` per effect column; then the base is fitted once more to
  ``m - B theta``. Exact for linear fitters, one Gauss-Newton step otherwise.
  (Plain alternation converges slowly when a flexible base absorbs part of an
  effect, e.g. a B-spline model and a backlash.)
- ``Fixed``: a method that cannot be refitted from points (identity, tables): the
  base is held as calibrated and the effects are fitted to its residual.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.diagnose.frame import PARAM_NAMES as FRAME_PARAMS
from postproc.diagnose.frame import FrameFit, frame_basis
from postproc.diagnose.guard import Guard, guarded_solve
from postproc.effects import Effect
from postproc.effects.linalg import solve_ls
from postproc.effects.periodic import Periodic
from postproc.effects.thermal import ThermalTime
from postproc.engine.base import Engine
from postproc.errors import CalibrationError, PostprocError

# Size (3D RMS, mm) of the probe displacement ``s B_k`` added to the measurements to
# read the fitter's response to an effect column: a few times a typical effect, so a
# slightly non-linear fitter is probed where it works, far above rounding (1e-12 mm).
PROBE_RMS_MM = 0.01

# An effect column whose part outside the base model's span is below this fraction of
# its norm is already modelled by the base (e.g. scale:X in the static model).
REDUNDANT_FRACTION = 1e-6

#: effects whose ``prepare`` searches a non-linear setting on the residual
SEARCHING = (Periodic, ThermalTime)


def stacked(B: np.ndarray) -> np.ndarray:
    """(N, 3, k) -> (3N, k), rows ordered point by point (x, y, z)."""
    n, _, k = B.shape
    return B.reshape(3 * n, k)


def effects_basis(effects: list[Effect], ds: Dataset) -> np.ndarray:
    if not effects:
        return np.zeros((len(ds), 3, 0))
    return np.concatenate([e.basis(ds.q, ds.r, ds.ctx) for e in effects], axis=2)


def split_params(effects: list[Effect], coef: np.ndarray, u_k2: np.ndarray | None = None) -> list[Effect]:
    """Effects with their parameters from ``coef``; ``u_k2`` (same length) sets each
    effect's ``uncertainty`` (parameter name -> k=2 expanded uncertainty)."""
    out, i = [], 0
    for e in effects:
        k = len(e.param_names)
        new = e.copy(params=coef[i:i + k])
        if u_k2 is not None:
            new.uncertainty = dict(zip(e.param_names, (float(v) for v in u_k2[i:i + k]), strict=True))
        out.append(new)
        i += k
    return out


def param_labels(effects: list[Effect]) -> list[str]:
    return [f"{e.name}.{p}" for e in effects for p in e.param_names]


@dataclass
class Fitted:
    """A fitted base engine and effects with their parameters (and the frame registration)."""

    engine: Engine
    effects: list[Effect]
    report: list[str]
    frame: FrameFit | None = None
    guard: Guard | None = field(default=None, repr=False)
    base_forward: Callable[[Dataset], np.ndarray] | None = field(default=None, repr=False)  # (N, 3), cached

    def predict(self, ds: Dataset) -> np.ndarray:
        if self.base_forward is not None:
            p = self.base_forward(ds)
        else:
            p = self.engine.forward(ds.q, ds.r, ds.ctx)
        for e in self.effects:
            p = p + e.displacement(ds.q, ds.r, ds.ctx)
        if self.frame is not None:
            p = p + self.frame.displacement(ds.q, ds.r)
        return p


def _guarded_effects(effects: list[Effect], P: np.ndarray, y: np.ndarray, raw: np.ndarray,
                     dof: int | None, frame_cols: int = 0) -> tuple[list[Effect], FrameFit | None, Guard | None]:
    """Solve the visible columns (effects first, then ``frame_cols`` registration columns)."""
    names = param_labels(effects) + list(FRAME_PARAMS[:frame_cols])
    coef, guard = guarded_solve(P, y, raw, names, dof)
    k = len(coef) - frame_cols
    u = guard.u_k2
    fitted = split_params(effects, coef[:k], None if u is None else u[:k])
    frame = None
    if frame_cols:
        absorbed = all(n in guard.undetermined for n in FRAME_PARAMS)
        frame = FrameFit(coef[k:], None if u is None else u[k:], absorbed=absorbed)
        guard.undetermined = [n for n in guard.undetermined if n not in FRAME_PARAMS]
        if effects:  # conditioning of the effects themselves (a frame the base holds is not theirs)
            own = guarded_solve(P[:, :k], y, raw[:k], names[:k], dof)[1]
            guard.condition, guard.min_visible = own.condition, own.min_visible
    # the conditioning reported is that of the effects; a frame alone has its own line
    return fitted, frame, (guard if effects else None)


class BaseModel:
    kind = ""
    description = ""
    #: fit a 6-DOF registration of the measurement frame as a nuisance
    register = False

    def fit(self, ds: Dataset, effects: list[Effect]) -> Fitted:
        raise NotImplementedError

    def span(self, ds: Dataset) -> np.ndarray | None:
        """(3N, m) columns the base can absorb exactly, for the redundancy test."""
        return None

    def redundant(self, ds: Dataset, effect: Effect) -> bool:
        A = self.span(ds)
        if A is None:
            return False
        ready = effect.prepare(ds.q, ds.r, ds.ctx, np.zeros_like(ds.m))  # any pitch or lag will do
        B = stacked(ready.basis(ds.q, ds.r, ds.ctx))
        coef = solve_ls(A, B)
        rest = np.linalg.norm(B - A @ coef, axis=0)
        return bool(np.all(rest <= REDUNDANT_FRACTION * np.maximum(np.linalg.norm(B, axis=0), 1e-300)))

    def prepare(self, ds: Dataset, effects: list[Effect]) -> list[Effect]:
        """Set every effect's non-linear config on ``ds``, in order, each on the residual
        of the model with the effects before it."""
        done: list[Effect] = []
        for e in effects:
            resid = None
            if isinstance(e, SEARCHING):
                resid = ds.m - self.fit(ds, done).predict(ds)
            done.append(e.prepare(ds.q, ds.r, ds.ctx, resid))
        return done


def static_design(ds: Dataset) -> np.ndarray:
    """(3N, 12): for component j the columns [1, X, Y, Z] of the static model."""
    n = len(ds)
    A = np.zeros((3 * n, 12))
    base = np.column_stack([np.ones(n), ds.q])
    for j in range(3):
        A[j::3, 4 * j:4 * j + 4] = base
    return A


class LinearStatic(BaseModel):
    kind = "static"
    description = "static model fitted jointly with the effects (one least-squares problem)"

    def span(self, ds: Dataset) -> np.ndarray:
        return static_design(ds)

    def fit(self, ds: Dataset, effects: list[Effect]) -> Fitted:
        from postproc.engine.static import StaticEngine, fit_affine

        guard = None
        if not effects:
            G, origin, _ = fit_affine(ds.q, ds.m - ds.r)
        else:
            fit_affine(ds.q, ds.m - ds.r)  # the same refusal of points that do not span 3 axes
            A0 = static_design(ds)
            E = stacked(effects_basis(effects, ds))
            y = (ds.m - ds.r).reshape(-1)
            P = E - A0 @ solve_ls(A0, E)
            yp = y - A0 @ solve_ls(A0, y)
            effects, _, guard = _guarded_effects(effects, P, yp, np.linalg.norm(E, axis=0),
                                                 len(y) - 12 - E.shape[1])
            coef = solve_ls(A0, y - E @ np.concatenate([e.param_vector() for e in effects]))
            block = coef.reshape(3, 4)
            origin, G = block[:, 0], block[:, 1:]
        volume = np.vstack([ds.q.min(axis=0), ds.q.max(axis=0)])
        engine = StaticEngine(G, origin, volume)
        # the static model holds a rigid motion of the frame itself (its origin and axes)
        frame = FrameFit(np.zeros(6), absorbed=True) if self.register else None
        return Fitted(engine, effects, static_summary(G, origin), frame, guard)


def static_summary(G: np.ndarray, origin: np.ndarray) -> list[str]:
    u = G / np.linalg.norm(G, axis=0)
    sq = [(a, (np.arccos(np.clip(u[:, i] @ u[:, j], -1, 1)) - np.pi / 2) * 1e6)
          for a, i, j in (("XY", 0, 1), ("XZ", 0, 2), ("YZ", 1, 2))]
    scale = (np.linalg.norm(G, axis=0) - 1.0) * 1e6
    return [
        f"axis scale errors (ppm): X {scale[0]:+.1f}  Y {scale[1]:+.1f}  Z {scale[2]:+.1f}",
        "out-of-squareness (urad): " + "  ".join(f"{a} {v:+.1f}" for a, v in sq),
        f"origin r_O1 (mm): {origin[0]:+.4f} {origin[1]:+.4f} {origin[2]:+.4f}",
    ]


class Refit(BaseModel):
    """A method with a point fitter; effects jointly through the fitter's response."""

    def __init__(self, method: str, fitter, options: dict | None = None, register: bool = False) -> None:
        self.kind = method
        self.fitter = fitter
        self.options = dict(options or {})
        self.register = register
        self.description = f"{method} model refitted jointly with the effects (through its fitter's response)"

    def _residual(self, ds: Dataset, m: np.ndarray):
        res = self.fitter([ds.with_m(m).to_measurements()], **self.options)
        return res, m - res.engine.forward(ds.q, ds.r, ds.ctx)

    def fit(self, ds: Dataset, effects: list[Effect]) -> Fitted:
        res, r0 = self._residual(ds, ds.m)
        if not effects and not self.register:
            return Fitted(res.engine, [], list(res.report))
        B = stacked(effects_basis(effects, ds))
        n_frame = 6 if self.register else 0
        if n_frame:
            B = np.hstack([B, stacked(frame_basis(ds.q, ds.r))])
        cols = []
        for k in range(B.shape[1]):
            bk = B[:, k].reshape(-1, 3)
            size = float(np.sqrt(np.mean(np.sum(bk**2, axis=1))))
            if size == 0.0:
                cols.append(np.zeros(len(B)))
                continue
            s = PROBE_RMS_MM / size
            _, rk = self._residual(ds, ds.m + s * bk)
            cols.append(((rk - r0) / s).reshape(-1))
        effects, frame, guard = _guarded_effects(effects, np.column_stack(cols), r0.reshape(-1),
                                                 np.linalg.norm(B, axis=0), None, n_frame)
        shift = sum((e.displacement(ds.q, ds.r, ds.ctx) for e in effects), np.zeros_like(ds.m))
        if frame is not None:
            shift = shift + frame.displacement(ds.q, ds.r)
        res, _ = self._residual(ds, ds.m - shift)
        return Fitted(res.engine, effects, list(res.report), frame, guard)


class Fixed(BaseModel):
    """The calibration held as it is; effects fitted to its residual."""

    def __init__(self, engine: Engine, why: str, register: bool = False) -> None:
        self.kind = engine.method
        self.engine = engine
        self.register = register
        reg = "; measurement frame registered (6 DOF)" if register else ""
        self.description = f"{engine.method} calibration held fixed ({why}){reg}"
        self._cache: list = []  # (q array, r array, forward) of recent datasets

    def forward(self, ds: Dataset) -> np.ndarray:
        """The fixed engine's prediction, remembered per dataset (cross-validation refits
        the same training folds for every candidate)."""
        for q, r, p in self._cache:
            if q is ds.q and r is ds.r:
                return p
        p = self.engine.forward(ds.q, ds.r, ds.ctx)
        self._cache = [*self._cache[-15:], (ds.q, ds.r, p)]
        return p

    def span(self, ds: Dataset) -> np.ndarray:
        """Only the registration is refitted (when on); otherwise only an effect that is
        identically zero is redundant."""
        if self.register:
            return stacked(frame_basis(ds.q, ds.r))
        return np.zeros((3 * len(ds), 0))

    def fit(self, ds: Dataset, effects: list[Effect]) -> Fitted:
        base = self.forward(ds)
        y = (ds.m - base).reshape(-1)
        E = stacked(effects_basis(effects, ds))
        if self.register:
            F = stacked(frame_basis(ds.q, ds.r))
            P = E - F @ solve_ls(F, E)
            yp = y - F @ solve_ls(F, y)
            fitted, _, guard = _guarded_effects(effects, P, yp, np.linalg.norm(E, axis=0),
                                                len(y) - 6 - E.shape[1])
            theta = np.concatenate([e.param_vector() for e in fitted]) if fitted else np.zeros(0)
            rest = y - E @ theta
            fcoef = solve_ls(F, rest)
            # the registration's own uncertainty, from the residual after it
            sse = float(np.sum((rest - F @ fcoef) ** 2))
            sigma2 = sse / max(len(y) - 6 - E.shape[1], 1)
            Fs = F / np.linalg.norm(F, axis=0)
            cov = np.linalg.pinv(Fs.T @ Fs) * sigma2
            u = 2.0 * np.sqrt(np.maximum(np.diag(cov), 0.0)) / np.linalg.norm(F, axis=0)
            return Fitted(self.engine, fitted, [], FrameFit(fcoef, u), guard, self.forward)
        fitted, _, guard = _guarded_effects(effects, E, y, np.linalg.norm(E, axis=0), len(y) - E.shape[1])
        return Fitted(self.engine, fitted, [], None, guard, self.forward)


def base_model(method: str, options: dict | None = None, engine: Engine | None = None,
               register: bool = False) -> BaseModel:
    """The base model for ``method``: joint for static and (through the fitter's response) other fitters,
    held fixed (needs ``engine``) when the method cannot be refitted from points.
    ``register``: fit a registration of the measurement frame as a nuisance."""
    if method == "static":
        model = LinearStatic()
        model.register = register
        return model
    from postproc.engine.registry import fitter

    try:
        fit = fitter(method)
    except (PostprocError, ImportError, AttributeError) as exc:
        if engine is None:
            msg = exc.message if isinstance(exc, PostprocError) else str(exc)
            raise CalibrationError(f"the {method} method cannot be refitted from points: {msg}",
                                   hint="use --method static, interval or grid") from None
        return Fixed(engine, f"the {method} method has no point fitter", register)
    return Refit(method, fit, options, register)
