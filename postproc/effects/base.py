"""The ``Effect`` interface: one physical effect that a geometric model may miss.

An effect is a displacement of the functional point added to a base model::

    p = F_base(q, r) + displacement(q, r, context)
    displacement = basis(q, r, context) @ params        (N, 3) = (N, 3, k) @ (k,)

It is linear in its ``params`` (so it can be fitted jointly with a linear base model
by least squares); any non-linear setting (the pitch of a lead screw, the time
constant of a thermal lag, a reference temperature) lives in ``config`` and is found
by :meth:`Effect.prepare` from a residual, by a search.

Serialised as ``{"name": "periodic:X", "config": {"pitch_mm": 10.0},
"params": {"cos_mm": 0.002, "sin_mm": -0.001}}`` (lengths mm, angles rad).
"""

from __future__ import annotations

import copy
import math
import numbers
from collections.abc import Mapping
from typing import Any, ClassVar, Self

import numpy as np

from postproc.effects.linalg import solve_ls
from postproc.engine.base import check_points, check_tool_vectors
from postproc.errors import CalibrationError, MissingSetupError, PostprocError

AXES = "XYZ"
DIR_COLUMNS = ("dirx", "diry", "dirz")

# A context column whose spread (max - min) is below this fraction of its magnitude
# (or exactly constant) cannot separate an effect from the model's constant offset.
MIN_RELATIVE_SPREAD = 1e-9


# A context column must differ from its most common value in at least this many rows:
# an effect fitted on one or two rows is those rows' noise.
MIN_ROWS_VARIED = 3


def axis_index(letter: str) -> int:
    return AXES.index(letter)


def unit_basis(values: np.ndarray, axis: int) -> np.ndarray:
    """(N,) values placed on one axis: an (N, 3) array."""
    out = np.zeros((len(values), 3))
    out[:, axis] = values
    return out


def context_hint(column: str) -> str:
    if column in DIR_COLUMNS:
        return (
            f"{column} is the approach direction of the axis (+1/-1): the correction pipeline "
            f"derives it from the program's moves; measurement files need a {column} column"
        )
    meaning = {
        "t": "seconds since the start of the warm-up",
        "load": "the static load on the table, in the unit of the calibration data",
    }.get(column, "°C" if column.startswith("temp") else "its value while the program runs")
    return f"give it as --context {column}=VALUE ({meaning})"


def context_column(ctx: Mapping[str, Any] | None, column: str, n: int, who: str) -> np.ndarray:
    """Context ``column`` as an (n,) float array; scalars are broadcast.

    Missing: MissingSetupError naming the ``--context NAME=VALUE`` to give.
    """
    if ctx is None or column not in ctx or ctx[column] is None:
        raise MissingSetupError(
            f"the calibration's effect {who} needs the context value {column!r}, which was not given",
            hint=context_hint(column),
        )
    v = np.asarray(ctx[column], dtype=float)
    if v.ndim == 0:
        return np.full(n, float(v))
    if v.shape != (n,):
        raise PostprocError(f"context {column!r}: expected a scalar or shape ({n},), got {v.shape}")
    return v


