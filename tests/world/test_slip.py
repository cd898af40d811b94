"""Traction (offroad_path.world.slip): a factor of 1 is today's world byte for byte; with slip, the
recorded steering is the input that makes the true motion on that ground, and the driven vehicle
turns by the factor."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from offroad_path.drive.vehicle import State, Vehicle, advance
from offroad_path.world.classes import CLASS_NAMES
from offroad_path.world.record import record_sequence, steering_under_slip
from offroad_path.world.scene import build_world
from offroad_path.world.slip import make_slip
from offroad_path.world.trajectory import VehicleGeometry

SMALL = ("world.frames=8", "world.width=64", "world.height=36")
NO_JITTER = ("world.slip.jitter=0", "world.slip.noise=0")


@pytest.mark.slow(seconds=7)
def test_a_factor_of_one_everywhere_renders_todays_world_byte_for_byte(compose_config, tmp_path):
    plain = compose_config(*SMALL).world
    slippery = compose_config().world.slip.factors
    ones = compose_config(*SMALL, "world.slip.enabled=true", *NO_JITTER, *(f"world.slip.factors.{c}=1.0" for c in slippery)).world
    assert set(ones.slip.factors.values()) == {1.0} and len(slippery) >= 4
    record_sequence(plain, seed=3, out_dir=tmp_path / "plain")
    record_sequence(ones, seed=3, out_dir=tmp_path / "ones")
    files = sorted(p.relative_to(tmp_path / "plain") for p in (tmp_path / "plain").rglob("*") if p.is_file())
    assert len(files) == 4 * 8 + 6
    for name in files:
        if name.name != "meta.json":
            assert (tmp_path / "ones" / name).read_bytes() == (tmp_path / "plain" / name).read_bytes(), name
    meta_plain = json.loads((tmp_path / "plain" / "meta.json").read_text())
    meta_ones = json.loads((tmp_path / "ones" / "meta.json").read_text())
    assert "slip" not in meta_plain and meta_ones.pop("slip")["enabled"] is True
    assert {k: v for k, v in meta_ones.items() if k != "steering"} == {k: v for k, v in meta_plain.items() if k != "steering"}


@pytest.mark.slow(seconds=6)
def test_with_slip_the_recorded_steering_makes_the_true_motion_on_that_ground(compose_config):
    cfg = compose_config(*SMALL, "world.frames=60", "world.slip.enabled=true", *NO_JITTER).world
    slippery, plain = build_world(cfg, 7), build_world(compose_config(*SMALL, "world.frames=60").world, 7)
    np.testing.assert_array_equal(slippery.poses, plain.poses)  # the same drive
    vehicle = VehicleGeometry.of(cfg.vehicle)
    xz, _, curvature = plain.drive.at(plain.frame_s)
    factor = np.array([cfg.slip.factors.get(CLASS_NAMES[c], 1.0) for c in plain.surface(xz)])
    lock = math.radians(vehicle.max_steering_deg)
    # The bicycle model's yaw rate times the ground's factor gives back the drive's curvature.
    np.testing.assert_allclose(np.tan(slippery.steering * lock) / vehicle.wheelbase_m * factor, curvature, atol=1e-12)
    assert factor.min() < 1.0  # some of it is slippery
    assert np.all(np.abs(slippery.steering) >= np.abs(plain.steering))


@pytest.mark.slow(seconds=8)
def test_steering_under_slip_of_a_recorded_sequence_and_a_config_that_did_not_render_it(compose_config, tmp_path):
    cfg = compose_config(*SMALL).world
    record_sequence(cfg, seed=4, out_dir=tmp_path / "seq")
    slippery = compose_config(*SMALL, "world.slip.enabled=true").world
    steering = steering_under_slip(cfg, [tmp_path / "seq"], workers=1)
    np.testing.assert_array_equal(steering["seq"], build_world(slippery, 4).steering)
    with pytest.raises(ValueError, match=re.escape(f"{tmp_path / 'seq' / 'meta.json'}: rendered with other world settings")):
        steering_under_slip(compose_config(*SMALL, "world.speed_max_mps=9").world, [tmp_path / "seq"], workers=1)


def test_an_unknown_surface_is_named(compose_config):
    cfg = compose_config("+world.slip.factors.gravel=0.5").world
    with pytest.raises(ValueError, match=r"world\.slip\.factors: unknown surface class 'gravel'"):
        make_slip(cfg.slip, 0, np.zeros(2), np.ones(2) * 10)


def test_the_driven_vehicle_turns_by_the_grounds_factor(compose_config):
    geometry = VehicleGeometry.of(compose_config().world.vehicle)
    grip, half = Vehicle(geometry, 1e6), Vehicle(geometry, 1e6, yaw_factor=lambda xz: 0.5)
    a, _ = advance(State(np.zeros(2), 0.0, 0.0), grip, 0.2, 5.0, 0.2)
    b, _ = advance(State(np.zeros(2), 0.0, 0.0), half, 0.2, 5.0, 0.2)
    assert b.heading == pytest.approx(a.heading / 2, rel=1e-12)
