"""Poses with a controlled drift: the drift made is about the one asked for, measured the KITTI way."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.odometry.perturb import drifted_poses, smooth_noise
from offroad_path.odometry.sequence_trajectory import drift
from offroad_path.sequence.reader import open_sequence


def test_smooth_noise_has_unit_variance_and_its_correlation_length():
    d = np.arange(0, 20000.0, 1.0)
    z = smooth_noise(d, 20.0, np.random.default_rng(0))
    assert z.std() == pytest.approx(1.0, abs=0.1)
    assert np.corrcoef(z[:-20], z[20:])[0, 1] == pytest.approx(np.exp(-1), abs=0.1)  # e^-1 at one correlation length


@pytest.mark.parametrize("percent", [1.0, 5.0])
def test_the_drift_made_is_the_drift_asked_for(drive, percent):
    poses = open_sequence(drive / "drive").poses
    np.testing.assert_allclose(drifted_poses(poses, 0.0), poses, atol=1e-9)  # the steps recomposed
    made = [drift(drifted_poses(poses, percent, seed=s), poses)[0].translation_drift_pct for s in range(8)]
    assert 0.4 * percent < np.mean(made) < 1.6 * percent  # over the 40 m drive's 20 m segments, 8 draws
    np.testing.assert_array_equal(drifted_poses(poses, percent, seed=3), drifted_poses(poses, percent, seed=3))
    rotation = drifted_poses(poses, percent)[:, :3, :3]
    np.testing.assert_allclose(rotation @ rotation.transpose(0, 2, 1), np.tile(np.eye(3), (len(poses), 1, 1)), atol=1e-9)
