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

Cell borders. Piecewise-constant pairs make the model jump at every interior border
(by a few to tens of micrometres: the neighbours' fits disagree there). A jump cannot
be followed by a program move crossing the border (the path would need a step of zero
length), so by default the two pairs are blended over a narrow zone of
``border_blend_mm`` centred on the border, with a smooth weight (3t^2 - 2t^3): the
model is then continuous, equal to the cell's own pair everywhere farther than half
the zone from a border, and steep but finite across it. ``border_blend_mm = 0`` gives
the seed's pure piecewise model.

Inverse: the first cell is the one where the static inverse (one ``G``, ``r_O1`` fitted
to all points) of the target lies; solve with that cell's pair (formula (1)), check
that the answer lies in that cell, otherwise move to the answer's cell and solve
again (see ``piecewise_inverse``). With a blend zone, answers that fall in it are then
refined by Newton steps on the blended model until the residual is below the solver
tolerance. Without it (pure model), where neighbouring images overlap the first
consistent cell wins; where they leave a gap no commanded point reaches the target,
the answer is the visited cell's solution nearest its own cell and the reported
residual is the size of the gap there.

Tool vector: carried unrotated, as in the static method.
"""

from __future__ import annotations

import numpy as np

from postproc.calibration.measurements import Measurements
from postproc.engine._tangents import (
    AXES,
    LATTICE_TOL_MM,
    NEWTON_TOL_MM,
    cell_index,
    distinct_positions,
    format_node,
    newton_refine,
    parse_intervals,
    piecewise_inverse,
    tool_vector_note,
)
from postproc.engine.base import (
    Engine,
    FitResult,
    InverseResult,
    check_points,
    check_tool_vectors,
)
from postproc.engine.static import StaticEngine, fit_affine
from postproc.errors import CalibrationError, MeasurementError, SolverError

# Intervals per axis when --intervals does not say (seed: "intervals of a preliminary
# partition"; three per axis over a 315 mm cube gives 105 mm cells of ~500 points on a
# 15 mm grid). Fewer when an axis has fewer distinct positions to fit.
DEFAULT_INTERVALS = 3

# Width of the zone centred on each interior border where the neighbouring pairs are
# blended. 1 mm: far below a useful interval (tens of mm), so the model is the seed's
# almost everywhere, and wide enough that a border jump of up to ~0.1 mm still leaves
# the model monotone (jump / width << 1) and a program crossing the border is followed
# with chords of a few tenths of a millimetre at a 1 um tolerance.
BORDER_BLEND_MM = 1.0

# A cell fitted from fewer points than this has little noise averaging (12 parameters);
# the fit report says so.
FEW_POINTS_PER_CELL = 12


class IntervalEngine(Engine):
    method = "interval"
    affine = False

    def __init__(self, edges, G, origin_mm, static_G, static_origin_mm, volume_mm,
                 border_blend_mm: float = BORDER_BLEND_MM) -> None:
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
        self.blend = float(border_blend_mm)
        shortest = min(np.diff(e).min() for e in self.edges)
        if not np.isfinite(self.blend) or self.blend < 0 or (
                self.blend > 0 and any(len(e) > 2 for e in self.edges) and shortest < 2 * self.blend):
            raise CalibrationError(
                f"interval model: border blend {self.blend:g} mm must be >= 0 and at most half "
                f"the shortest interval ({shortest:g} mm)"
            )

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

    def _blend_weights(self, q: np.ndarray, cells: np.ndarray):
        """Per axis: the neighbour cell, its weight and the weight's derivative (N, 3)."""
        nb = cells.copy()
        lam = np.zeros(q.shape)
        dlam = np.zeros(q.shape)
        if self.blend <= 0:
            return nb, lam, dlam
        w, half = self.blend, self.blend / 2
        for j in range(3):
            e = self.edges[j]
            c = cells[:, j]
            x = q[:, j]
            up = (c < len(e) - 2) & (x > e[np.minimum(c + 1, len(e) - 1)] - half)
            down = (c > 0) & (x < e[c] + half)
            # t runs 0 -> 1 across the zone [border - w/2, border + w/2]
            t = np.where(up, (x - (e[np.minimum(c + 1, len(e) - 1)] - half)) / w,
                         np.where(down, (x - (e[c] - half)) / w, 0.0))
            s = t * t * (3 - 2 * t)
            ds = 6 * t * (1 - t) / w
            nb[:, j] = np.where(up, c + 1, np.where(down, c - 1, c))
            lam[:, j] = np.where(up, s, np.where(down, 1 - s, 0.0))
            dlam[:, j] = np.where(up, ds, np.where(down, -ds, 0.0))
        return nb, lam, dlam

    def _blended(self, q: np.ndarray, jacobian: bool = False):
        cells = cell_index(q, self.edges)
        nb, lam, dlam = self._blend_weights(q, cells)
        value = np.zeros(q.shape)
        jac = np.zeros((len(q), 3, 3)) if jacobian else None
        for a in np.ndindex(2, 2, 2):
            sel = np.where(np.array(a, dtype=bool)[None, :], nb, cells)
            wj = np.where(np.array(a, dtype=bool)[None, :], lam, 1 - lam)
            weight = wj.prod(axis=1)
            used = weight > 0
            if not used.any():
                continue
            pv = self._apply(q[used], sel[used])
            value[used] += weight[used, None] * pv
            if jac is not None:
                i, j, k = sel[used].T
                jac[used] += weight[used, None, None] * self.G[i, j, k]
                dw = np.where(np.array(a, dtype=bool)[None, :], dlam, -dlam)[used]
                for m in range(3):
                    others = np.prod(np.delete(wj[used], m, axis=1), axis=1)
                    jac[used, :, m] += (dw[:, m] * others)[:, None] * pv
        return value, jac

    def position(self, q) -> np.ndarray:
        """Model position of the measured point (tool vector of the measurement removed)."""
        q = check_points(q, "q")
        cells = cell_index(q, self.edges)
        out = self._apply(q, cells)
        if self.blend > 0:
            _, lam, _ = self._blend_weights(q, cells)
            zone = np.any(lam > 0, axis=1)
            if zone.any():
                out[zone] = self._blended(q[zone])[0]
        return out

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        return self.position(q) + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        rr = check_tool_vectors(r, len(p))
        target = p - rr
        first = cell_index((target - self.static.origin_mm) @ self.static.G_inv.T, self.edges)
        q, iters = piecewise_inverse(target, first, self._solve, self.edges)
        if self.blend > 0:
            q, iters = self._newton(target, q, iters)
        resid = np.linalg.norm(self.forward(q, rr) - p, axis=1)
        return InverseResult(q, resid, iters)

    def _newton(self, target: np.ndarray, q: np.ndarray, iters: np.ndarray):
        """Refine answers that fall in a blend zone (elsewhere they are already exact)."""
        cells = cell_index(q, self.edges)
        _, lam, _ = self._blend_weights(q, cells)
        off = np.linalg.norm(self._apply(q, cells) - target, axis=1) >= NEWTON_TOL_MM
        active = np.flatnonzero(np.any(lam > 0, axis=1) | off)
        active = newton_refine(lambda x: self._blended(x, jacobian=True), target, q, iters, active)
        if len(active) == 0:
            return q, iters
        raise SolverError(
            f"interval inverse did not converge for {len(active)} point(s), first target "
            f"{format_node(target[active[0]])}",
            hint="the interval calibration is probably corrupt (border jumps as wide as the blend zone); refit it",
        )

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
            "border_blend_mm": self.blend,
        }

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> IntervalEngine:
        return cls(model["edges_mm"], model["G"], model["r_O1_mm"], model["static"]["G"],
                   model["static"]["r_O1_mm"], volume_mm,
                   border_blend_mm=model.get("border_blend_mm", BORDER_BLEND_MM))


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


