"""The verdict of a check, judged on held-out points, with its evidence in one line.

The ranking (:mod:`postproc.diagnose.rank`) cross-validates on random folds of repeat
groups. A random split cannot tell a local error from a global shape: a 15 um bump on
a tenth of the travel is in the training data of every fold, so a whole-travel S-shape
fitted to it predicts the held-out points near the bump well enough. The verdict is
therefore also judged on a **spatial** split: the volume is cut into slabs along each axis (or blocks, for a
flexible base), whole slabs are held out, and the model (base + effects) is refitted
without them. A shape fitted to a local error is then wrong where the error is not, and
right nowhere the error was held out. Likewise each tool vector and each level of a
discrete context column (load steps) is left out in turn: an effect that holds only for
the conditions it was fitted on is not the physics.

Verdicts, in the order they are tried:

- ``campaign-limited``, cause "frame jump": the measurement frame steps during the
  campaign (:mod:`postproc.diagnose.jump`: the tracker moved; one registration cannot hold
  both parts, whatever is suggested may be its echo; the evidence names the row to split at);
- ``consistent``: the calibration's cross-validated RMS, random and spatial, is within
  ``CONSISTENT_RATIO`` x the noise floor and nothing is suggested;
- ``missing-effect``: the suggested effects bring both there (named);
- ``model-too-stiff``: a finer model of the same family does (a parametric model with
  knots twice as close, an interval model with twice the cells per axis, the static
  model cut into 2 x 2 x 2 cells);
- ``campaign-limited``: the campaign cannot separate the rest from noise: the residual
  left is spatially white (neighbouring points do not share it: per-visit scatter, the
  machine's repeatability, which shots taken seconds apart do not show; the evidence adds
  how uncertain the floor itself is), or the residual has a shape but the campaign's
  sampling is too coarse for the model (a one-span refit, time confounded with position);
- ``unexplained``: none of these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.diagnose.crossval import FOLD_SEED, FoldCache, JointCV, rms3
from postproc.diagnose.data import DISCRETE_VALUES, Dataset
from postproc.diagnose.models import Fixed, LinearStatic, Refit
from postproc.effects import Effect, get_effect
from postproc.effects.base import DIR_COLUMNS
from postproc.errors import PostprocError

#: A cross-validated RMS within this many times the noise floor is consistent with noise.
CONSISTENT_RATIO = 1.15
# Blocks per axis of the spatial split of a flexible base (4: the 2 x 2 x 2 interior
# blocks, each a quarter of each travel, are held out).
SPATIAL_BLOCKS = 4
# Slabs along each axis of the spatial split of a global base (6: a held-out slab is a
# sixth of the travel; a local error inside it is not seen by the fit that predicts it).
SLABS = 6
# A held-out split this much worse than the random one: the suggestions do not carry over.
LOCAL_EXCESS = 1.1
# Levels of a discrete context column needed to leave one out (the two others span it).
MIN_LEVELS = 3
# Tool vectors needed to leave one out: with three, a tool left out is an extrapolation
# of the tool-length lever that the frame rotation and the tilt share (on the virtual
# machine even the true tilt misses it by 1.1-1.3 x the floor).
MIN_TOOLS = 4
# One-sided level of the noise floor's upper confidence bound (chi-square on its degrees
# of freedom): below it the floor is not known well enough to call a ratio above 1.15.
FLOOR_CONFIDENCE = 0.05
# Neighbour correlation of the held-out residual (nearest other point) above this many
# standard errors of white noise is spatial structure; below, the excess is scatter.
STRUCTURE_Z = 3.0
# Effects the ranking on a finer model may name.
FINER_MAX_EFFECTS = 2
# Nearest groups looked at for a neighbour in the same conditions.
NEIGHBOURS_SEARCHED = 40
# Campaign warnings that mean the sampling cannot resolve the model's form.
SAMPLING_WARNINGS = ("coarse knots", "time-position confounding", "time-tool confounding")


@dataclass
class Verdict:
    name: str  # consistent, missing-effect, model-too-stiff, campaign-limited, unexplained
    evidence: str  # one line
    random_ratio: float
    spatial_ratio: float | None
    details: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"name": self.name, "evidence": self.evidence, "random_ratio": self.random_ratio,
                "spatial_ratio": self.spatial_ratio, **self.details}


def spatial_folds(ds: Dataset, groups: np.ndarray, k: int, seed: int = FOLD_SEED) -> list[np.ndarray]:
    """Test masks of ``k`` folds of whole interior blocks of a SPATIAL_BLOCKS^3 lattice over
    the measured extent (blocks on its faces are never held out: a flexible model would be
    extrapolated there); repeat groups stay together (in the block of their first row)."""
    lo, span = ds.q.min(axis=0), np.ptp(ds.q, axis=0)
    cell = np.floor(SPATIAL_BLOCKS * (ds.q - lo) / np.where(span > 0, span, 1.0)).clip(0, SPATIAL_BLOCKS - 1)
    inside = np.all((cell > 0) & (cell < SPATIAL_BLOCKS - 1) | (span == 0), axis=1)
    block = (cell @ np.array([SPATIAL_BLOCKS**2, SPATIAL_BLOCKS, 1])).astype(int)
    block = _by_group(np.where(inside, block, -1), groups)
    ids = np.unique(block[block >= 0])
    if len(ids) < 2:
        return []
    k = max(2, min(k, len(ids)))
    order = np.random.default_rng(seed).permutation(ids)
    fold_of = {int(b): i % k for i, b in enumerate(order)}
    f = np.array([fold_of.get(int(b), -1) for b in block])
    return [f == i for i in range(k) if np.any(f == i)]


def slab_folds(ds: Dataset, groups: np.ndarray, axis: int) -> list[np.ndarray]:
    """Test masks of contiguous interior slabs along ``axis``: SLABS of equal width over the
    measured extent, the two end slabs never held out (a shape fitted without them would be
    extrapolated, which a real shape of the catalogue does badly too); one fold per
    distinct position when there are at most SLABS of them (a campaign of a few lines)."""
    x = ds.q[:, axis]
    distinct = np.unique(np.round(x, 3))
    if len(distinct) < 2:
        return []
    if len(distinct) <= SLABS:
        slab = _by_group(np.searchsorted(distinct, np.round(x, 3)), groups)
        return [slab == i for i in np.unique(slab)]
    lo, span = x.min(), np.ptp(x)
    slab = _by_group(np.floor(SLABS * (x - lo) / span).clip(0, SLABS - 1).astype(int), groups)
    return [slab == i for i in range(1, SLABS - 1) if np.any(slab == i)]


def level_folds(values: np.ndarray, groups: np.ndarray) -> list[np.ndarray]:
    """Leave one level out: one fold per distinct value (tool vectors, load steps)."""
    _, level = np.unique(values, axis=0, return_inverse=True)
    level = _by_group(level.ravel(), groups)
    return [level == i for i in np.unique(level)]


def _by_group(label: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """``label`` of each row replaced by that of its repeat group's first row."""
    first = np.full(int(groups.max()) + 1, -1)
    for i in range(len(groups) - 1, -1, -1):
        first[groups[i]] = label[i]
    return first[groups]


