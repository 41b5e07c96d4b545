"""Inverse solvers of the parametric model: find q with F(q, r) = p*.

``newton_inverse_located``: vectorised Newton with the analytic Jacobian of the first-order
model, converged to a hundredth of SOLVER_TOL_MM; a point that does not reach
SOLVER_TOL_MM raises SolverError naming it.

``astatic_inverse``: the KMTPP iteration of seed 000 (chapter 4) as the seed
describes it. The workspace is split into a grid of step u from the lower corner of
the calibrated volume (the tables' origin O1). A model point starts there, at the
actual position R = F(q_0, r), and moves by the astatic control law

    qdot_m = -K (q_m - q_d),   q_{m+1} = q_m + l qdot_m,     q_d = p* - r

(q_d: the nominal axis coordinates of the target). Its actual position is
accumulated along the path through the curved field, quasi-differentially:
R_{m+1} = R_m + G_M (q_{m+1} - q_m), with G_M the direction-cosine matrix of the grid
cell M holding q_m (column i: the secant of the model along axis i over one grid
step from the cell's node, the rotations composed by Rodrigues-Hamilton parameters
when the engine's order is "exact"). The iteration stops when R is within one grid
step of the target on every axis; then formula (2) gives
q = q_m + G_M^-1 (p* - R) with the last G. The result is not iterated further: its
residual |F(q) - p*| is what the method achieves, and is returned, not assumed.
"""

from __future__ import annotations

import numpy as np

from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM
from postproc.engine.base import InverseResult
from postproc.engine.parametric_errors import scratch
from postproc.errors import SolverError

# Newton stops at a hundredth of the tolerance: one more cheap iteration puts the
# residual far below anything a controller can resolve, and leaves margin for the
# rounding of the emitted coordinates.
NEWTON_STOP_MM = SOLVER_TOL_MM / 100


def _solver_error(what: str, idx: int, p: np.ndarray, resid: float, n: int) -> SolverError:
    x, y, z = p[idx]
    err = SolverError(
        f"{what} did not converge for point #{idx} (target {x:.4f}, {y:.4f}, {z:.4f} mm): "
        f"residual {resid * 1000:.4g} um after {n} iterations",
        hint="check that the target lies in the calibrated volume and that the error tables are sane "
             "(no jumps of millimetres between rows)",
    )
    err.point_index = idx
    return err


# A Jacobian whose determinant is below this is singular: the model maps a direction
# of motion to nothing (error slopes of -1 or worse), and no inverse exists there.
MIN_JACOBIAN_DET = 1e-6


# From this many points on, 3 x 3 systems are solved by :func:`_lu_solve_3x3` (numpy
# operations over all points at once) rather than one LAPACK call per point; below it
# the fixed cost of the numpy operations is the larger.
LU_VECTOR_MIN_POINTS = 48
# |det| of the vectorised LU at least this: LAPACK's determinant (the same LU's pivots
# through log and exp, a few ulps apart) is certainly above MIN_JACOBIAN_DET.
_LU_DET_MARGIN = 2.0


def _swap_rows(a: np.ndarray, b: np.ndarray, k: int, jp: np.ndarray) -> None:
    """Swap rows k and jp[n] of a[:, :, n] (3, 3, N) and of b[:, n] (3, N), where they differ."""
    sw = np.flatnonzero(jp != k)
    if len(sw):
        other = jp[sw]
        rows_k, rows_o = a[k][:, sw], a[other, :, sw].T
        a[k][:, sw], a[other, :, sw] = rows_o, rows_k.T
        bk, bo = b[k, sw], b[other, sw]
        b[k, sw], b[other, sw] = bo, bk


def _first_largest(m: np.ndarray) -> np.ndarray:
    """np.argmax(m, axis=0) of the magnitudes m (k, N), k = 2 or 3, the first NaN or the
    first largest of each column, by whole rows (argmax along the short first axis
    visits the columns one by one)."""
    idx = ((m[1] > m[0]) | (np.isnan(m[1]) & ~np.isnan(m[0]))).astype(np.intp)
    if len(m) == 3:
        # the largest of the first two (theirs where either is NaN: it is first)
        top = np.where(idx == 1, m[1], m[0])
        idx[(m[2] > top) | (np.isnan(m[2]) & ~np.isnan(top))] = 2
    return idx