def _check_number(name: str, where: str, key: str, value: Any) -> None:
    """Effect settings and parameters read from a file must be finite numbers."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise CalibrationError(
            f"effect {name}: {where}.{key} is {value!r}, not a finite number",
            hint="an effect's config and params hold numbers (lengths mm, angles rad, times s); "
                 "refit with 'postproc fit --effect'",
        )


class Effect:
    """Base class of every effect. Subclasses set the class attributes and :meth:`basis`.

    Instance attributes: ``target`` (what follows the colon in the name), ``config``
    (non-linear settings), ``params`` (dict name -> value, in ``param_names`` order).
    """

    kind: ClassVar[str] = ""
    #: one line: the physical meaning, shown by ``check``
    meaning: ClassVar[str] = ""
    #: True when ``correct`` can compensate it (given its context); else the reason why not
    compensable: ClassVar[bool] = True
    #: the targets the kind takes (``backlash``: X, Y, Z); None: any context column
    targets: ClassVar[tuple[str, ...] | None] = None
    #: a context-column target must start with this (``thermal:temp...``)
    target_prefix: ClassVar[str] = ""
    #: what the target names, where several classes share a kind (``thermal``)
    target_meaning: ClassVar[str] = ""
    #: whether ``check`` tries it as a candidate at all
    candidate: ClassVar[bool] = True
    #: parameter name -> k=2 expanded uncertainty; set on a fitted effect only
    #: (:func:`postproc.diagnose.models.split_params`), so read with ``getattr``
    uncertainty: dict[str, float]

    def __init__(self, target: str, config: Mapping | None = None, params: Mapping | None = None):
        self.target = target
        self.config: dict = dict(config or {})
        names = self.param_names
        params = dict(params or {})
        unknown = set(params) - set(names)
        if unknown:
            raise CalibrationError(
                f"effect {self.name}: unknown parameter(s) {', '.join(sorted(unknown))}",
                hint=f"its parameters are {', '.join(names)}",
            )
        for where, values in (("config", self.config), ("params", params)):
            for key, value in values.items():
                if where == "config" and isinstance(value, list | tuple):
                    # a profile along an axis (e.g. a reversal value per table position)
                    for v in value:
                        _check_number(self.name, where, key, v)
                    continue
                _check_number(self.name, where, key, value)
        self.params = {k: float(params.get(k, 0.0)) for k in names}

    # -- the registry's questions ---------------------------------------------------
    @classmethod
    def accepts(cls, target: str) -> bool:
        """Whether ``kind:target`` names an effect of this class."""
        if cls.targets is not None:
            return target in cls.targets
        return bool(target) and target.startswith(cls.target_prefix)

    @classmethod
    def candidates(cls, columns: list[str]) -> list[str]:
        """The names of this class worth trying on data with these context columns
        (those whose column is absent too: ``check`` reports them untestable)."""
        if not cls.candidate:
            return []
        if cls.targets is not None:
            return [f"{cls.kind}:{t}" for t in cls.targets]
        return [f"{cls.kind}:{c}" for c in columns if cls.accepts(c)] or [f"{cls.kind}:{cls.target_prefix}"]

    # -- description -------------------------------------------------------------
    @property
    def name(self) -> str:
        return f"{self.kind}:{self.target}"

    @property
    def needs(self) -> tuple[str, ...]:
        """Context columns the effect needs (beyond q and r)."""
        return ()

    @property
    def param_names(self) -> tuple[str, ...]:
        raise NotImplementedError

    @property
    def compensable_reason(self) -> str:
        """How ``correct`` compensates it, or why it cannot."""
        if not self.needs:
            return "compensated from the commanded position"
        return "compensated given " + ", ".join(self.needs)

    def describe(self, params: Mapping | None = None) -> str:
        """The fitted size in physical units, one short line."""
        p = self.params if params is None else params
        return ", ".join(f"{k} {v * 1000:+.2f} um" if k.endswith("_mm") else f"{k} {v:+.3g}"
                         for k, v in p.items())

    # -- the model ---------------------------------------------------------------
    def basis(self, q, r, ctx) -> np.ndarray:
        """(N, 3, k): displacement = basis @ params. Uses ``self.config``."""
        raise NotImplementedError

    def param_vector(self) -> np.ndarray:
        return np.array([self.params[k] for k in self.param_names])

    def displacement(self, q, r=None, ctx=None, params=None) -> np.ndarray:
        """(N, 3) displacement of the functional point in mm."""
        q = check_points(q, "q")
        rr = check_tool_vectors(r, len(q))
        if params is None:
            vec = self.param_vector()
        elif isinstance(params, Mapping):
            vec = np.array([float(params.get(k, 0.0)) for k in self.param_names])
        else:
            vec = np.asarray(params, dtype=float)
        return self.basis(q, rr, ctx) @ vec

    # -- fitting support ---------------------------------------------------------
    def missing(self, ctx: Mapping | None) -> list[str]:
        return [c for c in self.needs if ctx is None or c not in ctx]

    def untestable_reason(self, q, r, ctx) -> str | None:
        """Why this data cannot test the effect (missing or constant column), else None."""
        miss = self.missing(ctx)
        if miss:
            return f"no {', '.join(miss)} column in the data"
        for c in self.needs:
            v = np.asarray(ctx[c], dtype=float)
            if np.ptp(v) <= MIN_RELATIVE_SPREAD * max(1.0, float(np.max(np.abs(v)))):
                return f"{c} does not vary in the data (always {v.flat[0]:g})"
            values, counts = np.unique(v, return_counts=True)
            off_mode = len(v) - int(counts.max())
            if off_mode < MIN_ROWS_VARIED:
                return (f"{c} varies in only {off_mode} row(s) (always {values[np.argmax(counts)]:g} "
                        f"otherwise): too little variation to test")
        return None

    def prepare(self, q, r, ctx, resid) -> Self:
        """A copy whose ``config`` is set from training data and the current residual.

        Default: no non-linear settings. Periodic errors search the pitch, thermal
        lags the time constant, context terms take their reference value.
        """
        return self.copy()

    # -- serialisation -----------------------------------------------------------
    def copy(self, *, config: Mapping | None = None, params=None) -> Self:
        new = copy.copy(self)
        new.config = copy.deepcopy(dict(self.config if config is None else config))
        if params is None:
            new.params = dict(self.params)
        elif isinstance(params, Mapping):
            new.params = {k: float(params.get(k, 0.0)) for k in self.param_names}
        else:
            new.params = dict(zip(self.param_names, (float(v) for v in params), strict=True))
        return new

    def to_dict(self) -> dict:
        return {"name": self.name, "config": copy.deepcopy(self.config), "params": dict(self.params)}

    def __repr__(self) -> str:
        return f"<Effect {self.name} config={self.config} params={self.params}>"


def lstsq_with_offset(B: np.ndarray, resid: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares of ``resid`` (N, 3) on effect basis ``B`` (N, 3, k) plus a constant
    offset per component; returns (effect params, residual sum of squares).

    Used by the non-linear searches (pitch, time constant): the offset stands in for the
    base model's own constant term.
    """
    n, _, k = B.shape
    A = np.zeros((3 * n, k + 3))
    A[:, :k] = B.reshape(3 * n, k)
    for j in range(3):
        A[j::3, k + j] = 1.0
    y = resid.reshape(3 * n)
    coef = solve_ls(A, y)
    sse = float(np.sum((y - A @ coef) ** 2))
    return coef[:k], sse


