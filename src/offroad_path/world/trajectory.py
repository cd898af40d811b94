"""The vehicle: a smooth random drive over the ground, posed on the terrain under its wheels.

Heading psi is measured from +z (forward) toward +x (right), so positive curvature turns right.
Steering follows a kinematic bicycle model: delta = atan(wheelbase * curvature).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from offroad_path.geometry.exact import norm_rows
from offroad_path.world.terrain import Terrain

ARC_STEP_M = 0.05


@dataclass
class Curve:
    """A planar curve sampled every ARC_STEP_M metres of arc length."""

    xz: np.ndarray  # (N, 2)
    heading: np.ndarray  # (N,) radians
    curvature: np.ndarray  # (N,) 1/m

    @property
    def length(self) -> float:
        return (len(self.xz) - 1) * ARC_STEP_M

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(xz, heading, curvature) at arc lengths s, linearly interpolated."""
        grid = np.arange(len(self.xz)) * ARC_STEP_M
        xz = np.stack([np.interp(s, grid, self.xz[:, 0]), np.interp(s, grid, self.xz[:, 1])], axis=-1)
        return xz, np.interp(s, grid, self.heading), np.interp(s, grid, self.curvature)

    def normal(self) -> np.ndarray:
        """Unit vectors to the right of the direction of travel, (N, 2)."""
        return np.stack([np.cos(self.heading), -np.sin(self.heading)], axis=1)


def smooth_random(rng: np.random.Generator, s: np.ndarray, wavelengths: tuple[float, float], terms: int) -> np.ndarray:
    """A sum of random sinusoids in s, scaled to peak magnitude 1."""
    out = np.zeros_like(s)
    for _ in range(terms):
        k = 2 * np.pi / rng.uniform(*wavelengths)
        out += rng.uniform(0.3, 1.0) * np.sin(k * s + rng.uniform(0, 2 * np.pi))
    return out / max(np.abs(out).max(), 1e-9)


def integrate_curve(start_xz: np.ndarray, start_heading: float, curvature: np.ndarray) -> Curve:
    heading = start_heading + np.concatenate([[0.0], np.cumsum(curvature[:-1]) * ARC_STEP_M])
    # Midpoint rule: each step follows the average heading over it.
    mid = heading[:-1] + 0.5 * curvature[:-1] * ARC_STEP_M
    steps = ARC_STEP_M * np.stack([np.sin(mid), np.cos(mid)], axis=1)
    xz = start_xz + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return Curve(xz=xz, heading=heading, curvature=curvature)


def random_drive(rng: np.random.Generator, length_m: float, max_curvature: float) -> Curve:
    """A drive starting at the origin heading +z, with smoothly varying curvature."""
    s = np.arange(int(length_m / ARC_STEP_M) + 1) * ARC_STEP_M
    curvature = max_curvature * smooth_random(rng, s, (40.0, 160.0), 4)
    return integrate_curve(np.zeros(2), 0.0, curvature)


def frame_arc_lengths(rng: np.random.Generator, n_frames: int, fps: float, speed_range: tuple[float, float]) -> np.ndarray:
    """Arc length at each frame for a speed that wanders smoothly within speed_range (m/s)."""
    t = np.arange(n_frames) / fps
    lo, hi = speed_range
    speed = lo + (hi - lo) * 0.5 * (1.0 + smooth_random(rng, t, (8.0, 30.0), 3))
    return np.concatenate([[0.0], np.cumsum(speed[:-1] / fps)])


@dataclass
class VehicleGeometry:
    wheelbase_m: float
    track_m: float
    width_m: float
    length_m: float
    camera_height_m: float  # above the ground under the body centre
    camera_forward_m: float  # camera ahead of the body centre
    camera_pitch_deg: float  # downward tilt of the optical axis
    max_steering_deg: float

    @classmethod
    def of(cls, vehicle) -> VehicleGeometry:
        """From the `vehicle` config (world.vehicle, drive.other_vehicle) or meta.json's `vehicle`: the same names."""
        value = (lambda name: vehicle[name]) if isinstance(vehicle, Mapping) else (lambda name: getattr(vehicle, name))
        return cls(**{f.name: float(value(f.name)) for f in fields(cls)})


def camera_poses(curve: Curve, s: np.ndarray, terrain: Terrain, vehicle: VehicleGeometry) -> np.ndarray:
    """Left-camera-to-world poses (N, 4, 4) for a vehicle whose four wheels touch the terrain."""
    xz, heading, _ = curve.at(s)
    return camera_poses_at(xz, heading, terrain, vehicle)


def camera_poses_at(xz: np.ndarray, heading: np.ndarray, terrain: Terrain, vehicle: VehicleGeometry) -> np.ndarray:
    """Left-camera-to-world poses (N, 4, 4) of a vehicle whose body centre is at xz (N, 2) with
    headings (N,), its four wheels on the terrain (closed-loop driving poses it anywhere)."""
    fwd2 = np.stack([np.sin(heading), np.cos(heading)], axis=1)
    right2 = np.stack([np.cos(heading), -np.sin(heading)], axis=1)
    half_wb, half_tr = vehicle.wheelbase_m / 2, vehicle.track_m / 2

    def contact(a: float, b: float) -> np.ndarray:
        p = xz + a * fwd2 + b * right2
        e = terrain.elevation(p[:, 0], p[:, 1])
        return np.stack([p[:, 0], -e, p[:, 1]], axis=1)

    fl, fr = contact(half_wb, -half_tr), contact(half_wb, half_tr)
    rl, rr = contact(-half_wb, -half_tr), contact(-half_wb, half_tr)
    centre = (fl + fr + rl + rr) / 4
    forward = _unit((fl + fr) - (rl + rr))
    right = (fr + rr) - (fl + rl)
    down = _unit(np.cross(forward, right))
    right = np.cross(down, forward)

    tilt = np.deg2rad(vehicle.camera_pitch_deg)
    z_cam = np.cos(tilt) * forward + np.sin(tilt) * down
    y_cam = np.cos(tilt) * down - np.sin(tilt) * forward
    origin = centre - vehicle.camera_height_m * down + vehicle.camera_forward_m * forward

    poses = np.tile(np.eye(4), (len(xz), 1, 1))
    poses[:, :3, 0] = right
    poses[:, :3, 1] = y_cam
    poses[:, :3, 2] = z_cam
    poses[:, :3, 3] = origin
    return poses


def normalised_steering(curvature: np.ndarray, vehicle: VehicleGeometry) -> np.ndarray:
    """Bicycle-model steering angle over the maximum angle, in [-1, 1]; positive turns right."""
    delta = np.arctan(vehicle.wheelbase_m * curvature)
    return np.clip(delta / np.deg2rad(vehicle.max_steering_deg), -1.0, 1.0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / norm_rows(v)[..., None]
