"""Which missing effect explains the residual? Candidate ranking by cross-validation.

Every candidate effect is added to the model (base + effects already selected) and
the whole is refitted on the training folds; the held-out residuals are compared
with those of the model without it. Greedy forward selection: the best significant
candidate is added, then all others are ranked again against the enlarged model, so
two hidden effects are found in order of size.

Significance: ``delta = e_without - e_with`` is what adding the candidate changes in
the held-out prediction. If the effect is real, ``delta`` predicts the held-out
residual ``e_without``: the slope ``beta`` of ``e_without`` on ``delta`` is near 1; if
it fits only noise, ``beta`` is near 0. The held-out residual also carries the fitted
model's own error (its parameters were estimated on the training folds), shared by
every point of a fold; ``delta`` is first made orthogonal, fold by fold, to the
directions that error can take on the held-out points (the base model's span and the
selected effects), so that under "no effect" ``sum delta * e_without`` is a sum over
independent held-out noise. One-sided t-test of ``beta > 0`` with a cluster-robust
standard error over repeat groups (held out together), G - 1 degrees of freedom.
The noise term is the scatter about the slope, so an effect confined to part of the
data (the first hour of a warm-up) is seen beside other unexplained residual.

For methods refitted through their fitter (interval, grid, parametric) the span of
their error is not explicit; there the test is the paired one on squared errors:
per repeat group ``d_g = sum |e_without|^2 - |e_with|^2``, one-sided t-test of
mean(d_g) > 0 (conservative: a candidate fitting noise makes d slightly negative).

Either way, that adding it actually lowers the held-out error by a useful amount is
required separately (``MIN_EXPLAINED``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.diagnose.crossval import FoldCache, JointCV, rms3
from postproc.diagnose.data import Dataset
from postproc.diagnose.frame import FrameFit
from postproc.diagnose.guard import Guard
from postproc.diagnose.models import BaseModel, Fixed, LinearStatic, stacked
from postproc.effects import Effect, get_effect
from postproc.effects.linalg import solve_ls
from postproc.errors import CalibrationError, PostprocError

# Significance threshold (one-sided p-value) for suggesting an effect. About 30
# candidates are tried in each round; 0.001 each keeps the chance of one false
# suggestion per round near 3 % (Bonferroni), while a real effect at twice the noise
# on a few hundred points reaches p < 1e-10.
SIGNIFICANCE_P = 1e-3
# An effect explaining less than 2 % of the residual variance lowers the RMS by less
# than 1 %: not worth a term in the model, however significant.
MIN_EXPLAINED = 0.02
# Most effects added by the greedy search; each round costs a full ranking.
MAX_SELECTED = 4
# Fewer held-out groups than this cannot support a t-test of their mean.
MIN_GROUPS_FOR_TEST = 8
# Candidates per round whose parameters are fitted on all data for the report.
N_FITTED_REPORTED = 5
# Periodic terms per axis the greedy search may add (two pitches on one screw: the lead
# and a harmonic, or a screw and a scale): each further one at the pitch the residual shows.
MAX_PERIODIC_PER_AXIS = 2


@dataclass
class Candidate:
    name: str
    status: str  # "significant", "not significant", "untestable", "in model"
    reason: str = ""
    explained: float = 0.0  # fraction of the base model's cross-validated residual variance
    rms_after_mm: float | None = None  # cross-validated 3D RMS with it added
    p_value: float | None = None
    round: int = 0
    effect: Effect | None = None  # with parameters fitted on all data (when computed)
    resid: np.ndarray | None = field(default=None, repr=False)

    @property
    def meaning(self) -> str:
        return get_effect(self.name).meaning


@dataclass
class Ranking:
    model: BaseModel
    folds: int
    base_cv_rms_mm: float
    base_cv_resid: np.ndarray
    rounds: list[list[Candidate]]
    selected: list[Candidate]
    untestable: list[Candidate]
    in_model: list[Candidate]
    final_cv_rms_mm: float
    final_effects: list[Effect]  # all effects of the final model, fitted on all data
    final_cv_resid: np.ndarray | None = field(default=None, repr=False)  # held-out residual after them
    final_guard: Guard | None = None  # conditioning of the final joint fit
    final_frame: FrameFit | None = None  # the frame registration fitted with the final effects


def slope_p_value(y: np.ndarray, delta: np.ndarray, groups: np.ndarray) -> float:
    """One-sided p-value of slope > 0 of held-out residual ``y`` on ``delta`` (both (N, 3)),
    cluster-robust over ``groups``."""
    from scipy.stats import t as student_t

    n_groups = int(np.count_nonzero(np.bincount(groups)))
    if n_groups < MIN_GROUPS_FOR_TEST:
        return float("nan")
    d, yy = delta.reshape(-1), y.reshape(-1)
    sxx = float(d @ d)
    if sxx == 0.0:
        return 1.0
    beta = float(d @ yy) / sxx
    g = np.repeat(groups, y.shape[1])
    per_group = np.bincount(g, weights=d * (yy - beta * d))
    var = float(per_group @ per_group) / sxx**2 * n_groups / (n_groups - 1)
    if var == 0.0:
        return 0.0 if beta > 0 else 1.0
    # Degrees of freedom from the effective number of groups carrying delta: a delta
    # confined to a few groups (a short warm-up, the ends of an axis) has a variance
    # estimate resting on those few, and gets the heavier tails it deserves.
    w = np.bincount(g, weights=d * d)
    n_eff = float(np.sum(w) ** 2 / np.sum(w * w))
    return float(student_t.sf(beta / np.sqrt(var), max(n_eff - 1.0, 1.0)))


def paired_p_value(e0: np.ndarray, e1: np.ndarray, groups: np.ndarray) -> float:
    """One-sided p-value that held-out errors ``e1`` are smaller than ``e0`` (per group)."""
    from scipy.stats import t as student_t

    d = np.sum(e0**2, axis=1) - np.sum(e1**2, axis=1)
    counts = np.bincount(groups)
    dg = np.bincount(groups, weights=d)[counts > 0]
    n = len(dg)
    if n < MIN_GROUPS_FOR_TEST:
        return float("nan")
    mean, sd = float(np.mean(dg)), float(np.std(dg, ddof=1))
    if sd == 0.0:
        return 0.0 if mean > 0 else 1.0
    return float(student_t.sf(mean / (sd / np.sqrt(n)), n - 1))


def rank_effects(model: BaseModel, ds: Dataset, existing: list[Effect], candidates: list[str],
                 folds: list[np.ndarray], *, max_selected: int = MAX_SELECTED) -> Ranking:
    """Greedy forward selection of candidate effects under cross-validation."""
    groups = ds.repeat_groups()
    selected_effects = [get_effect(e.name) for e in existing]
    in_model = [Candidate(e.name, "in model", "already in the calibration") for e in existing]
    names = [n for n in candidates if n not in {e.name for e in existing}]
    untestable: list[Candidate] = []
    testable: list[str] = []
    for name in names:
        eff = get_effect(name)
        why = eff.untestable_reason(ds.q, ds.r, ds.ctx)
        if why:
            untestable.append(Candidate(name, "untestable", why))
        elif model.redundant(ds, eff):
            in_model.append(Candidate(name, "in model", f"already modelled by the {model.kind} method"))
        else:
            testable.append(name)

    joint = isinstance(model, LinearStatic | Fixed)  # exact joint refits are cheap only there
    scorer = JointCV if joint else FoldCache
    cache = scorer(model, ds, selected_effects, folds)
    e0 = cache.residuals()
    base_resid, base_sse = e0, float(np.sum(e0**2))
    rounds: list[list[Candidate]] = []
    selected: list[Candidate] = []
    for rnd in range(max_selected + 1):
        results = []
        for name in list(testable):
            taken = sum(c.name == name for c in selected)
            if taken and not (name.startswith("periodic:") and taken < MAX_PERIODIC_PER_AXIS):
                continue
            try:
                e1 = cache.with_effect(get_effect(name))
            except PostprocError as exc:
                untestable.append(Candidate(name, "untestable", f"cannot be fitted: {exc.message}"))
                testable.remove(name)
                continue
            sse0, sse1 = float(np.sum(e0**2)), float(np.sum(e1**2))
            explained = (sse0 - sse1) / base_sse if base_sse > 0 else 0.0
            ortho = cache.project_out(e0 - e1)
            p = slope_p_value(e0, ortho, groups) if ortho is not None else paired_p_value(e0, e1, groups)
            ok = np.isfinite(p) and p < SIGNIFICANCE_P and explained >= MIN_EXPLAINED
            if not np.isfinite(p):
                why = "too few points for a test"
            elif p < SIGNIFICANCE_P and not ok:
                why = f"explains less than {MIN_EXPLAINED:.0%}"
            else:
                why = ""
            results.append(Candidate(name, "significant" if ok else "not significant", why,
                                     explained, rms3(e1), p, rnd, resid=e1))
        results.sort(key=lambda c: -c.explained)
        _fit_reported(model, ds, selected_effects, results[:N_FITTED_REPORTED], joint)
        rounds.append(results)
        best = next((c for c in results if c.status == "significant"), None)
        if best is None or rnd == max_selected:
            break
        if best.effect is None:
            _fit_reported(model, ds, selected_effects, [best], joint)
        selected.append(best)
        selected_effects.append(get_effect(best.name))
        cache = scorer(model, ds, selected_effects, folds)
        if joint and best.resid is not None:  # every candidate of a round holds its held-out residuals
            e0 = best.resid
        else:
            # the selected effect refitted jointly with the base: report that model
            sse_prev, e0 = float(np.sum(e0**2)), cache.residuals()
            best.rms_after_mm = rms3(e0)
            best.explained = (sse_prev - float(np.sum(e0**2))) / base_sse if base_sse > 0 else 0.0
    final, final_guard, final_frame = [], None, None
    if selected_effects:
        fitted = model.fit(ds, model.prepare(ds, selected_effects))
        final, final_guard, final_frame = fitted.effects, fitted.guard, fitted.frame
    # Suggestions are sized jointly with the base and each other, as 'fit --effect' sizes them
    # (the per-round fit on the base's residual underrates what a flexible base partly absorbs).
    offset = len(existing)
    for i, c in enumerate(selected):
        if offset + i < len(final) and final[offset + i].name == c.name:
            c.effect = final[offset + i]
    return Ranking(model, len(folds), rms3(base_resid), base_resid, rounds, selected, untestable,
                   in_model, rms3(e0), final, e0, final_guard, final_frame)


def empirical_offer(model: BaseModel, ds: Dataset, ranking: Ranking, existing: list[Effect],
                    folds: list[np.ndarray]) -> dict | None:
    """The empirical field (:mod:`postproc.effects.empirical`) added to the final model,
    its degree chosen by the same cross-validation; None when no degree lowers the
    held-out error."""
    from postproc.effects.empirical import DEGREES, Empirical

    effects = [get_effect(e.name) for e in existing] + [get_effect(c.name) for c in ranking.selected]
    joint = isinstance(model, LinearStatic | Fixed)
    cache = (JointCV if joint else FoldCache)(model, ds, effects, folds)
    base = rms3(cache.residuals())
    best = None
    for target in DEGREES:
        name = f"empirical:{target}"
        eff = get_effect(name)
        if len(eff.param_names) * 3 > len(ds):  # 3 observations per parameter at least
            continue
        try:
            rms = rms3(cache.with_effect(eff))
        except PostprocError:
            continue
        # worth a term only if it removes a useful part of the held-out variance
        if rms**2 < (1 - MIN_EXPLAINED) * base**2 and (best is None or rms < best[1]):
            best = (name, rms)
    if best is None:
        return None
    fitted = _fit_all(model, ds, [*effects, get_effect(best[0])])[-1]
    extent = fitted.extent() if isinstance(fitted, Empirical) else None
    if extent is None:
        raise CalibrationError(f"the fitted {best[0]} has no extent (center_x_mm ... half_z_mm) in its config")
    return {"effect": best[0], "cv_rms_before_mm": base, "cv_rms_after_mm": best[1],
            "extent_mm": extent.tolist(), "description": fitted.describe(),
            "meaning": fitted.meaning}


def _fit_reported(model: BaseModel, ds: Dataset, selected: list[Effect], cands: list[Candidate],
                  joint: bool) -> None:
    """Parameters of the leading candidates, fitted on all data, for the report."""
    if joint:
        for c in cands:
            c.effect = _fit_all(model, ds, [*selected, get_effect(c.name)])[-1]
        return
    if not cands:
        return
    fitted = model.fit(ds, model.prepare(ds, selected))
    resid = ds.m - fitted.predict(ds)
    for c in cands:
        e = get_effect(c.name).prepare(ds.q, ds.r, ds.ctx, resid)
        coef = solve_ls(stacked(e.basis(ds.q, ds.r, ds.ctx)), resid.reshape(-1))
        c.effect = e.copy(params=coef)


def _fit_all(model: BaseModel, ds: Dataset, effects: list[Effect]) -> list[Effect]:
    return model.fit(ds, model.prepare(ds, effects)).effects
