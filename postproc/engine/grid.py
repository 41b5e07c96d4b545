"""Quasi-differential tangential method (seed 000, chapter 2, formula 2).

A laser tracker measures the functional point at the nodes of a regular lattice of
commanded positions ``q_ijk = q0 + (i u1, j u2, k u3)``. The physical axes are curved:
their tangent direction cosines, scaled by the axis' own step ratio, are read off
differences of measured node positions ``P_ijk`` (tool vector removed)::

    Q1_i    = (P[i+1, 0, 0] - P[i, 0, 0]) / u1          X along the line Y = Z = 0
    Q2_ij   = (P[i, j+1, 0] - P[i, j, 0]) / u2          Y at that X, on Z = 0
    Q3_ijk  = (P[i, j, k+1] - P[i, j, k]) / u3          Z at that X, Y

so ``Q1`` depends on ``q1``, ``Q2`` on ``(q1, q2)`` and ``Q3`` on ``(q1, q2, q3)`` as in the
seed. The curvilinear integral along the path "X first, then Y at that X, then Z at
that X, Y" becomes the sums::

    R(M) = r_O1 + u1 sum_{i<M1} Q1_i + u2 sum_{j<M2} Q2_{M1 j} + u3 sum_{k<M3} Q3_{M1 M2 k}

which reproduce the measured node ``P[M]`` (the sums telescope). The seed's ``Q`` are
unit direction cosines; here they keep their length ``|Q| = 1 + scale error`` so the
sums also carry each axis' positioning error, which unit vectors would drop.

Inside the cell ``M`` the tangent matrix ``G_M = [Q1 Q2 Q3]`` at node ``M`` (the cell's
own edges from its lower corner) gives formula (2)::

    q = G_M^-1 (p* - R(M)) + q0 + [u1 M1, u2 M2, u3 M3]

Two forward models are offered:

- ``"trilinear"`` (default): trilinear interpolation of the nodes. It is continuous
  across cells, passes through every measured node, and its tangent matrix at the
  cell's lower corner is exactly ``G_M``. The inverse starts with formula (2) in the
  cell of ``p*`` and repeats it with the tangent matrix at the current point (Newton
  on the interpolated field) until ``|F(q) - p*|`` is below the solver tolerance.
- ``"cell"``: the seed's piecewise-affine model ``p = R(M) + G_M (q - q_M)``, exact
  at the four nodes on the cell's lower-corner edges but discontinuous at the upper
  faces. The inverse is formula (2) with the cell walk and border rule of
  :func:`postproc.engine._tangents.piecewise_inverse`.

Tool vector: the model describes the motion of the functional point for the tool
vectors used in the measurement; a different tool vector at correction time is added
unrotated (``p = P(q) + r``), as in the static method, so angular errors acting on the
difference of tool vectors are not corrected.
"""

from __future__ import annotations

import math

import numpy as np

from postproc.calibration.measurements import Measurements
from postproc.engine._tangents import (
    AXES,
    LATTICE_TOL_MM,
    cell_index,
    distinct_positions,
    format_node,
    newton_refine,
    parse_screw_pitch,
    parse_step,
    piecewise_inverse,
    step_warnings,
    tool_vector_note,
)
from postproc.engine.base import (
    Engine,
    FitResult,
    InverseResult,
    check_points,
    check_tool_vectors,
)
from postproc.errors import CalibrationError, MeasurementError, PostprocError, SolverError

MODELS = ("trilinear", "cell")

# A step detected from the data must repeat within this relative difference to count as
# a regular lattice (commanded positions are exact to 1 nm, steps >= 1 mm).
STEP_REL_TOL = 1e-4

# Missing nodes named in an error message; the rest are counted.
MAX_NODES_NAMED = 8
# Nodes of one grid (a fit's lattice, a calibration's tangents): measured grids have
# thousands (315 mm at 10 mm: 32^3 = 32,768); each node costs ~300 bytes in the engine's
# arrays, so this keeps a grid under a few hundred MB, whatever --step or file it comes from.
MAX_GRID_NODES = 1_000_000

# The interpolation check predicts every other node from a grid of twice the step; it
# needs at least this many nodes per axis to leave some nodes to predict.
MIN_NODES_FOR_CHECK = 5


