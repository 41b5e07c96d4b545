"""Homogeneous 4x4 transforms, small-angle error matrices and frames from points.

Convention (seed 002, ``M_Ci``): a module matrix maps coordinates given in the
*next* (child) frame to coordinates in the *current* (parent) frame; its columns are
the child's unit axes and origin expressed in the parent. Chains are multiplied from
the workpiece to the tool, ``r_workpiece = M_1 M_2 ... M_m r_tool``.

Seed 004 writes the opposite direction, ``[M]_{i-1,i}`` (formula 2): rows are the
direction cosines of the new axes, the translation is ``-W b`` (formula 17), and it
maps old coordinates to new ones. :func:`direct_from_points` gives that matrix;
:func:`pose_from_points` its inverse, the seed-002 form used in chains.

Every function is vectorised: scalar parameters may be arrays of any common shape
``S`` and the result has shape ``S + (4, 4)``.
"""

from __future__ import annotations

import numpy as np

from postproc.errors import PostprocError
from postproc.rotation import matrices_from_rotation_vectors

# Three frame points closer to a line than this (twice the triangle's area over the
# square of its longest side) do not define a plane; a real base triangle on a machine
# part has a ratio of order 1, a numerically collinear one 1e-12.
COLLINEAR_RATIO = 1e-9

# A rotation block whose R R^T differs from I by less than this is treated as rigid and
# inverted by transposition; the small-angle matrix of seed 002 (off by angle**2, 1e-8
# for 1e-4 rad) is not, and goes through the general inverse.
ORTHONORMAL_TOL = 1e-12

_AXES = {"x": 0, "y": 1, "z": 2}


def axis_index(axis: str) -> int:
    """``"x"|"y"|"z"`` (any case) -> 0, 1, 2."""
    try:
        return _AXES[str(axis).lower()]
    except KeyError:
        raise PostprocError(f"axis must be x, y or z, got {axis!r}") from None


def _shape(*values) -> tuple:
    return np.broadcast_shapes(*(np.shape(v) for v in values))


def identity(shape: tuple = ()) -> np.ndarray:
    """Identity transforms of shape ``shape + (4, 4)``."""
    return np.broadcast_to(np.eye(4), tuple(shape) + (4, 4)).copy()


def translation(dx, dy, dz) -> np.ndarray:
    """Pure translation by (dx, dy, dz) mm (each scalar or array)."""
    shape = _shape(dx, dy, dz)
    m = identity(shape)
    m[..., 0, 3] = dx
    m[..., 1, 3] = dy
    m[..., 2, 3] = dz
    return m


def translation_along(direction, distance) -> np.ndarray:
    """Translation by ``distance`` (scalar or array) along a 3-vector ``direction``."""
    d = np.asarray(direction, dtype=float)
    s = np.asarray(distance, dtype=float)
    return translation(s * d[0], s * d[1], s * d[2])


def rotation(axis: str, angle_rad) -> np.ndarray:
    """Rotation by ``angle_rad`` about the x, y or z axis (right hand, counter-clockwise)."""
    i = axis_index(axis)
    a = np.asarray(angle_rad, dtype=float)
    c, s = np.cos(a), np.sin(a)
    m = identity(a.shape)
    j, k = (i + 1) % 3, (i + 2) % 3
    m[..., j, j] = c
    m[..., k, k] = c
    m[..., j, k] = -s
    m[..., k, j] = s
    return m


def small_angle_matrix(u, v, w, alpha, beta, gamma) -> np.ndarray:
    """Seed 002's error matrix ``M_D``: translations u, v, w and small angles.

    ::

        | 1     -gamma  beta   u |
        | gamma  1     -alpha  v |
        | -beta  alpha  1      w |
        | 0      0      0      1 |

    It is the first-order expansion of :func:`exact_error_matrix`; applied to a tool
    vector it gives exactly the first-order formula ``r + rho + eps x r``.
    """
    shape = _shape(u, v, w, alpha, beta, gamma)
    m = identity(shape)
    m[..., 0, 1] = -np.asarray(gamma)
    m[..., 0, 2] = beta
    m[..., 1, 0] = gamma
    m[..., 1, 2] = -np.asarray(alpha)
    m[..., 2, 0] = -np.asarray(beta)
    m[..., 2, 1] = alpha
    m[..., 0, 3] = u
    m[..., 1, 3] = v
    m[..., 2, 3] = w
    return m


def rodrigues(alpha, beta, gamma) -> np.ndarray:
    """Finite rotation ``exp([e]x)`` for the rotation vector ``e = (alpha, beta, gamma)``."""
    e = np.stack(np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (alpha, beta, gamma))), axis=-1)
    return matrices_from_rotation_vectors(e)


def exact_error_matrix(u, v, w, alpha, beta, gamma) -> np.ndarray:
    """Error transform with the finite rotation ``exp([e]x)`` instead of the small-angle one."""
    shape = _shape(u, v, w, alpha, beta, gamma)
    m = identity(shape)
    m[..., :3, :3] = rodrigues(*np.broadcast_arrays(alpha, beta, gamma))
    m[..., 0, 3] = u
    m[..., 1, 3] = v
    m[..., 2, 3] = w
    return m