def refit_options(engine) -> dict:
    """The :func:`fit` options that fit ``engine``'s partition again (its edges)."""
    model = engine.model_to_dict()
    if "edges_mm" not in model:
        return {}
    return {"intervals": ";".join(f"{a}={','.join(f'{v:.3f}' for v in e)}"
                                  for a, e in zip("XYZ", model["edges_mm"], strict=True))}


def fit(measurements, *, intervals=None, border_blend_mm: float = BORDER_BLEND_MM, **options) -> FitResult:
    """Fit ``G`` and ``r_O1`` per cell by least squares.

    Options: ``intervals`` (spec string, see :func:`parse_intervals`),
    ``border_blend_mm`` (0 for the seed's pure piecewise model).
    """
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
    engine = IntervalEngine(edges, G, origin, static_G, static_origin, volume, border_blend_mm)
    resid = target - engine.forward(q)
    result = FitResult(engine=engine, residuals_mm=resid)
    jumps = engine.border_jumps()
    report = [
        f"interval fit: {shape[0]} x {shape[1]} x {shape[2]} cells on {len(meas)} points "
        f"({counts.min()}..{counts.max()} per cell, border points count in both neighbours)",
        *(f"  {AXES[j]} edges (mm): " + ", ".join(f"{v:g}" for v in edges[j]) for j in range(3)),
        "largest jump of the pairs across interior borders (um): "
        + "  ".join(f"{AXES[j]} {jumps[j] * 1000:.1f}" for j in range(3))
        + (f"; blended over {engine.blend:g} mm at each border" if engine.blend > 0 else
           "; not blended (pure piecewise model)"),
    ]
    report += tool_vector_note(meas.r, "interval")
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
