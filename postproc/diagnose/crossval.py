"""K-fold cross-validation over points, refitting the base model on the training folds.

Repeated points (same commanded point and context) stay in one fold, so a held-out
point is never predicted by its own repeat: a flexible model cannot hide a misfit.
"""

from __future__ import annotations

import numpy as np

from postproc.diagnose.data import Dataset
from postproc.diagnose.models import BaseModel, effects_basis, stacked, static_design
from postproc.effects import Effect
from postproc.effects.linalg import solve_ls

DEFAULT_FOLDS = 5
# Fold assignment is random but reproducible: the same data always gives the same report.
FOLD_SEED = 20240


def make_folds(groups: np.ndarray, k: int, seed: int = FOLD_SEED) -> list[np.ndarray]:
    """Boolean test masks of ``k`` folds; whole repeat groups go to one fold."""
    ids = np.unique(groups)
    k = max(2, min(k, len(ids)))
    order = np.random.default_rng(seed).permutation(ids)
    fold_of = np.empty(int(ids.max()) + 1, dtype=int)
    fold_of[order] = np.arange(len(order)) % k
    f = fold_of[groups]
    return [f == i for i in range(k)]


class JointCV:
    """Cross-validation of "the selected effects + one candidate", refitting the base
    jointly with all of them on every training fold (exact for the static method).

    The selected effects' settings and the training residual they leave are the same
    for every candidate, so they are computed once per fold; each candidate's own
    search (pitch, time constant) runs on that residual, as ``model.prepare`` would.
    """

    def __init__(self, model: BaseModel, ds: Dataset, effects: list[Effect], folds: list[np.ndarray]):
        self.model, self.ds = model, ds
        self.items = []
        for test in folds:
            train, held = ds.subset(~test), ds.subset(test)
            prepared = model.prepare(train, effects)
            fitted = model.fit(train, prepared)
            self.items.append((test, train, held, prepared, train.m - fitted.predict(train),
                               held.m - fitted.predict(held)))
        self.spans = [_held_span(model, it[2], it[3]) for it in self.items]

    def residuals(self) -> np.ndarray:
        out = np.empty_like(self.ds.m)
        for test, *_, r_held in self.items:
            out[test] = r_held
        return out

    def project_out(self, delta: np.ndarray) -> np.ndarray | None:
        """``delta`` (N, 3) with, in each held-out fold, its part along the fitted model's
        own error directions removed (see rank.held_out_p_value); None if unknown."""
        return _project_fold(self.items, self.spans, delta)

    def with_effect(self, effect: Effect) -> np.ndarray:
        out = np.empty_like(self.ds.m)
        for test, train, held, prepared, r_train, _ in self.items:
            e = effect.prepare(train.q, train.r, train.ctx, r_train)
            fitted = self.model.fit(train, [*prepared, e])
            out[test] = held.m - fitted.predict(held)
        return out


class FoldCache:
    """Per fold, the current model (base + selected effects) fitted on the training part
    once, so that candidates are scored on its residuals without refitting the base.

    Used for methods refitted through their fitter (interval, grid, parametric):
    a candidate is fitted to the training residual (the base held as fitted
    without it) and tested on the held-out one. It underrates effects the base can
    partly absorb, never overrates them.
    """

    def __init__(self, model: BaseModel, ds: Dataset, effects: list[Effect], folds: list[np.ndarray]):
        self.ds = ds
        self.items = []
        spans = []
        for test in folds:
            train, held = ds.subset(~test), ds.subset(test)
            prepared = model.prepare(train, effects)
            fitted = model.fit(train, prepared)
            self.items.append((test, train, held, train.m - fitted.predict(train), held.m - fitted.predict(held)))
            spans.append(_held_span(model, held, prepared))
        self.spans = spans

    def residuals(self) -> np.ndarray:
        out = np.empty_like(self.ds.m)
        for test, _, _, _, r_held in self.items:
            out[test] = r_held
        return out

    def project_out(self, delta: np.ndarray) -> np.ndarray | None:
        return _project_fold(self.items, self.spans, delta)

    def with_effect(self, effect: Effect) -> np.ndarray:
        """Held-out residual with ``effect`` fitted to the training residual. The base
        refitted with the effect would also move its own affine terms (origin, scale,
        squareness, which every fitter holds): the effect's columns are first made
        orthogonal to them on the training rows, and the same map applied on the held-out
        rows. (Fitted raw, a drift whose mean the base's origin already took would come
        out a twentieth of its size.)"""
        out = np.empty_like(self.ds.m)
        for test, train, held, r_train, r_held in self.items:
            e = effect.prepare(train.q, train.r, train.ctx, r_train)
            B = e.basis(train.q, train.r, train.ctx)
            k = B.shape[2]
            A, Ah = static_design(train), static_design(held)
            G = solve_ls(A, B.reshape(-1, k))
            coef = solve_ls(B.reshape(-1, k) - A @ G, r_train.reshape(-1))
            Bh = e.basis(held.q, held.r, held.ctx).reshape(-1, k) - Ah @ G
            out[test] = r_held - (Bh @ coef).reshape(-1, 3)
        return out


def _held_span(model: BaseModel, held: Dataset, prepared: list[Effect]) -> np.ndarray | None:
    """Columns (3n, m) on the held-out rows along which the fitted model's own error
    lies: the base's span and the selected effects. None when the base has no
    explicit span (methods refitted through their fitter)."""
    base = model.span(held)
    if base is None:
        return None
    return np.hstack([base, stacked(effects_basis(prepared, held))])


def _project_out(span: np.ndarray | None, delta: np.ndarray) -> np.ndarray | None:
    if span is None:
        return None
    y = delta.reshape(-1)
    if span.shape[1] == 0:
        return delta.copy()
    return (y - span @ solve_ls(span, y)).reshape(delta.shape)


def _project_fold(items, spans, delta: np.ndarray) -> np.ndarray | None:
    if any(sp is None for sp in spans):
        return None
    out = np.empty_like(delta)
    for (test, *_), span in zip(items, spans, strict=True):
        out[test] = _project_out(span, delta[test])
    return out


def rms3(resid: np.ndarray) -> float:
    """3D RMS: sqrt(mean |e|^2) over points."""
    return float(np.sqrt(np.mean(np.sum(resid**2, axis=1)))) if len(resid) else 0.0
