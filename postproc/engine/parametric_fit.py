"""Identification of the 21-parameter model from point measurements.

``fit(measurements, knot_spacing=None) -> FitResult`` estimates the 18 error
functions and the 3 squareness constants by linear least squares on the first-order
model (formula 3)::

    m - q - r = o + rho(q) + eps(q) x r + noise

Each function is a clamped cubic B-spline in its own axis coordinate (knots evenly
spaced, ``knot_spacing`` mm or chosen from the data). The gauge freedoms are fixed
explicitly, as ISO 230-1 tables fix them:

- every function is zero at the reference position, the lowest commanded position
  of its axis in the data; a constant offset ``o`` (3) carries the origin;
- straightness functions are zero at both ends (no linear trend): the trends are
  carried by the squareness EC0Y, EB0Z, EA0Z and by three *alignment* angles, the
  direction of the X axis (trends of EYX, EZX) and the tilt of the XY plane (trend
  of EZY) in the measurement frame, which formats.md's squareness (taken relative to
  X and the XY plane) does not hold;
- angular functions act only through the tool vectors: a constant angle eps0 (3) and
  the per-axis angular functions are determined only as far as the data's tool
  vectors see them. With a single tool vector every angular function is either
  invisible (rotation about r) or indistinguishable from a linear error.

Parameters the data cannot determine are found by the numerical rank of the design
matrix (columns normalised; singular values below RANK_RTOL of the largest) in two
stages: the linear errors first, then the angular errors in what the linear errors
leave unexplained. Undetermined combinations are set to zero (the minimum-norm
solution in the normalised parameters) and listed by name in the report and in
``info["undetermined"]``; nothing is invented for them. The fitted model is sampled
into axis error tables, so the result is an ordinary ``ParametricEngine``.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline

from postproc.calibration.axis_tables import AXES, COLUMNS, AxisTables, Squareness
from postproc.calibration.measurements import Measurements
from postproc.engine.base import FitResult
from postproc.engine.parametric import ParametricEngine
from postproc.errors import MeasurementError

# Relative singular value below which a direction of the (column-normalised) design
# matrix is taken as undetermined. Exact confounding shows as ~1e-8 through the normal
# equations (rounding of the squared values); a direction a million times weaker than
# the strongest would amplify a 1 um noise to a metre, so it is not determined either.
RANK_RTOL = 1e-6

# A block whose share of the null space is above this fraction of its size is listed
# as undetermined; between PARTLY_MIN and this, as partly undetermined.
FULLY_UNDETERMINED = 0.99
PARTLY_MIN = 0.05

# An axis that travels less than this in the data cannot carry error functions.
MIN_TRAVEL_MM = 1.0

# Default knots: no closer than this (waviness shorter than ~2 knot spacings is not a
# geometric error a table can hold; lead-screw periodic errors are an effect of their own) ...
MIN_DEFAULT_KNOT_MM = 10.0
# ... at least this many distinct measured positions per knot interval ...
POSITIONS_PER_INTERVAL = 3
# ... and no more parameters than this fraction of the scalar observations.
MAX_PARAMS_PER_OBSERVATION = 0.25

# Sampling step of the fitted functions into tables (pchip between samples is then
# within ~0.01 um of the spline for knot spacings of 10 mm and more).
TABLE_STEP_MM = 2.5
# Rounding guard when counting knot intervals: a travel of exactly n spacings gives n
# intervals, not n + 1 from floating-point division.
INTERVAL_COUNT_GUARD = 1e-9

_UNIT = np.eye(3)


def _role(axis: int, col: int) -> str:
    if col < 3:
        return "positioning" if col == axis else f"straightness in {'xyz'[col]}"
    k = col - 3
    return "roll" if k == axis else f"angular about {'xyz'[k]}"


def _knots(lo: float, hi: float, n_int: int) -> np.ndarray:
    inner = np.linspace(lo, hi, n_int + 1)
    return np.concatenate([[lo] * 3, inner, [hi] * 3])


def _default_intervals(x: np.ndarray, n_obs: int, spacing: float | None) -> int:
    lo, hi = x.min(), x.max()
    if spacing is not None:
        if not spacing > 0:
            raise MeasurementError(f"knot spacing {spacing} mm: must be positive",
                                   hint="give --knot-spacing in mm, e.g. 20")
        n = max(1, int(np.ceil(min((hi - lo) / spacing, 1e12) - INTERVAL_COUNT_GUARD)))
        budget = int(MAX_PARAMS_PER_OBSERVATION * n_obs / 18) - 3
        if n > max(budget, 1):
            raise MeasurementError(
                f"knot spacing {spacing:g} mm makes {n:,} intervals over {hi - lo:g} mm: more coefficients "
                f"than {n_obs} observations can fit (at most {max(budget, 1)} intervals)",
                hint=f"give a --knot-spacing of at least {(hi - lo) / max(budget, 1):.3g} mm")
        return n
    distinct = len(np.unique(np.round(x, 3)))
    n = min(int((hi - lo) // MIN_DEFAULT_KNOT_MM), (distinct - 1) // POSITIONS_PER_INTERVAL)
    # 3 axes x 6 functions x (n + 3) coefficients within the parameter budget.
    budget = int(MAX_PARAMS_PER_OBSERVATION * n_obs / 18) - 3
    return max(1, min(n, budget))


class _Design:
    """Columns of the design matrix, each an (N, 3) displacement, with names and blocks."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.cols: list[np.ndarray] = []
        self.block: list[str] = []

    def add(self, block: str, col: np.ndarray) -> None:
        self.cols.append(col)
        self.block.append(block)

    def matrix(self) -> np.ndarray:
        return np.stack([c.reshape(-1) for c in self.cols], axis=1) if self.cols else np.zeros((3 * self.n, 0))