def invert(m) -> np.ndarray:
    """Inverse of rigid transforms (rotation part orthonormal); general inverse otherwise."""
    m = np.asarray(m, dtype=float)
    rot = m[..., :3, :3]
    if np.allclose(rot @ np.swapaxes(rot, -1, -2), np.eye(3), atol=ORTHONORMAL_TOL):
        out = identity(m.shape[:-2])
        rt = np.swapaxes(rot, -1, -2)
        out[..., :3, :3] = rt
        out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, m[..., :3, 3])
        return out
    return np.linalg.inv(m)


def apply(m, points) -> np.ndarray:
    """Apply transforms ``m`` (..., 4, 4) to points (..., 3); shapes broadcast."""
    m = np.asarray(m, dtype=float)
    pts = np.asarray(points, dtype=float)
    return np.einsum("...ij,...j->...i", m[..., :3, :3], pts) + m[..., :3, 3]


def _unit(v, what: str) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise PostprocError(f"{what}: zero-length vector")
    return v / n


def pose_from_points(pi, pj, pk) -> np.ndarray:
    """Frame on the triangle (i, j, k) as a child-to-parent transform (seed 004, 10-16).

    Origin at ``i``; x along ``i -> j`` (formulas 10-12); z normal to the triangle,
    ``(j - i) x (k - i)`` (formulas 13-15); y = z x x (formula 16). Points are given
    in the parent frame, shape (..., 3). The columns of the result are x, y, z and i.
    """
    pi, pj, pk = np.broadcast_arrays(*(np.asarray(p, dtype=float) for p in (pi, pj, pk)))
    vij = pj - pi
    vik = pk - pi
    normal = np.cross(vij, vik)
    twice_area = np.linalg.norm(normal, axis=-1)
    longest = np.max(
        np.stack([np.linalg.norm(vij, axis=-1), np.linalg.norm(vik, axis=-1), np.linalg.norm(pk - pj, axis=-1)]),
        axis=0,
    )
    if np.any(twice_area <= COLLINEAR_RATIO * longest**2):
        raise PostprocError(
            "frame points are collinear: three points on a line do not define a frame",
            hint="choose i, j, k as corners of a triangle on the base surface",
        )
    ex = _unit(vij, "frame x axis")
    ez = normal / twice_area[..., None]
    ey = np.cross(ez, ex)
    shape = np.broadcast_shapes(ex.shape, pi.shape)[:-1]
    m = identity(shape)
    m[..., :3, 0] = ex
    m[..., :3, 1] = ey
    m[..., :3, 2] = ez
    m[..., :3, 3] = pi
    return m


def direct_from_points(pi, pj, pk) -> np.ndarray:
    """Seed 004's ``[M]_{i-1,i}`` (formula 2): parent coordinates -> triangle-frame coordinates.

    Rows are the direction cosines of the new axes; the translation column is
    ``-W b`` with ``b`` the new origin in the old frame (formula 17).
    """
    return invert(pose_from_points(pi, pj, pk))


def fit_plane(xy, z) -> np.ndarray:
    """Least-squares plane ``z = b0 + b1 x + b2 y`` (seed 004, formulas 18-22).

    ``xy``: (k, 2) node coordinates (k >= 3, not collinear); ``z``: (..., k) heights,
    e.g. one row per Monte-Carlo draw. Returns ``b`` of shape (..., 3):
    ``b = (C^T C)^-1 C^T Z`` with ``C = [1, x, y]``, solved by a pseudo-inverse.
    """
    xy = np.asarray(xy, dtype=float)
    z = np.asarray(z, dtype=float)
    if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 3:
        raise PostprocError(f"plane nodes: expected shape (k >= 3, 2), got {xy.shape}")
    if z.shape[-1] != xy.shape[0]:
        raise PostprocError(f"plane heights: expected {xy.shape[0]} values per plane, got {z.shape[-1]}")
    c = np.column_stack([np.ones(len(xy)), xy])
    if np.linalg.matrix_rank(c) < 3:
        raise PostprocError("plane nodes are collinear", hint="give corner points of a rectangle")
    return z @ np.linalg.pinv(c).T


def plane_height(b, x, y) -> np.ndarray:
    """Height of plane(s) ``b`` (..., 3) at (x, y)."""
    b = np.asarray(b, dtype=float)
    return b[..., 0] + b[..., 1] * x + b[..., 2] * y


def pose_on_plane(b, xy_frame) -> np.ndarray:
    """Frame on plane(s) ``b`` built from three of its points above ``xy_frame`` (3, 2).

    The points ``(x, y, z(x, y))`` are the triangle of :func:`pose_from_points`.
    """
    xy_frame = np.asarray(xy_frame, dtype=float)
    if xy_frame.shape != (3, 2):
        raise PostprocError(f"plane frame nodes: expected shape (3, 2), got {xy_frame.shape}")
    pts = []
    for x, y in xy_frame:
        h = plane_height(b, x, y)
        pts.append(np.stack(np.broadcast_arrays(np.full_like(h, x), np.full_like(h, y), h), axis=-1))
    return pose_from_points(*pts)
