"""The one rotation formula (postproc.rotation) and the modules that use it.

References are independent of the formula under test: scipy's ``Rotation.from_rotvec``
and the two closed forms the package used before (``sin(t)/t`` and ``(1 - cos t)/t^2``
with their Taylor series below 1e-4 rad), written out here.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation

from postproc.calibration.axis_tables import AXES, AxisTables
from postproc.engine.parametric import ParametricEngine
from postproc.predict import frames
from postproc.rotation import (
    cross,
    matrices_from_rotation_vectors,
    matrix_from_rotation_vector,
    rotate,
)
from postproc.simulate.machine import MachineGeometry


def rotation_vectors(rng, n=60):
    """Machine-sized, tiny, large and zero rotation vectors."""
    return np.vstack([rng.normal(0, 3e-5, (n, 3)), rng.normal(0, 1e-9, (n, 3)),
                      rng.normal(0, 0.7, (n, 3)), np.zeros((2, 3))])


def series_matrices(e):
    """exp([e]x) as I + a K + b K^2 with a Taylor series for small angles (the former
    closed form of predict/frames.py and simulate/machine.py)."""
    t2 = np.sum(e * e, axis=-1)
    t = np.sqrt(t2)
    small = t < 1e-4
    safe = np.where(small, 1.0, t)
    a = np.where(small, 1 - t2 / 6 + t2**2 / 120, np.sin(safe) / safe)
    b = np.where(small, 0.5 - t2 / 24 + t2**2 / 720, (1 - np.cos(safe)) / safe**2)
    k = np.zeros(e.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2] = -e[..., 2], e[..., 1]
    k[..., 1, 0], k[..., 1, 2] = e[..., 2], -e[..., 0]
    k[..., 2, 0], k[..., 2, 1] = -e[..., 1], e[..., 0]
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def test_rotate_matches_scipy_and_the_series_form():
    rng = np.random.default_rng(1)
    eps = rotation_vectors(rng)
    r = rng.normal(0, 100, (len(eps), 3))
    got = rotate(eps, r)
    assert_allclose(got, Rotation.from_rotvec(eps).apply(r), rtol=0, atol=1e-12)
    assert_allclose(got, np.einsum("nij,nj->ni", series_matrices(eps), r), rtol=0, atol=1e-12)
    assert_allclose(rotate(np.zeros((3, 3)), r[:3]), r[:3], rtol=0, atol=0)


def test_matrices_match_scipy_in_batches_of_any_shape():
    rng = np.random.default_rng(2)
    e = rotation_vectors(rng, 20).reshape(2, -1, 3)
    m = matrices_from_rotation_vectors(e)
    assert m.shape == e.shape[:-1] + (3, 3)
    assert_allclose(m.reshape(-1, 3, 3), Rotation.from_rotvec(e.reshape(-1, 3)).as_matrix(), rtol=0, atol=1e-15)
    assert_allclose(m, series_matrices(e), rtol=0, atol=1e-15)
    one = matrix_from_rotation_vector(e[1, 5])
    assert one.shape == (3, 3)
    assert_allclose(one, m[1, 5], rtol=0, atol=0)
    with pytest.raises(ValueError, match="shape"):
        matrix_from_rotation_vector(e[0])


def test_matrices_and_rotate_agree():
    rng = np.random.default_rng(3)
    eps = rotation_vectors(rng)
    r = rng.normal(0, 100, (len(eps), 3))
    assert_allclose(np.einsum("nij,nj->ni", matrices_from_rotation_vectors(eps), r), rotate(eps, r),
                    rtol=0, atol=1e-12)


def test_cross_is_numpys():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(2, 50, 3))
    assert_allclose(cross(a, b), np.cross(a, b), rtol=0, atol=1e-15)


def angle_tables(rng):
    """Axis tables with angular errors only (up to a milliradian), linear columns zero."""
    x = np.linspace(0.0, 300.0, 31)
    errors = {}
    for ax in AXES:
        e = np.zeros((len(x), 6))
        e[:, 3:] = rng.normal(0, 1e-3, (len(x), 3))
        errors[ax] = e
    return AxisTables({ax: x for ax in AXES}, errors)


def test_engine_machine_and_frames_rotate_a_tool_vector_alike():
    # The same angular errors through the three users of the rotation: the parametric
    # engine (order exact), the virtual machine (finite rotation) and the exact error
    # matrix of predict; each against scipy applied to the summed angles.
    rng = np.random.default_rng(5)
    tables = angle_tables(rng)
    q = rng.uniform(0, 300, (100, 3))
    r = np.array([30.0, -20.0, -150.0])
    eps = sum(np.column_stack([np.interp(q[:, i], tables.position_mm[ax], tables.errors[ax][:, k])
                               for k in range(3, 6)]) for i, ax in enumerate(AXES))
    expected = q + Rotation.from_rotvec(eps).apply(r)
    engine = ParametricEngine(tables, interpolation="linear", order="exact")
    machine = MachineGeometry(tables, {}, tables.volume_mm, rotation="finite")
    assert_allclose(engine.forward(q, r), expected, rtol=0, atol=1e-11)
    assert_allclose(machine.forward(q, r), expected, rtol=0, atol=1e-11)
    m = frames.exact_error_matrix(0.0, 0.0, 0.0, eps[:, 0], eps[:, 1], eps[:, 2])
    assert_allclose(q + frames.apply(m, r), expected, rtol=0, atol=1e-11)
    assert_allclose(frames.rodrigues(*eps.T), Rotation.from_rotvec(eps).as_matrix(), rtol=0, atol=1e-15)
