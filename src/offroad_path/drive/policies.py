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

import copy
import math
from dataclasses import dataclass, field, replace
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
from offroad_path.world.render import PinholeCamera
from offroad_path.world.renderer import Renderer
from offroad_path.world.trajectory import camera_poses_at


@dataclass
class StereoRig:
    """The driven vehicle's stereo rig in one world: renders views at poses through conf/render's
    renderer (world.renderer: the reference one view at a time, or the torch port in batches), matches a pair."""

    renderer: Renderer
    baseline_m: float
    matcher: cv2.StereoSGBM

    def __post_init__(self) -> None:
        self.to_right = np.eye(4)
        self.to_right[0, 3] = self.baseline_m

    @property
    def camera(self) -> PinholeCamera:
        return self.renderer.camera

    def render(self, pose: np.ndarray) -> np.ndarray:
        return self.render_many([pose])[0]

    def render_many(self, poses: list[np.ndarray]) -> list[np.ndarray]:
        """(H, W, 3) RGB images, one per camera-to-world pose (4, 4)."""
        return [view.image for view in self.renderer.views(poses)]


LEFT, RIGHT = "left", "right"


@dataclass
class Frame:
    """One control step: the state, where it stands on the course, and the camera's views, rendered
    on demand or beforehand for many frames at once (render_views_of)."""

    state: State
    progress_s: float
    vehicle: Vehicle
    course: Course
    rig: StereoRig
    views: dict[str, np.ndarray] = field(default_factory=dict)  # LEFT, RIGHT -> (H, W, 3) RGB

    @cached_property
    def pose(self) -> np.ndarray:  # (4, 4) left camera to world
        return camera_poses_at(self.state.xz[None], np.array([self.state.heading]), self.course.world.terrain, self.vehicle.geometry)[0]

    def view_pose(self, name: str) -> np.ndarray:
        return self.pose if name == LEFT else self.pose @ self.rig.to_right

    def _view(self, name: str) -> np.ndarray:
        if name not in self.views:
            self.views[name] = self.rig.render(self.view_pose(name))
        return self.views[name]

    @property
    def left(self) -> np.ndarray:  # (H, W, 3) RGB
        return self._view(LEFT)

    @cached_property
    def depth(self) -> np.ndarray:  # (H, W) metres from StereoSGBM, 0 where unknown
        grey = [cv2.cvtColor(self._view(name), cv2.COLOR_RGB2GRAY) for name in (LEFT, RIGHT)]
        return depth_from_disparity(compute_disparity(self.rig.matcher, *grey), self.rig.camera.fx, self.rig.baseline_m)


def render_views_of(frames: list[Frame], views: list[tuple[str, ...]]) -> None:
    """Render views[k] of frames[k] (not yet rendered), all in one batch per rig."""
    wanted: dict[int, list[tuple[Frame, str]]] = {}
    for frame, names in zip(frames, views, strict=True):
        wanted.setdefault(id(frame.rig), []).extend((frame, name) for name in names if name not in frame.views)
    for pairs in wanted.values():
        if pairs:
            images = pairs[0][0].rig.render_many([frame.view_pose(name) for frame, name in pairs])
            for (frame, name), image in zip(pairs, images, strict=True):
                frame.views[name] = image


class Policy:
    """steer(frame) = act(frame, look([frame])[0]). look is the part batched over drives: it may use
    only `network`, which drives whose policies share it share; act is the drive's own."""

    name: str
    shown: np.ndarray | None = None  # what the last step saw, for the drive's video: a path mask or None
    views: tuple[str, ...] = ()  # the camera views a step renders for it
    network: object | None = None  # what look runs; None: look is per drive

    def reset(self) -> None:
        """After an intervention: the vehicle was moved, forget the past."""

    def fresh(self) -> Policy:
        """The same policy for another drive: its network shared, its state its own."""
        return copy.copy(self)

    def look(self, frames: list[Frame]) -> list:
        return [None] * len(frames)

    def act(self, frame: Frame, seen: object) -> float | None:
        raise NotImplementedError

    def steer(self, frame: Frame) -> float | None:
        return self.act(frame, self.look([frame])[0])


@dataclass
class StraightPolicy(Policy):
    name: str = "straight"

    def act(self, frame: Frame, seen: object) -> float | None:
        return 0.0


@dataclass
class OraclePolicy(Policy):
    lookahead_m: float
    name: str = "oracle"

    def act(self, frame: Frame, seen: object) -> float | None:
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
    views = (LEFT,)

    def __post_init__(self) -> None:
        self._prepare = steering_transforms(jitter=0.0, seed=0)

    @property
    def network(self) -> torch.nn.Module:
        return self.task

    def look(self, frames: list[Frame]) -> list[float]:
        # The resize and normalisation of training (steering.angle_dataset), without the jitter.
        images = [cv2.resize(f.left, (self.width, self.height), interpolation=cv2.INTER_LINEAR) for f in frames]
        batch = torch.stack([self._prepare(image=image)["image"] for image in images])  # (N, 3, H, W)
        device = next(self.task.parameters()).device
        with torch.no_grad():
            return [float(v) for v in self.task(batch.to(device)).float().cpu().reshape(len(frames))]

    def act(self, frame: Frame, seen: object) -> float | None:
        normalised = float(seen)
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

    views = (LEFT, RIGHT)

    def __post_init__(self) -> None:
        if self.temporal_alpha is not None:
            self._filter = TemporalFilter(self.temporal_alpha)

    @property
    def network(self) -> PathModel:
        return self.model

    def fresh(self) -> PathPolicy:
        return replace(self, _filter=None, _previous_pose=None)  # __post_init__ gives it its own filter

    def reset(self) -> None:
        if self._filter is not None:
            self._filter.reset()
        self._previous_pose = None

    def look(self, frames: list[Frame]) -> list[np.ndarray]:
        return self.model([f.left for f in frames])  # (H, W) path confidence at the camera's size, each

    def act(self, frame: Frame, seen: object) -> float | None:
        confidence, depth = seen, frame.depth
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