def nodes_from_tangents(r_O1, Q1, Q2, Q3, step) -> np.ndarray:
    """The seed's sums ``R`` at every node: (n1, n2, n3, 3)."""
    Q1, Q2, Q3 = (np.asarray(a, dtype=float) for a in (Q1, Q2, Q3))
    u = np.asarray(step, dtype=float)
    n1, n2, n3 = len(Q1) + 1, Q2.shape[1] + 1, Q3.shape[2] + 1
    line = np.zeros((n1, 3))
    line[1:] = np.cumsum(u[0] * Q1, axis=0)
    plane = np.zeros((n1, n2, 3))
    plane[:, 1:] = np.cumsum(u[1] * Q2, axis=1)
    plane += line[:, None, :]
    P = np.zeros((n1, n2, n3, 3))
    P[:, :, 1:] = np.cumsum(u[2] * Q3, axis=2)
    P += plane[:, :, None, :]
    return P + np.asarray(r_O1, dtype=float)


def tangents_from_nodes(P: np.ndarray, step) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(r_O1, Q1, Q2, Q3)`` along the seed's path from node positions (n1, n2, n3, 3)."""
    u = np.asarray(step, dtype=float)
    Q1 = np.diff(P[:, 0, 0], axis=0) / u[0]
    Q2 = np.diff(P[:, :, 0], axis=1) / u[1]
    Q3 = np.diff(P, axis=2) / u[2]
    return P[0, 0, 0].copy(), Q1, Q2, Q3