def fit(measurements, knot_spacing: float | None = None, **options) -> FitResult:
    """Least-squares identification of the parametric model (see the module docstring).

    ``options`` may carry engine settings (order, solver, interpolation, extrapolate,
    astatic) for the fitted engine; other options are ignored and reported.
    """
    items = list(measurements) if isinstance(measurements, list | tuple) else [measurements]
    meas = Measurements.concat(items)
    q, r = meas.q, meas.r
    y = meas.m - q - r
    n = len(q)
    lo, hi = q.min(axis=0), q.max(axis=0)
    for i, ax in enumerate(AXES):
        if hi[i] - lo[i] < MIN_TRAVEL_MM:
            raise MeasurementError(
                f"axis {ax} travels {hi[i] - lo[i]:.3f} mm in the data: a parametric fit needs every axis moved",
                path=meas.path or None,
                hint="measure points spread over the volume, or use the static method",
            )
    spacing = [None] * 3 if knot_spacing is None else [float(knot_spacing)] * 3
    n_int = [_default_intervals(q[:, i], 3 * n, spacing[i]) for i in range(3)]
    knots = [_knots(lo[i], hi[i], n_int[i]) for i in range(3)]
    basis = [BSpline.design_matrix(np.clip(q[:, i], lo[i], hi[i]), knots[i], 3).toarray() for i in range(3)]

    lin, ang, coef_index = _build_design(q, r, lo, basis)
    A_L, A_E = lin.matrix(), ang.matrix()
    yv = y.reshape(-1)
    theta_L, theta_E, analysis = _staged_solve(A_L, A_E, yv, lin.block, ang.block)

    # Tables sampled from the fitted functions, plus the global terms.
    L = dict(zip(lin.block, theta_L, strict=True))  # the scalar blocks by name
    blocks_L = _by_block(lin.block, theta_L)
    blocks_E = _by_block(ang.block, theta_E)
    positions, errors = {}, {}
    for i, ax in enumerate(AXES):
        m = max(2, int(np.ceil((hi[i] - lo[i]) / TABLE_STEP_MM)) + 1)
        x = np.linspace(lo[i], hi[i], m)
        Bx = BSpline.design_matrix(x, knots[i], 3).toarray()
        cols = np.zeros((m, 6))
        for c in range(6):
            kind, idx = coef_index[(i, c)]
            coef = np.zeros(Bx.shape[1])
            theta = theta_L if kind == "lin" else theta_E
            js = range(1, Bx.shape[1] - 1) if (c < 3 and c != i) else range(1, Bx.shape[1])
            coef[list(js)] = theta[list(idx)]
            cols[:, c] = Bx @ coef
        positions[ax], errors[ax] = x, cols
    errors["X"][:, :3] += blocks_L["offset"]
    errors["X"][:, 3:] += np.concatenate([blocks_E[f"eps0{c}"] for c in "xyz"])
    errors["X"][:, 1] += L["EYX trend"] * (positions["X"] - lo[0])
    errors["X"][:, 2] += L["EZX trend"] * (positions["X"] - lo[0])
    errors["Y"][:, 2] += L["EZY trend"] * (positions["Y"] - lo[1])
    sq = Squareness(EC0Y=L["EC0Y"], EB0Z=L["EB0Z"], EA0Z=L["EA0Z"])
    engine_opts = {k: v for k, v in options.items()
                   if k in ("order", "solver", "interpolation", "extrapolate", "astatic") and v is not None}
    engine = ParametricEngine(AxisTables(positions, errors), sq, np.vstack([lo, hi]), **engine_opts)
    resid = meas.m - engine.forward(q, r)

    tools = np.unique(np.round(r, 6), axis=0)
    report = [
        f"parametric identification on {n} points from {len(items)} file(s), "
        f"{len(tools)} distinct tool vector(s)",
        "knot spacing (mm): " + "  ".join(f"{ax} {(hi[i] - lo[i]) / n_int[i]:.2f}" for i, ax in enumerate(AXES))
        + f"; reference position (functions zero): {lo[0]:.3f}, {lo[1]:.3f}, {lo[2]:.3f}",
        f"design: {analysis['n_params']} parameters, numerical rank {analysis['rank']} "
        f"(relative threshold {RANK_RTOL:g}), condition number {analysis['condition']:.3g}",
    ]
    if analysis["undetermined"] or analysis["partly"]:
        report.append("not determined by these data (set to zero, not invented):")
        for name, why in analysis["undetermined"].items():
            report.append(f"  {name} ({_describe(name)}): {why}")
        for name, why in analysis["partly"].items():
            report.append(f"  {name} ({_describe(name)}): partly, {why}")
    else:
        report.append("all parameters are determined by these data")
    report.append("squareness (urad): " + "  ".join(f"{k} {v * 1e6:+.2f}" for k, v in sq.as_dict().items()))
    report.append(
        "alignment of the machine in the measurement frame (urad): "
        + "  ".join(f"{k.split()[0]} {L[k] * 1e6:+.2f}" for k in ("EYX trend", "EZX trend", "EZY trend"))
    )
    ignored = sorted(k for k, v in options.items() if v is not None and k not in engine_opts)
    if ignored:
        report.append(f"option(s) {', '.join(ignored)} do not apply to the parametric fit: ignored")
    rms = float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))
    info = {
        "kind": "parametric identification",
        "n_points": n,
        "rms_mm": rms,
        "max_mm": float(np.max(np.linalg.norm(resid, axis=1))),
        "sources": [m.path for m in items],
        "knot_spacing_mm": [float((hi[i] - lo[i]) / n_int[i]) for i in range(3)],
        "reference_mm": lo.tolist(),
        "n_params": analysis["n_params"],
        "rank": analysis["rank"],
        "condition": analysis["condition"],
        "undetermined": sorted(analysis["undetermined"]),
        "partly_undetermined": sorted(analysis["partly"]),
        "tool_vectors_mm": tools[:10].tolist(),
    }
    return FitResult(engine=engine, residuals_mm=resid, report=report, info=info)


