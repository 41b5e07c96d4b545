"""Small least-squares helper shared by the effects and the diagnostics.

The problems here are tall and thin (3N rows, 1-30 columns) and solved thousands of
times in a cross-validated ranking. A multithreaded SVD (``numpy.linalg.lstsq``) on
them costs milliseconds in thread start-up alone; the normal equations of the
column-scaled matrix cost microseconds. With unit-norm columns the condition number
of ``A^T A`` is that of ``A`` squared, which for these designs (affine terms and a
few effect shapes) stays below ~1e8, far inside double precision; a rank-deficient
design (an effect the model already holds) gets the minimum-norm solution.
"""

from __future__ import annotations

import numpy as np

# Relative cut-off for singular values of the scaled normal matrix: below this a
# direction is not determined by the data (the squared condition number limit of
# double precision is ~1e16; 1e-12 leaves four orders of margin).
NORMAL_RCOND = 1e-12


def solve_ls(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``y`` (rows,) or (rows, m) on the columns of ``A``."""
    if A.shape[1] == 0:
        return np.zeros((0,) + y.shape[1:])
    norms = np.linalg.norm(A, axis=0)
    norms[norms == 0] = 1.0
    As = A / norms
    coef = np.linalg.lstsq(As.T @ As, As.T @ y, rcond=NORMAL_RCOND)[0]
    return coef / (norms if coef.ndim == 1 else norms[:, None])
