"""The 21-parameter model of a three-axis machine (seed 000, chapter 3) as an engine.

For commanded positions ``q = (X, Y, Z)`` and tool vector ``r`` (formats.md signs)::

    rho(q) = sum_i (EX_i, EY_i, EZ_i)(q_i) + (-EC0Y*Y + EB0Z*Z, -EA0Z*Z, 0)
    eps(q) = sum_i (EA_i, EB_i, EC_i)(q_i)              = (A, B, C)

    first  (formula 3):  p = q + r + rho + eps x r
    second (formula 4):  p = q + r + rho + s (v + 0.5 eps x v),   v = eps x r,
                         s = 1 / (1 + |eps|^2 / 4)
    exact:               p = q + rho + R(eps) r                   (Rodrigues-Hamilton)

Formula (4) with the nominal angles is the Cayley form of the finite rotation: it
agrees with the exact rotation to third order in the angles. The seed's interval
terms (products of the per-axis angles with undetermined signs) give the bounds
``delta+`` and ``delta-`` of :meth:`ParametricEngine.second_order_bounds`.

Interpolation between table rows is piecewise cubic Hermite with monotone
(Fritsch-Carlson, "pchip") slopes by default: it passes through every measured row,
never overshoots between two rows (a noisy interferometer table does not turn into
oscillations, as an interpolating natural spline would make of it), and is C1, so
the inverse's Jacobian is continuous and Newton converges quadratically. ``linear``
(what controllers do with compensation tables) is available too.

Outside the table ranges the engine never fails: with ``extrapolate="clamp"`` (the
default) each function keeps its end value; with ``"linear"`` it continues with its
end slope. Squareness terms are linear in q and stay so. The calibrated volume is
the table ranges; the correction pipeline refuses points outside it unless asked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from postproc.calibration.axis_tables import AXES, AxisTables, Squareness
from postproc.constants import SOLVER_TOL_MM, VOLUME_EDGE_SLACK_MM
from postproc.engine import parametric_solvers
from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.engine.parametric_errors import Located, StackedErrors, scratch
from postproc.engine.pchip import Pchip
from postproc.errors import CalibrationError
from postproc.rotation import cross, rotate

ORDERS = ("first", "second", "exact")
SOLVERS = ("newton", "astatic")
INTERPOLATIONS = ("pchip", "linear")
EXTRAPOLATIONS = ("clamp", "linear")


# Cells of the astatic grid along the calibrated volume's longest axis: an iteration walks
# them one by one (the seed's u = 2 mm gives ~160 on a 315 mm machine; 10,000 is 0.03 mm).
ASTATIC_MAX_CELLS = 10_000
# Iterations of the astatic law: it approaches its target in tens (seed 000, chapter 4).
ASTATIC_MAX_ITER = 100_000


@dataclass(frozen=True)
class AstaticSettings:
    """KMTPP astatic control law (seed 000, chapter 4): grid step u, gain K, step l.

    Defaults are the seed's best values: u = 2 mm, K = 1.5, l = 0.1.
    """

    grid_step_mm: float = 2.0
    gain: float = 1.5
    time_step: float = 0.1
    max_iter: int = 2000

    def __post_init__(self) -> None:
        kl = self.gain * self.time_step
        if not (self.grid_step_mm > 0 and 0 < kl < 2 and 0 < self.max_iter <= ASTATIC_MAX_ITER):
            raise CalibrationError(
                f"astatic settings u={self.grid_step_mm}, K={self.gain}, l={self.time_step}: "
                f"need u > 0 and 0 < K*l < 2 (otherwise the iteration does not approach the target), and 1 to "
                f"{ASTATIC_MAX_ITER:,} iterations (max_iter {self.max_iter})"
            )

    def check_cells(self, volume_mm: np.ndarray) -> None:
        """Refuse a grid step that cuts the calibrated volume into more than
        :data:`ASTATIC_MAX_CELLS` cells along an axis: each iteration walks the cells one
        by one, so the time grows as their number (u = 1e-9 mm ran for hours)."""
        cells = float(np.max(np.ptp(volume_mm, axis=0))) / self.grid_step_mm
        if cells > ASTATIC_MAX_CELLS:
            raise CalibrationError(
                f"astatic grid step u={self.grid_step_mm:g} mm cuts the calibrated volume into {cells:.3g} cells "
                f"along an axis: more than {ASTATIC_MAX_CELLS:,}",
                hint=f"give astatic grid_step_mm of at least "
                     f"{float(np.max(np.ptp(volume_mm, axis=0))) / ASTATIC_MAX_CELLS:.3g} mm (the method's own "
                     "value is 2 mm)")

    def to_dict(self) -> dict:
        return {"grid_step_mm": self.grid_step_mm, "gain": self.gain, "time_step": self.time_step,
                "max_iter": self.max_iter}


class AxisFunctions:
    """The six error functions of one axis, interpolated from its table rows."""

    def __init__(self, position_mm: np.ndarray, values: np.ndarray, interpolation: str,
                 extrapolate: str) -> None:
        self.x = np.asarray(position_mm, dtype=float)
        self.values = np.asarray(values, dtype=float)
        self.interpolation = interpolation
        self.extrapolate = extrapolate
        if interpolation == "pchip":
            self._f = Pchip(self.x, self.values)
            self._df = self._f.derivative
        else:
            self._slopes = np.diff(self.values, axis=0) / np.diff(self.x)[:, None]

    def _linear(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        w = (t - self.x[idx]) / (self.x[idx + 1] - self.x[idx])
        v = self.values[idx] * (1 - w)[:, None] + self.values[idx + 1] * w[:, None]
        return v, self._slopes[idx]

    def evaluate(self, t, derivative: bool = False):
        """Values (N, 6) at positions t (N,), and their derivatives when asked."""
        t = np.asarray(t, dtype=float)
        tc = np.clip(t, self.x[0], self.x[-1])
        if self.interpolation == "pchip":
            v, dv = self._f(tc), (self._df(tc) if (derivative or self.extrapolate == "linear") else None)
        else:
            v, dv = self._linear(tc)
        outside = t != tc
        if dv is None:  # pchip without derivative, clamped: the values are all that is asked
            return v
        if self.extrapolate == "linear":
            v = v + (t - tc)[:, None] * dv
        elif derivative and outside.any():
            dv = np.where(outside[:, None], 0.0, dv)
        return (v, dv) if derivative else v


def second_order_displacement(eps: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Formula (4) angular part: s (v + 0.5 eps x v), v = eps x r."""
    v = cross(eps, r)
    return s[:, None] * (v + 0.5 * cross(eps, v))