def spatial_splits(model, ds: Dataset, groups: np.ndarray, k: int) -> list[tuple[str, list[np.ndarray]]]:
    """The splits a model is judged on beside the random one, each a list of test masks.

    - Space: for a global base (static, or a calibration held fixed) interior slabs along
      each axis, so a function of one axis is tested where it was not fitted; for a
      refitted flexible base (parametric, grid, interval: local support, which a held-out
      slab would leave without data) the interior blocks of a 4 x 4 x 4 lattice.
    - Conditions: with MIN_TOOLS or more tool vectors, each tool left out in turn (an
      effect fitted to the positional part of a tool-dependent error is wrong for the
      tool it did not see); likewise each level of a discrete context column (load steps:
      a deflection fitted as load plus a fixed shape is wrong at the load it did not see).
    """
    if isinstance(model, LinearStatic | Fixed):
        out = [(f"{'XYZ'[j]} slabs", slab_folds(ds, groups, j)) for j in range(3)]
    else:
        out = [("blocks", spatial_folds(ds, groups, k))]
    tools = np.round(ds.r, 3)
    if len(np.unique(tools, axis=0)) >= MIN_TOOLS:
        out.append(("tools", level_folds(tools, groups)))
    for name, v in sorted(ds.ctx.items()):
        if name in DIR_COLUMNS or name == "t":
            continue
        if MIN_LEVELS <= len(np.unique(v)) <= DISCRETE_VALUES:
            out.append((f"{name} levels", level_folds(v, groups)))
    return [(name, f) for name, f in out if len(f) >= 2]


