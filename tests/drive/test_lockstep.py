"""Drives in lockstep (drive.loop.drive_together) in a rendered world: each drive the same as driven
alone, their views rendered in one batch per step and a shared network run once per step; the
rig's views from the torch renderer agree with the reference's."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from offroad_path.drive.course import Course
from offroad_path.drive.loop import Drive, LoopSettings, Setup, drive, drive_together
from offroad_path.drive.policies import LEFT, OraclePolicy, Policy, StereoRig, StraightPolicy
from offroad_path.drive.vehicle import Vehicle
from offroad_path.drive.worlds import stereo_rig
from offroad_path.geometry.stereo import sgbm
from offroad_path.world.render import PinholeCamera
from offroad_path.world.render_torch import torch_device
from offroad_path.world.renderer import Renderer
from offroad_path.world.scene import build_world
from offroad_path.world.trajectory import VehicleGeometry

SETTINGS = LoopSettings(rate_hz=5.0, speed_mps=5.0, length_m=6.0, respawn_m=5.0, timeout_factor=3.0, water_intervenes=False)


@dataclass
class Calls:
    """What a shared network and a rig were asked to do: the batch sizes, per call."""

    looks: list[int] = field(default_factory=list)
    renders: list[int] = field(default_factory=list)


class CountingRig(StereoRig):
    calls: Calls

    def render_many(self, poses: list[np.ndarray]) -> list[np.ndarray]:
        self.calls.renders.append(len(poses))
        return super().render_many(poses)


@dataclass
class Shade(Policy):
    """Steers toward the brighter half of the left image: a policy that looks, with a 'network' (the
    brightness difference) that drives share."""

    calls: Calls
    name: str = "shade"
    views = (LEFT,)

    def __post_init__(self) -> None:
        self.network = self.calls

    def look(self, frames: list) -> list[float]:
        self.calls.looks.append(len(frames))
        halves = [np.array_split(f.left.mean(axis=2), 2, axis=1) for f in frames]
        return [float(right.mean() - left.mean()) for left, right in halves]

    def act(self, frame, seen: object) -> float:
        return float(np.clip(0.02 * float(seen), -0.3, 0.3))


@pytest.fixture(scope="module")
def world_and_rig(compose_config):
    cfg = compose_config("world.frames=12", "world.max_distance_m=40").world  # a small world: a third of the build
    world = build_world(cfg, seed=23)
    geometry = VehicleGeometry.of(cfg.vehicle)
    camera = PinholeCamera.from_fov(64, 36, cfg.hfov_deg)
    rig = CountingRig(Renderer(world, camera, cfg.max_distance_m), cfg.rig.baseline_m, sgbm(compose_config().label.disparity))
    course = Course(world, geometry, 2.5, (0.25, 2.0))
    return cfg, world, rig, Setup(course, Vehicle(geometry, 60.0), rig, SETTINGS)


def test_drives_together_are_each_the_drive_alone(world_and_rig):
    _, _, rig, setup = world_and_rig
    calls = Calls()
    rig.calls = calls
    plan = [(Shade(calls), 0.0), (Shade(calls), 8.0), (OraclePolicy(6.0), 4.0), (StraightPolicy(), 0.0)]
    alone = [drive(setup, policy.fresh(), start) for policy, start in plan]
    calls.looks.clear(), calls.renders.clear()
    together = drive_together([Drive(setup, policy.fresh(), start) for policy, start in plan])
    for a, t in zip(alone, together, strict=True):
        assert (t.policy, t.steps, t.offsets, t.interventions) == (a.policy, a.steps, a.offsets, a.interventions)
        assert t.progress_m == a.progress_m
        assert np.array_equal(np.array(t.trajectory), np.array(a.trajectory), equal_nan=True)
    shade = [t.steps for t in together[:2]]
    assert min(shade) > 3 and len(calls.looks) == max(shade)  # one look per step, over every drive still going
    assert calls.looks[: min(shade)] == [2] * min(shade) and calls.renders == calls.looks  # their two left views, one batch


def test_two_drives_sharing_one_policy_object_are_refused(world_and_rig):
    setup, policy = world_and_rig[3], StraightPolicy()
    with pytest.raises(ValueError, match="share a policy object"):
        drive_together([Drive(setup, policy, 0.0), Drive(setup, policy, 4.0)])


def test_the_rig_renders_with_the_torch_port_in_batches(compose_config, world_and_rig):
    """The drive stage's rig with render.backend=torch (on the GPU where there is one) renders views
    that agree with the reference's, and a view's bytes do not depend on the batch it renders in."""
    cfg, world, rig, _ = world_and_rig
    config = compose_config("render.backend=torch", "render.views_per_batch=2")
    ported = stereo_rig(world, rig.camera, cfg, config.label.disparity, config.render)
    assert ported.renderer.device_world.device == torch_device("auto") and ported.renderer.views_per_batch == 2
    poses = list(world.poses[[2, 6, 10]])
    reference = np.stack(StereoRig.render_many(rig, poses)).astype(int)
    images = ported.render_many(poses)  # in two batches: 2 views, then 1
    difference = np.abs(reference - np.stack(images))
    assert (difference <= 1).mean() > 0.995 and difference.mean() < 0.05
    assert np.array_equal(ported.render(poses[2]), images[2]) and np.array_equal(ported.render(poses[1]), images[1])
