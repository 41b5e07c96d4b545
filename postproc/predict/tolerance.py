"""Tolerance analysis over a chain's random variables (seed 004).

Random variables stand for the corner heights of surfaces inside their tolerance
fields (a plane through them is fitted by least squares, formulas 18-22) and for the
positions of parts inside joint clearances. A distribution is

- ``{"uniform": [lo, hi]}``: any value in the field equally likely (the seed's
  "random-number generator" inside the tolerance field);
- ``{"normal": [mean, sigma]}``: its worst case is taken at mean +- 3 sigma.

:func:`monte_carlo` draws them (seeded, reproducible) and evaluates a feature error
for all draws in one vectorised call; :func:`worst_case` evaluates it at every corner
of the box of variables (the seed's deterministic "worst position"), which is exact
when the error is affine in the variables, as it is to first order for small errors.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from postproc.errors import PostprocError

# Worst case of a normal variable: the usual process-capability bound, 99.73 %.
NORMAL_WORST_SIGMAS = 3.0

# Corner enumeration costs 2**k evaluations; past this many variables it is refused
# (2**16 = 65536 chain evaluations take well under a second, 2**24 would not).
MAX_WORST_CASE_VARIABLES = 16

# Draws evaluated at once: a chain of 4x4 matrices for 9 section points costs about
# 1 kB per draw and matrix, so blocks of 10 000 stay near 100 MB whatever n is.
DRAWS_PER_BLOCK = 10_000


def check_distribution(dist: Any, where: str) -> None:
    """Raise PostprocError unless ``dist`` is ``{"uniform": [lo, hi]}`` or ``{"normal": [m, s]}``."""
    ok = isinstance(dist, Mapping) and len(dist) == 1
    if ok:
        kind, args = next(iter(dist.items()))
        ok = kind in ("uniform", "normal") and isinstance(args, list) and len(args) == 2
        ok = ok and all(isinstance(a, int | float) and np.isfinite(a) for a in args)
        if ok and kind == "uniform":
            ok = args[0] <= args[1]
        if ok and kind == "normal":
            ok = args[1] >= 0
    if not ok:
        raise PostprocError(
            f"{where}: a distribution is {{\"uniform\": [lo, hi]}} or {{\"normal\": [mean, sigma]}}, got {dist!r}",
            hint="lo <= hi and sigma >= 0, lengths in mm, angles in rad",
        )


def bounds(dist: Mapping) -> tuple[float, float]:
    """Lower and upper value used by the worst case."""
    kind, (a, b) = next(iter(dist.items()))
    if kind == "uniform":
        return float(a), float(b)
    return float(a - NORMAL_WORST_SIGMAS * b), float(a + NORMAL_WORST_SIGMAS * b)


def varying(random: Mapping[str, Mapping], used) -> list[str]:
    """The random variables among ``used`` whose field has a width (the others are constants)."""
    out = []
    for name, dist in random.items():
        lo, hi = bounds(dist)
        if name in used and hi > lo:
            out.append(name)
    return out


def nominal(random: Mapping[str, Mapping]) -> dict[str, float]:
    """Centre of every variable (mid-field, or the mean)."""
    return {name: 0.5 * sum(bounds(d)) for name, d in random.items()}


def sample(random: Mapping[str, Mapping], n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """``n`` draws of every variable, in the order of the mapping (reproducible per seed)."""
    out = {}
    for name, dist in random.items():
        kind, (a, b) = next(iter(dist.items()))
        out[name] = rng.uniform(a, b, n) if kind == "uniform" else rng.normal(a, b, n)
    return out


def corners(random: Mapping[str, Mapping]) -> dict[str, np.ndarray]:
    """All ``2**k`` combinations of the variables' bounds, as arrays of that length."""
    names = list(random)
    if len(names) > MAX_WORST_CASE_VARIABLES:
        raise PostprocError(
            f"worst case over {len(names)} variables needs 2**{len(names)} evaluations",
            hint=f"use at most {MAX_WORST_CASE_VARIABLES} random variables, or Monte Carlo",
        )
    bits = (np.arange(2 ** len(names))[:, None] >> np.arange(len(names))[None, :]) & 1
    out = {}
    for i, name in enumerate(names):
        lo, hi = bounds(random[name])
        out[name] = np.where(bits[:, i] == 1, hi, lo)
    return out


@dataclass
class Distribution:
    """Monte-Carlo result for a feature error with ``d`` components (mm)."""

    names: list[str]
    samples_mm: np.ndarray  # (n, d)
    tolerance_mm: np.ndarray  # (d,) symmetric limits +-tol per component
    seed: int

    @property
    def mean_mm(self) -> np.ndarray:
        return self.samples_mm.mean(axis=0)

    @property
    def std_mm(self) -> np.ndarray:
        return self.samples_mm.std(axis=0, ddof=1)

    @property
    def within(self) -> np.ndarray:
        """(n,) which draws meet every component's tolerance."""
        return np.all(np.abs(self.samples_mm) <= self.tolerance_mm, axis=1)

    @property
    def p_within(self) -> float:
        return float(np.mean(self.within))

    @property
    def p_within_ci95(self) -> tuple[float, float]:
        """Wilson 95 % interval of ``p_within`` (the Monte-Carlo sampling error)."""
        n = len(self.samples_mm)
        p = self.p_within
        z = 1.959963984540054
        centre = (p + z * z / (2 * n)) / (1 + z * z / n)
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        return float(centre - half), float(centre + half)

    def to_dict(self) -> dict:
        lo, hi = self.p_within_ci95
        return {
            "components": self.names,
            "n": int(len(self.samples_mm)),
            "seed": self.seed,
            "mean_mm": self.mean_mm.tolist(),
            "std_mm": self.std_mm.tolist(),
            "min_mm": self.samples_mm.min(axis=0).tolist(),
            "max_mm": self.samples_mm.max(axis=0).tolist(),
            "tolerance_mm": self.tolerance_mm.tolist(),
            "p_within": self.p_within,
            "p_within_ci95": [lo, hi],
        }


