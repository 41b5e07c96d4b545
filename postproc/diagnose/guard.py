"""Identifiability guard for joint fits of effects: conditioning, undetermined
parameter directions (regularised to zero, named), and k=2 uncertainties.

The effect columns ``E`` (3N, k) enter a fit beside a base that can absorb part of
them. What the data determine of the effects is the part the base cannot absorb:
``P E`` (the columns made orthogonal to the base's span, or, for a base refitted
through its fitter, the fitter's residual response to each column). Each column is
scaled by the norm of the raw effect column, so a singular value of the scaled
matrix is the fraction of an effect shape that remains visible beside the base. A
direction with a fraction below ``VISIBLE_FRACTION`` is not determined by the data:
noise along it is amplified more than ``1 / VISIBLE_FRACTION`` times, and the base
and the effect trade it freely (a bow of metres balanced by an alignment of
radians). Such directions are set to zero (truncated SVD: the minimum-norm solution
in the effect's own units) and the parameters loading on them are named.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# A parameter direction whose displacement stays visible beside the base by less than
# this fraction of its size is undetermined: its noise is amplified 20 times or more.
VISIBLE_FRACTION = 0.05
# A parameter is named as taking part in an undetermined direction when its share of
# that direction (squared loading of the unit singular vector) exceeds this.
NAMED_LOADING = 0.1
# Coverage factor of the reported uncertainties (about 95 %).
K_COVERAGE = 2.0


@dataclass
class Guard:
    """What a joint fit could determine."""

    condition: float = 1.0  # of the scaled, base-projected effect columns
    min_visible: float = 1.0  # smallest visible fraction of an effect direction
    undetermined: list[str] = field(default_factory=list)  # parameter names set toward zero
    u_k2: np.ndarray | None = None  # (k,) expanded uncertainty of each effect parameter

    def to_json(self) -> dict:
        return {"condition_number": float(self.condition), "min_visible_fraction": float(self.min_visible),
                "undetermined": list(self.undetermined)}

    def lines(self, names: list[str] | None = None) -> list[str]:
        out = [f"conditioning of the effect parameters: condition number {self.condition:.3g}, "
               f"smallest visible fraction {self.min_visible:.3g}"]
        if self.undetermined:
            out.append("not determined by these data beside the base model (set to zero, not invented): "
                       + ", ".join(self.undetermined))
        return out


def guarded_solve(P: np.ndarray, y: np.ndarray, raw_norms: np.ndarray, names: list[str],
                  dof: int | None = None) -> tuple[np.ndarray, Guard]:
    """Coefficients of ``y`` on the visible effect columns ``P`` (3N, k) with undetermined
    directions set to zero. ``raw_norms`` (k,) are the norms of the raw effect columns;
    ``dof`` the residual degrees of freedom for the uncertainty (default 3N - k)."""
    k = P.shape[1]
    if k == 0:
        return np.zeros(0), Guard(u_k2=np.zeros(0))
    scale = np.where(raw_norms > 0, raw_norms, 1.0)
    Ps = P / scale
    # singular values and right vectors from the small Gram matrix (k x k): the tall SVD
    # costs far more, and the cut-off (s >= 0.05, s^2 >= 2.5e-3) is far above rounding
    w, V = np.linalg.eigh(Ps.T @ Ps)
    order = np.argsort(-w)
    w, V = np.maximum(w[order], 0.0), V[:, order]
    s = np.sqrt(w)
    Vt = V.T
    keep = s >= VISIBLE_FRACTION
    coef_s = Vt[keep].T @ ((Vt[keep] @ (Ps.T @ y)) / w[keep])
    coef = coef_s / scale
    undetermined: list[str] = []
    for i in np.nonzero(~keep)[0]:
        for j in np.nonzero(Vt[i] ** 2 > NAMED_LOADING)[0]:
            if names[j] not in undetermined:
                undetermined.append(names[j])
    for j in np.nonzero(raw_norms == 0)[0]:
        if names[j] not in undetermined:
            undetermined.append(names[j])
    resid = y - P @ coef
    n_dof = dof if dof is not None else len(y) - int(keep.sum())
    sigma2 = float(resid @ resid) / max(n_dof, 1)
    cov_s = (Vt[keep].T / s[keep] ** 2) @ Vt[keep]
    u = K_COVERAGE * np.sqrt(np.maximum(np.diag(cov_s), 0.0) * sigma2) / scale
    u[[names.index(n) for n in undetermined]] = np.nan  # not determined: no uncertainty to give
    smin = float(s.min()) if len(s) else 1.0
    cond = float(s.max() / smin) if smin > 0 else float("inf")
    return coef, Guard(cond, smin, undetermined, u)
