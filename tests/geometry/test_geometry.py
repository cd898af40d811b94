"""The shared helpers: distance along the path, a label's end, mirroring, exact solves, against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.geometry.path import distance_along, label_end, mirror, path_length


def test_distance_along_positions_and_poses():
    positions = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 4.0], [3.0, 0.0, 4.0], [3.0, 12.0, 9.0]])  # 5 m, 0 m, 13 m
    np.testing.assert_allclose(distance_along(positions), [0.0, 5.0, 5.0, 18.0])
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, :3, 3] = positions
    np.testing.assert_allclose(distance_along(poses), [0.0, 5.0, 5.0, 18.0])
    assert path_length(poses) == pytest.approx(18.0)


def test_a_label_ends_at_the_first_frame_farther_than_its_distance_in_a_straight_line():
    line = np.c_[np.zeros(30), np.zeros(30), np.arange(30.0)]  # 1 m apart
    assert label_end(line, 0, 20.0) == 21 and label_end(line, 5, 20.0) == 26  # 21 m > 20; exactly 20 m is not beyond
    assert label_end(line, 9, 20.0) is None  # frame 29 is 20 m ahead: no frame beyond
    u_turn = np.c_[np.r_[np.zeros(15), np.full(15, 3.0)], np.zeros(30), np.r_[np.arange(15.0), np.arange(14.0, -1, -1)]]
    assert label_end(u_turn, 0, 20.0) is None  # 28 m driven, never 20 m away


def test_mirror_flips_left_right_and_is_contiguous():
    image = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    flipped = mirror(image)
    assert flipped.flags.c_contiguous and np.array_equal(flipped[:, 0], image[:, 3])
    assert np.array_equal(mirror(flipped), image)


def test_the_blas_free_solve_and_power_agree_with_numpys():
    """geometry.exact.solve and power (the odometry's, without BLAS) against LAPACK's and matrix_power."""
    from offroad_path.geometry.exact import power, solve

    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6)) + 6 * np.eye(6)
    b = rng.normal(size=6)
    np.testing.assert_allclose(solve(a, b), np.linalg.solve(a, b), rtol=1e-12, atol=1e-12)
    swapped = np.array([[0.0, 2.0], [3.0, 1.0]])  # a zero pivot: the rows must be exchanged
    np.testing.assert_allclose(solve(swapped, np.array([4.0, 5.0])), [1.0, 2.0])
    with pytest.raises(np.linalg.LinAlgError):
        solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.array([1.0, 1.0]))
    t = np.eye(4)
    t[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    t[:3, 3] = [1.0, 2.0, 0.5]
    np.testing.assert_allclose(power(t, 5), np.linalg.matrix_power(t, 5), atol=1e-12)
    np.testing.assert_array_equal(power(t, 0), np.eye(4))
