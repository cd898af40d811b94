"""Results by condition: the world's per-frame conditions on a hand-made world with known
shadows, water, paving and a fork, and the grouping of per-image counts into pooled IoU."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.data.manifest import Sample
from offroad_path.evaluate.by_condition import by_condition, read_conditions
from offroad_path.world.classes import DIRT, GRASS, PAVED, WATER
from offroad_path.world.conditions import STRAIGHT_RADIUS_M, frame_conditions
from offroad_path.world.scene import World
from offroad_path.world.terrain import Grid, Terrain
from offroad_path.world.trajectory import ARC_STEP_M, Curve, integrate_curve

FRAMES_AT_M = [0.0, 50.0, 85.0, 110.0, 135.0]


def straight(start: tuple[float, float], heading: float, length_m: float) -> Curve:
    n = int(length_m / ARC_STEP_M) + 1
    return integrate_curve(np.array(start, float), heading, np.zeros(n))


def hand_made_world() -> World:
    """Flat ground; a straight drive north (+z) on a dirt strip, paved from 50 to 70 m, a puddle 1.3 m
    right of the vehicle's side at 100 m, a shaded band from 120 to 125 m, a fork branching right at 150 m."""
    grid = Grid(x0=-40.0, z0=-10.0, step=0.05, shape=(4200, 1600))
    x = grid.x0 + grid.step * np.arange(grid.shape[1])
    z = grid.z0 + grid.step * np.arange(grid.shape[0])
    materials = np.full(grid.shape, GRASS, np.uint8)
    materials[:, np.abs(x) < 2.0] = DIRT
    materials[np.ix_((z >= 50) & (z <= 70), np.abs(x) < 2.0)] = PAVED
    materials[np.ix_((z >= 100) & (z <= 101), (x > 2.25) & (x < 3.0))] = WATER
    shadow = np.ones(grid.shape, np.float32)
    shadow[(z >= 120) & (z <= 125), :] = 0.0
    drive = straight((0.0, 0.0), 0.0, 200.0)
    poses = np.repeat(np.eye(4)[None], len(FRAMES_AT_M), axis=0)
    poses[:, 1, 3] = -1.8  # the camera 1.8 m above flat ground (y points down)
    poses[:, 2, 3] = FRAMES_AT_M
    return World(terrain=Terrain(np.zeros((10, 10)), Grid(-40.0, -10.0, 50.0, (10, 10))), materials=materials, material_grid=grid,
                 shadow=shadow, objects=None, palette=None, sky=None, drive=drive, track=drive, frame_s=np.array(FRAMES_AT_M),
                 poses=poses, steering=np.zeros(len(FRAMES_AT_M)), textures={},
                 forks=[straight((0.0, 150.0), np.deg2rad(45), 60.0)])  # fmt: skip


def test_world_conditions_of_a_hand_made_world(compose_config):
    rows = frame_conditions(hand_made_world(), compose_config().world)
    assert [r["surface"] for r in rows] == ["dirt", "paved", "dirt", "dirt", "dirt"]
    assert [r["water"] for r in rows] == [False, False, True, False, False]
    assert [r["fork"] for r in rows] == [False, False, False, False, True]  # 15 to 29 m ahead, 45 degrees right: in the 80-degree view
    assert rows[3]["shadow"] == pytest.approx(21 / 81, abs=0.02)  # samples every 0.25 m over 110-130 m: 21 of 81 lie in 120-125 m
    assert [r["shadow"] for i, r in enumerate(rows) if i != 3] == [0.0] * 4
    assert all(r["bend_radius_m"] == STRAIGHT_RADIUS_M for r in rows)


def test_bend_radius_of_a_circular_drive(compose_config):
    world = hand_made_world()
    world.drive = integrate_curve(np.zeros(2), 0.0, np.full(int(200 / ARC_STEP_M), 1 / 25.0))
    assert {r["bend_radius_m"] for r in frame_conditions(world, compose_config().world)} == {25.0}


def sample(root, f0: int, mirrored: bool = False) -> Sample:
    return Sample("drive", f0, mirrored, str(root / "drive" / "image_l" / f"{f0:06d}.png"), "", "", "", 300.0, 0.2)


def test_grouping_pools_the_counts_of_each_group(tmp_path):
    (tmp_path / "drive").mkdir()
    (tmp_path / "drive" / "conditions.csv").write_text(
        "frame,shadow,water,fork,surface,bend_radius_m\n0,0.0,False,False,dirt,50.0\n1,0.5,True,False,grass,15.0\n2,0.2,False,True,paved,25.0\n"
    )
    samples = [sample(tmp_path, 2), sample(tmp_path, 1), sample(tmp_path, 1, mirrored=True)]
    rows = read_conditions(samples)
    assert [r["frame"] for r in rows] == [2, 1, 1]  # mirrored copies share their frame's row
    per_image = np.array([[6, 2, 90, 2], [1, 3, 90, 4], [3, 1, 90, 0]])  # tp, fp, tn, fn of each sample
    table = by_condition(rows, {"net": per_image})
    got = dict(zip(table.keys, zip(table.frames, table.iou["net"], strict=True), strict=True))
    assert got["all"] == (3, pytest.approx(10 / (10 + 6 + 6)))
    assert got["shadow"] == (3, pytest.approx(10 / 22))  # 0.5, 0.5, 0.2: all at least 10 %
    assert got["water"] == (2, pytest.approx(4 / (4 + 4 + 4)))
    assert got["off_track"] == got["sharp_bend"] == got["water"]
    assert got["fork"] == (1, pytest.approx(6 / 10)) and got["paved"] == got["fork"] and got["bend"] == got["fork"]
    assert got["dirt"][0] == 0 and np.isnan(got["dirt"][1]) and table.metrics({"net": "net"})["dirt"] == {"frames": 0, "net": None}


def test_recordings_without_conditions_get_no_table_and_a_short_table_is_an_error(tmp_path):
    assert read_conditions([sample(tmp_path, 0)]) is None
    (tmp_path / "drive").mkdir()
    (tmp_path / "drive" / "conditions.csv").write_text("frame,shadow,water,fork,surface,bend_radius_m\n0,0.0,False,False,dirt,50.0\n")
    with pytest.raises(ValueError, match=r"drive/conditions\.csv: has no row for frame 3"):
        read_conditions([sample(tmp_path, 3)])
    (tmp_path / "drive" / "conditions.csv").write_text("frame,shadow,water,fork,surface,bend_radius_m\n0,0.0,maybe,False,dirt,50.0\n")
    with pytest.raises(ValueError, match=r"drive/conditions\.csv: line 2: 'maybe' is not true"):
        read_conditions([sample(tmp_path, 0)])
