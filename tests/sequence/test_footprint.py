"""Footprint projection against pixel coordinates computed by hand."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from offroad_path.sequence.footprint import (
    Occlusion,
    VehicleFootprint,
    clip_near,
    footprint_depth,
    path_label,
    path_mask,
    project,
    swept_polygons,
)

K = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
SIZE = (100, 80)
CAR = VehicleFootprint(width_m=2.0, front_m=1.0, rear_m=-1.0, camera_height_m=1.0)


def pose(x: float = 0.0, z: float = 0.0, yaw_deg: float = 0.0) -> np.ndarray:
    """Camera-to-world: at (x, 0, z), heading turned yaw_deg from +z toward +x."""
    c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    out = np.eye(4)
    out[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    out[:3, 3] = (x, 0, z)
    return out


def test_straight_ahead_corners_project_where_computed_by_hand():
    poses = np.array([pose(), pose(z=4.0)])
    (quad,) = swept_polygons(poses, 0, 1, CAR)
    # Frame 1's footprint spans z = 3..5, x = -1..1, one metre below the camera.
    np.testing.assert_allclose(quad, [[-1, 1, 3], [1, 1, 3], [1, 1, 5], [-1, 1, 5]])
    # u = 100 x / z + 50, v = 100 * 1 / z + 40
    np.testing.assert_allclose(project(K, quad), [[50 - 100 / 3, 40 + 100 / 3], [50 + 100 / 3, 40 + 100 / 3], [70, 60], [30, 60]])
    mask = path_mask(footprint_depth(swept_polygons(poses, 0, 1, CAR), K, SIZE))
    assert mask[65, 50] == 255 and mask[61, 35] == 255  # inside the trapezoid
    assert mask[65, 10] == 0 and mask[58, 50] == 0 and mask[40, 50] == 0  # beside it, beyond it, at the horizon
    camera = SimpleNamespace(calibration=SimpleNamespace(K=K), image_size=SIZE)  # what path_label reads of a sequence
    assert np.array_equal(path_label(camera, poses, (0, 1), CAR), mask)


def test_a_turn_carries_the_footprint_round():
    # Frame 1 at z = 5 heading +x (a right turn of 90 degrees).
    poses = np.array([pose(), pose(z=5.0, yaw_deg=90.0)])
    (quad,) = swept_polygons(poses, 0, 1, CAR)
    # The vehicle's front-left corner (-1, 1, +1) in its own frame is at x = +1, z = 6 in f0's.
    np.testing.assert_allclose(quad[3], [1.0, 1.0, 6.0], atol=1e-12)
    np.testing.assert_allclose(project(K, quad[3:]), [[50 + 100 / 6, 40 + 100 / 6]])


def test_swept_area_closes_the_gaps_of_a_turn():
    poses = np.array([pose()] + [pose(x=0.3 * k * k, z=2.0 * k, yaw_deg=15.0 * k) for k in range(1, 4)])
    polygons = swept_polygons(poses, 0, 3, CAR)
    assert len(polygons) == 3 + 2 * 2  # three footprints, two edge sweeps between each pair
    with_sweeps = path_mask(footprint_depth(swept_polygons(poses, 0, 3, CAR), K, SIZE))
    frames_only = np.zeros_like(with_sweeps)
    frames_only[np.isfinite(footprint_depth(polygons[:3], K, SIZE))] = 255
    assert np.all(with_sweeps >= frames_only)
    assert (with_sweeps > frames_only).sum() > 0  # the corners between rotated rectangles


def test_footprint_partly_behind_the_camera_is_clipped_not_mirrored():
    square = np.array([[-1, 1, -1.0], [1, 1, -1.0], [1, 1, 3.0], [-1, 1, 3.0]])
    clipped = clip_near(square, near=0.3)
    assert clipped[:, 2].min() == pytest.approx(0.3) and clipped[:, 2].max() == 3.0
    assert len(clipped) == 4
    # A long vehicle at f0's own place reaches 1 m behind the camera and 3 m ahead; the bottom
    # image row sees the ground at z = 100 / 39 = 2.56 m, so rows 73 to 79 show its front.
    long = VehicleFootprint(width_m=2.0, front_m=3.0, rear_m=-1.0, camera_height_m=1.0)
    mask = path_mask(footprint_depth(swept_polygons(np.array([pose(), pose(z=0.0)]), 0, 1, long), K, SIZE))
    assert mask[79, 50] == 255 and mask[74, 50] == 255 and mask[72, 50] == 0
    assert not mask[:41].any()  # nothing mirrored up above the horizon
    assert clip_near(square - [0, 0, 5]).shape == (0, 3)  # wholly behind: nothing at all


def test_occlusion_removes_footprint_behind_a_crest():
    poses = np.array([pose()] + [pose(z=float(z)) for z in range(1, 21)])
    measured = np.zeros((80, 100), np.float32)  # unknown depth everywhere keeps the whole label
    full = path_mask(footprint_depth(swept_polygons(poses, 0, 20, CAR), K, SIZE), Occlusion(measured, 1.0, 0.1))
    # A wall at 6 m across the whole view: footprint beyond 6 * 1.1 + 1 = 7.6 m is hidden.
    measured[:, :] = 6.0
    occluded = path_mask(footprint_depth(swept_polygons(poses, 0, 20, CAR), K, SIZE), Occlusion(measured, 1.0, 0.1))
    v_at = {z: round(100 / z + 40) for z in (5, 10)}
    assert full[v_at[10], 50] == 255 and occluded[v_at[10], 50] == 0
    assert occluded[v_at[5], 50] == 255
    assert np.array_equal(path_mask(footprint_depth(swept_polygons(poses, 0, 20, CAR), K, SIZE)), full)