def _build_design(q, r, lo, basis):
    """Design columns: (linear-error design, angular-error design, coefficient index per function)."""
    n = len(q)
    lin, ang = _Design(n), _Design(n)
    zeros = np.zeros((n, 3))
    for k in range(3):
        lin.add("offset", zeros + _UNIT[k])
    lin.add("EC0Y", np.outer(-q[:, 1], _UNIT[0]))
    lin.add("EB0Z", np.outer(q[:, 2], _UNIT[0]))
    lin.add("EA0Z", np.outer(-q[:, 2], _UNIT[1]))
    lin.add("EYX trend", np.outer(q[:, 0] - lo[0], _UNIT[1]))
    lin.add("EZX trend", np.outer(q[:, 0] - lo[0], _UNIT[2]))
    lin.add("EZY trend", np.outer(q[:, 1] - lo[1], _UNIT[2]))
    turn = [np.cross(_UNIT[k], r) for k in range(3)]  # e_k x r, (N, 3)
    for k in range(3):
        ang.add(f"eps0{'xyz'[k]}", turn[k])
    coef_index: dict[tuple[int, int], tuple[str, range]] = {}
    for i, ax in enumerate(AXES):
        B = basis[i]
        nb = B.shape[1]
        for c in range(6):
            name = f"{COLUMNS[c]}{ax}"
            design = lin if c < 3 else ang
            # zero at the reference (first coefficient); straightness also at the far end.
            js = range(1, nb - 1) if (c < 3 and c != i) else range(1, nb)
            start = len(design.cols)
            for j in js:
                design.add(name, np.outer(B[:, j], _UNIT[c]) if c < 3 else B[:, j, None] * turn[c - 3])
            coef_index[(i, c)] = ("lin" if c < 3 else "ang", range(start, start + len(js)))

    return lin, ang, coef_index


def _describe(name: str) -> str:
    if name.startswith("eps0"):
        return f"constant angle about {name[-1]} (tool-side tilt)"
    if name.endswith(" trend"):
        return "linear trend: alignment of the machine in the measurement frame"
    if len(name) == 3 and name[:2] in COLUMNS and name[2] in AXES:
        return f"{_role(AXES.index(name[2]), COLUMNS.index(name[:2]))} of {name[2]}"
    return name


def _by_block(names: list[str], theta: np.ndarray) -> dict[str, np.ndarray]:
    out: dict[str, list] = {}
    for nm, v in zip(names, theta, strict=True):
        out.setdefault(nm, []).append(v)
    return {k: np.array(v) for k, v in out.items()}


