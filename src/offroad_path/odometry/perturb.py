"""Poses with a controlled odometry error, for measuring how much of it the labels tolerate
(benchmarks/label_noise.py). The paper's VO (libviso2) drifts about 2 %; this project's windowed VO
0.3 % on its world: the study asks what a worse odometry costs.

Each step's true relative motion keeps its rotation; its length is scaled by 1 + s and the heading
turned by w metres-of-travel times a rate, where s and the rate are smooth random processes over the
distance driven (Ornstein-Uhlenbeck, correlation length `correlation_m`, stationary standard
deviations from `percent`). Position errors then grow as a smooth random walk. `percent` sets the
noise, half of it (in quadrature) in scale and half in heading: scale sd p / sqrt(2), heading-rate
sd sqrt(2) p / 20 m (a constant rate r turns a 20 m segment's end sideways by r 20^2 / 2). The
drift this makes, averaged within segments, is smaller: on the rendered drives the KITTI metric
(odometry.trajectory.drift) measures about 0.6 p (seq_000, 5 draws: 0.59 p at p = 0.3 to 5), so
benchmarks/label_noise.py asks for 0.5, 1.7, 3.4 and 8.5 to make about 0.3, 1, 2 and 5 %, and
reports the drift it measured.
"""

from __future__ import annotations

import numpy as np

SEGMENT_M = 20.0


def smooth_noise(distance: np.ndarray, correlation_m: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance Ornstein-Uhlenbeck samples at increasing `distance` (N,) along the drive."""
    z = np.empty(len(distance))
    z[0] = rng.standard_normal()
    for k in range(1, len(distance)):
        a = np.exp(-(distance[k] - distance[k - 1]) / correlation_m)
        z[k] = a * z[k - 1] + np.sqrt(1 - a * a) * rng.standard_normal()
    return z


def _about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of `angle` radians about unit `axis` (Rodrigues)."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def drifted_poses(poses: np.ndarray, percent: float, seed: int = 0, correlation_m: float = SEGMENT_M) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses with the drift of the module docstring; percent 0: the poses."""
    rng = np.random.default_rng(seed)
    steps = np.linalg.inv(poses[:-1]) @ poses[1:]  # (N-1, 4, 4): each frame in the one before
    lengths = np.linalg.norm(steps[:, :3, 3], axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(lengths)])[1:]
    p = percent / 100.0
    scale = 1.0 + p / np.sqrt(2) * smooth_noise(travelled, correlation_m, rng)
    turn_rate = np.sqrt(2) * p / SEGMENT_M * smooth_noise(travelled, correlation_m, rng)  # rad per metre
    out = [poses[0].copy()]
    down = poses[0][:3, 1]  # the first camera's y axis in the world: the heading turns about it
    for k, step in enumerate(steps):
        moved = step.copy()
        moved[:3, 3] *= scale[k]
        turned = np.eye(4)
        turned[:3, :3] = _about(out[-1][:3, :3].T @ down, turn_rate[k] * lengths[k])
        out.append(out[-1] @ turned @ moved)
    return np.stack(out)
