"""The parametric model's 18 error functions evaluated together, axis-major.

The six functions of an axis interpolate that axis's table rows (PCHIP or linear, see
:mod:`postproc.engine.parametric`). Instead of one interpolant per axis, each asked on
its own, :class:`StackedErrors` keeps the interval data of all three axes in two
stacked tables, built once, one column per knot interval of any axis:

- values: ``y0, d0, y1, d1`` (PCHIP: end values and end slopes of the interval) or
  ``y0, y1`` (linear), six rows each;
- slopes: ``y0 - y1, d0, d1`` (PCHIP) or the secant slope (linear).

A call locates the points once (buckets or one ``searchsorted`` per axis on the clamped
positions), takes the columns of all three axes with one gather, and evaluates the
Hermite basis on (3, N) arrays, component-major (6, 3, N) after that. The slopes are
evaluated only when asked, and only for the points asked, from the located state and
the rows the values took (the Newton solver asks them for the points it has not yet
converged, at the positions whose values it has just evaluated). Large temporaries live
in per-thread scratch buffers (:func:`scratch`).

Every value is computed with the same floating-point operations in the same order as
the one-interpolant-per-axis evaluation (tests/parametric_reference.py), so the results
are identical to the last bit: nothing is refactored algebraically (no power-basis
coefficients, no products of constants moved across a division).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from postproc.engine.pchip import Pchip

# From this many points on, positions are located by buckets (a dozen whole-array
# operations) rather than by three binary searches.
BUCKET_MIN_POINTS = 64


class Located:
    """Where the points of one call lie: (3, N) arrays, axis-major.

    ``t``: the positions; ``tc``: clamped to the tables; ``g``: the stacked interval row;
    ``s``: the position in the interval (0..1), ``h``: its length; ``dv``: the slopes of
    all rows (6, 3, N) when the values needed them (linear extrapolation), else None.
    """

    __slots__ = ("t", "tc", "g", "s", "s2", "h", "dv", "rows", "generation")

    def __init__(self, t, tc, g, s, s2, h, dv) -> None:
        self.t, self.tc, self.g, self.s, self.s2, self.h, self.dv = t, tc, g, s, s2, h, dv
        # the PCHIP rows (24, 3, N) the values took (a scratch array) and its generation
        self.rows: np.ndarray | None = None
        self.generation = -1


class StackedErrors:
    """Values (N, 6) summed over the axes, and per-axis slopes (6, 3, N), at points (N, 3).

    ``knots[a]`` (n_a,) strictly increasing, ``rows[a]`` (n_a, 6): the table of axis a.
    Arrays are component-major inside (the long point axis last), so that every numpy
    operation runs over all points of all axes at once.
    """

    def __init__(self, knots, rows, interpolation: str, extrapolate: str) -> None:
        self.interpolation, self.extrapolate = interpolation, extrapolate
        self.knots = [np.ascontiguousarray(x, dtype=float) for x in knots]
        self.pchip = interpolation == "pchip"
        self.linear_extrapolation = extrapolate == "linear"
        values, slopes, starts, lengths = [], [], [], []
        start = 0
        for x, y in zip(self.knots, rows, strict=True):
            y = np.asarray(y, dtype=float)
            h = np.diff(x)
            if self.pchip:
                d = Pchip(x, y).d
                values.append(np.hstack([y[:-1], d[:-1], y[1:], d[1:]]))
                slopes.append(np.hstack([y[:-1] - y[1:], d[:-1], d[1:]]))
            else:
                values.append(np.hstack([y[:-1], y[1:]]))
                slopes.append(np.diff(y, axis=0) / h[:, None])
            starts.append(start)
            lengths.append(h)
            start += len(h)
        # (columns, interval rows of all axes)
        self._values = np.ascontiguousarray(np.vstack(values).T)
        self._slopes = np.ascontiguousarray(np.vstack(slopes).T)
        self._left = np.concatenate([x[:-1] for x in self.knots])
        self._h = np.concatenate(lengths)
        self._lo = np.array([x[0] for x in self.knots])[:, None]
        self._hi = np.array([x[-1] for x in self.knots])[:, None]
        first = np.array(starts)
        # searchsorted(x, tc, "right") - 1, clipped to 0 .. n - 2, plus the axis's first row
        self._gmin = first[:, None]
        self._gmax = (first + np.array([len(x) - 2 for x in self.knots]))[:, None]
        self._gshift = (first - 1)[:, None]
        self._init_buckets(first)

    def _init_buckets(self, first: np.ndarray) -> None:
        """Buckets for locating many points without a binary search: each axis's span cut
        into pieces no longer than its shortest interval, each knowing the interval its
        start lies in. A point's bucket (one multiplication) then names its interval or the
        one next to it; two steps up and one down, checked against the interval's ends,
        find it. The ends of each axis's outer intervals are -inf and +inf for the steps
        and the check (the clamped positions never leave them)."""
        starts, sizes, x0s, inv_w = [], [], [], []
        offset = 0
        for a, x in enumerate(self.knots):
            w = float(np.min(np.diff(x)))
            nb = int(np.ceil((x[-1] - x[0]) / w)) + 1
            if not (np.isfinite(w) and nb <= 8 * len(x) + 16):
                self._buckets = None  # far from uniform knots: binary search
                return
            edges = x[0] + w * np.arange(nb)
            starts.append(np.clip(np.searchsorted(x, edges, side="right") - 1, 0, len(x) - 2) + first[a])
            sizes.append(nb)
            x0s.append(x[0])
            inv_w.append(1.0 / w)
            offset += nb
        self._buckets = np.concatenate(starts)
        self._bucket_first = np.cumsum([0] + sizes[:-1])[:, None]
        self._bucket_last = (np.cumsum(sizes) - 1)[:, None]
        self._bucket_x0 = np.array(x0s)[:, None]
        self._bucket_inv_w = np.array(inv_w)[:, None]
        left = self._left.copy()
        right = np.concatenate([x[1:] for x in self.knots])
        left[self._gmin[:, 0]] = -np.inf
        right[self._gmax[:, 0]] = np.inf
        self._step_left, self._step_right = left, right

    def _bucket_locate(self, tc: np.ndarray) -> np.ndarray | None:
        """The stacked interval rows (3, N) of clamped positions, or None when a position
        is not where the buckets say (not finite): the binary search then answers."""
        if self._buckets is None:
            return None
        with np.errstate(invalid="ignore"):  # not finite: no bucket, the check below refuses it
            b = ((tc - self._bucket_x0) * self._bucket_inv_w).astype(np.intp)
        np.clip(b + self._bucket_first, self._bucket_first, self._bucket_last, out=b)
        g = self._buckets[b]
        right, left = self._step_right, self._step_left
        g += right[g] <= tc
        g += right[g] <= tc
        g -= left[g] > tc
        if not ((left[g] <= tc) & (tc < right[g])).all():
            return None
        return g

    # -- locating ------------------------------------------------------------------------
    def locate(self, q: np.ndarray, near: Located | None = None) -> Located:
        """The interval of every point's position on every axis; q (N, 3) float.

        ``near``: where the same points lay a moment ago (a Newton step earlier): where
        every position is still in its interval, the intervals are those (each position
        lies in one interval only), and so are the rows the values took from them while
        no other evaluation has taken rows since."""
        t = np.ascontiguousarray(q.T)
        tc = np.clip(t, self._lo, self._hi)
        if near is not None and near.g.shape == t.shape and self._buckets is not None:
            g = near.g
            if ((self._step_left[g] <= tc) & (tc < self._step_right[g])).all():
                h = near.h
                s = (tc - self._left[g]) / h
                loc = Located(t, tc, g, s, s * s if self.pchip else None, h, None)
                if near.generation == _generation():
                    loc.rows, loc.generation = near.rows, near.generation
                return loc
        g = self._bucket_locate(tc) if t.shape[1] >= BUCKET_MIN_POINTS else None
        if g is None:
            g = np.empty(t.shape, dtype=np.intp)
            for a, x in enumerate(self.knots):
                g[a] = np.searchsorted(x, tc[a], side="right")
            g += self._gshift
            # clamped positions are at least the first knot: only the upper clip acts
            # (the last knot, and NaN, which sorts last)
            np.minimum(g, self._gmax, out=g)
        h = self._h[g]
        s = (tc - self._left[g]) / h
        return Located(t, tc, g, s, s * s if self.pchip else None, h, None)

    # -- values --------------------------------------------------------------------------
    def _axis_values(self, loc: Located) -> np.ndarray:
        """(6, 3, N): each axis's six functions at its clamped positions (a scratch array)."""
        n = loc.g.shape[1]
        if self.pchip:
            if loc.rows is not None and loc.generation == _generation():
                rows = loc.rows  # the rows of these intervals, taken a step earlier
            else:
                rows = np.take(self._values, loc.g, axis=1, out=scratch("rows", (24, 3, n)), mode="clip")
                loc.rows, loc.generation = rows, _generation()
            s, h, s2 = loc.s, loc.h, loc.s2
            s3 = s2 * s  # s * s * s
            # the basis 2 s3 - 3 s2 + 1, (s3 - 2 s2 + s) h, -2 s3 + 3 s2, (s3 - s2) h, the
            # products shared (-2 s3 + 3 s2 is 3 s2 - 2 s3 to the last bit, zeros' signs too)
            t2 = 2 * s3
            t3 = 3 * s2
            b0 = t2 - t3 + 1
            b1 = (s3 - 2 * s2 + s) * h
            b2 = t3 - t2
            b3 = (s3 - s2) * h
            # b0 y0 + b1 d0 + b2 y1 + b3 d1, left to right, without temporaries
            v = np.multiply(b0, rows[0:6], out=scratch("v", (6, 3, n)))
            term = np.multiply(b1, rows[6:12], out=scratch("term", (6, 3, n)))
            v += term
            v += np.multiply(b2, rows[12:18], out=term)
            v += np.multiply(b3, rows[18:24], out=term)
            return v
        rows = np.take(self._values, loc.g, axis=1, out=scratch("rows", (12, 3, n)), mode="clip")
        s = loc.s
        v = np.multiply(rows[0:6], 1 - s, out=scratch("v", (6, 3, n)))
        term = np.multiply(rows[6:12], s, out=scratch("term", (6, 3, n)))
        v += term
        return v

    def _axis_slopes(self, g: np.ndarray, s: np.ndarray, s2, h: np.ndarray,
                     values_rows: np.ndarray | None = None) -> np.ndarray:
        """(6, 3, M): the slopes at the clamped positions of the rows g, s, h (PCHIP: from
        the rows the values took, when given); a scratch array."""
        m = g.shape[1]
        if not self.pchip:
            return np.take(self._slopes, g, axis=1, out=scratch("dv", (6, 3, m)), mode="clip")
        dv = scratch("dv", (6, 3, m))
        term = scratch("dterm", (6, 3, m))
        if values_rows is None:
            rows = np.take(self._slopes, g, axis=1, out=scratch("drows", (18, 3, m)), mode="clip")
            dy, d0, d1 = rows[0:6], rows[6:12], rows[12:18]
        else:
            dy = np.subtract(values_rows[0:6], values_rows[12:18], out=term)
            d0, d1 = values_rows[6:12], values_rows[18:24]
        a = 6 * s2 - 6 * s
        b = 3 * s2 - 4 * s + 1
        c = 3 * s2 - 2 * s
        # a dy / h + b d0 + c d1, left to right
        np.multiply(a, dy, out=dv)
        dv /= h
        dv += np.multiply(b, d0, out=term)
        dv += np.multiply(c, d1, out=term)
        return dv

    def values(self, loc: Located) -> np.ndarray:
        """The six errors summed over the axes (N, 6), C-ordered (squareness not included)."""
        v = self._axis_values(loc)
        if self.linear_extrapolation:
            dv = self._axis_slopes(loc.g, loc.s, loc.s2, loc.h, loc.rows)
            # kept for the Jacobian at these points (a copy: the scratch is reused)
            loc.dv = dv = dv.copy()
            term = np.multiply(loc.t - loc.tc, dv, out=scratch("term", dv.shape))
            v += term
        total = np.empty((v.shape[2], 6))
        tt = total.T
        np.add(v[:, 0], 0.0, out=tt)
        tt += v[:, 1]
        tt += v[:, 2]
        return total

    def slopes(self, loc: Located, rows=None) -> np.ndarray:
        """Derivatives (6, 3, M) of each axis's functions along its axis, at the located
        points (``rows``: a boolean mask or index of them, None: all). Clamped outside
        the tables: 0 there; extrapolated linearly: the end slope. The answer may be a
        scratch array, valid until the next evaluation in this thread."""
        if loc.dv is not None:
            return loc.dv if rows is None else loc.dv[:, :, rows]
        if rows is None:
            g, s, s2, h, t, tc = loc.g, loc.s, loc.s2, loc.h, loc.t, loc.tc
            # the rows the values took, unless another evaluation has reused them since
            taken = loc.rows if loc.generation == _generation() else None
            dv = self._axis_slopes(g, s, s2, h, taken)
        else:
            g, s, h, t, tc = loc.g[:, rows], loc.s[:, rows], loc.h[:, rows], loc.t[:, rows], loc.tc[:, rows]
            s2 = None if loc.s2 is None else loc.s2[:, rows]
            dv = self._axis_slopes(g, s, s2, h)
        if self.linear_extrapolation:
            return dv
        outside = t != tc
        return np.where(outside, 0.0, dv) if outside.any() else dv


