"""The driven vehicle: a kinematic bicycle on the terrain, its road wheels turned toward the policy's
command no faster than the steering rate and no farther than the lock.

Heading psi is measured from +z toward +x (the world's convention, offroad_path.world.trajectory),
so a positive road-wheel angle turns right. The rear axle moves along the heading and the heading
turns at

    dpsi/dt = v tan(delta) / L * f

with L the wheelbase and f the ground's yaw-rate factor (1 without slip, offroad_path.world.slip).
Each control period is integrated in small sub-steps, each along the arc of its mid-step heading.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from offroad_path.world.trajectory import VehicleGeometry

SUBSTEP_M = 0.1  # the arc of one sub-step: collisions are checked at every one


YawFactor = Callable[[np.ndarray], float]  # body centre (2,) -> the ground's yaw-rate factor there


@dataclass(frozen=True)
class Vehicle:
    geometry: VehicleGeometry
    steering_rate_deg_s: float  # road wheels
    yaw_factor: YawFactor | None = None  # traction (offroad_path.world.slip); None: the bicycle model exactly

    @property
    def lock_rad(self) -> float:
        return math.radians(self.geometry.max_steering_deg)

    @property
    def rear_axle_behind_camera_m(self) -> float:
        return self.geometry.camera_forward_m + self.geometry.wheelbase_m / 2


@dataclass(frozen=True)
class State:
    xz: np.ndarray  # (2,) body centre on the ground plane
    heading: float  # radians
    steer: float  # road-wheel angle now, radians

    @property
    def forward(self) -> np.ndarray:
        return np.array([math.sin(self.heading), math.cos(self.heading)])

    @property
    def right(self) -> np.ndarray:
        return np.array([math.cos(self.heading), -math.sin(self.heading)])

    def to_vehicle(self, xz: np.ndarray, behind_m: float = 0.0) -> np.ndarray:
        """World points (N, 2) in the vehicle's frame (x right, z forward) from a point behind_m
        behind the body centre (the rear axle for pure pursuit)."""
        origin = self.xz - behind_m * self.forward
        rel = xz - origin
        return np.stack([rel @ self.right, rel @ self.forward], axis=1)


def advance(state: State, vehicle: Vehicle, command: float, speed_mps: float, dt_s: float) -> tuple[State, np.ndarray]:
    """The state after one control period of dt_s with the road wheels steered toward `command`
    (radians), and the body centre after every sub-step (n, 2)."""
    g = vehicle.geometry
    half = g.wheelbase_m / 2
    target = float(np.clip(command, -vehicle.lock_rad, vehicle.lock_rad))
    distance = speed_mps * dt_s
    n = max(1, math.ceil(distance / SUBSTEP_M))
    h = dt_s / n
    max_turn = math.radians(vehicle.steering_rate_deg_s) * h
    rear = state.xz - half * state.forward
    heading, steer = state.heading, state.steer
    centres = np.empty((n, 2))
    for i in range(n):
        steer += float(np.clip(target - steer, -max_turn, max_turn))
        factor = 1.0 if vehicle.yaw_factor is None else vehicle.yaw_factor(rear + half * np.array([math.sin(heading), math.cos(heading)]))
        turn = speed_mps * math.tan(steer) / g.wheelbase_m * factor * h
        mid = heading + turn / 2
        rear = rear + speed_mps * h * np.array([math.sin(mid), math.cos(mid)])
        heading += turn
        centres[i] = rear + half * np.array([math.sin(heading), math.cos(heading)])
    return replace(state, xz=centres[-1].copy(), heading=heading, steer=steer), centres
