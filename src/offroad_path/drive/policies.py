"""Policies: what steers the vehicle in closed loop, one small class each behind one interface.

Each gets the frame of the current control step (the vehicle's state, and its camera's images,
rendered only when a policy asks for them) and returns a road-wheel angle in radians (positive
turns right), or None when it has nothing to say (no path predicted: the vehicle steers straight).

- PathPolicy: a trained path network, the paper's post-processing with the rendered pair's
  StereoSGBM depth (as a vehicle would have it), optionally the temporal filter, then pure pursuit
  on the path's centre line (offroad_path.steering.pure_pursuit) with the driven vehicle's geometry.
- PilotNetPolicy: the end-to-end baseline; its normalised output times the driven vehicle's lock
  (the same steering command on another vehicle turns it by what that vehicle's lock gives).
- OraclePolicy: pure pursuit on the reference drive's true future path (the method's ceiling).
- StraightPolicy: the road wheels straight (the floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
import torch

from offroad_path.drive.course import Course
from offroad_path.drive.vehicle import State, Vehicle
from offroad_path.geometry.stereo import compute_disparity, depth_from_disparity
from offroad_path.inference.path_filter import PostprocessParams, postprocess
from offroad_path.inference.runners import PathModel
from offroad_path.inference.temporal_filter import TemporalFilter
from offroad_path.steering.angle_dataset import steering_transforms
from offroad_path.steering.pure_pursuit import GroundCamera, pure_pursuit, steering_from_path
from offroad_path.world.render import PinholeCamera, render_view
from offroad_path.world.trajectory import camera_poses_at


@dataclass
class StereoRig:
    """The driven vehicle's stereo rig in one world: renders the pair at a pose, matches it."""

    world: object
    camera: PinholeCamera
    baseline_m: float
    max_distance_m: float
    matcher: cv2.StereoSGBM

    def __post_init__(self) -> None:
        self.rays = self.camera.rays()
        self.to_right = np.eye(4)
        self.to_right[0, 3] = self.baseline_m

    def render(self, pose: np.ndarray) -> np.ndarray:
        return render_view(self.world, self.camera, pose, self.max_distance_m, self.rays).image


@dataclass
class Frame:
    """One control step: the state, where it stands on the course, and the camera's view on demand."""

    state: State
    progress_s: float
    vehicle: Vehicle
    course: Course
    rig: StereoRig

    @cached_property
    def pose(self) -> np.ndarray:  # (4, 4) left camera to world
        return camera_poses_at(self.state.xz[None], np.array([self.state.heading]), self.course.world.terrain, self.vehicle.geometry)[0]

    @cached_property
    def left(self) -> np.ndarray:  # (H, W, 3) RGB
        return self.rig.render(self.pose)

    @cached_property
    def depth(self) -> np.ndarray:  # (H, W) metres from StereoSGBM, 0 where unknown
        right = self.rig.render(self.pose @ self.rig.to_right)
        grey = [cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) for image in (self.left, right)]
        return depth_from_disparity(compute_disparity(self.rig.matcher, *grey), self.rig.camera.fx, self.rig.baseline_m)


class Policy:
    name: str
    shown: np.ndarray | None = None  # what the last step saw, for the drive's video: a path mask or None

    def reset(self) -> None:
        """After an intervention: the vehicle was moved, forget the past."""

    def steer(self, frame: Frame) -> float | None:
        raise NotImplementedError


@dataclass
class StraightPolicy(Policy):
    name: str = "straight"

    def steer(self, frame: Frame) -> float | None:
        return 0.0


@dataclass
class OraclePolicy(Policy):
    lookahead_m: float
    name: str = "oracle"

    def steer(self, frame: Frame) -> float | None:
        v = frame.vehicle
        ahead = frame.course.reference_ahead(frame.progress_s, 3 * self.lookahead_m)
        return pure_pursuit(frame.state.to_vehicle(ahead, v.geometry.wheelbase_m / 2), self.lookahead_m, v.geometry.wheelbase_m)


@dataclass
class PilotNetPolicy(Policy):
    task: torch.nn.Module  # SteeringTask, eval mode
    width: int
    height: int
    name: str = "pilotnet"  # drive.pilotnets' key
    # 1/m of output 1 for a PilotNet that predicts curvature (steering.target=curvature); None: it
    # predicts the normalised angle, which is scaled by this vehicle's lock
    max_curvature: float | None = None

    def __post_init__(self) -> None:
        self._prepare = steering_transforms(jitter=0.0, seed=0)

    def steer(self, frame: Frame) -> float | None:
        # The resize and normalisation of training (steering.angle_dataset), without the jitter.
        image = cv2.resize(frame.left, (self.width, self.height), interpolation=cv2.INTER_LINEAR)
        batch = self._prepare(image=image)["image"][None]  # (1, 3, H, W)
        with torch.no_grad():
            normalised = float(self.task(batch)[0])
        if self.max_curvature is None:
            return normalised * frame.vehicle.lock_rad
        # As pure pursuit steers any vehicle along a path: its own wheelbase times the curvature.
        return math.atan(frame.vehicle.geometry.wheelbase_m * normalised * self.max_curvature)


@dataclass
class PathPolicy(Policy):
    name: str
    model: PathModel
    params: PostprocessParams
    lookahead_m: float
    threshold: float
    temporal_alpha: float | None = None  # the temporal filter's alpha; None: each frame alone
    _filter: TemporalFilter | None = field(default=None, repr=False)
    _previous_pose: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.temporal_alpha is not None:
            self._filter = TemporalFilter(self.temporal_alpha)

    def reset(self) -> None:
        if self._filter is not None:
            self._filter.reset()
        self._previous_pose = None

    def steer(self, frame: Frame) -> float | None:
        confidence = self.model([frame.left])[0]  # (H, W) at the camera's size
        depth = frame.depth
        if self._filter is not None:
            # The camera's motion since the last step, as wheel odometry or VO would give it.
            moved = np.eye(4) if self._previous_pose is None else np.linalg.inv(self._previous_pose) @ frame.pose
            confidence = self._filter(confidence, depth, frame.rig.camera.K, moved)
            self._previous_pose = frame.pose
        path = postprocess(confidence, depth if self.params.use_depth else None, self.params) > self.threshold
        self.shown = path
        v = frame.vehicle
        camera = GroundCamera(frame.rig.camera.K, v.geometry.camera_height_m, v.geometry.camera_pitch_deg, v.rear_axle_behind_camera_m)
        return steering_from_path(path, camera, self.lookahead_m, v.geometry.wheelbase_m)
