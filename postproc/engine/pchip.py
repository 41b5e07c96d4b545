"""Piecewise cubic Hermite interpolation that keeps the shape of the data (PCHIP).

The same interpolant as :class:`scipy.interpolate.PchipInterpolator` (Fritsch and Butland's
weighted harmonic mean of the neighbouring slopes inside, the three-point shape-preserving
formula at the ends; tests/test_parametric_engine.py holds the two equal), in numpy alone:
importing scipy.interpolate takes about a second, longer than a short correction job.
"""

from __future__ import annotations

import numpy as np


def _edge(h0: float, h1: float, m0: np.ndarray, m1: np.ndarray) -> np.ndarray:
    d = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    d = np.where(np.sign(d) != np.sign(m0), 0.0, d)
    return np.where((np.sign(m0) != np.sign(m1)) & (np.abs(d) > np.abs(3.0 * m0)), 3.0 * m0, d)


class Pchip:
    """``f(t)`` and ``f.derivative(t)`` for rows ``y`` (n, k) at increasing knots ``x`` (n,);
    cubic extrapolation outside, as scipy's ``extrapolate=True``."""

    def __init__(self, x, y) -> None:
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if y.ndim == 1:
            y = y[:, None]
        if len(x) < 2 or np.any(np.diff(x) <= 0):
            raise ValueError("PCHIP needs at least two strictly increasing knots")
        h = np.diff(x)
        m = np.diff(y, axis=0) / h[:, None]
        if len(x) == 2:
            d = np.vstack([m[0], m[0]])
        else:
            h0, h1 = h[:-1, None], h[1:, None]
            m0, m1 = m[:-1], m[1:]
            w1, w2 = 2.0 * h1 + h0, h1 + 2.0 * h0
            same = (np.sign(m0) == np.sign(m1)) & (m0 != 0) & (m1 != 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                inner = (w1 + w2) / (w1 / m0 + w2 / m1)
            inner = np.where(same, inner, 0.0)
            d = np.vstack([_edge(h[0], h[1], m[0], m[1]), inner, _edge(h[-1], h[-2], m[-1], m[-2])])
        self.x, self.y, self.d, self.h = x, y, d, h

    def _locate(self, t: np.ndarray):
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.x, t, side="right") - 1, 0, len(self.x) - 2)
        h = self.h[i][:, None]
        s = ((t - self.x[i]) / self.h[i])[:, None]
        return i, h, s

    def __call__(self, t) -> np.ndarray:
        i, h, s = self._locate(t)
        y0, y1, d0, d1 = self.y[i], self.y[i + 1], self.d[i], self.d[i + 1]
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h * d0
                + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * h * d1)

    def derivative(self, t) -> np.ndarray:
        i, h, s = self._locate(t)
        y0, y1, d0, d1 = self.y[i], self.y[i + 1], self.d[i], self.d[i + 1]
        s2 = s * s
        return ((6 * s2 - 6 * s) * (y0 - y1) / h + (3 * s2 - 4 * s + 1) * d0 + (3 * s2 - 2 * s) * d1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Largest ``|f|``, ``|f'|`` and ``|f''|`` of each column over the knots' span
        (k,) each: exact for the piecewise cubic (``f''`` is linear on each interval, so
        its extremes are at the interval ends; ``f'`` is quadratic, its extreme at an end
        or at its vertex)."""
        y0, y1, d0, d1 = self.y[:-1], self.y[1:], self.d[:-1], self.d[1:]
        h = self.h[:, None]
        dy = (y0 - y1) / h
        # f'(s) = a s^2 + b s + c on s in [0, 1]
        a = 6.0 * dy + 3.0 * d0 + 3.0 * d1
        b = -6.0 * dy - 4.0 * d0 - 2.0 * d1
        with np.errstate(divide="ignore", invalid="ignore"):
            sv = np.where(a != 0.0, -b / (2.0 * a), 0.0)
        sv = np.clip(sv, 0.0, 1.0)
        slope = np.maximum.reduce([np.abs(d0), np.abs(d1), np.abs(a * sv * sv + b * sv + d0)])
        curv = self.interval_curvature()
        # |f| <= the larger end value plus the most the cubic bulges: h/4 of the slopes
        value = np.maximum(np.abs(y0), np.abs(y1)) + 0.25 * h * slope
        return value.max(axis=0), slope.max(axis=0), curv.max(axis=0)

    def interval_curvature(self) -> np.ndarray:
        """Largest ``|f''|`` of each column on each knot interval (n - 1, k): ``f''`` is
        linear there, so it is the larger of its two ends."""
        y0, y1, d0, d1 = self.y[:-1], self.y[1:], self.d[:-1], self.d[1:]
        h = self.h[:, None]
        dy = (y0 - y1) / h
        a = 6.0 * dy + 3.0 * d0 + 3.0 * d1
        b = -6.0 * dy - 4.0 * d0 - 2.0 * d1
        # f''(s) h = 2 a s + b on s in [0, 1]
        return np.maximum(np.abs(b), np.abs(2.0 * a + b)) / h