class GridEngine(Engine):
    method = "grid"
    affine = False

    def __init__(self, origin_q_mm, step_mm, r_O1, Q1, Q2, Q3, volume_mm=None, model: str = "trilinear") -> None:
        self.q0 = np.asarray(origin_q_mm, dtype=float)
        self.step = np.asarray(step_mm, dtype=float)
        Q1, Q2, Q3 = (np.asarray(a, dtype=float) for a in (Q1, Q2, Q3))
        if self.q0.shape != (3,) or self.step.shape != (3,) or np.any(self.step <= 0):
            raise CalibrationError("grid model needs origin_q_mm (3,) and positive step_mm (3,)")
        if model not in MODELS:
            raise CalibrationError(f"grid interpolation {model!r} is not one of {', '.join(MODELS)}")
        n1 = len(Q1) + 1
        if Q1.ndim != 2 or Q2.ndim != 3 or Q3.ndim != 4 or Q1.shape[1:] != (3,):
            raise CalibrationError("grid model: Q1, Q2, Q3 must have shapes (n1-1, 3), (n1, n2-1, 3), (n1, n2, n3-1, 3)")
        n2 = Q2.shape[1] + 1
        n3 = Q3.shape[2] + 1
        if n1 * n2 * n3 > MAX_GRID_NODES:
            raise CalibrationError(f"grid model of {n1} x {n2} x {n3} nodes: more than {MAX_GRID_NODES:,}")
        if Q2.shape != (n1, n2 - 1, 3) or Q3.shape != (n1, n2, n3 - 1, 3) or min(n1, n2, n3) < 2:
            raise CalibrationError(
                f"grid model: inconsistent tangent shapes Q1 {Q1.shape}, Q2 {Q2.shape}, Q3 {Q3.shape}"
            )
        self.shape = np.array([n1, n2, n3])
        self.model = model
        self.r_O1 = np.asarray(r_O1, dtype=float)
        if self.r_O1.shape != (3,):
            raise CalibrationError(f"grid model needs r_O1_mm (3,), got shape {self.r_O1.shape}")
        self.Q1, self.Q2, self.Q3 = Q1, Q2, Q3
        self.nodes = nodes_from_tangents(self.r_O1, Q1, Q2, Q3, self.step)
        self.edges = [self.q0[j] + self.step[j] * np.arange(self.shape[j]) for j in range(3)]
        if volume_mm is None:
            volume_mm = [self.q0, self.q0 + self.step * (self.shape - 1)]
        super().__init__(volume_mm)
        # Tangent matrix of each cell's lower corner (the cell's own edges), for formula (2).
        P = self.nodes
        G = np.empty((n1 - 1, n2 - 1, n3 - 1, 3, 3))
        G[..., 0] = (P[1:, :-1, :-1] - P[:-1, :-1, :-1]) / self.step[0]
        G[..., 1] = (P[:-1, 1:, :-1] - P[:-1, :-1, :-1]) / self.step[1]
        G[..., 2] = (P[:-1, :-1, 1:] - P[:-1, :-1, :-1]) / self.step[2]
        det = np.linalg.det(G)
        if not np.all(np.isfinite(det)) or np.any(det < 0.5):
            bad = np.argwhere(~(det >= 0.5))[0]
            raise CalibrationError(
                f"grid cell at {format_node(self.q0 + bad * self.step)} has tangent determinant "
                f"{det[tuple(bad)]:.3g}: its axes are not independent directions",
                hint="the measured node positions there are wrong (swapped columns or a bad point)",
            )
        self.G_cells = G
        self.G_cells_inv = np.linalg.inv(G)

    # -- interpolation ----------------------------------------------------------------
    def _local(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = (q - self.q0) / self.step
        cells = np.clip(np.floor(s).astype(int), 0, self.shape - 2)
        return cells, s - cells

    def _trilinear(self, q: np.ndarray, jacobian: bool = False):
        cells, t = self._local(q)
        n2, n3 = int(self.shape[1]), int(self.shape[2])
        base = (cells[:, 0] * n2 + cells[:, 1]) * n3 + cells[:, 2]
        flat = self.nodes.reshape(-1, 3)
        # Differences along z, then y, then x (the standard nested form of trilinear
        # interpolation): 8 gathers, and the Jacobian from the same intermediate values.
        tx, ty, tz = t[:, 0:1], t[:, 1:2], t[:, 2:3]
        c = {}
        for a in (0, 1):
            for b in (0, 1):
                lo = flat[base + (a * n2 + b) * n3]
                hi = flat[base + (a * n2 + b) * n3 + 1]
                c[a, b] = (lo, hi - lo)  # value at z-low, z-difference
        # interpolate along z
        zv = {ab: v + tz * d for ab, (v, d) in c.items()}
        # along y
        y0, y1 = zv[0, 0] + ty * (zv[0, 1] - zv[0, 0]), zv[1, 0] + ty * (zv[1, 1] - zv[1, 0])
        value = y0 + tx * (y1 - y0)
        if not jacobian:
            return value, None
        jac = np.empty((len(q), 3, 3))
        jac[:, :, 0] = (y1 - y0) / self.step[0]
        dy0 = zv[0, 1] - zv[0, 0]
        dy1 = zv[1, 1] - zv[1, 0]
        jac[:, :, 1] = (dy0 + tx * (dy1 - dy0)) / self.step[1]
        dz = {ab: d for ab, (_, d) in c.items()}
        dz0 = dz[0, 0] + ty * (dz[0, 1] - dz[0, 0])
        dz1 = dz[1, 0] + ty * (dz[1, 1] - dz[1, 0])
        jac[:, :, 2] = (dz0 + tx * (dz1 - dz0)) / self.step[2]
        return value, jac

    def _cell_affine(self, q: np.ndarray, cells: np.ndarray) -> np.ndarray:
        i, j, k = cells.T
        corner_q = self.q0 + cells * self.step
        G = self.G_cells[i, j, k]
        return self.nodes[i, j, k] + np.einsum("nab,nb->na", G, q - corner_q)

    def position(self, q) -> np.ndarray:
        """Model position of the measured point (tool vector of the measurement removed)."""
        q = check_points(q, "q")
        if self.model == "cell":
            return self._cell_affine(q, cell_index(q, self.edges))
        return self._trilinear(q)[0]

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        return self.position(q) + check_tool_vectors(r, len(q))

    def _formula2(self, cells: np.ndarray, target: np.ndarray) -> np.ndarray:
        i, j, k = cells.T
        return (
            np.einsum("nab,nb->na", self.G_cells_inv[i, j, k], target - self.nodes[i, j, k])
            + self.q0 + cells * self.step
        )

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        rr = check_tool_vectors(r, len(p))
        target = p - rr
        # The cell M is where the target projects on the commanded axes (seed: the
        # intervals of Ox, Oy, Oz holding the target point).
        first = cell_index(target, self.edges)
        if self.model == "cell":
            q, iters = piecewise_inverse(target, first, self._formula2, self.edges)
        else:
            q, iters = self._newton(target, self._formula2(first, target))
        resid = np.linalg.norm(self.forward(q, rr) - p, axis=1)
        return InverseResult(q, resid, iters)

    def _newton(self, target: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Formula (2) repeated with the tangent matrix at the current point."""
        iters = np.ones(len(q), dtype=int)  # the first step was formula (2) itself
        active = newton_refine(lambda x: self._trilinear(x, jacobian=True), target, q, iters,
                               np.arange(len(q)))
        if len(active) == 0:
            return q, iters
        raise SolverError(
            f"quasi-differential inverse did not converge for {len(active)} point(s), "
            f"first target {format_node(target[active[0]])}",
            hint="the grid calibration is probably corrupt; refit it",
        )

    # -- serialisation ----------------------------------------------------------------
    def model_to_dict(self) -> dict:
        return {
            "interpolation": self.model,
            "origin_q_mm": self.q0.tolist(),
            "step_mm": self.step.tolist(),
            "shape": self.shape.tolist(),
            "r_O1_mm": self.r_O1.tolist(),
            "Q1": self.Q1.tolist(),
            "Q2": self.Q2.tolist(),
            "Q3": self.Q3.tolist(),
        }

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> GridEngine:
        eng = cls(
            model["origin_q_mm"], model["step_mm"], model["r_O1_mm"],
            model["Q1"], model["Q2"], model["Q3"], volume_mm,
            model=model.get("interpolation", "trilinear"),
        )
        if list(eng.shape) != list(model.get("shape", eng.shape)):
            raise CalibrationError(f"grid model: shape {model['shape']} does not match its tangents {eng.shape.tolist()}")
        return eng

    @classmethod
    def from_nodes(cls, origin_q_mm, step_mm, nodes, volume_mm=None, model: str = "trilinear") -> GridEngine:
        r_O1, Q1, Q2, Q3 = tangents_from_nodes(np.asarray(nodes, dtype=float), step_mm)
        return cls(origin_q_mm, step_mm, r_O1, Q1, Q2, Q3, volume_mm, model=model)


# -- fitting --------------------------------------------------------------------------

def detect_lattice(q: np.ndarray, step: np.ndarray | None, path: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lattice origin, step and node count per axis from commanded positions.

    Without ``step`` the data must lie on a regular lattice (equal spacing per axis).
    With ``step`` the lattice starts at the smallest commanded position and points that
    are not on it are left out (a finer grid can be fitted at a coarser step).
    """
    origin = q.min(axis=0)
    steps = np.empty(3)
    counts = np.empty(3, dtype=int)
    for j in range(3):
        pos = distinct_positions(q[:, j])
        if len(pos) < 2:
            raise MeasurementError(
                f"the grid has a single commanded {AXES[j]} position ({pos[0]:.3f}): "
                "the quasi-differential method needs a 3-D lattice",
                path=path or None,
                hint="measure at least two positions along each axis (a step of 10-20 mm is typical)",
            )
        if step is None:
            d = np.diff(pos)
            if np.ptp(d) > STEP_REL_TOL * d.mean() + LATTICE_TOL_MM:
                raise MeasurementError(
                    f"commanded {AXES[j]} positions are not evenly spaced (steps from "
                    f"{d.min():.3f} to {d.max():.3f} mm): not a regular grid",
                    path=path or None,
                    hint="give the grid step with --step, points off that lattice are then left out",
                )
            steps[j] = d.mean()
        else:
            steps[j] = step[j]
        with np.errstate(over="ignore"):  # a step of 1e-320 mm: inf nodes, refused just below
            n = np.floor((pos[-1] - origin[j]) / steps[j] + LATTICE_TOL_MM / steps[j]) + 1
        if not n <= MAX_GRID_NODES:  # (also inf) refused before it becomes an integer
            _check_nodes([n], path, f" along {AXES[j]}")
        counts[j] = int(n)
        if counts[j] < 2:
            raise MeasurementError(
                f"grid step {steps[j]:g} mm on {AXES[j]} is longer than the measured travel "
                f"{pos[-1] - origin[j]:.3f} mm",
                path=path or None,
                hint="choose a smaller --step",
            )
    _check_nodes(counts, path)
    return origin, steps, counts


def _check_nodes(counts, path: str | None = None, along: str = "") -> None:
    """Refuse a lattice of more than :data:`MAX_GRID_NODES` nodes."""
    total = math.prod(float(c) for c in counts)
    if not total <= MAX_GRID_NODES:
        raise MeasurementError(
            f"a grid of {' x '.join(f'{c:.6g}' for c in counts)} nodes{along}: more than {MAX_GRID_NODES:,}",
            path=path or None, hint="choose a larger --step (measured grids have a step of 10-20 mm)")


def _shifted(pad: np.ndarray, n: np.ndarray, axis: int, k: int) -> np.ndarray:
    """The nodes ``k`` steps away along ``axis`` from a lattice padded by 2 NaN layers."""
    sl = [slice(2, 2 + n[a]) for a in range(3)]
    sl[axis] = slice(2 + k, 2 + k + n[axis])
    return pad[tuple(sl)]


def fill_missing_nodes(nodes: np.ndarray) -> np.ndarray:
    """Fill NaN nodes from their lattice neighbours (a documented, opt-in fill).

    Pass after pass, a missing node takes the mean over axes of the midpoint of its two
    neighbours on that axis when both are known; failing that, the mean of the linear
    extrapolations from two known nodes on one side. Nodes no pass can reach (a whole
    empty region) get the affine (static) fit of all known nodes.
    """
    P = nodes.copy()
    n = np.array(P.shape[:3])
    while True:
        missing = np.isnan(P[..., 0])
        if not missing.any():
            return P
        pad = np.pad(P, [(2, 2)] * 3 + [(0, 0)], constant_values=np.nan)
        two = np.zeros_like(P)
        two_n = np.zeros(P.shape[:3])
        one = np.zeros_like(P)
        one_n = np.zeros(P.shape[:3])
        for j in range(3):
            near = {k: _shifted(pad, n, j, k) for k in (-2, -1, 1, 2)}
            for est, acc, cnt in (((near[-1] + near[1]) / 2, two, two_n),
                                  (2 * near[-1] - near[-2], one, one_n),
                                  (2 * near[1] - near[2], one, one_n)):
                ok = ~np.isnan(est[..., 0])
                acc[ok] += est[ok]
                cnt[ok] += 1
        use_two = missing & (two_n > 0)
        use_one = missing & ~use_two & (one_n > 0)
        if not (use_two.any() or use_one.any()):
            known = ~missing
            qk = np.argwhere(known).astype(float)
            A = np.column_stack([np.ones(len(qk)), qk])
            coef, *_ = np.linalg.lstsq(A, P[known], rcond=None)
            qm = np.argwhere(missing).astype(float)
            P[missing] = np.column_stack([np.ones(len(qm)), qm]) @ coef
            return P
        P[use_two] = two[use_two] / two_n[use_two, None]
        P[use_one] = one[use_one] / one_n[use_one, None]


def node_means(q, p, origin, step, counts, path: str = "", fill: bool = False):
    """Average the points at each lattice node (repeated shots).

    Returns (nodes, index, on_lattice, missing node indices). Missing nodes raise a
    MeasurementError naming them, unless ``fill`` (then :func:`fill_missing_nodes`).
    """
    s = (q - origin) / step
    idx = np.rint(s).astype(int)
    on = np.all(np.abs(s - idx) * step < LATTICE_TOL_MM, axis=1) & np.all((idx >= 0) & (idx < counts), axis=1)
    flat = np.ravel_multi_index(idx[on].T, counts)
    total = np.zeros((int(np.prod(counts)), 3))
    n = np.zeros(int(np.prod(counts)))
    np.add.at(total, flat, p[on])
    np.add.at(n, flat, 1.0)
    missing = np.flatnonzero(n == 0)
    if fill and len(missing) > len(n) - 4:
        raise MeasurementError(
            f"only {len(n) - len(missing)} of {len(n)} lattice nodes are measured: too few to fill the rest",
            path=path or None,
        )
    if len(missing) and not fill:
        names = [format_node(origin + np.array(np.unravel_index(m, counts)) * step) for m in missing[:MAX_NODES_NAMED]]
        more = f" and {len(missing) - MAX_NODES_NAMED} more" if len(missing) > MAX_NODES_NAMED else ""
        raise MeasurementError(
            f"incomplete grid: {len(missing)} of {len(n)} nodes of the "
            f"{counts[0]} x {counts[1]} x {counts[2]} lattice (step "
            f"{', '.join(f'{u:g}' for u in step)} mm) have no measurement: {'; '.join(names)}{more}",
            path=path or None,
            hint="measure the missing nodes, or fit a coarser --step or a smaller region",
        )
    with np.errstate(invalid="ignore", divide="ignore"):
        nodes = (total / n[:, None]).reshape(*counts, 3)
    if len(missing):
        nodes = fill_missing_nodes(nodes)
    return nodes, idx, on, np.array(np.unravel_index(missing, counts)).T


def _interpolation_check(origin, step, nodes) -> str | None:
    """Predict every other node from the grid of twice the step (how smooth the field is)."""
    if np.any(np.array(nodes.shape[:3]) < MIN_NODES_FOR_CHECK):
        return None
    coarse_nodes = nodes[::2, ::2, ::2]
    coarse = GridEngine.from_nodes(origin, 2 * step, coarse_nodes)
    n = np.array(nodes.shape[:3])
    reach = (np.array(coarse_nodes.shape[:3]) - 1) * 2  # nodes the coarse grid spans
    idx = np.stack(np.meshgrid(*[np.arange(reach[j] + 1) for j in range(3)], indexing="ij"), -1).reshape(-1, 3)
    skipped = idx[np.any(idx % 2 == 1, axis=1) & np.all(idx < n, axis=1)]
    pred = coarse.position(origin + skipped * step)
    err = np.linalg.norm(pred - nodes[tuple(skipped.T)], axis=1)
    return (
        f"interpolation check: a grid of twice the step predicts the {len(skipped)} skipped nodes "
        f"to RMS {np.sqrt(np.mean(err**2)) * 1000:.1f} um, max {err.max() * 1000:.1f} um "
        "(includes twice the node noise; the interpolation error of smooth errors falls as the step squared)"
    )


def refit_options(engine) -> dict:
    """The :func:`fit` options that fit ``engine``'s lattice again (its step)."""
    model = engine.model_to_dict()
    return {"step": ",".join(f"{v:g}" for v in model["step_mm"])} if "step_mm" in model else {}


def fit(measurements, *, step=None, screw_pitch=None, model: str = "trilinear", fill_missing: bool = False,
        **options) -> FitResult:
    """Fit the quasi-differential model from tracker points on a regular lattice.

    Options: ``step`` ("15" or "15,15,10" mm; default: the lattice step of the data),
    ``screw_pitch`` (["X=5", ...] mm, for the aliasing warning), ``model``
    ("trilinear" or "cell"), ``fill_missing`` (fill nodes without measurements from
    their neighbours instead of refusing; for cross-validation and partial grids).
    """
    if model not in MODELS:
        raise PostprocError(f"grid model {model!r} is not one of {', '.join(MODELS)}")
    items = list(measurements)
    meas = Measurements.concat(items)
    path = meas.path
    steps = parse_step(step)
    pitches = parse_screw_pitch(screw_pitch)
    P_obs = meas.m - meas.r
    origin, steps, counts = detect_lattice(meas.q, steps, path)
    nodes, idx, on, filled = node_means(meas.q, P_obs, origin, steps, counts, path, fill=fill_missing)
    engine = GridEngine.from_nodes(origin, steps, nodes, model=model)
    resid = P_obs[on] - nodes[tuple(idx[on].T)]
    result = FitResult(engine=engine, residuals_mm=resid)
    span = steps * (counts - 1)
    shots = on.sum() / np.prod(counts)
    report = [
        f"quasi-differential ({model}) fit: {counts[0]} x {counts[1]} x {counts[2]} nodes, step "
        f"{', '.join(f'{u:g}' for u in steps)} mm, from {on.sum()} points ({shots:.3g} per node)",
        "calibrated volume (mm): " + "  ".join(
            f"{AXES[j]} {origin[j]:.3f}..{origin[j] + span[j]:.3f}" for j in range(3)
        ),
    ]
    if len(filled):
        names = "; ".join(format_node(origin + f * steps) for f in filled[:MAX_NODES_NAMED])
        more = f" and {len(filled) - MAX_NODES_NAMED} more" if len(filled) > MAX_NODES_NAMED else ""
        report.append(f"warning: {len(filled)} node(s) without measurement filled from their neighbours: {names}{more}")
    if (~on).sum():
        report.append(f"left out {(~on).sum()} points that are not on the lattice")
    lengths = [np.linalg.norm(engine.Q1, axis=-1), np.linalg.norm(engine.Q2, axis=-1), np.linalg.norm(engine.Q3, axis=-1)]
    report.append(
        "tangent length - 1 (ppm, min..max): " + "  ".join(
            f"{AXES[j]} {(lengths[j].min() - 1) * 1e6:+.0f}..{(lengths[j].max() - 1) * 1e6:+.0f}" for j in range(3)
        )
    )
    report.append("the model passes through the node means: the fit residual is the scatter of repeated shots")
    report += tool_vector_note(meas.r[on], "quasi-differential")
    check = _interpolation_check(origin, steps, nodes)
    if check:
        report.append(check)
    report += step_warnings(steps, span, pitches)
    unused = sorted(k for k, v in options.items() if v is not None)
    if unused:
        report.append(f"note: option(s) {', '.join(unused)} do not apply to the grid method and were ignored")
    result.report = report
    result.info = {
        "n_points": int(on.sum()), "n_nodes": int(np.prod(counts)), "n_filled_nodes": len(filled),
        "step_mm": steps.tolist(),
        "rms_mm": result.rms_mm, "max_mm": result.max_mm, "sources": [m.path for m in items],
    }
    return result
