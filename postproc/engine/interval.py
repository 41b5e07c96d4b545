"""Interval tangential method (seed 000, chapter 2).

The commanded axes are split into intervals; on each cell of the partition the axes
are straight (static model) with their own direction-cosine matrix ``G`` and origin
``r_O1``, piecewise constant::

    p = r_O1[c] + G[c] q + r          c = the cell that q lies in
    q = G[c]^-1 (p* - r - r_O1[c])    inverse, formula (1) with the cell's pair

Fitting: least squares per cell from the points inside it (a point on a shared border
takes part in both neighbours' fits, which pulls their pairs together at the border).
A cell whose points do not span three axes (fewer than 4, or all on a plane) is
refused with an error naming the cell; give fewer intervals or measure more points.

Inverse: the first cell is the one where the static inverse (one ``G``, ``r_O1`` fitted
to all points) of the target lies; solve with that cell's pair, check that the answer
lies in that cell, otherwise move to the answer's cell and solve again. The model is
discontinuous at borders: where neighbouring images overlap the first consistent cell
wins; where they leave a gap the answer is the solution nearest its own cell and the
reported residual is the size of the gap there (see ``piecewise_inverse``).

Tool vector: carried unrotated, as in the static method.
"""

from __future__ import annotations

import numpy as np

from postproc.engine._tangents import (
    AXES,
    LATTICE_TOL_MM,
    cell_index,
    distinct_positions,
    parse_intervals,
    piecewise_inverse,
)
from postproc.engine.base import (
    Engine,
    FitResult,
    InverseResult,
    check_points,
    check_tool_vectors,
)
from postproc.engine.static import StaticEngine, fit_affine
from postproc.errors import CalibrationError, MeasurementError

# Intervals per axis when --intervals does not say (seed: "intervals of a preliminary
# partition"; three per axis over a 315 mm cube gives 105 mm cells of ~500 points on a
# 15 mm grid). Fewer when an axis has fewer distinct positions to fit.
DEFAULT_INTERVALS = 3

# A cell fitted from fewer points than this has little noise averaging (12 parameters);
# the fit report says so.
FEW_POINTS_PER_CELL = 12


class IntervalEngine(Engine):
    method = "interval"
    affine = False

    def __init__(self, edges, G, origin_mm, static_G, static_origin_mm, volume_mm) -> None:
        super().__init__(volume_mm)
        self.edges = [np.asarray(e, dtype=float) for e in edges]
        if len(self.edges) != 3 or any(e.ndim != 1 or len(e) < 2 or np.any(np.diff(e) <= 0) for e in self.edges):
            raise CalibrationError("interval model: edges must be three increasing lists of at least 2 values")
        shape = tuple(len(e) - 1 for e in self.edges)
        self.G = np.asarray(G, dtype=float)
        self.origin_mm = np.asarray(origin_mm, dtype=float)
        if self.G.shape != (*shape, 3, 3) or self.origin_mm.shape != (*shape, 3):
            raise CalibrationError(
                f"interval model: {shape} cells need G {(*shape, 3, 3)} and r_O1 {(*shape, 3)}, "
                f"got {self.G.shape} and {self.origin_mm.shape}"
            )
        det = np.linalg.det(self.G)
        if not np.all(np.isfinite(det)) or np.any(det < 0.5):
            bad = tuple(np.argwhere(~(det >= 0.5))[0])
            raise CalibrationError(
                f"interval model: cell {self.cell_name(bad)} has G with determinant {det[bad]:.3g}",
                hint="G must be close to the identity (columns = measured axis directions)",
            )
        self.G_inv = np.linalg.inv(self.G)
        self.static = StaticEngine(static_G, static_origin_mm, volume_mm)
        self.shape = shape

    def cell_name(self, c) -> str:
        return " ".join(
            f"{AXES[j]}[{self.edges[j][c[j]]:g},{self.edges[j][c[j] + 1]:g}]" for j in range(3)
        )

    def cells_of(self, q) -> np.ndarray:
        """(N, 3) cell index of commanded points (border points go to the upper cell)."""
        return cell_index(check_points(q, "q"), self.edges)

    def _apply(self, q: np.ndarray, cells: np.ndarray) -> np.ndarray:
        i, j, k = cells.T
        return self.origin_mm[i, j, k] + np.einsum("nab,nb->na", self.G[i, j, k], q)

    def _solve(self, cells: np.ndarray, target: np.ndarray) -> np.ndarray:
        i, j, k = cells.T
        return np.einsum("nab,nb->na", self.G_inv[i, j, k], target - self.origin_mm[i, j, k])

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        return self._apply(q, cell_index(q, self.edges)) + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        rr = check_tool_vectors(r, len(p))
        first = cell_index(self.static.inverse(p, rr).q, self.edges)
        q, iters = piecewise_inverse(p - rr, first, self._solve, self.edges)
        resid = np.linalg.norm(self.forward(q, rr) - p, axis=1)
        return InverseResult(q, resid, iters)

    def border_jumps(self) -> np.ndarray:
        """Largest jump (mm) of the model across each axis' interior borders, per axis."""
        out = np.zeros(3)
        for j in range(3):
            for b in range(1, len(self.edges[j]) - 1):
                lo = self.edges[j][b]
                # corners and centre of every face on the border plane
                others = [a for a in range(3) if a != j]
                pts = []
                for ca in range(self.shape[others[0]]):
                    for cb in range(self.shape[others[1]]):
                        ea = self.edges[others[0]][ca: ca + 2]
                        eb = self.edges[others[1]][cb: cb + 2]
                        for va in (*ea, ea.mean()):
                            for vb in (*eb, eb.mean()):
                                q = np.empty(3)
                                q[j], q[others[0]], q[others[1]] = lo, va, vb
                                pts.append((q, ca, cb))
                q = np.array([t[0] for t in pts])
                upper = np.empty((len(pts), 3), dtype=int)
                upper[:, j] = b
                upper[:, others[0]] = [t[1] for t in pts]
                upper[:, others[1]] = [t[2] for t in pts]
                lower = upper.copy()
                lower[:, j] = b - 1
                d = np.linalg.norm(self._apply(q, upper) - self._apply(q, lower), axis=1)
                out[j] = max(out[j], d.max())
        return out

    def model_to_dict(self) -> dict:
        return {
            "edges_mm": [e.tolist() for e in self.edges],
            "G": self.G.tolist(),
            "r_O1_mm": self.origin_mm.tolist(),
            "static": {"G": self.static.G.tolist(), "r_O1_mm": self.static.origin_mm.tolist()},
        }

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> IntervalEngine:
        return cls(model["edges_mm"], model["G"], model["r_O1_mm"], model["static"]["G"],
                   model["static"]["r_O1_mm"], volume_mm)