# -- scratch arrays --------------------------------------------------------------------
# The evaluation's large temporaries (tens of kilobytes to megabytes) live in buffers kept
# per thread and reused from call to call: fresh arrays of that size come from mmap and
# cost a page fault per 4 kB on first touch, as much time as the arithmetic itself.
# Larger temporaries (calls of more than some 7000 points) are allocated afresh and not
# kept: at most a few tens of megabytes stay per thread.
_SCRATCH = threading.local()
SCRATCH_MAX_DOUBLES = 1 << 19


def scratch(name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A C-ordered float array of ``shape`` for temporary use, the same memory each call
    with this name in this thread (valid until the next call with this name)."""
    size = math.prod(shape)
    pool = getattr(_SCRATCH, "pool", None)
    if pool is None:
        pool = _SCRATCH.pool = {}
        _SCRATCH.generation = 0
    if name == "rows":
        _SCRATCH.generation += 1
    if size > SCRATCH_MAX_DOUBLES:
        return np.empty(shape)
    buf = pool.get(name)
    if buf is None or buf.size < size:
        grown = 2 * (0 if buf is None else buf.size)
        buf = pool[name] = np.empty(min(max(size, grown), SCRATCH_MAX_DOUBLES))
    return buf[:size].reshape(shape)


def _generation() -> int:
    """How many times the values' rows scratch has been handed out in this thread."""
    return getattr(_SCRATCH, "generation", 0)