def held_out(model, ds: Dataset, effects: list[Effect], folds: list[np.ndarray]) -> np.ndarray:
    """Held-out residual (N, 3) of ``model`` with ``effects`` (refitted on every training
    fold); NaN on rows no fold holds out."""
    scorer = JointCV if isinstance(model, LinearStatic | Fixed) else FoldCache
    out = scorer(model, ds, [get_effect(e.name) for e in effects], folds).residuals()
    tested = np.any(folds, axis=0)
    out[~tested] = np.nan
    return out


def held_rms(resid: np.ndarray) -> float:
    """3D RMS over the rows held out (finite)."""
    ok = np.all(np.isfinite(resid), axis=1)
    return rms3(resid[ok])


def floor_upper(floor_mm: float, dof: int) -> float:
    """Upper confidence bound of a noise floor estimated on ``dof`` degrees of freedom."""
    from scipy.stats import chi2

    if dof <= 0:
        return float("inf")
    return floor_mm * float(np.sqrt(dof / chi2.ppf(FLOOR_CONFIDENCE, dof)))


def neighbour_structure(ds: Dataset, resid: np.ndarray, groups: np.ndarray) -> tuple[float, float]:
    """(correlation, z) of each repeat group's mean residual with its nearest other group's:
    white scatter gives ~0 (z ~ N(0, 1)), a spatial shape a clearly positive value."""
    ids, inv = np.unique(groups, return_inverse=True)
    counts = np.bincount(inv)
    e = np.zeros((len(ids), 3))
    q = np.zeros((len(ids), 3))
    np.add.at(e, inv, resid)
    np.add.at(q, inv, ds.q)
    e, q = e / counts[:, None], q / counts[:, None]
    # a neighbour is the nearest group at another position measured in the same conditions
    # (tool, approach directions, every discrete context column: a load step): an error
    # that depends on the conditions is shared by such neighbours, scatter is not
    key = np.round(q, 3)
    cond_cols = [np.round(ds.r, 3)] + [v[:, None] for k, v in sorted(ds.ctx.items())
                                       if k in DIR_COLUMNS or len(np.unique(v)) <= DISCRETE_VALUES]
    cond_rows = np.hstack(cond_cols)
    cond = np.zeros((len(ids), cond_rows.shape[1]))
    cond[inv] = cond_rows
    if len(ids) < 8:
        return 0.0, 0.0
    from scipy.spatial import cKDTree

    scaled = q / np.maximum(np.ptp(q, axis=0), 1e-9)
    tree = cKDTree(scaled)
    _, nn = tree.query(scaled, k=min(len(ids), NEIGHBOURS_SEARCHED))
    partner = np.full(len(ids), -1)
    for i in range(len(ids)):
        for j in nn[i][1:]:
            if not np.array_equal(key[i], key[j]) and np.array_equal(cond[i], cond[j]):
                partner[i] = j
                break
    ok = partner >= 0
    if ok.sum() < 8:
        return 0.0, 0.0
    ec = e - e[ok].mean(axis=0)
    a, b = ec[ok], ec[partner[ok]]
    den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
    corr = float(np.sum(a * b) / den) if den > 0 else 0.0
    return corr, corr * float(np.sqrt(3 * ok.sum()))


