"""Closed-loop driving (offroad_path.drive) on hand-made tracks, checked against geometry worked
out by hand: the oracle stays on, straight ahead leaves a circle where the circle says, a steady
steering error drifts as the bicycle model says, an intervention puts the vehicle back on the line,
an object ahead is hit where it stands."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from offroad_path.drive.course import Course
from offroad_path.drive.interventions import finding, score, versus_end_to_end
from offroad_path.drive.loop import LoopSettings, Setup, drive
from offroad_path.drive.policies import OraclePolicy, Policy, StraightPolicy
from offroad_path.drive.vehicle import State, Vehicle, advance
from offroad_path.statistics.bootstrap import Resampling
from offroad_path.world.classes import DIRT, FOLIAGE, OBSTACLE, TREE, WATER
from offroad_path.world.objects import Objects
from offroad_path.world.terrain import Grid, Terrain
from offroad_path.world.trajectory import ARC_STEP_M, VehicleGeometry, integrate_curve

GEOMETRY = VehicleGeometry(wheelbase_m=2.8, track_m=1.6, width_m=1.9, length_m=4.2, camera_height_m=1.8,
                           camera_forward_m=0.4, camera_pitch_deg=7.0, max_steering_deg=30.0)  # fmt: skip
FAST_WHEELS = 1e6  # deg/s: the wheels reach the command in the first sub-step
SETTINGS = LoopSettings(rate_hz=5.0, speed_mps=5.0, length_m=60.0, respawn_m=5.0, timeout_factor=3.0, water_intervenes=True)
CORRIDOR_M = 2.5


def hand_made_world(curvature: float, length_m: float = 150.0, objects: Objects | None = None, water: tuple | None = None):
    """Flat dirt ground with one track of constant curvature from the origin heading +z, which is
    also the reference drive; no forks. water: (x0, x1, z0, z1) of a pond."""
    n = int(length_m / ARC_STEP_M) + 1
    curve = integrate_curve(np.zeros(2), 0.0, np.full(n, curvature))
    grid = Grid(x0=-200.0, z0=-200.0, step=0.25, shape=(1601, 1601))
    materials = np.full(grid.shape, DIRT, np.uint8)
    if water is not None:
        x0, x1, z0, z1 = water
        materials[int((z0 + 200) / 0.25) : int((z1 + 200) / 0.25), int((x0 + 200) / 0.25) : int((x1 + 200) / 0.25)] = WATER

    def surface(xz: np.ndarray) -> np.ndarray:
        row, col = grid.nearest(xz[:, 0], xz[:, 1])
        return materials[row, col]

    return SimpleNamespace(drive=curve, track=curve, forks=[], objects=objects or Objects(), surface=surface,
                           terrain=Terrain(np.zeros(grid.shape), grid))  # fmt: skip


def setup_for(world, rate: float = FAST_WHEELS, settings: LoopSettings = SETTINGS) -> Setup:
    return Setup(Course(world, GEOMETRY, CORRIDOR_M, (0.25, 2.0)), Vehicle(GEOMETRY, rate), None, settings)


class Constant(Policy):
    """Steers one road-wheel angle whatever it sees."""

    def __init__(self, angle: float):
        self.name, self.angle = "constant", angle

    def act(self, frame, seen) -> float:
        return self.angle


@pytest.mark.parametrize("curvature", [0.0, 1 / 20.0])
def test_the_oracle_drives_a_straight_and_a_circle_without_interventions(curvature):
    log = drive(setup_for(hand_made_world(curvature), rate=60.0), OraclePolicy(10.0), 0.0)
    assert log.interventions == []
    assert log.distance_m == pytest.approx(60.0, abs=SETTINGS.speed_mps / SETTINGS.rate_hz)
    # Pure pursuit of the rear axle cuts a circle a little inside; on the straight it stays on.
    assert max(log.offsets) < (0.01 if curvature == 0 else 0.3)


def test_straight_ahead_leaves_the_circle_where_geometry_says():
    radius = 20.0
    log = drive(setup_for(hand_made_world(1 / radius)), StraightPolicy(), 0.0)
    # Along the tangent, the body centre is sqrt(R^2 + d^2) - R from the circle: it passes the
    # corridor at d = sqrt((R + c)^2 - R^2) = 10.31 m; the intervention is counted at the end of
    # the control period in which that happens.
    leave = math.sqrt((radius + CORRIDOR_M) ** 2 - radius**2)
    x, z, why = log.interventions[0]
    assert why == "corridor"
    assert x == pytest.approx(0.0, abs=1e-9)  # straight along the start's heading, +z
    assert leave <= z < leave + SETTINGS.speed_mps / SETTINGS.rate_hz


def test_a_steady_steering_error_drifts_as_the_bicycle_model_says():
    """0.1 of the lock too far right on a straight: the rear axle goes round a circle of radius
    L / tan(delta), and the body centre sits L / 2 ahead of it."""
    delta = 0.1 * math.radians(GEOMETRY.max_steering_deg)
    vehicle = Vehicle(GEOMETRY, FAST_WHEELS)
    state = State(np.zeros(2), 0.0, 0.0)
    for _ in range(10):  # 10 m at 5 m/s, 0.2 s periods
        state, _ = advance(state, vehicle, delta, 5.0, 0.2)
    radius = GEOMETRY.wheelbase_m / math.tan(delta)
    turned = 10.0 / radius
    half = GEOMETRY.wheelbase_m / 2
    rear = np.array([radius * (1 - math.cos(turned)), -half + radius * math.sin(turned)])
    expected = rear + half * np.array([math.sin(turned), math.cos(turned)])
    assert state.heading == pytest.approx(turned, rel=1e-9)
    np.testing.assert_allclose(state.xz, expected, atol=1e-4)
    assert state.xz[0] > 0.6  # to the right, by about 0.66 m after 10 m


def test_a_steering_rate_limit_delays_the_turn():
    slow, fast = Vehicle(GEOMETRY, 10.0), Vehicle(GEOMETRY, FAST_WHEELS)
    lock = math.radians(GEOMETRY.max_steering_deg)
    a, _ = advance(State(np.zeros(2), 0.0, 0.0), slow, lock, 5.0, 0.2)
    b, _ = advance(State(np.zeros(2), 0.0, 0.0), fast, 2 * lock, 5.0, 0.2)  # beyond the lock: held at it
    assert a.steer == pytest.approx(math.radians(10.0) * 0.2)
    assert b.steer == pytest.approx(lock)
    assert 0 < a.heading < b.heading


def test_an_intervention_puts_the_vehicle_back_on_the_centre_line():
    radius = 20.0
    log = drive(setup_for(hand_made_world(1 / radius)), StraightPolicy(), 0.0)
    gap = next(i for i, p in enumerate(log.trajectory) if math.isnan(p[0]))  # the vehicle was moved here
    # The next step starts on the circle, heading along it, and drives 1 m straight: sqrt(R^2 + 1) - R from it.
    x, z = log.trajectory[gap + 1]
    assert math.hypot(x - radius, z) - radius == pytest.approx(math.sqrt(radius**2 + 1) - radius, abs=1e-3)
    # It started respawn_m past the farthest progress: the arc of the last step still in the corridor
    # (the circle's centre is (R, 0); a point's arc is R times its angle from the start).
    x_last, z_last = log.trajectory[gap - 2]
    farthest = radius * math.atan2(z_last, radius - x_last)
    started = radius * (math.atan2(z, radius - x) - math.atan(1 / radius))
    assert started == pytest.approx(farthest + SETTINGS.respawn_m, abs=ARC_STEP_M)


def test_an_object_ahead_is_hit_where_it_stands():
    objects = Objects()
    objects.add_cylinder(np.array([0.3, 30.0]), (-1.5, 0.2), 0.1, OBSTACLE, np.ones(3))  # a post beside the line, 1.5 m tall
    log = drive(setup_for(hand_made_world(0.0, objects=objects)), OraclePolicy(10.0), 0.0)
    _, z, why = log.interventions[0]
    assert why == "object"
    # The front of the body (2.1 m ahead of its centre) reaches the post's disc at z = 30 - 0.1.
    front_reaches = 30.0 - 0.1 - GEOMETRY.length_m / 2
    assert front_reaches <= z < front_reaches + 1.0


def test_a_post_beside_the_body_or_a_crown_above_it_is_not_hit():
    objects = Objects()
    objects.add_cylinder(np.array([1.5, 30.0]), (-1.5, 0.2), 0.1, OBSTACLE, np.ones(3))  # 1.5 m right: clear of the 0.95 m half-width
    objects.add_sphere(np.array([0.0, -3.5, 40.0]), 1.0, TREE, np.ones(3))  # a crown from 2.5 m up: above the body's band
    world = hand_made_world(0.0, objects=objects)
    setup = setup_for(world)
    setup = replace(setup, course=Course(world, GEOMETRY, CORRIDOR_M, (0.25, 2.0), foliage=True))
    assert drive(setup, OraclePolicy(10.0), 0.0).interventions == []


def test_foliage_is_brushed_through_unless_it_counts():
    objects = Objects()
    objects.add_sphere(np.array([0.0, -1.0, 30.0]), 0.8, FOLIAGE, np.ones(3))  # a bush on the line
    world = hand_made_world(0.0, objects=objects)
    brushed = drive(setup_for(world), OraclePolicy(10.0), 0.0)
    counted = setup_for(world)
    counted = replace(counted, course=Course(world, GEOMETRY, CORRIDOR_M, (0.25, 2.0), foliage=True))
    assert brushed.interventions == []
    assert [why for _, _, why in drive(counted, OraclePolicy(10.0), 0.0).interventions] == ["object"]


def test_water_is_an_intervention_or_counted():
    world = hand_made_world(0.0, water=(-1.0, 1.0, 20.0, 22.0))
    counted = drive(setup_for(world, settings=replace(SETTINGS, water_intervenes=False)), OraclePolicy(10.0), 0.0)
    intervened = drive(setup_for(world), OraclePolicy(10.0), 0.0)
    assert counted.interventions == [] and counted.water_entries == 1
    assert [why for _, _, why in intervened.interventions] == ["water"]


def test_scores_against_hand_counts():
    def log(policy: str, interventions: int, metres: float):
        g = drive(setup_for(hand_made_world(0.0), settings=replace(SETTINGS, length_m=metres)),
                  StraightPolicy(), 0.0)  # fmt: skip
        g.policy, g.interventions = policy, [(0.0, 0.0, "corridor")] * interventions
        return g

    a = [log("unet", 0, 20.0), log("unet", 1, 20.0), log("unet", 0, 20.0)]
    b = [log("pilotnet", 1, 20.0), log("pilotnet", 2, 20.0), log("pilotnet", 1, 20.0)]
    resampling = Resampling(200, 0, 0.95)
    s = score(a, 6.0, resampling)
    # 1 intervention in 60 m: 16.7 per km; 12 s driven: 1 - 6 / 12 = 50 % autonomy.
    assert s.per_km.estimate == pytest.approx(1000 / 60)
    assert s.autonomy_pct.estimate == pytest.approx(50.0)
    # the rate's exact Poisson interval, 1 event in 0.06 km: chi2(0.025, 2) / 2 = 0.02532 and chi2(0.975, 4) / 2 = 5.5716
    assert s.per_km.low == pytest.approx(0.025318 / 0.06, rel=1e-4) and s.per_km.high == pytest.approx(5.571643 / 0.06, rel=1e-4)
    none = score([log("unet", 0, 20.0)] * 3, 6.0, resampling).per_km  # none in 60 m: not [0, 0]
    assert none.low == 0.0 and none.high == pytest.approx(3.688879 / 0.06, rel=1e-4)
    comparisons = versus_end_to_end({"unet": a, "pilotnet": b}, ["pilotnet"], resampling)
    difference, exact_p = comparisons["unet", "pilotnet"]
    assert difference.estimate == pytest.approx((1 - 4) * 1000 / 60)
    assert difference.high < 0  # every drive: one fewer; every resample is below 0
    assert exact_p == pytest.approx(0.375)  # 1 of 5 at even chance, two-sided: the exact test does not reject
    assert "interval below 0: unet - pilotnet" in finding(comparisons) and "exact p 0.3750" in finding(comparisons)
