"""The verdict of a check, judged on held-out points, with its evidence in one line.

The ranking (:mod:`postproc.diagnose.rank`) cross-validates on random folds of repeat
groups. A random split cannot tell a local error from a global shape: a 15 um bump on
a tenth of the travel is in the training data of every fold, so a whole-travel S-shape
fitted to it predicts the held-out points near the bump well enough. The verdict is
therefore also judged on a **spatial** split: the volume is cut into blocks (a 3 x 3 x 3
lattice over the measured extent), whole blocks are held out, and the model (base +
effects) is refitted without them. A shape fitted to a local error is then wrong where
the error is not, and right nowhere the error was held out.

Verdicts, in the order they are tried:

- ``consistent``: the calibration's cross-validated RMS, random and spatial, is within
  ``CONSISTENT_RATIO`` x the noise floor and nothing is suggested;
- ``missing-effect``: the suggested effects bring both there (named);
- ``model-too-stiff``: a finer model of the same family does (a parametric model with
  knots twice as close, an interval model with twice the cells per axis, the static
  model cut into 2 x 2 x 2 cells);
- ``campaign-limited``: the campaign cannot separate the rest from noise: the noise
  floor rests on too few repeats to be sure of it, or the residual left is spatially
  white (neighbouring points do not share it: per-visit scatter, the machine's
  repeatability, which shots taken seconds apart do not show), or the campaign's
  sampling is too coarse for the model (see the campaign warnings);
- ``unexplained``: none of these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from postproc.diagnose.crossval import FOLD_SEED, FoldCache, JointCV, rms3
from postproc.diagnose.data import Dataset
from postproc.diagnose.models import Fixed, LinearStatic, Refit
from postproc.effects import Effect, get_effect
from postproc.errors import PostprocError

#: A cross-validated RMS within this many times the noise floor is consistent with noise.
CONSISTENT_RATIO = 1.15
# Blocks per axis of the spatial split (3: a held-out block is a third of each travel,
# wider than a local error of a tenth of it and narrower than a whole-travel shape).
SPATIAL_BLOCKS = 3
# One-sided level of the noise floor's upper confidence bound (chi-square on its degrees
# of freedom): below it the floor is not known well enough to call a ratio above 1.15.
FLOOR_CONFIDENCE = 0.05
# Neighbour correlation of the held-out residual (nearest other point) above this many
# standard errors of white noise is spatial structure; below, the excess is scatter.
STRUCTURE_Z = 3.0
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
    """Test masks of ``k`` folds of whole spatial blocks (a SPATIAL_BLOCKS^3 lattice over the
    measured extent); repeat groups stay together (in the block of their first row)."""
    lo, span = ds.q.min(axis=0), np.ptp(ds.q, axis=0)
    cell = np.floor(SPATIAL_BLOCKS * (ds.q - lo) / np.where(span > 0, span, 1.0)).clip(0, SPATIAL_BLOCKS - 1)
    block = (cell @ np.array([SPATIAL_BLOCKS**2, SPATIAL_BLOCKS, 1])).astype(int)
    first = np.full(int(groups.max()) + 1, -1)
    for i in range(len(groups) - 1, -1, -1):
        first[groups[i]] = block[i]
    block = first[groups]
    ids = np.unique(block)
    k = max(2, min(k, len(ids)))
    order = np.random.default_rng(seed).permutation(ids)
    fold_of = {int(b): i % k for i, b in enumerate(order)}
    f = np.array([fold_of[int(b)] for b in block])
    return [f == i for i in range(k) if np.any(f == i)]


def held_out(model, ds: Dataset, effects: list[Effect], folds: list[np.ndarray]) -> np.ndarray:
    """Held-out residual (N, 3) of ``model`` with ``effects`` (refitted on every training fold)."""
    scorer = JointCV if isinstance(model, LinearStatic | Fixed) else FoldCache
    return scorer(model, ds, [get_effect(e.name) for e in effects], folds).residuals()


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
    # groups at one position (other approach, other tool) are not neighbours: a reversal or
    # tool error is not spatial structure
    key = np.round(q, 3)
    if len(ids) < 8:
        return 0.0, 0.0
    from scipy.spatial import cKDTree

    tree = cKDTree(q / np.maximum(np.ptp(q, axis=0), 1e-9))
    _, nn = tree.query(q / np.maximum(np.ptp(q, axis=0), 1e-9), k=min(len(ids), 8))
    partner = np.full(len(ids), -1)
    for i in range(len(ids)):
        for j in nn[i][1:]:
            if not np.array_equal(key[i], key[j]):
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


def finer_model(model, ds: Dataset):
    """(model, description) of a finer model of the same family, or None."""
    from postproc.diagnose.models import base_model

    if isinstance(model, Fixed):
        return None
    if isinstance(model, LinearStatic):
        return (base_model("interval", {"intervals": "X=2;Y=2;Z=2", "border_blend_mm": 0.0},
                           register=model.register), "the static model cut into 2 x 2 x 2 cells (interval)")
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


def judge(res, model, groups: np.ndarray, folds: list[np.ndarray]) -> Verdict | None:
    """The verdict of check result ``res`` (ranking done), with its one-line evidence."""
    rk, floor = res.ranking, res.noise.rms_mm
    if rk is None or not floor:
        return None
    ds = res.ds
    final_effects = [*res.refitted_effects, *(get_effect(c.name) for c in rk.selected)]
    sfolds = spatial_folds(ds, groups, len(folds))
    r_random = rk.final_cv_rms_mm / floor
    try:
        e_spatial = held_out(model, ds, final_effects, sfolds)
        r_spatial = rms3(e_spatial) / floor
    except PostprocError:
        e_spatial, r_spatial = None, None
    worst = max(r_random, r_spatial or 0.0)
    split = (f"random {r_random:.2f}, spatial {r_spatial:.2f} x the floor" if r_spatial is not None
             else f"random {r_random:.2f} x the floor (no spatial split)")
    names = ", ".join(c.name for c in rk.selected)
    if worst <= CONSISTENT_RATIO:
        if not rk.selected:
            return Verdict("consistent", f"held-out RMS {split} (<= {CONSISTENT_RATIO:g}); nothing suggested",
                           r_random, r_spatial)
        return Verdict("missing-effect", f"{names}: held-out RMS with them {split} "
                       f"(<= {CONSISTENT_RATIO:g}; {rk.base_cv_rms_mm / floor:.2f} without)", r_random, r_spatial,
                       {"effects": [c.name for c in rk.selected]})
    local = ""
    if rk.selected and r_random <= CONSISTENT_RATIO and r_spatial is not None:
        local = (f"{names} hold(s) on random folds but not on blocks it was not fitted to "
                 f"(a local error taken for a global shape); ")
    finer = finer_model(model, ds)
    if finer is not None:
        try:
            f_model, f_desc = finer
            fr = rms3(held_out(f_model, ds, final_effects, folds)) / floor
            fs = rms3(held_out(f_model, ds, final_effects, sfolds)) / floor
        except PostprocError:
            fr = fs = float("inf")
        if max(fr, fs) <= CONSISTENT_RATIO:
            return Verdict("model-too-stiff", f"{local}held-out RMS {split}; {f_desc}: random {fr:.2f}, "
                           f"spatial {fs:.2f} x the floor", r_random, r_spatial,
                           {"finer_model": f_desc, "finer_random_ratio": fr, "finer_spatial_ratio": fs})
    nf = res.noise
    upper = floor_upper(floor, nf.dof) if nf.source == "repeats" else floor
    if worst * floor <= CONSISTENT_RATIO * upper:
        return Verdict("campaign-limited", f"{local}held-out RMS {split}, but the floor rests on {nf.dof} "
                       f"degrees of freedom and may be up to {upper / floor:.2f} x higher (95 %): "
                       "more repeated shots would tell", r_random, r_spatial, {"cause": "floor uncertain"})
    e_final = rk.final_cv_resid if rk.final_cv_resid is not None else rk.base_cv_resid
    corr, z = neighbour_structure(ds, e_final, groups)
    if z < STRUCTURE_Z and not local:
        excess = float(np.sqrt(max(rms3(e_final) ** 2 - floor**2, 0.0)))
        return Verdict("campaign-limited", f"held-out RMS {split}; the {excess * 1000:.2f} um above the floor "
                       f"is spatially white (neighbour correlation {corr:+.2f}, z {z:.1f} < {STRUCTURE_Z:g}): "
                       "scatter between visits (repeatability), which shots seconds apart do not show; "
                       "revisit points later in the campaign to measure it", r_random, r_spatial,
                       {"cause": "repeatability", "neighbour_correlation": corr})
    sampling = [w for w in res.warnings if w.get("kind") in SAMPLING_WARNINGS]
    if sampling:
        return Verdict("campaign-limited", f"{local}held-out RMS {split}; the campaign cannot resolve it: "
                       f"{sampling[0]['kind']} (see the warnings)", r_random, r_spatial,
                       {"cause": sampling[0]["kind"]})
    return Verdict("unexplained", f"{local}held-out RMS {split}; residual spatially structured "
                   f"(neighbour correlation {corr:+.2f}, z {z:.1f}); no effect in the catalogue, no finer "
                   "model of the same family and no limit of the campaign explains it", r_random, r_spatial,
                   {"neighbour_correlation": corr})