class ParametricEngine(Engine):
    """Forward model from axis error tables and squareness, with two inverse solvers.

    ``order``: "first" (formula 3), "second" (formula 4, nominal angles) or "exact"
    (finite rotation). ``solver``: "newton" (converged to SOLVER_TOL_MM) or "astatic"
    (KMTPP, seed 000 chapter 4). ``volume_mm`` defaults to the table ranges.
    """

    method = "parametric"
    affine = False

    def __init__(self, tables: AxisTables, squareness: Squareness | None = None, volume_mm=None, *,
                 order: str = "first", solver: str = "newton", interpolation: str = "pchip",
                 extrapolate: str = "clamp", astatic: AstaticSettings | dict | None = None) -> None:
        tables.require_all()
        table_volume = tables.volume_mm
        super().__init__(table_volume if volume_mm is None else volume_mm)
        if np.any(self.volume_mm[0] < table_volume[0] - VOLUME_EDGE_SLACK_MM) or np.any(
            self.volume_mm[1] > table_volume[1] + VOLUME_EDGE_SLACK_MM
        ):
            raise CalibrationError(
                f"calibrated volume {self.volume_mm.tolist()} reaches beyond the table ranges "
                f"{table_volume.tolist()}",
                hint="the calibrated volume of a parametric model is at most its table ranges",
            )
        for name, value, allowed in (("order", order, ORDERS), ("solver", solver, SOLVERS),
                                     ("interpolation", interpolation, INTERPOLATIONS),
                                     ("extrapolate", extrapolate, EXTRAPOLATIONS)):
            if value not in allowed:
                raise CalibrationError(f"parametric {name} {value!r} is not one of {', '.join(allowed)}")
        self.tables = tables
        self.squareness = squareness or Squareness()
        self.order, self.solver = order, solver
        self.interpolation, self.extrapolate = interpolation, extrapolate
        if isinstance(astatic, dict):
            astatic = AstaticSettings(**astatic)
        elif astatic is not None and not isinstance(astatic, AstaticSettings):
            raise CalibrationError(f"astatic settings must be an object (grid_step_mm, gain, time_step), got {astatic!r}")
        self.astatic = astatic or AstaticSettings()
        self.astatic.check_cells(self.volume_mm)
        # Largest inverse residual the solver stands for. Newton: SOLVER_TOL_MM (it
        # converges or raises). Astatic: one grid step u, the method's own criterion; its
        # measured errors are tens of micrometres (see benchmarks/solvers.py), reported
        # per point in InverseResult.residual_mm.
        self.accept_residual_mm = SOLVER_TOL_MM if solver == "newton" else float(self.astatic.grid_step_mm)
        self._functions = [AxisFunctions(tables.position_mm[a], tables.errors[a], interpolation, extrapolate)
                           for a in AXES]
        # the same functions, all evaluated at once (the engine's hot path)
        self._stacked = StackedErrors([tables.position_mm[a] for a in AXES], [tables.errors[a] for a in AXES],
                                      interpolation, extrapolate)
        sq = self.squareness
        # Squareness as a constant matrix: rho += S q.
        self._S = np.array([[0.0, -sq.EC0Y, sq.EB0Z], [0.0, 0.0, -sq.EA0Z], [0.0, 0.0, 0.0]])
        self._ST = self._S.T
        self._S3 = self._S[:, :, None]
        self._eye3 = np.eye(3)[:, :, None]
        self._bounds: tuple | None = None  # of the error functions, for line_curvature_bound

    def with_options(self, **changes) -> ParametricEngine:
        """A copy with other order / solver / interpolation / extrapolate / astatic settings."""
        opts: dict[str, Any] = {"order": self.order, "solver": self.solver, "interpolation": self.interpolation,
                "extrapolate": self.extrapolate, "astatic": self.astatic}
        unknown = set(changes) - set(opts)
        if unknown:
            raise CalibrationError(f"unknown parametric option(s) {', '.join(sorted(unknown))}")
        opts.update({k: v for k, v in changes.items() if v is not None})
        if isinstance(opts["astatic"], dict):
            opts["astatic"] = replace(self.astatic, **opts["astatic"])
        return ParametricEngine(self.tables, self.squareness, self.volume_mm, **opts)

    def with_extrapolation(self, mode: str) -> ParametricEngine:
        return self.with_options(extrapolate=mode)

    # -- the error functions -----------------------------------------------------------
    def errors_at(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Summed linear errors rho (N, 3) mm (squareness included) and angles eps (N, 3) rad."""
        q = check_points(q, "q")
        total = self._stacked.values(self._stacked.locate(q))
        return total[:, :3] + q @ self._ST, total[:, 3:]

    def axis_errors(self, axis: str, t) -> np.ndarray:
        """The six error functions (N, 6) of one axis at its positions t (N,): EX, EY,
        EZ in mm and EA, EB, EC in rad, interpolated as the model does (squareness not
        included)."""
        return self._functions[AXES.index(axis)].evaluate(np.asarray(t, dtype=float).reshape(-1))

    def error_derivatives(self, q) -> tuple[np.ndarray, np.ndarray]:
        """d rho / dq and d eps / dq as (N, 3, 3) arrays (column i: derivative along axis i)."""
        q = check_points(q, "q")
        d = self._stacked.slopes(self._stacked.locate(q))
        drho = np.empty((len(q), 3, 3))
        np.add(d[:3].transpose(2, 0, 1), self._S, out=drho)
        return drho, d[3:].transpose(2, 0, 1).copy()  # d is scratch: always a copy

    def line_curvature_bound(self, q0, q1, r_norm_mm, margin_mm: float = 0.0) -> np.ndarray:
        """See :meth:`Engine.line_curvature_bound`. Each error is a sum of functions of one
        axis each, so along a unit direction u the second derivative of the linear errors
        is ``sum_i u_i^2 f_i''`` (squareness adds none): at most the largest ``|f_i''|``;
        the angles' term adds ``|eps''| |r|``, the second-order terms ``2 |r| (|eps|
        |eps''| + |eps'|^2)``. The inverse's second derivative is that bound over
        ``(1 - e)^3``, with e the largest norm of the error Jacobian. Within the tables'
        span only (PCHIP is twice differentiable there, piecewise); inf elsewhere, and
        for linear interpolation (its kinks have no bounded second derivative)."""
        q0 = np.asarray(q0, dtype=float)
        q1 = np.asarray(q1, dtype=float)
        r = np.asarray(r_norm_mm, dtype=float)
        if self.interpolation != "pchip":
            return np.full(len(q0), np.inf)
        if self._bounds is None:
            k_eps = s_rho = s_eps = v_eps = 0.0
            local = []
            for f in self._functions:
                value, slope, _curv = f._f.bounds()
                c = f._f.interval_curvature()
                local.append((f.x, np.linalg.norm(c[:, :3], axis=1), np.linalg.norm(c[:, 3:], axis=1)))
                k_eps = max(k_eps, float(np.linalg.norm(_curv[3:])))
                s_rho = max(s_rho, float(np.linalg.norm(slope[:3])))
                s_eps = max(s_eps, float(np.linalg.norm(slope[3:])))
                v_eps += float(np.linalg.norm(value[3:]))
            self._bounds = (local, k_eps, s_rho, s_eps, v_eps, float(np.linalg.norm(self._S)))
        local, k_eps, s_rho, s_eps, v_eps, s_norm = self._bounds
        # the largest second derivative on the knot intervals each move's axis range meets
        k_rho = np.zeros(len(q0))
        k_ang = np.zeros(len(q0))
        inside = np.ones(len(q0), dtype=bool)
        for i, (x, c_rho, c_eps) in enumerate(local):
            a = np.minimum(q0[:, i], q1[:, i]) - margin_mm
            b = np.maximum(q0[:, i], q1[:, i]) + margin_mm
            inside &= (a >= x[0]) & (b <= x[-1])
            j0 = np.clip(np.searchsorted(x, a, side="right") - 1, 0, len(x) - 2)
            j1 = np.clip(np.searchsorted(x, b, side="left") - 1, 0, len(x) - 2)
            near = j1 - j0 <= 1  # one or two intervals: their own values; more: the largest anywhere
            k_rho = np.maximum(k_rho, np.where(near, np.maximum(c_rho[j0], c_rho[j1]), c_rho.max()))
            k_ang = np.maximum(k_ang, np.where(near, np.maximum(c_eps[j0], c_eps[j1]), c_eps.max()))
        jac = s_norm + math.sqrt(3.0) * (s_rho + r * s_eps)
        k = k_rho + r * k_ang + 2.0 * r * (v_eps * k_eps + 3.0 * s_eps * s_eps)
        bound = np.where(jac < 0.5, k / np.maximum(1.0 - jac, 0.5) ** 3, np.inf)
        return np.where(inside, bound, np.inf)

    # -- the model -----------------------------------------------------------------------
    def forward(self, q, r=None, context=None) -> np.ndarray:
        return self.forward_order(q, r, self.order)

    def forward_order(self, q, r=None, order: str | None = None) -> np.ndarray:
        """Forward model with an explicit order ("first", "second", "exact")."""
        q = check_points(q, "q")
        r = check_tool_vectors(r, len(q))
        return self.forward_located(q, r, order or self.order)[0]

    def forward_located(self, q: np.ndarray, r: np.ndarray, order: str,
                         near: Located | None = None) -> tuple[np.ndarray, Located]:
        """F(q, r) (N, 3) of checked arrays, and where q lies in the tables (for the
        Jacobian at the same points: :meth:`jacobian_located`); ``near``: where the same
        points lay a step earlier (:meth:`StackedErrors.locate`)."""
        loc = self._stacked.locate(q, near)
        total = self._stacked.values(loc)
        rho, eps = total[:, :3] + q @ self._ST, total[:, 3:]
        if order == "first":
            return q + r + rho + cross(eps, r), loc
        if order == "second":
            s = 1.0 / (1.0 + 0.25 * np.sum(eps**2, axis=1))
            return q + r + rho + second_order_displacement(eps, r, s), loc
        if order == "exact":
            return q + rho + rotate(eps, r), loc
        raise CalibrationError(f"parametric order {order!r} is not one of {', '.join(ORDERS)}")

    def second_order_bounds(self, q, r=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Volumetric error vectors (delta+, delta-, delta first order), each (N, 3), mm.

        Formula (4) with the interval numbers A, B, C of seed 000: each angle sum gains
        half the products of the per-axis angles of the two other components with all
        signs + (delta+) or all signs - (delta-). Summed over the nine axis pairs these
        products are A' = A +- B C / 2, B' = B +- A C / 2, C' = C +- A B / 2. (The seed's
        B line lists eps_xz*eps_zy where the pattern of all three lines, every pair of
        a-type and c-type angles, has eps_yz*eps_zx; the pattern is followed here.)
        s is the seed's Rodrigues factor of the plain sums.
        """
        q = check_points(q, "q")
        r = check_tool_vectors(r, len(q))
        rho, eps = self.errors_at(q)
        A, B, C = eps.T
        s = 1.0 / (1.0 + 0.25 * np.sum(eps**2, axis=1))
        pair = 0.5 * np.column_stack([B * C, A * C, A * B])
        plus = rho + second_order_displacement(eps + pair, r, s)
        minus = rho + second_order_displacement(eps - pair, r, s)
        return plus, minus, rho + cross(eps, r)

    def jacobian(self, q, r=None) -> np.ndarray:
        """dF/dq (N, 3, 3) of the first-order model (the other orders differ by O(|eps|^2))."""
        q = check_points(q, "q")
        r = check_tool_vectors(r, len(q))
        return self.jacobian_located(self._stacked.locate(q), None, r).copy()  # scratch: a copy

    def jacobian_located(self, loc: Located, rows, r: np.ndarray) -> np.ndarray:
        """:meth:`jacobian` at located points (``rows``: which of them, None: all), r (M, 3).
        The (M, 3, 3) answer is a view of a (3, 3, M) scratch array (row, column, point),
        valid until the next evaluation in this thread."""
        d = self._stacked.slopes(loc, rows)
        JT = scratch("jacobian", (3, 3, d.shape[2]))
        np.add(d[:3], self._S3, out=JT)
        JT += self._eye3
        # column i += (d eps / d q_i) x r, the three columns at once
        e0, e1, e2 = d[3], d[4], d[5]
        r0, r1, r2 = r.T.copy()  # contiguous rows, each read twice
        JT[0] += e1 * r2 - e2 * r1
        JT[1] += e2 * r0 - e0 * r2
        JT[2] += e0 * r1 - e1 * r0
        return JT.transpose(2, 0, 1)

    def inverse(self, p, r=None, context=None, *, solver: str | None = None) -> InverseResult:
        p = check_points(p, "p")
        r = check_tool_vectors(r, len(p))
        solver = solver or self.solver
        if solver == "newton":
            return parametric_solvers.newton_inverse_located(self, p, r)
        if solver == "astatic":
            return parametric_solvers.astatic_inverse(self, p, r, self.astatic)
        raise CalibrationError(f"parametric solver {solver!r} is not one of {', '.join(SOLVERS)}")

    # -- serialisation ---------------------------------------------------------------
    def model_to_dict(self) -> dict:
        return {
            "order": self.order,
            "solver": self.solver,
            "interpolation": self.interpolation,
            "extrapolate": self.extrapolate,
            "astatic": self.astatic.to_dict(),
            "squareness_rad": self.squareness.as_dict(),
            "tables": self.tables.to_dict(),
        }

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> ParametricEngine:
        tables = AxisTables.from_dict(model["tables"])
        values: dict[str, Any] = {k: float(v) for k, v in model.get("squareness_rad", {}).items()}
        sq = Squareness(**values)
        return cls(tables, sq, volume_mm, order=model.get("order", "first"),
                   solver=model.get("solver", "newton"), interpolation=model.get("interpolation", "pchip"),
                   extrapolate=model.get("extrapolate", "clamp"), astatic=model.get("astatic"))
