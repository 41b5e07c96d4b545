"""The parametric engine's evaluation and Newton inverse as they were written before the
stacked evaluation (postproc/engine/parametric_errors.py): one interpolant per axis, each
evaluated on its own, the Jacobian's slopes evaluated afresh, a generic Newton loop.

The tests hold the engine bit-identical to this: the same floating-point operations in
the same order, so any difference in the last bit is a regression, not rounding.
Only the knot slopes of PCHIP come from the package (:class:`postproc.engine.pchip.Pchip`,
whose construction the stacked evaluation shares).
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.axis_tables import AXES
from postproc.engine.base import InverseResult, check_points, check_tool_vectors
from postproc.engine.parametric import second_order_displacement
from postproc.engine.parametric_solvers import NEWTON_STOP_MM, _solve, _solver_error
from postproc.engine.pchip import Pchip
from postproc.rotation import cross, rotate


class ReferencePchip:
    def __init__(self, x, y) -> None:
        f = Pchip(x, y)
        self.x, self.y, self.d, self.h = f.x, f.y, f.d, f.h

    def _locate(self, t):
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        h = self.h[i][:, None]
        s = ((t - self.x[i]) / self.h[i])[:, None]
        return i, h, s

    def __call__(self, t):
        i, h, s = self._locate(t)
        y0, y1, d0, d1 = self.y[i], self.y[i + 1], self.d[i], self.d[i + 1]
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h * d0
                + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * h * d1)

    def derivative(self, t):
        i, h, s = self._locate(t)
        y0, y1, d0, d1 = self.y[i], self.y[i + 1], self.d[i], self.d[i + 1]
        s2 = s * s
        return ((6 * s2 - 6 * s) * (y0 - y1) / h + (3 * s2 - 4 * s + 1) * d0 + (3 * s2 - 2 * s) * d1)


class ReferenceAxis:
    def __init__(self, x, values, interpolation: str, extrapolate: str) -> None:
        self.x = np.asarray(x, dtype=float)
        self.values = np.asarray(values, dtype=float)
        self.interpolation, self.extrapolate = interpolation, extrapolate
        if interpolation == "pchip":
            self._f = ReferencePchip(self.x, self.values)
            self._df = self._f.derivative
        else:
            self._slopes = np.diff(self.values, axis=0) / np.diff(self.x)[:, None]

    def _linear(self, t):
        idx = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        w = (t - self.x[idx]) / (self.x[idx + 1] - self.x[idx])
        v = self.values[idx] * (1 - w)[:, None] + self.values[idx + 1] * w[:, None]
        return v, self._slopes[idx]

    def evaluate(self, t, derivative: bool = False):
        t = np.asarray(t, dtype=float)
        tc = np.clip(t, self.x[0], self.x[-1])
        if self.interpolation == "pchip":
            v, dv = self._f(tc), (self._df(tc) if (derivative or self.extrapolate == "linear") else None)
        else:
            v, dv = self._linear(tc)
        outside = t != tc
        if dv is None:
            return v
        if self.extrapolate == "linear":
            v = v + (t - tc)[:, None] * dv
        elif derivative and outside.any():
            dv = np.where(outside[:, None], 0.0, dv)
        return (v, dv) if derivative else v


class ReferenceParametric:
    """Forward model, Jacobian and Newton inverse of a ParametricEngine, the old way."""

    def __init__(self, engine) -> None:
        self.engine = engine
        self.order = engine.order
        self._functions = [ReferenceAxis(engine.tables.position_mm[a], engine.tables.errors[a],
                                         engine.interpolation, engine.extrapolate) for a in AXES]
        sq = engine.squareness
        self._S = np.array([[0.0, -sq.EC0Y, sq.EB0Z], [0.0, 0.0, -sq.EA0Z], [0.0, 0.0, 0.0]])

    def errors_at(self, q):
        q = check_points(q, "q")
        total = np.zeros((len(q), 6))
        for i, f in enumerate(self._functions):
            total += f.evaluate(q[:, i])
        return total[:, :3] + q @ self._S.T, total[:, 3:]

    def axis_errors(self, axis: str, t):
        return self._functions[AXES.index(axis)].evaluate(np.asarray(t, dtype=float).reshape(-1))

    def error_derivatives(self, q):
        q = check_points(q, "q")
        drho = np.empty((len(q), 3, 3))
        deps = np.empty((len(q), 3, 3))
        for i, f in enumerate(self._functions):
            _, d = f.evaluate(q[:, i], derivative=True)
            drho[:, :, i] = d[:, :3]
            deps[:, :, i] = d[:, 3:]
        return drho + self._S, deps

    def forward(self, q, r=None):
        return self.forward_order(q, r, self.order)

    def forward_order(self, q, r=None, order=None):
        q = check_points(q, "q")
        r = check_tool_vectors(r, len(q))
        rho, eps = self.errors_at(q)
        order = order or self.order
        if order == "first":
            return q + r + rho + cross(eps, r)
        if order == "second":
            s = 1.0 / (1.0 + 0.25 * np.sum(eps**2, axis=1))
            return q + r + rho + second_order_displacement(eps, r, s)
        return q + rho + rotate(eps, r)

    def jacobian(self, q, r=None):
        q = check_points(q, "q")
        r = check_tool_vectors(r, len(q))
        drho, deps = self.error_derivatives(q)
        J = drho + np.eye(3)
        for i in range(3):
            J[:, :, i] += cross(deps[:, :, i], r)
        return J

    def inverse(self, p, r=None, *, tol_mm: float, max_iter: int) -> InverseResult:
        p = check_points(p, "p")
        r = check_tool_vectors(r, len(p))
        n = len(p)
        q = p - r
        iterations = np.zeros(n, dtype=int)
        resid = np.full(n, np.inf)
        active = np.arange(n)
        for k in range(max_iter + 1):
            f = self.forward(q[active], r[active]) - p[active]
            res = np.linalg.norm(f, axis=1)
            resid[active] = res
            keep = ~(res <= NEWTON_STOP_MM)
            active, f = active[keep], f[keep]
            if not len(active) or k == max_iter:
                break
            J = self.jacobian(q[active], r[active])
            q[active] -= _solve(J, f, "Newton inverse", active, p)
            iterations[active] += 1
        bad = np.flatnonzero(~(resid <= tol_mm))
        if len(bad):
            worst = bad[np.argmax(np.where(np.isfinite(resid[bad]), resid[bad], np.inf))]
            raise _solver_error("Newton inverse", int(worst), p, float(resid[worst]), int(iterations[worst]))
        return InverseResult(q, resid, iterations)
