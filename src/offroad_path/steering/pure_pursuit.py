"""A steering angle from a path image: the comparison Holder & Breckon (2018, Sec. V) say their
path prediction cannot make with end-to-end steering. The path's centre line is projected onto the
ground with the camera's height and pitch, and pure pursuit (Coulter, CMU-RI-TR-92-01, 1992) steers
the rear axle along the arc through the point one look-ahead distance away:

    delta = atan(2 L sin(alpha) / l_d)

with L the wheelbase, alpha the bearing of the look-ahead point from the vehicle's axis, and l_d
its distance. On a circle of radius R through the rear axle this is the bicycle model's
atan(L / R), the angle the rendered world records as steering.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GroundCamera:
    """A camera over flat ground: intrinsics at the path image's size, height, pitch down."""

    K: np.ndarray  # (3, 3)
    height_m: float
    pitch_deg: float
    rear_axle_behind_m: float  # how far the rear axle is behind the camera, along the vehicle's axis

    def _hits(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rays (camera frame) of the pixels below the horizon and each one's ground point in the
        level frame (x right, y down, z forward), as (M, 3) each."""
        rays = np.linalg.solve(self.K, np.c_[pixels, np.ones(len(pixels))].T).T  # camera frame, y down
        tilt = math.radians(self.pitch_deg)
        # camera = rotation @ level, the rotation of sequence.footprint; level = rotation.T @ camera
        rotation = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(tilt), -math.sin(tilt)], [0.0, math.sin(tilt), math.cos(tilt)]])
        level = rays @ rotation
        below = level[:, 1] > 1e-6
        t = self.height_m / level[below, 1]
        return rays[below] * t[:, None], level[below] * t[:, None]

    def to_ground(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) pixels (u, v) to (M, 2) ground points (x right, z forward) from the rear axle, in
        metres; pixels at or above the horizon are dropped."""
        level = self._hits(pixels)[1]
        return np.stack([level[:, 0], level[:, 2] + self.rear_axle_behind_m], axis=1)

    def to_camera(self, pixels: np.ndarray) -> np.ndarray:
        """(N, 2) pixels to (M, 3) points where their rays meet the ground, in the camera's frame
        (x right, y down, z forward; metres); pixels at or above the horizon are dropped."""
        return self._hits(pixels)[0]


def centre_line(path: np.ndarray) -> np.ndarray:
    """(N, 2) pixels (u, v): the middle of the path in every image row that has path, bottom up.
    On flat ground a row is one distance ahead, so the row's middle is the path's middle there."""
    rows = np.flatnonzero(path.any(axis=1))[::-1]
    columns = np.arange(path.shape[1], dtype=np.float64)
    middles = [(columns[path[r]].min() + columns[path[r]].max()) / 2.0 for r in rows]
    return np.stack([np.asarray(middles), rows.astype(np.float64)], axis=1) if len(rows) else np.zeros((0, 2))


def pure_pursuit(ground: np.ndarray, lookahead_m: float, wheelbase_m: float) -> float | None:
    """Road-wheel angle in radians (positive turns right) towards the point of the centre line
    (ground points ordered near to far) at lookahead_m from the rear axle, linearly interpolated;
    the farthest point when the line ends sooner; None when there is no point ahead."""
    ahead = ground[ground[:, 1] > 0]
    if not len(ahead):
        return None
    distance = np.hypot(ahead[:, 0], ahead[:, 1])
    beyond = np.flatnonzero(distance >= lookahead_m)
    if len(beyond) and beyond[0] > 0:
        i = beyond[0]
        s = (lookahead_m - distance[i - 1]) / (distance[i] - distance[i - 1])
        target = ahead[i - 1] + s * (ahead[i] - ahead[i - 1])
    else:
        target = ahead[beyond[0]] if len(beyond) else ahead[np.argmax(distance)]
    l_d = float(np.hypot(*target))
    alpha = math.atan2(target[0], target[1])
    return math.atan(2.0 * wheelbase_m * math.sin(alpha) / l_d)


def steering_from_path(path: np.ndarray, camera: GroundCamera, lookahead_m: float, wheelbase_m: float) -> float | None:
    """Road-wheel angle (radians) from a binary (H, W) path image; None when it has no path below the horizon."""
    return pure_pursuit(camera.to_ground(centre_line(path)), lookahead_m, wheelbase_m)
