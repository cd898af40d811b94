"""Poses with a controlled odometry error, for measuring how much of it the labels tolerate
(benchmarks/label_noise.py); and calibrations jittered far below their precision, for measuring how
much the odometry's answer moves with them (`jittered`, benchmarks/calibration_sensitivity.py).

The label-noise study asks what an odometry worse than this project's windowed VO (its drift over 20
m segments on the world is in metrics/label.json) costs; the paper reports no drift figure for
its libviso2 (about 2 % is a KITTI benchmark figure, not the paper's).

Each step's true relative motion keeps its rotation; its length is scaled by 1 + s and the heading
turned by w metres-of-travel times a rate, where s and the rate are smooth random processes over the
distance driven (Ornstein-Uhlenbeck, correlation length `correlation_m`, stationary standard
deviations from `percent`). Position errors then grow as a smooth random walk. `percent` sets the
noise, half of it (in quadrature) in scale and half in heading: scale sd p / sqrt(2), heading-rate
sd sqrt(2) p / 20 m (a constant rate r turns a 20 m segment's end sideways by r 20^2 / 2). The
drift this makes, averaged within segments, is smaller: on the rendered drives the KITTI metric
(odometry.sequence_trajectory.drift) measures about 0.6 p (seq_000, 5 draws: 0.59 p at p = 0.3 to 5), so
benchmarks/label_noise.py asks for 0.5, 1.7, 3.4 and 8.5 to make about 0.3, 1, 2 and 5 %, and
reports the drift it measured.

`PoseError` adds what moves a projected label most and what VO does when it fails: the same smooth
rate about the camera's lateral axis (pitch) and optical axis (roll), a smooth climb or sink of the
camera (height: vertical metres per metre driven, sd p / 100), steps the VO lost (the frame keeps
the pose before it, so the rest of the drive lags by one step) and resets (the pose chain restarts
at the first pose, so every later pose jumps). Each kind draws its own noise after the step and
heading noise, so a PoseError with only `step` set gives `drifted_poses`' poses exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.sequence.calibration import StereoCalibration

SEGMENT_M = 20.0


@dataclass(frozen=True)
class PoseError:
    """An odometry error, each rate in `percent` units as the module docstring sets them."""

    step: float = 0.0  # step length and heading (the original study's `percent`)
    pitch: float = 0.0  # a smooth rate about the camera's x axis (right)
    roll: float = 0.0  # a smooth rate about the camera's z axis (forward)
    height: float = 0.0  # a smooth vertical displacement per metre driven, sd height / 100
    drops_per_km: float = 0.0  # steps the VO lost, at random frames
    resets: int = 0  # the pose chain restarted at its first pose, at evenly spaced frames

    def describe(self) -> str:
        parts = [f"{name} {value:g}" for name, value in vars(self).items() if value]
        return ", ".join(parts) or "none"


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
    """(N, 4, 4) camera-to-world poses with the step and heading drift of the module docstring; percent 0: the poses."""
    return erroneous_poses(poses, PoseError(step=percent), seed, correlation_m)


def erroneous_poses(poses: np.ndarray, error: PoseError, seed: int = 0, correlation_m: float = SEGMENT_M) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses with `error` (PoseError) on the true ones."""
    rng = np.random.default_rng(seed)
    steps = np.linalg.inv(poses[:-1]) @ poses[1:]  # (N-1, 4, 4): each frame in the one before
    lengths = np.linalg.norm(steps[:, :3, 3], axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(lengths)])[1:]
    p = error.step / 100.0
    scale = 1.0 + p / np.sqrt(2) * smooth_noise(travelled, correlation_m, rng)
    turn_rate = np.sqrt(2) * p / SEGMENT_M * smooth_noise(travelled, correlation_m, rng)  # rad per metre

    def rate(percent: float) -> np.ndarray:  # rad per metre about one axis; no draw when unused
        return np.sqrt(2) * percent / 100.0 / SEGMENT_M * smooth_noise(travelled, correlation_m, rng) if percent else np.zeros(len(steps))

    pitch_rate, roll_rate = rate(error.pitch), rate(error.roll)
    climb = error.height / 100.0 * smooth_noise(travelled, correlation_m, rng) if error.height else np.zeros(len(steps))
    dropped = rng.random(len(steps)) < error.drops_per_km * lengths / 1000.0 if error.drops_per_km else np.zeros(len(steps), bool)
    out = [poses[0].copy()]
    down = poses[0][:3, 1]  # the first camera's y axis in the world: the heading turns, and the camera climbs, about it
    for k, step in enumerate(steps):
        if dropped[k]:
            out.append(out[-1].copy())
            continue
        moved = step.copy()
        moved[:3, 3] *= scale[k]
        turned = np.eye(4)
        turned[:3, :3] = _about(out[-1][:3, :3].T @ down, turn_rate[k] * lengths[k])
        if pitch_rate[k] or roll_rate[k]:
            turned[:3, :3] = turned[:3, :3] @ _about(np.array([1.0, 0, 0]), pitch_rate[k] * lengths[k])
            turned[:3, :3] = turned[:3, :3] @ _about(np.array([0, 0, 1.0]), roll_rate[k] * lengths[k])
        pose = out[-1] @ turned @ moved
        pose[:3, 3] -= down * climb[k] * lengths[k]  # up is -down
        out.append(pose)
    result = np.stack(out)
    for r in np.linspace(0, len(result), error.resets + 2)[1:-1].astype(int):
        result[r:] = result[0] @ np.linalg.inv(result[r]) @ result[r:]
    return result


def jittered(calibration: StereoCalibration, scale: float, rng: np.random.Generator) -> StereoCalibration:
    """`calibration` with fx, fy, cx, cy and the baseline each scaled by 1 + s r, r uniform in
    [1e-8, scale] and s a random sign: a change far below what any calibration is known to, for
    measuring how much an estimator's answer moves with it."""

    def factor() -> float:
        return 1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(1e-8, scale)

    K = calibration.K.copy()
    K[0, 0], K[1, 1], K[0, 2], K[1, 2] = K[0, 0] * factor(), K[1, 1] * factor(), K[0, 2] * factor(), K[1, 2] * factor()
    return StereoCalibration.from_intrinsics(K, calibration.baseline_m * factor())