def finer_models(model, ds: Dataset) -> list:
    """[(model, description)] of finer models of the same family, coarsest first."""
    from postproc.diagnose.models import base_model

    if isinstance(model, Fixed):
        return []
    if isinstance(model, LinearStatic):
        # the static model's terms (positioning, straightness, angles) as functions of
        # position: piecewise in cells, then the 21 smooth error functions
        return [(base_model("interval", {"intervals": "X=2;Y=2;Z=2", "border_blend_mm": 0.0},
                            register=model.register), "the static model cut into 2 x 2 x 2 cells (interval)"),
                (base_model("parametric", {}, register=model.register),
                 "the parametric model (the static terms as B-spline functions of position)")]
    finer = finer_model(model, ds)
    return [finer] if finer is not None else []


def finer_model(model, ds: Dataset):
    """(model, description) of the refitted flexible ``model`` made finer, or None."""
    from postproc.diagnose.models import base_model

    if isinstance(model, Refit) and model.kind == "parametric":
        try:
            res = model.fitter([ds.to_measurements()], **model.options)
        except PostprocError:
            return None
        spacing = min(res.info.get("knot_spacing_mm") or [0.0])
        if not spacing > 0:
            return None
        opts = {**model.options, "knot_spacing": spacing / 2}
        return (base_model("parametric", opts, register=model.register),
                f"the parametric model with knots every {spacing / 2:.1f} mm (was {spacing:.1f})")
    if isinstance(model, Refit) and model.kind == "interval":
        spec = model.options.get("intervals")
        counts = {}
        if isinstance(spec, str):
            for part in spec.split(";"):
                axis, _, v = part.partition("=")
                counts[axis.strip()] = len(v.split(",")) - 1 if "," in v else int(float(v))
        new = ";".join(f"{a}={2 * counts.get(a, 1)}" for a in "XYZ")
        opts = {**model.options, "intervals": new}
        return base_model("interval", opts, register=model.register), f"the interval model with {new} cells"
    return None


def _rank_on_finer(res, f_model, f_effects, folds) -> tuple[list[str], str | None]:
    """The catalogue ranked again on the finer model (a stiff base hides what it cannot
    follow and what is missing alike): the effects it names, and the fit command."""
    import shlex
    from pathlib import Path

    from postproc.diagnose.rank import rank_effects
    from postproc.effects import candidate_names
    from postproc.engine.registry import fold_options, option_flag

    held = {e.name for e in f_effects}
    try:
        rk = rank_effects(f_model, res.ds, [get_effect(e.name) for e in f_effects],
                          [n for n in candidate_names(res.ds.ctx) if n not in held], folds,
                          max_selected=FINER_MAX_EFFECTS)
        named = [c.name for c in rk.selected]
    except PostprocError:
        named = []
    command = None
    if isinstance(f_model, Refit) and res.files:
        skip = set(fold_options(f_model.kind))
        args = ["postproc", "fit", *res.files, "--method", f_model.kind]
        for key, value in f_model.options.items():
            if key not in skip:
                args += [option_flag(key), f"{value:g}" if isinstance(value, float) else str(value)]
        for n in [*held, *named]:
            args += ["--effect", n]
        stem = Path(res.cal_path).stem if res.cal_path else "calibration"
        command = shlex.join([*args, "-o", f"{stem}_finer.json"])
    return named, command


