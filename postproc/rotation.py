"""Finite rotations given by rotation vectors: the one rotation formula of the package.

A rotation vector ``e`` (rad) is the axis times the angle ``theta = |e|``. Its
rotation is ``R(e) = exp([e]x)``, written with the Rodrigues-Hamilton (Euler-Rodrigues)
parameters ``lambda0 = cos(theta/2)`` and ``lambda = sin(theta/2) e / theta``::

    R r = r + 2 lambda0 (lambda x r) + 2 lambda x (lambda x r)
    R   = I + 2 lambda0 [lambda]x + 2 [lambda]x^2

``sin(theta/2) / theta`` is taken from ``numpy.sinc``, which is exact at 0 and keeps
every digit for the micro-radian angles of machine errors, so no small-angle series
and no threshold are needed.

:func:`rotate` applies the rotations to vectors row by row (the engines' hot path: no
3x3 matrix is built); :func:`matrix_from_rotation_vector` gives one matrix and
:func:`matrices_from_rotation_vectors` its batch variant. The first-order rotation of
the error models is ``r + e x r``, with the row-wise :func:`cross`.
"""

from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (faster than np.cross for 3-vectors)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
                     a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _hamilton(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lambda0 (...), lambda (..., 3)) of rotation vectors e (..., 3)."""
    theta = np.linalg.norm(e, axis=-1)
    lam0 = np.cos(theta / 2)
    lam = 0.5 * np.sinc(theta / (2 * np.pi))[..., None] * e  # sin(theta/2)/theta * e
    return lam0, lam


def rotate(eps: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``R(eps_i) r_i`` for rotation vectors ``eps`` (N, 3) and vectors ``r`` (N, 3)."""
    lam0, lam = _hamilton(np.asarray(eps, dtype=float))
    lr = cross(lam, r)
    return r + 2 * lam0[:, None] * lr + 2 * cross(lam, lr)


def matrices_from_rotation_vectors(e) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of rotation vectors ``e`` (..., 3)."""
    e = np.asarray(e, dtype=float)
    if e.shape[-1:] != (3,):
        raise ValueError(f"rotation vectors: expected shape (..., 3), got {e.shape}")
    lam0, lam = _hamilton(e)
    k = np.zeros(e.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2] = -lam[..., 2], lam[..., 1]
    k[..., 1, 0], k[..., 1, 2] = lam[..., 2], -lam[..., 0]
    k[..., 2, 0], k[..., 2, 1] = -lam[..., 1], lam[..., 0]
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + 2 * lam0[..., None, None] * k + 2 * (k @ k)


def matrix_from_rotation_vector(e) -> np.ndarray:
    """The rotation matrix (3, 3) of one rotation vector ``e`` (3,)."""
    e = np.asarray(e, dtype=float)
    if e.shape != (3,):
        raise ValueError(f"rotation vector: expected shape (3,), got {e.shape}")
    return matrices_from_rotation_vectors(e)
