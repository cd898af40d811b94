"""The rectified calibration ingest writes: OpenCV's definition, without its float32 rounding."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from offroad_path.recordings.rectify import Rectifier, rectified_projections
from offroad_path.recordings.rig_calibration import CameraModel, StereoRig

KITTI_K = np.array([[718.856, 0.0, 607.1928], [0.0, 718.856, 185.2157], [0.0, 0.0, 1.0]])
KITTI_SIZE = (1241, 376)


def test_a_rig_already_rectified_keeps_its_calibration_to_the_last_digit():
    """KITTI's rectified cameras through ingest's rectification at their own size: OpenCV's
    stereoRectify gives fx 718.8560119 and cx, cy rounded to float32 (a 2e-8 change that moved one
    real drive's drift by 0.6 points with the odometry before its robust PnP); the calibration
    written is the one given."""
    camera = CameraModel(KITTI_K, np.zeros(5), KITTI_SIZE)
    rig = StereoRig(camera, camera, np.eye(3), np.array([-0.537, 0.0, 0.0]), Path("kitti.yaml")).checked()
    calibration = Rectifier(rig, KITTI_SIZE, KITTI_SIZE, 0.0).calibration
    assert np.abs(calibration.K - KITTI_K).max() < 1e-11
    assert calibration.baseline_m == pytest.approx(0.537, rel=1e-14)


@pytest.mark.parametrize("alpha", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("output_size", [(1280, 720), (512, 288)])
def test_a_distorted_rig_gets_opencvs_rectification_to_float32_rounding(alpha, output_size):
    """Two cameras with strong radial distortion, turned by a degree against each other: the
    projections agree with cv2.stereoRectify's to the float32 rounding OpenCV's own has (the
    principal point, the valid-pixel scale), at every alpha and at a smaller output size."""
    left = CameraModel(np.array([[700.0, 0, 640], [0, 705, 360], [0, 0, 1]]), np.array([-0.28, 0.09, 0.001, -0.0005, -0.01]), (1280, 720))
    right = CameraModel(np.array([[710.0, 0, 630], [0, 708, 365], [0, 0, 1]]), np.array([-0.27, 0.08, -0.001, 0.0004, -0.01]), (1280, 720))
    R, T = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0], np.array([[-0.12], [0.002], [0.001]])
    R1, R2, P1, P2, *_ = cv2.stereoRectify(
        left.K, left.D, right.K, right.D, (1280, 720), R, T, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha, newImageSize=output_size
    )
    ours = rectified_projections(((left, R1), (right, R2)), R2 @ T, (1280, 720), output_size, alpha)
    for theirs, mine in zip((P1, P2), ours, strict=True):
        assert np.abs(mine - theirs).max() < 1e-6 * abs(theirs[0, 0])