def _lu_solve_3x3(J: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """x with J x = f (N, 3) and the determinants up to their sign (N,), or None when a
    matrix is not finite (LAPACK then decides).

    The operations of LAPACK's dgetrf (unblocked, left-looking, partial pivoting on the
    first largest magnitude, multipliers scaled by the pivot's reciprocal) and dgetrs
    (forward then backward substitution, dividing by the pivots) as numpy's solve runs
    them for a 3 x 3 system, in the same order: the results are the same to the last bit
    (tests/test_parametric_speed.py holds them equal on many matrices, pivoting ones too).
    """
    if not np.isfinite(J).all():
        return None
    a = scratch("lu", (3, 3, len(J)))  # (row, column, point)
    np.copyto(a, J.transpose(1, 2, 0))
    b = f.T.copy()
    # column 0: pivot, scale
    _swap_rows(a, b, 0, _first_largest(np.abs(a[:, 0])))
    u00, u01, u02 = a[0]
    rec = 1.0 / u00
    l10 = a[1, 0] * rec
    l20 = a[2, 0] * rec
    # column 1: update, pivot, scale
    a[1, 1] = a[1, 1] - l10 * u01
    a[2, 1] = a[2, 1] - l20 * u01
    a[1, 0], a[2, 0] = l10, l20
    _swap_rows(a, b, 1, 1 + _first_largest(np.abs(a[1:, 1])))
    l10, l20 = a[1, 0], a[2, 0]
    u11 = a[1, 1]
    l21 = a[2, 1] * (1.0 / u11)
    # column 2: update
    u12 = a[1, 2] - l10 * u02
    u22 = a[2, 2] - (l20 * u02 + l21 * u12)
    # forward substitution (unit lower), then backward (upper)
    b0 = b[0]
    b1 = b[1] + (-b0) * l10
    b2 = b[2] + (-b0) * l20
    b2 = b2 + (-b1) * l21
    x = np.empty_like(f)
    x2 = b2 / u22
    b0 = b0 + (-x2) * u02
    b1 = b1 + (-x2) * u12
    x1 = b1 / u11
    x[:, 2], x[:, 1], x[:, 0] = x2, x1, (b0 + (-x1) * u01) / u00
    return x, u00 * u11 * u22


def _solve(J: np.ndarray, f: np.ndarray, what: str, idx: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Solve J x = f per point; a singular J raises SolverError naming the point."""
    if len(J) >= LU_VECTOR_MIN_POINTS:
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # singular: LAPACK says so below
            lu = _lu_solve_3x3(J, f)
        if lu is not None and np.all(np.abs(lu[1]) >= _LU_DET_MARGIN * MIN_JACOBIAN_DET):
            return lu[0]
    det = np.linalg.det(J)
    bad = np.flatnonzero(~(np.abs(det) >= MIN_JACOBIAN_DET))
    if len(bad):
        k = int(idx[bad[0]])
        x, y, z = p[k]
        err = SolverError(
            f"{what}: the model's axis directions are singular at point #{k} "
            f"(target {x:.4f}, {y:.4f}, {z:.4f} mm; det {det[bad[0]]:.3g})",
            hint="the error tables have a slope of -1 or worse here (a jump of millimetres between rows?)",
        )
        err.point_index = k
        raise err
    return np.linalg.solve(J, f[:, :, None])[:, :, 0]


def newton_inverse_located(engine, p: np.ndarray, r: np.ndarray, *, tol_mm: float = SOLVER_TOL_MM,
                           max_iter: int = SOLVER_MAX_ITER) -> InverseResult:
    """Newton iteration q <- q - J^-1 (F(q) - p*), per point, from q = p* - r. The
    Jacobian of the points not yet converged is built from where the error tables were
    just located for their residual (no second search, no re-evaluated values); the
    iterates are those of the plain loop (tests/parametric_reference.py) to the last bit."""
    n = len(p)
    q = p - r
    iterations = np.zeros(n, dtype=int)
    resid = np.full(n, np.inf)
    active = np.arange(n)
    # all points still iterate: whole arrays, no gathering and scattering (C-ordered, as
    # gathered rows are: the squareness product and the residual's sum see the same layout)
    everyone = q.flags.c_contiguous and p.flags.c_contiguous and r.flags.c_contiguous
    order = engine.order
    loc = None
    for k in range(max_iter + 1):
        if everyone:
            qa, ra, pa = q, r, p
        else:
            qa, ra, pa = q[active], r[active], p[active]
        # the same points as in the step before: their intervals, most likely, too
        value, loc = engine.forward_located(qa, ra, order, loc if everyone else None)
        f = value - pa
        # np.linalg.norm(f, axis=1) without its checks, and its sum of the three squares
        # taken as (x2 + y2) + z2 by whole columns (a reduction along rows of three runs
        # ten times slower; the same sums)
        f2 = f * f
        res = np.sqrt((f2[:, 0] + f2[:, 1]) + f2[:, 2])
        resid[active] = res
        keep = ~(res <= NEWTON_STOP_MM)
        if everyone and keep.all():
            rows = None
        else:
            rows = keep
            everyone = False
            active, f, ra = active[keep], f[keep], ra[keep]
        if not len(active) or k == max_iter:
            break
        J = engine.jacobian_located(loc, rows, ra)
        if everyone:
            q -= _solve(J, f, "Newton inverse", active, p)
            iterations += 1
        else:
            q[active] -= _solve(J, f, "Newton inverse", active, p)
            iterations[active] += 1
    bad = np.flatnonzero(~(resid <= tol_mm))
    if len(bad):
        worst = bad[np.argmax(np.where(np.isfinite(resid[bad]), resid[bad], np.inf))]
        raise _solver_error("Newton inverse", int(worst), p, float(resid[worst]), int(iterations[worst]))
    return InverseResult(q, resid, iterations)


def cell_matrix(engine, node: np.ndarray, r: np.ndarray, step_mm: float) -> np.ndarray:
    """G_M (N, 3, 3): column i = (F(node + u e_i) - F(node)) / u, the axis directions of the cell."""
    f0 = engine.forward(node, r)
    G = np.empty((len(node), 3, 3))
    for i in range(3):
        shifted = node.copy()
        shifted[:, i] += step_mm
        G[:, :, i] = (engine.forward(shifted, r) - f0) / step_mm
    return G


def astatic_inverse(engine, p: np.ndarray, r: np.ndarray, settings) -> InverseResult:
    """KMTPP astatic iteration (see the module docstring), vectorised over points."""
    u, K, dt = settings.grid_step_mm, settings.gain, settings.time_step
    n = len(p)
    origin = engine.volume_mm[0].copy()
    q_d = p - r
    q_m = np.tile(origin, (n, 1))
    R = engine.forward(q_m, r)
    iterations = np.zeros(n, dtype=int)
    G_last = np.empty((n, 3, 3))
    active = np.arange(n)

    def node_of(q):
        return origin + np.floor((q - origin) / u) * u

    for _ in range(settings.max_iter):
        G_last[active] = cell_matrix(engine, node_of(q_m[active]), r[active], u)
        close = np.all(np.abs(R[active] - p[active]) <= u, axis=1)
        active = active[~close]
        if not len(active):
            break
        step = dt * (-K * (q_m[active] - q_d[active]))
        # The actual position accumulates cell by cell along the step (sub-steps of at
        # most one grid step on every axis), each with its own cell's G.
        n_sub = np.maximum(1, np.ceil(np.max(np.abs(step), axis=1) / u)).astype(int)
        sub = step / n_sub[:, None]
        for j in range(int(n_sub.max())):
            sel = n_sub > j
            idx = active[sel]
            G = cell_matrix(engine, node_of(q_m[idx]), r[idx], u)
            R[idx] += np.einsum("nij,nj->ni", G, sub[sel])
            q_m[idx] += sub[sel]
        iterations[active] += 1
    else:
        if len(active):
            dist = np.max(np.abs(R[active] - p[active]), axis=1)
            worst = int(active[np.argmax(dist)])
            raise _solver_error("astatic iteration", worst, p, float(dist.max()), settings.max_iter)
    # Formula (2) with the last G: one linear step from the model point to the target.
    q = q_m + _solve(G_last, p - R, "astatic iteration", np.arange(n), p)
    resid = np.linalg.norm(engine.forward(q, r) - p, axis=1)
    return InverseResult(q, resid, iterations + 1)