def tolerance(nf) -> tuple[float, str]:
    """The ratio to the floor that is consistent with noise, and its text for the evidence
    (with why it differs from CONSISTENT_RATIO, when it does).

    CONSISTENT_RATIO allows for a floor estimated from Gaussian noise. With heavy-tailed
    noise (:attr:`NoiseFloor.heavy_tailed`) the floor is less certain: the variance of a
    pooled variance grows by (2 + kappa) / 2 with the excess kurtosis kappa, so it rests
    on fewer effective degrees of freedom, and a campaign's own noise can sit 8 % above
    its floor on pure noise (Student t, 4 degrees of freedom, 120 pairs). The ratio is
    widened by the floor's upper confidence bound on those degrees of freedom over that
    of Gaussian noise on as many."""
    if not (nf.heavy_tailed and nf.kurtosis and nf.dof > 0):
        return CONSISTENT_RATIO, f"{CONSISTENT_RATIO:g}"
    dof_eff = nf.dof * 2.0 / (2.0 + nf.kurtosis)
    widen = floor_upper(1.0, dof_eff) / floor_upper(1.0, nf.dof)
    return (CONSISTENT_RATIO * widen,
            f"{CONSISTENT_RATIO * widen:.2f}: {CONSISTENT_RATIO:g} widened for heavy-tailed noise, excess kurtosis {nf.kurtosis:.1f}, "
            f"{dof_eff:.0f} effective degrees of freedom of the floor instead of {nf.dof}")


def _split_text(r_random: float, r_spatial: float | None, where: str, names: list[str]) -> str:
    """The held-out ratios of the evidence line: random folds, and the worst held-out split."""
    if r_spatial is None:
        return f"random folds {r_random:.2f} x the floor (no spatial split)"
    return (f"random folds {r_random:.2f}, worst of the held-out {', '.join(names)}: "
            f"{where} {r_spatial:.2f} x the floor")


def _jump_verdict(jump, names: str, split: str, r_random: float, r_spatial: float | None) -> Verdict:
    """campaign-limited by a step of the measurement frame (:mod:`postproc.diagnose.jump`)."""
    echo = f" ({names} may be its echo)" if names else ""
    return Verdict("campaign-limited", f"{jump.describe()}: the tracker moved or was set up again during the "
                   f"campaign, and one registration cannot hold both parts{echo}; register the two parts "
                   f"separately: split the measurements before {jump.place} and check each part on its own; "
                   f"held-out RMS {split}", r_random, r_spatial,
                   {"cause": "frame jump", "row": jump.row + 1, "place": jump.place})


