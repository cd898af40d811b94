"""A pose moves about as little as its calibration did: a change of the intrinsics by 1e-7 of
themselves (a calibration rounded to float32 moves them by about that) must not re-draw it. RANSAC's
discrete choices did; a pose now ends at the minimum of a smooth loss. Rendered drives still move by
up to a few tenths of a point (docs/odometry.md); these bound the PnP and the real snippet."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.odometry.features import FrontEnd
from offroad_path.odometry.perturb import jittered
from offroad_path.odometry.sequence_trajectory import drift, run_odometry
from offroad_path.sequence import open_sequence
from offroad_path.sequence.calibration import StereoCalibration

K = np.array([[700.0, 0.0, 320.0], [0.0, 700.0, 180.0], [0.0, 0.0, 1.0]])


def _rotation(degrees: tuple[float, float, float]) -> np.ndarray:
    return cv2.Rodrigues(np.radians(np.array(degrees, float)))[0]


@pytest.fixture
def scene() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) in the first camera, their pixels (N, 2) in a camera that moved, the true
    transform taking the first camera's frame into the second's): 0.3 px noise, a quarter of the
    tracks wrong by 3 to 30 px."""
    rng = np.random.default_rng(3)
    n = 200
    z = rng.uniform(4.0, 40.0, n)
    xyz = np.stack([(rng.uniform(0, 640, n) - 320) * z / 700, (rng.uniform(0, 360, n) - 180) * z / 700, z], axis=1)
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = _rotation((0.4, -1.5, 0.2)), [0.05, -0.02, -1.0]
    p = xyz @ truth[:3, :3].T + truth[:3, 3]
    uv = np.stack([700 * p[:, 0] / p[:, 2] + 320, 700 * p[:, 1] / p[:, 2] + 180], axis=1)
    uv += rng.normal(0, 0.3, uv.shape)
    wrong = rng.random(n) < 0.25
    angle = rng.uniform(0, 2 * np.pi, n)
    uv[wrong] += (rng.uniform(3, 30, n) * np.stack([np.cos(angle), np.sin(angle)]))[:, wrong].T
    return xyz, uv, truth


@pytest.fixture
def odometry(compose_config) -> OdometryConfig:
    return OdometryConfig(**compose_config().label.odometry)


def test_the_robust_pose_is_the_same_from_any_start_in_its_basin(scene, odometry):
    """RANSAC only picks where the refinement starts: two starts 3 cm and half a degree apart end at
    the same pose, near the truth."""
    xyz, uv, truth = scene
    front = FrontEnd(StereoCalibration.from_intrinsics(K, 0.5), odometry)
    nudged = truth.copy()
    nudged[:3, :3] = _rotation((0.3, -0.2, 0.1)) @ truth[:3, :3]
    nudged[:3, 3] += [0.02, -0.01, 0.02]
    a, b = front._robust_pose(truth, xyz, uv), front._robust_pose(nudged, xyz, uv)
    assert np.abs(a - b).max() < 1e-9
    assert np.abs(a[:3, 3] - truth[:3, 3]).max() < 0.01


def test_pnp_moves_as_little_as_the_calibration_did(scene, odometry):
    """fx, fy, cx and cy changed by about 1e-7 of themselves: the pose moves by well under a
    micrometre (RANSAC's winning sample and its inliers would move it by millimetres when they flip),
    and the inliers are the tracks that are right."""
    xyz, uv, truth = scene
    calibration = StereoCalibration.from_intrinsics(K, 0.5)
    given, found = FrontEnd(calibration, odometry).pnp(xyz, uv)
    rng = np.random.default_rng(0)
    for _ in range(5):
        moved, inliers = FrontEnd(jittered(calibration, 1e-7, rng), odometry).pnp(xyz, uv)
        assert np.abs(moved[:3, 3] - given[:3, 3]).max() < 1e-6
        assert np.array_equal(inliers, found)
    assert np.abs(given[:3, 3] - truth[:3, 3]).max() < 0.01


@pytest.mark.slow(seconds=14)
def test_the_drift_on_the_real_snippet_holds_when_the_calibration_moves_by_1e_7(odometry, kitti_snippet):
    """On the real KITTI snippet the label stage's drift moved by up to 0.03 points under such
    changes (RANSAC's choices re-drawn); it now moves by under 0.005."""
    sequence = open_sequence(kitti_snippet)

    def drift_pct(seq) -> float:
        run = run_odometry(seq, odometry)
        return drift(run.poses, seq.poses, 20.0, run.pieces)[0].translation_drift_pct

    given = drift_pct(sequence)
    rng = np.random.default_rng(0)
    for _ in range(2):
        moved = drift_pct(dataclasses.replace(sequence, calibration=jittered(sequence.calibration, 1e-7, rng)))
        assert abs(moved - given) < 0.005