@dataclass
class WorstCase:
    """Largest |error| per component over the corners, and the corner that gives it."""

    names: list[str]
    max_abs_mm: np.ndarray  # (d,)
    corner: list[dict[str, float]]  # per component, the variable values
    tolerance_mm: np.ndarray
    min_mm: np.ndarray  # (d,) smallest and largest signed error over the corners
    max_mm: np.ndarray

    @property
    def within(self) -> bool:
        return bool(np.all(self.max_abs_mm <= self.tolerance_mm))

    def to_dict(self) -> dict:
        return {
            "components": self.names,
            "max_abs_mm": self.max_abs_mm.tolist(),
            "min_mm": self.min_mm.tolist(),
            "max_mm": self.max_mm.tolist(),
            "tolerance_mm": self.tolerance_mm.tolist(),
            "within": self.within,
            "corner": self.corner,
        }


ErrorFn = Callable[[Mapping[str, np.ndarray]], np.ndarray]


def _rows(err, n: int) -> np.ndarray:
    """An error function's result as (n, d): a result that does not depend on the draws
    (a chain that ignores the variables) is the same row n times."""
    err = np.asarray(err, dtype=float)
    if err.ndim <= 1:
        return np.broadcast_to(err.reshape(1, -1), (n, err.size))
    return np.broadcast_to(err.reshape(-1, err.shape[-1]), (n, err.shape[-1]))


def single(error_fn: ErrorFn, values: Mapping[str, float], *, tolerance_mm, names: list[str]) -> WorstCase:
    """The one prediction of a deterministic chain, as its own worst case."""
    err = _rows(error_fn({k: np.asarray([v], dtype=float) for k, v in values.items()}), 1)[0]
    return WorstCase(names, np.abs(err), [dict(values) for _ in err],
                     np.broadcast_to(np.asarray(tolerance_mm, float), err.shape).copy(), err.copy(), err.copy())


def monte_carlo(
    error_fn: ErrorFn,
    random: Mapping[str, Mapping],
    *,
    n: int,
    seed: int,
    tolerance_mm,
    names: list[str],
) -> Distribution:
    """Draw ``n`` sets of the random variables and evaluate ``error_fn(env) -> (n, d)``."""
    if n < 2:
        raise PostprocError(f"Monte-Carlo size must be at least 2, got {n}")
    if not random:
        raise PostprocError("no random variables to draw", hint='add a "random" section to the chain file')
    draws = sample(random, n, np.random.default_rng(seed))
    blocks = []
    for start in range(0, n, DRAWS_PER_BLOCK):
        part = {k: v[start:start + DRAWS_PER_BLOCK] for k, v in draws.items()}
        blocks.append(_rows(error_fn(part), len(next(iter(part.values())))))
    err = np.concatenate(blocks)
    return Distribution(names, err, np.broadcast_to(np.asarray(tolerance_mm, float), err.shape[1:]).copy(), seed)


def worst_case(error_fn: ErrorFn, random: Mapping[str, Mapping], *, tolerance_mm, names: list[str]) -> WorstCase:
    """Evaluate ``error_fn`` at every corner of the variables' box."""
    env = corners(random)
    err = _rows(error_fn(env), len(next(iter(env.values()))) if env else 1)
    idx = np.argmax(np.abs(err), axis=0)
    worst = [{k: float(v[i]) for k, v in env.items()} for i in idx]
    return WorstCase(
        names,
        np.abs(err[idx, np.arange(err.shape[1])]),
        worst,
        np.broadcast_to(np.asarray(tolerance_mm, float), err.shape[1:]).copy(),
        err.min(axis=0),
        err.max(axis=0),
    )


def plot_histograms(dist: Distribution, worst: WorstCase | None = None, ax=None):
    """Histogram of each error component with its tolerance limits -> axes."""
    import matplotlib.pyplot as plt

    d = dist.samples_mm.shape[1]
    if ax is None:
        _, ax = plt.subplots(1, d, figsize=(5 * d, 4), squeeze=False)
        ax = ax[0]
    for i in range(d):
        a = ax[i]
        a.hist(dist.samples_mm[:, i] * 1e3, bins=80, color="tab:blue", alpha=0.8)
        for s in (-1, 1):
            a.axvline(s * dist.tolerance_mm[i] * 1e3, color="k", ls="--", lw=1)
        if worst is not None:
            for v in (worst.min_mm[i], worst.max_mm[i]):
                a.axvline(v * 1e3, color="tab:red", ls=":", lw=1.5)
        a.set_xlabel(f"error {dist.names[i]} (µm)")
        a.set_title(f"{dist.names[i]}: mean {dist.mean_mm[i] * 1e3:.1f} µm, std {dist.std_mm[i] * 1e3:.1f} µm")
    ax[0].set_ylabel("draws")
    ax[0].figure.suptitle(f"P(within tolerance) = {dist.p_within:.5f}, n = {len(dist.samples_mm)}; "
                          "dashed: tolerance, dotted: worst-case range")
    ax[0].figure.tight_layout()
    return ax