def judge(res, model, groups: np.ndarray, folds: list[np.ndarray]) -> Verdict | None:
    """The verdict of check result ``res`` (ranking done), with its one-line evidence."""
    rk, floor = res.ranking, res.noise.rms_mm
    if rk is None or not floor:
        return None
    ds = res.ds
    nf = res.noise
    tol, bound = tolerance(nf)

    final_effects = [*res.refitted_effects, *(get_effect(c.name) for c in rk.selected)]
    splits = spatial_splits(model, ds, groups, len(folds))
    e_final = rk.final_cv_resid if rk.final_cv_resid is not None else rk.base_cv_resid
    r_random = held_rms(e_final) / floor
    r_without = held_rms(rk.base_cv_resid) / floor
    r_spatial, where = None, ""
    for label, sfolds in splits:
        try:
            r = held_rms(held_out(model, ds, final_effects, sfolds)) / floor
        except PostprocError:
            continue
        if r_spatial is None or r > r_spatial:
            r_spatial, where = r, label
    worst = max(r_random, r_spatial or 0.0)
    split = _split_text(r_random, r_spatial, where, [n for n, _ in splits])
    names = ", ".join(c.name for c in rk.selected)
    jump = getattr(res, "jump", None)
    if jump is not None:
        return _jump_verdict(jump, names, split, r_random, r_spatial)
    # a widened tolerance allows for the floor's uncertainty, which every ratio shares; a
    # held-out split much worse than the random folds is not the floor (a local error)
    carried = not (rk.selected and r_spatial is not None and r_spatial > CONSISTENT_RATIO
                   and r_spatial > LOCAL_EXCESS * r_random)
    if worst <= tol and carried:
        if not rk.selected:
            return Verdict("consistent", f"held-out RMS {split} (<= {bound}); nothing suggested",
                           r_random, r_spatial)
        return Verdict("missing-effect", f"{names}: held-out RMS with them {split} "
                       f"(<= {bound}; {r_without:.2f} without)", r_random, r_spatial,
                       {"effects": [c.name for c in rk.selected]})
    local = ""
    if rk.selected and r_spatial is not None and (r_random <= tol or r_spatial > LOCAL_EXCESS * r_random):
        local = (f"{names} miss(es) the {where} held out ({r_spatial:.2f} x the floor, against {r_random:.2f} on "
                 "random folds): it holds only where it was fitted (a local error, or one of the conditions, "
                 "taken for a global shape); ")
    own = list(res.refitted_effects)
    tries = [(m, d, own) for m, d in finer_models(model, ds)]
    if rk.selected:  # the finer model may stand for the suggested shapes, or need them beside it
        tries += [(m, d + " with " + names, final_effects) for m, d in finer_models(model, ds)]
    for f_model, f_desc, f_effects in tries:
        try:
            fr = held_rms(held_out(f_model, ds, f_effects, folds)) / floor
            if fr > tol:
                continue
            fs = max((held_rms(held_out(f_model, ds, f_effects, f)) / floor
                      for _, f in spatial_splits(f_model, ds, groups, len(folds))), default=fr)
        except PostprocError:
            continue
        if max(fr, fs) <= tol:
            named, command = _rank_on_finer(res, f_model, f_effects, folds)
            also = (f"; on it the ranking names {', '.join(named)}" if named else
                    "; on it no effect of the catalogue is significant")
            return Verdict("model-too-stiff", f"{local}held-out RMS {split}; {f_desc}: random folds {fr:.2f}, "
                           f"held-out splits {fs:.2f} x the floor{also}", r_random, r_spatial,
                           {"finer_model": f_desc, "finer_random_ratio": fr, "finer_spatial_ratio": fs,
                            "finer_effects": named, "finer_command": command})
    upper = floor_upper(floor, nf.dof) if nf.source == "repeats" else floor
    corr, z = neighbour_structure(ds, e_final, groups)
    if z < STRUCTURE_Z and not local:
        excess = float(np.sqrt(max(r_random**2 - 1.0, 0.0))) * floor
        why = (f"the {excess * 1000:.2f} um above the floor is spatially white (neighbour correlation "
               f"{corr:+.2f}, z {z:.1f} < {STRUCTURE_Z:g}): scatter this campaign cannot attribute, between "
               "visits (the machine's repeatability, which shots seconds apart do not show) or on a scale "
               "finer than its point spacing; revisit points later in the campaign, or measure denser")
        if worst * floor <= tol * upper:
            why += (f"; and the floor rests on {nf.dof} degrees of freedom (up to {upper / floor:.2f} x "
                    "higher at 95 %)")
        return Verdict("campaign-limited", f"held-out RMS {split}; {why}", r_random, r_spatial,
                       {"cause": "repeatability", "neighbour_correlation": corr, "floor_upper_mm": upper})
    sampling = [w for w in res.warnings if w.get("kind") in SAMPLING_WARNINGS]
    if sampling:
        return Verdict("campaign-limited", f"{local}held-out RMS {split}; the campaign cannot resolve it: "
                       f"{sampling[0]['kind']} (see the warnings)", r_random, r_spatial,
                       {"cause": sampling[0]["kind"]})
    return Verdict("unexplained", f"{local}held-out RMS {split}; residual spatially structured "
                   f"(neighbour correlation {corr:+.2f}, z {z:.1f}); no effect in the catalogue, no finer "
                   "model of the same family and no limit of the campaign explains it", r_random, r_spatial,
                   {"neighbour_correlation": corr})
