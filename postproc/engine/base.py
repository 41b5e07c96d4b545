"""The engine interface every compensation method implements.

Names (see the README's "Model" section):

- ``q``: commanded machine-axis positions (N, 3) in mm, what the controller is told;
  with a tool, the position of the spindle gauge point.
- ``r``: tool vector (N, 3) or (3,) in mm, from the spindle gauge point to the
  functional point (a vertical tool of length L is ``(0, 0, -L)``).
- ``p``: actual position of the functional point in the ideal frame (N, 3), mm.
  On an ideal machine ``p = q + r``.
- ``context``: optional mapping of per-point context variables (arrays of shape (N,)
  or scalars): ``dirx, diry, dirz`` approach directions, ``t``, ``temp``, ``load``...

Compensation: for a program target ``p*`` find ``q`` with ``F(q, r) = p*``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from postproc.constants import VOLUME_EDGE_SLACK_MM
from postproc.errors import CalibrationError, PostprocError

Context = Mapping[str, Any]


def check_points(a, name: str = "points") -> np.ndarray:
    """Return ``a`` as a float (N, 3) array or raise naming expected and actual shape."""
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise PostprocError(f"{name}: expected shape (N, 3), got {arr.shape}")
    return arr


def check_tool_vectors(r, n: int, name: str = "tool vectors") -> np.ndarray:
    """Broadcast ``r`` (None, (3,) or (N, 3)) to a float (N, 3) array."""
    if r is None:
        return np.zeros((n, 3))
    arr = np.asarray(r, dtype=float)
    if arr.shape == (3,):
        return np.broadcast_to(arr, (n, 3)).copy()
    if arr.shape != (n, 3):
        raise PostprocError(f"{name}: expected shape (3,) or ({n}, 3), got {arr.shape}")
    return arr


@dataclass
class InverseResult:
    """Answer of an inverse solver.

    ``q``: commanded positions (N, 3); ``residual_mm``: |F(q, r) - p*| per point (N,);
    ``iterations``: iterations used per point (N,) (0 for closed-form solvers).
    """

    q: np.ndarray
    residual_mm: np.ndarray
    iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))


class Engine(ABC):
    """A forward model of the machine and its inverse.

    Subclasses set ``method`` (the name used in calibration files and ``--method``)
    and implement :meth:`forward`, :meth:`inverse`, :meth:`model_to_dict` and
    :meth:`model_from_dict`. ``volume_mm`` is the calibrated volume in commanded
    coordinates ``q``: a (2, 3) array of lower and upper bounds.
    """

    method: str = ""
    #: True when F is affine in q for fixed r (lines map to lines, no splitting needed).
    affine: ClassVar[bool] = False

    def __init__(self, volume_mm) -> None:
        vol = np.asarray(volume_mm, dtype=float)
        if vol.shape != (2, 3) or not np.all(np.isfinite(vol)) or np.any(vol[0] > vol[1]):
            raise CalibrationError(
                f"calibrated volume must be [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {vol.tolist()}"
            )
        self.volume_mm = vol

    # -- what the correction pipeline asks of every engine (defaults here) ---------------
    #: name of the inverse solver when the engine has a choice (parametric: newton | astatic)
    solver: str = ""
    #: largest inverse residual (mm) the engine's solver stands for; 0: the pipeline's own
    #: acceptance (ten times the solver tolerance) applies
    accept_residual_mm: float = 0.0

    def with_extrapolation(self, mode: str) -> Engine:
        """The engine extrapolating outside its tables by ``mode`` ("clamp": hold the end
        values, "linear": continue the end slopes). Engines whose model already covers
        all space (static, interval, grid) return themselves."""
        return self

    @property
    def needs(self) -> tuple[str, ...]:
        """Context values the engine reads (effects' ``dirx``, ``t``, ...); none by default."""
        return ()

    @property
    def direction_dependent(self) -> bool:
        """True when the correction depends on the approach direction of the axes
        (backlash): the planner then cuts moves at reversals and takes them up."""
        return any(c in ("dirx", "diry", "dirz") for c in self.needs)

    def line_curvature_bound(self, q0, q1, r_norm_mm, margin_mm: float = 0.0) -> np.ndarray:
        """An upper bound (1/mm) on the second derivative, along each straight move from
        ``q0`` to ``q1`` (N, 3) with a tool vector of length ``r_norm_mm`` (N,), of the
        correction as a function of arc length (inf: no bound known). The commands the
        inverse finds lie within ``margin_mm`` of the moves. A move of length L then
        departs from the chord of its corrected ends by at most ``bound L^2 / 8``, which
        spares the planner sampling it. Affine engines: 0."""
        n = len(np.asarray(q0))
        return np.zeros(n) if self.affine else np.full(n, np.inf)

    def check_context(self, names) -> None:
        """Refuse (PostprocError) when a context value the engine needs is not among
        ``names``; engines without effects need none."""
        return None

    # -- the model -------------------------------------------------------------------
    @abstractmethod
    def forward(self, q, r=None, context: Context | None = None) -> np.ndarray:
        """Actual functional-point positions p (N, 3) for commanded q (N, 3)."""

    @abstractmethod
    def inverse(self, p, r=None, context: Context | None = None) -> InverseResult:
        """Commanded positions q with F(q, r) = p, and the residual of each point."""

    # -- serialisation ---------------------------------------------------------------
    @abstractmethod
    def model_to_dict(self) -> dict:
        """Method-specific parameters as plain JSON data (lengths mm, angles rad)."""

    @classmethod
    @abstractmethod
    def model_from_dict(cls, model: dict, volume_mm) -> Engine:
        """Inverse of :meth:`model_to_dict`; raise CalibrationError on bad content."""

    # -- helpers shared by all engines ----------------------------------------------
    def inside(self, q) -> np.ndarray:
        """Boolean (N,) mask: which commanded points lie in the calibrated volume."""
        q = check_points(q)
        lo = self.volume_mm[0] - VOLUME_EDGE_SLACK_MM
        hi = self.volume_mm[1] + VOLUME_EDGE_SLACK_MM
        within = (q >= lo) & (q <= hi)
        return within[:, 0] & within[:, 1] & within[:, 2]  # np.all(.., axis=1), by whole columns

    def correction(self, p, r=None, context: Context | None = None) -> InverseResult:
        """Inverse expressed as the change of the nominal command ``p - r``.

        Returns an InverseResult whose ``q`` is the *delta* to add to the nominal
        command. Useful to the emitter, which rewrites program coordinates.
        """
        p = check_points(p)
        rr = check_tool_vectors(r, len(p))
        res = self.inverse(p, rr, context)
        return InverseResult(res.q - (p - rr), res.residual_mm, res.iterations)

    def residual(self, q, p, r=None, context: Context | None = None) -> np.ndarray:
        """|F(q, r) - p| per point."""
        return np.linalg.norm(self.forward(q, r, context) - check_points(p), axis=1)


@dataclass
class FitResult:
    """What a fitter returns: the engine and how well it fits the data it came from.

    ``residuals_mm`` (N, 3) are measured - model at the fitted points; ``report`` is
    human-readable lines (rank, conditioning, undetermined parameters...) that the CLI
    prints; ``info`` goes into the calibration file's ``fit`` section.
    """

    engine: Engine
    residuals_mm: np.ndarray
    report: list[str] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    effects: list = field(default_factory=list)

    @property
    def rms_mm(self) -> float:
        r = np.asarray(self.residuals_mm)
        return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else 0.0

    @property
    def max_mm(self) -> float:
        r = np.asarray(self.residuals_mm)
        return float(np.max(np.linalg.norm(r, axis=1))) if len(r) else 0.0


