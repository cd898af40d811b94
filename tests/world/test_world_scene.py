"""The world's contents, the vehicle on the terrain, steering, presets and determinism."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from offroad_path.label.frame_selection import select_segments
from offroad_path.world.classes import CLASS_NAMES
from offroad_path.world.record import camera_for, record_sequence, sequence_seed
from offroad_path.world.render import render_view
from offroad_path.world.scene import build_world
from offroad_path.world.trajectory import ARC_STEP_M, VehicleGeometry, integrate_curve, normalised_steering


def test_constant_curvature_drives_a_circle_to_the_right():
    kappa = 0.05
    curve = integrate_curve(np.zeros(2), 0.0, np.full(int(30 / ARC_STEP_M) + 1, kappa))
    # Heading +z, turning right (toward +x): the centre of the circle is at x = +1/kappa.
    radius = np.linalg.norm(curve.xz - np.array([1 / kappa, 0.0]), axis=1)
    np.testing.assert_allclose(radius, 1 / kappa, atol=1e-4)
    assert curve.xz[-1, 0] > 0


def test_steering_is_the_bicycle_model_angle(compose_config):
    vehicle = VehicleGeometry.of(compose_config().world.vehicle)
    # wheelbase 2.8 m, max 30 deg: atan(2.8 * 0.05) = 7.970 deg -> 0.2657; far past the limit -> 1.
    np.testing.assert_allclose(normalised_steering(np.array([0.05, -0.05, 0.0, 5.0]), vehicle), [0.26567, -0.26567, 0.0, 1.0], atol=1e-4)


def test_vehicle_stands_on_rolling_terrain(compose_config):
    cfg = compose_config("world.frames=80").world
    world = build_world(cfg, seed=3)
    origin = world.poses[:, :3, 3]
    ground = world.terrain.elevation(origin[:, 0], origin[:, 2])
    height = -origin[:, 1] - ground
    assert np.all(np.abs(height - cfg.vehicle.camera_height_m) < 0.3)
    # Camera axes against gravity (+y): roll from the x axis, pitch of the body from z (less the tilt).
    roll = np.degrees(np.arcsin(world.poses[:, 1, 0]))
    pitch = np.degrees(np.arcsin(world.poses[:, 1, 2])) - cfg.vehicle.camera_pitch_deg
    assert np.ptp(roll) > 0.5 and np.ptp(pitch) > 0.5  # the ground is not a plane
    assert np.all(np.abs(roll) < 15) and np.all(np.abs(pitch) < 15)
    speed = np.linalg.norm(np.diff(origin, axis=0), axis=1) * cfg.fps
    assert speed.min() > 0.9 * cfg.speed_min_mps and speed.max() < 1.1 * cfg.speed_max_mps


LAPTOP_SAMPLE = 6  # of the laptop preset's training drives, the first: building all of them doubles the file's time


@pytest.fixture(scope="module")
def laptop_worlds(compose_config):
    cfg = compose_config()
    assert cfg.synthesize.sequences >= LAPTOP_SAMPLE
    return cfg, [build_world(cfg.world, sequence_seed(cfg.synthesize.seed, i)) for i in range(LAPTOP_SAMPLE)]


@pytest.mark.slow(seconds=30)
def test_laptop_preset_yields_enough_labels(laptop_worlds):
    """At least 300 training labels from the preset's drives: the first drives' share of them."""
    cfg, worlds = laptop_worlds
    label = cfg.label
    settings = (label.distance_m, label.strategy, label.stride_m, label.min_motion_m)
    count = sum(len(select_segments(w.poses[:, :3, 3], *settings)) for w in worlds)
    assert count >= 300 * LAPTOP_SAMPLE / cfg.synthesize.sequences


@pytest.mark.slow(seconds=16)
def test_laptop_preset_shows_all_eight_classes(laptop_worlds):
    cfg, worlds = laptop_worlds
    camera = camera_for(cfg.world)
    seen = np.zeros(len(CLASS_NAMES), int)
    for world in worlds:
        for pose in world.poses[::12]:
            seen += np.bincount(render_view(world, camera, pose, cfg.world.max_distance_m).semantic.ravel(), minlength=len(CLASS_NAMES))
    missing = [name for name, n in zip(CLASS_NAMES, seen, strict=True) if n == 0]
    assert not missing


def _digest(folder) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.slow(seconds=6)
def test_same_seed_same_bytes(compose_config, tmp_path):
    cfg = compose_config("world.frames=2", "world.width=160", "world.height=96").world
    record_sequence(cfg, 11, tmp_path / "a")
    record_sequence(cfg, 11, tmp_path / "b")
    record_sequence(cfg, 12, tmp_path / "c")
    a, b, c = _digest(tmp_path / "a"), _digest(tmp_path / "b"), _digest(tmp_path / "c")
    assert len(a) == 8 + 6  # 4 folders x 2 frames, calib, poses, times, steering, conditions, meta
    assert a == b
    assert a["image_l/000000.png"] != c["image_l/000000.png"]