class AxisEffect(Effect):
    """An effect of one axis: the target is X, Y or Z."""

    targets = tuple(AXES)

    @property
    def axis(self) -> int:
        return AXES.index(self.target)


class ContextLinear(Effect):
    """A zero-point shift along x, y and z proportional to a value of one context column::

        displacement = (px, py, pz) * value(ctx[column])      (component-wise with q for
                                                                 a weight per axis)

    The column is the target (``load:load``, ``linear:humidity``); :meth:`value` turns
    the column into the factor (by default its departure from the ``reference`` in the
    config). A subclass names its three parameters and how they read, and overrides
    :meth:`value` when the factor is not the column itself.
    """

    #: the parameters of x, y and z
    param_names_xyz: ClassVar[tuple[str, str, str]] = ("", "", "")
    #: the config key of the reference value subtracted from the column ("": none)
    reference_key: ClassVar[str] = ""
    #: the reference used when the config has none
    reference_default: ClassVar[float] = 0.0
    #: how ``--context`` gives the value: "the load ... VALUE"
    given_as: ClassVar[tuple[str, str]] = ("the value", "VALUE")
    #: the fitted size: a head "shift per unit of" before the column, and the unit and
    #: format of each component (value * scale)
    describe_head: ClassVar[str] = ""
    describe_unit: ClassVar[str] = "um"
    describe_scale: ClassVar[float] = 1000.0
    describe_format: ClassVar[str] = "+.3f"

    @property
    def column(self) -> str:
        return self.target

    @property
    def needs(self) -> tuple[str, ...]:
        return (self.column,)

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.param_names_xyz

    @property
    def compensable_reason(self) -> str:
        what, unit = self.given_as
        return f"compensated at {what} given as --context {self.column}={unit}"

    def describe(self, params=None) -> str:
        p = self.params if params is None else params
        return (f"{self.describe_head} {self.column} "
                + " ".join(f"{a} {p[k] * self.describe_scale:{self.describe_format}} {self.describe_unit}"
                           for a, k in zip(AXES, self.param_names, strict=True)))

    @property
    def reference(self) -> float:
        return float(self.config.get(self.reference_key, self.reference_default)) if self.reference_key else 0.0

    def prepare(self, q, r, ctx, resid) -> Self:
        """The reference set to its default (a subclass may take it from the data)."""
        return self.copy(config={self.reference_key: self.reference_default}) if self.reference_key else self.copy()

    def value(self, v: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The factor of each parameter: (N,) for all three axes alike, or (N, 3)."""
        return v - self.reference if self.reference_key else v

    def basis(self, q, r, ctx) -> np.ndarray:
        v = context_column(ctx, self.column, len(q), self.name)
        B = np.zeros((len(q), 3, 3))
        w = self.value(v, q)
        diagonal = np.arange(3)
        B[:, diagonal, diagonal] = w[:, None] if w.ndim == 1 else w
        return B