def partition_edges(q: np.ndarray, spec: list, path: str = "") -> list[np.ndarray]:
    """Interval edges per axis from a parsed ``--intervals`` spec and the data."""
    edges = []
    for j in range(3):
        lo, hi = q[:, j].min(), q[:, j].max()
        item = spec[j]
        if isinstance(item, list):
            e = np.asarray(item, dtype=float)
            if e[0] > hi or e[-1] < lo:
                raise MeasurementError(
                    f"--intervals for {AXES[j]} ({e[0]:g}..{e[-1]:g}) miss the measured range {lo:.3f}..{hi:.3f}",
                    path=path or None,
                )
        else:
            n = item
            if n is None:
                n = max(1, min(DEFAULT_INTERVALS, len(distinct_positions(q[:, j])) - 1))
            if hi - lo < LATTICE_TOL_MM:
                raise MeasurementError(
                    f"all points have {AXES[j]} = {lo:.3f}: the interval method needs motion on every axis",
                    path=path or None,
                )
            e = np.linspace(lo, hi, n + 1)
        edges.append(e)
    return edges


def fit(measurements, *, intervals=None, **options) -> FitResult:
    """Fit ``G`` and ``r_O1`` per cell by least squares; options: ``intervals`` (spec string)."""
    from postproc.calibration.measurements import Measurements

    items = list(measurements)
    meas = Measurements.concat(items)
    path = meas.path
    spec = parse_intervals(intervals) if isinstance(intervals, str) or intervals is None else list(intervals)
    q, target = meas.q, meas.m - meas.r
    edges = partition_edges(q, spec, path)
    shape = tuple(len(e) - 1 for e in edges)
    G = np.empty((*shape, 3, 3))
    origin = np.empty((*shape, 3))
    counts = np.zeros(shape, dtype=int)
    # Membership with closed boxes (slack for rounding): border points feed both sides.
    # The first and last intervals reach out to cover all points.
    inside = []
    for j in range(3):
        e = edges[j].copy()
        e[0], e[-1] = -np.inf, np.inf
        inside.append([(q[:, j] >= e[c] - LATTICE_TOL_MM) & (q[:, j] <= e[c + 1] + LATTICE_TOL_MM)
                       for c in range(shape[j])])
    static_G, static_origin, _ = fit_affine(q, target)
    for c in np.ndindex(shape):
        sel = inside[0][c[0]] & inside[1][c[1]] & inside[2][c[2]]
        counts[c] = sel.sum()
        where = " in interval cell " + " ".join(
            f"{AXES[j]}[{edges[j][c[j]]:g},{edges[j][c[j] + 1]:g}]" for j in range(3)
        )
        try:
            G[c], origin[c], _ = fit_affine(q[sel], target[sel], where)
        except MeasurementError as exc:
            exc.hint = ("give fewer intervals (--intervals 'X=2;Y=2;Z=2') or edges that put "
                        "enough points in every cell, or measure more points there")
            raise exc.at(path=path or None) from None
    volume = np.vstack([
        [max(edges[j][0], q[:, j].min()) for j in range(3)],
        [min(edges[j][-1], q[:, j].max()) for j in range(3)],
    ])
    engine = IntervalEngine(edges, G, origin, static_G, static_origin, volume)
    resid = target - engine.forward(q)
    result = FitResult(engine=engine, residuals_mm=resid)
    jumps = engine.border_jumps()
    report = [
        f"interval fit: {shape[0]} x {shape[1]} x {shape[2]} cells on {len(meas)} points "
        f"({counts.min()}..{counts.max()} per cell, border points count in both neighbours)",
        *(f"  {AXES[j]} edges (mm): " + ", ".join(f"{v:g}" for v in edges[j]) for j in range(3)),
        "largest jump of the model across interior borders (um): "
        + "  ".join(f"{AXES[j]} {jumps[j] * 1000:.1f}" for j in range(3)),
    ]
    few = int((counts < FEW_POINTS_PER_CELL).sum())
    if few:
        report.append(f"warning: {few} cell(s) fitted from fewer than {FEW_POINTS_PER_CELL} points: "
                      "little averaging of measurement noise there")
    unused = sorted(k for k, v in options.items() if v is not None)
    if unused:
        report.append(f"note: option(s) {', '.join(unused)} do not apply to the interval method and were ignored")
    result.report = report
    result.info = {
        "n_points": len(meas), "cells": list(shape), "rms_mm": result.rms_mm, "max_mm": result.max_mm,
        "border_jump_mm": jumps.tolist(), "sources": [m.path for m in items],
    }
    return result