def _block_shares(null: np.ndarray, names: list[str]) -> dict[str, tuple[float, int]]:
    """Per block: (share of the null space inside it, block size)."""
    out: dict[str, tuple[float, int]] = {}
    for nm in dict.fromkeys(names):
        rows = [j for j, b in enumerate(names) if b == nm]
        out[nm] = (float(np.sum(null[rows] ** 2)) if null.size else 0.0, len(rows))
    return out


def _pinv_sym(G: np.ndarray, tol: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Eigen-decomposition of a symmetric PSD matrix: (values desc, vectors, pseudo-inverse, rank).

    Eigenvalues below ``tol`` (default RANK_RTOL^2 times the largest) count as zero.
    """
    lam, V = np.linalg.eigh(G)
    lam, V = lam[::-1], V[:, ::-1]
    if tol is None:
        tol = RANK_RTOL**2 * max(float(lam[0]), 0.0)
    k = int(np.sum(lam > tol))
    pinv = (V[:, :k] / lam[:k]) @ V[:, :k].T
    return lam, V, pinv, k


def _staged_solve(A_L, A_E, y, names_L, names_E):
    """Least squares with the linear errors first, then the angular errors; min-norm gauge.

    Worked on the normal equations of the column-normalised design (p x p matrices, so
    the cost is one product A^T A); the rank threshold RANK_RTOL on singular values is
    RANK_RTOL^2 on these eigenvalues, far above their rounding (~1e-16).
    """
    A = np.hstack([A_L, A_E])
    norms = np.sqrt(np.einsum("ij,ij->j", A, A))
    seen = norms > 0
    scale = np.where(seen, norms, 1.0)
    An = A / scale
    G = An.T @ An
    b = An.T @ y
    nL = A_L.shape[1]
    L, E = slice(0, nL), slice(nL, None)
    lam_L, V_L, G_LL_pinv, k_L = _pinv_sym(G[L, L])
    tol = RANK_RTOL**2 * float(lam_L[0])  # relative to the largest singular value
    undetermined: dict[str, str] = {}
    partly: dict[str, str] = {}
    for nm, (share, size) in _block_shares(V_L[:, k_L:], names_L).items():
        _classify(nm, share, size, "the measured points do not move it independently", undetermined, partly)

    # Angular columns: what the linear errors cannot explain (Schur complement).
    coef_LE = G_LL_pinv @ G[L, E]  # linear parameters reproducing each angular column
    S = G[E, E] - G[E, L] @ coef_LE
    S = (S + S.T) / 2
    lam_E, V_E, S_pinv, k_E = _pinv_sym(S, tol)
    seen_E = seen[E]
    for nm, (share, size) in _block_shares(V_E[:, k_E:], names_E).items():
        rows = [j for j, bname in enumerate(names_E) if bname == nm]
        if not seen_E[rows].any():
            why = "not seen at all: the rotation is about the tool vectors measured (or they are zero)"
        else:
            why = ("indistinguishable at these tool vectors from " + ", ".join(_carriers(coef_LE[:, rows], names_L))
                   + " (measure with other tool vectors to separate them)")
        _classify(nm, share, size, why, undetermined, partly)
    phi_E = S_pinv @ (b[E] - G[E, L] @ (G_LL_pinv @ b[L]))
    phi_L = G_LL_pinv @ (b[L] - G[L, E] @ phi_E)
    kept = np.concatenate([lam_L[:k_L], lam_E[:k_E]])
    analysis = {
        "n_params": A.shape[1],
        "rank": int(k_L + k_E),
        "condition": float(np.sqrt(kept.max() / kept.min())),
        "undetermined": undetermined,
        "partly": partly,
    }
    return phi_L / scale[L], phi_E / scale[E], analysis


def _classify(name, share, size, why, undetermined, partly) -> None:
    if share >= FULLY_UNDETERMINED * size:
        undetermined[name] = why
    elif share >= PARTLY_MIN:
        partly[name] = f"about {share:.0f} of {size} coefficients; {why}" if share >= 1 else (
            f"a combination worth {share:.2f} of {size} coefficients; {why}")


def _carriers(coef: np.ndarray, names_L: list[str]) -> list[str]:
    """The linear-error blocks that carry the given angular columns (by coefficient energy)."""
    energy: dict[str, float] = {}
    for j, nm in enumerate(names_L):
        energy[nm] = energy.get(nm, 0.0) + float(np.sum(coef[j] ** 2))
    total = sum(energy.values()) or 1.0
    top = sorted(((v / total, k) for k, v in energy.items()), reverse=True)
    return [k for share, k in top if share >= 0.1][:3] or ["the linear errors"]
