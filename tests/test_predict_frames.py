"""Hand-computed transforms: translations, rotations, error matrices, frames, planes."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.errors import PostprocError
from postproc.predict import frames


def test_translation_and_rotations_move_points_as_by_hand():
    assert_allclose(frames.apply(frames.translation(1, -2, 3), [10, 20, 30]), [11, 18, 33])
    q = np.pi / 2
    assert_allclose(frames.apply(frames.rotation("z", q), [1, 0, 0]), [0, 1, 0], atol=1e-15)
    assert_allclose(frames.apply(frames.rotation("x", q), [0, 1, 0]), [0, 0, 1], atol=1e-15)
    assert_allclose(frames.apply(frames.rotation("y", q), [0, 0, 1]), [1, 0, 0], atol=1e-15)
    # 30 degrees about z: (2, 0, 5) -> (2 cos 30, 2 sin 30, 5) = (sqrt 3, 1, 5)
    assert_allclose(frames.apply(frames.rotation("z", np.pi / 6), [2, 0, 5]), [np.sqrt(3), 1, 5])


def test_transforms_are_vectorised_over_parameters():
    angles = np.linspace(0, 2 * np.pi, 7)
    m = frames.rotation("z", angles)
    assert m.shape == (7, 4, 4)
    pts = frames.apply(m, [3.0, 0, 0])
    assert_allclose(pts[:, 0], 3 * np.cos(angles), atol=1e-14)
    assert_allclose(pts[:, 1], 3 * np.sin(angles), atol=1e-14)


def test_small_angle_matrix_is_the_first_order_formula():
    u, v, w, a, b, g = 0.01, -0.02, 0.005, 3e-5, -7e-5, 4e-5
    r = np.array([30.0, -20.0, -100.0])
    p = frames.apply(frames.small_angle_matrix(u, v, w, a, b, g), r)
    assert_allclose(p, r + [u, v, w] + np.cross([a, b, g], r), rtol=0, atol=1e-13)


def test_exact_error_matrix_is_a_rotation_and_differs_from_small_angle_at_second_order():
    r = np.array([30.0, -20.0, -100.0])
    diffs = []
    for scale in (1e-4, 2e-4):
        e = scale * np.array([1.0, -0.5, 0.8])
        exact = frames.exact_error_matrix(0, 0, 0, *e)
        rot = exact[:3, :3]
        assert_allclose(rot @ rot.T, np.eye(3), atol=1e-15)
        assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-15)
        # second-order term of exp([e]x) r is 0.5 e x (e x r)
        d = frames.apply(exact, r) - frames.apply(frames.small_angle_matrix(0, 0, 0, *e), r)
        assert_allclose(d, 0.5 * np.cross(e, np.cross(e, r)), rtol=1e-3)
        diffs.append(np.linalg.norm(d))
    assert diffs[1] / diffs[0] == pytest.approx(4.0, rel=1e-3)
    # a single-axis finite rotation is the plain rotation matrix, also for large angles
    assert_allclose(frames.exact_error_matrix(0, 0, 0, 0, 0, 0.7), frames.rotation("z", 0.7), atol=1e-15)
    assert_allclose(frames.exact_error_matrix(0, 0, 0, 0, 1e-6, 0), frames.rotation("y", 1e-6), atol=1e-18)


def test_frame_from_a_known_triangle():
    # i at the origin, j on +y, k on -x: x = +y, z = x cross (k - i) = +z, y = z cross x = -x,
    # i.e. a rotation of 90 degrees about z placed at i.
    i, j, k = np.array([5.0, 6.0, 7.0]), np.array([5.0, 8.0, 7.0]), np.array([4.0, 6.0, 7.0])
    pose = frames.pose_from_points(i, j, k)
    expected = frames.translation(5, 6, 7) @ frames.rotation("z", np.pi / 2)
    assert_allclose(pose, expected, atol=1e-15)
    # seed 004 direct transform (formula 2, 17): old -> new coordinates
    direct = frames.direct_from_points(i, j, k)
    assert_allclose(frames.apply(direct, j), [2, 0, 0], atol=1e-15)
    assert_allclose(frames.apply(direct, k), [0, 1, 0], atol=1e-15)
    assert_allclose(direct[:3, 3], -direct[:3, :3] @ i)  # formula 17: -W b
    assert_allclose(direct[:3, :3], pose[:3, :3].T)  # formula 6: W_{i-1,i} = W_{i,i-1}^T


def test_frame_from_a_tilted_triangle_has_the_triangle_normal_as_z():
    i, j, k = np.array([0.0, 0, 0]), np.array([3.0, 0, 4.0]), np.array([0.0, 2.0, 0])
    pose = frames.pose_from_points(i, j, k)
    assert_allclose(pose[:3, 0], [0.6, 0, 0.8])  # formula 11: (j - i) / l_ij, l_ij = 5
    assert_allclose(pose[:3, 2], [-0.8, 0, 0.6])  # formulas 13-15: (j - i) x (k - i) / 2 Delta
    assert_allclose(pose[:3, 1], [0, 1, 0], atol=1e-15)  # formula 16


def test_collinear_points_are_refused():
    with pytest.raises(PostprocError, match="collinear"):
        frames.pose_from_points([0, 0, 0], [1, 1, 1], [2, 2, 2])


def test_least_squares_plane_through_corner_points():
    nodes = np.array([[0, 0], [500, 0], [0, 400], [500, 400]], dtype=float)
    # seed 004 table 1: T at x = 0, 0 at x = L -> z = T - T x / L
    t = 0.05
    b = frames.fit_plane(nodes, [t, 0, t, 0])
    assert_allclose(b, [t, -t / 500, 0], atol=1e-15)
    # four points not on a plane: the least-squares solution of formula (19)
    z = np.array([0.01, 0.03, 0.02, 0.05])
    c = np.column_stack([np.ones(4), nodes])
    assert_allclose(frames.fit_plane(nodes, z), np.linalg.solve(c.T @ c, c.T @ z), rtol=1e-12)
    # vectorised over draws
    zs = np.random.default_rng(0).uniform(0, t, (10, 4))
    assert frames.fit_plane(nodes, zs).shape == (10, 3)
    with pytest.raises(PostprocError, match="collinear"):
        frames.fit_plane([[0, 0], [1, 1], [2, 2]], [0, 0, 0])


def test_frame_on_a_plane_has_the_plane_normal_as_z():
    b = np.array([0.02, 1e-4, -2e-4])
    pose = frames.pose_on_plane(b, [[0, 0], [500, 0], [0, 400]])
    normal = np.array([-b[1], -b[2], 1.0]) / np.linalg.norm([-b[1], -b[2], 1.0])
    assert_allclose(pose[:3, 2], normal, atol=1e-15)
    assert_allclose(pose[:3, 3], [0, 0, 0.02])
    # a point of the plane frame on its x-y plane lies on the fitted plane
    p = frames.apply(pose, [120.0, 80.0, 0.0])
    assert p[2] == pytest.approx(frames.plane_height(b, p[0], p[1]), abs=1e-12)
