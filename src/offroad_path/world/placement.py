"""Objects placed around the drive of a rendered world: trees, bushes, posts, boxes and fences,
drawn from the world's generator in a fixed order (the same seed places the same objects)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from offroad_path.config.world_schema import WorldConfig
from offroad_path.geometry.exact import norm_rows
from offroad_path.world.classes import BASE_COLORS, FOLIAGE, OBSTACLE, TREE, TRUNK_COLOR
from offroad_path.world.objects import Objects
from offroad_path.world.terrain import Terrain, polyline_mask
from offroad_path.world.trajectory import ARC_STEP_M, Curve


@dataclass
class Placement:
    """Placing objects around the drive: the generator, the settings, the ground, the drive, the
    cells the vehicle must find clear, and the objects placed so far."""

    rng: np.random.Generator
    cfg: WorldConfig
    terrain: Terrain
    drive: Curve
    objects: Objects = field(default_factory=Objects)

    def __post_init__(self) -> None:
        self.grid = self.terrain.grid
        self.keep_clear = polyline_mask(self.grid, self.drive.xz, self.cfg.vehicle.width_m + 2.5) > 0

    def ground_y(self, xz: np.ndarray) -> float:
        return -float(self.terrain.elevation(np.array([xz[0]]), np.array([xz[1]]))[0])

    def blocked(self, xz: np.ndarray) -> bool:
        row, col = self.grid.nearest(xz[:1], xz[1:])
        return bool(self.keep_clear[row[0], col[0]])


def place_objects(place: Placement, track: Curve, density: np.ndarray) -> Objects:
    """Trees and bushes off the drive and the track, then the man-made obstacles beside the drive."""
    rng, cfg, grid, objects = place.rng, place.cfg, place.grid, place.objects
    on_track = polyline_mask(grid, track.xz, cfg.track_width_m + 1.0) > 0
    area_ha = grid.shape[0] * grid.shape[1] * grid.step**2 / 1e4

    def free_points(n: int, blocked: np.ndarray) -> np.ndarray:
        xz = rng.uniform([grid.x0, grid.z0], [grid.x0 + grid.shape[1] * grid.step, grid.z0 + grid.shape[0] * grid.step], (n, 2))
        row, col = grid.nearest(xz[:, 0], xz[:, 1])
        return xz[~blocked[row, col]]

    blocked = place.keep_clear | on_track
    for xz in free_points(rng.poisson(cfg.trees_per_hectare * density[2] * area_ha), blocked):
        y = place.ground_y(xz)
        trunk_r, trunk_h = rng.uniform(0.12, 0.3), rng.uniform(1.8, 4.0)
        crown_r = rng.uniform(1.2, 2.8)
        objects.add_cylinder(xz, (y - trunk_h - 0.5 * crown_r, y + 0.3), trunk_r, TREE, np.asarray(TRUNK_COLOR))
        crown_colour = np.asarray(BASE_COLORS[TREE]) * rng.uniform(0.7, 1.3)
        objects.add_sphere(np.array([xz[0], y - trunk_h - 0.6 * crown_r, xz[1]]), crown_r, TREE, crown_colour)
    for xz in free_points(rng.poisson(cfg.bushes_per_hectare * density[3] * area_ha), blocked):
        r = rng.uniform(0.35, 1.1)
        colour = np.asarray(BASE_COLORS[FOLIAGE]) * rng.uniform(0.7, 1.4)
        objects.add_sphere(np.array([xz[0], place.ground_y(xz) - 0.35 * r, xz[1]]), r, FOLIAGE, colour)
    _man_made(place)
    return objects


def _man_made(place: Placement) -> None:
    """Posts, boxes and fences near the drive: obstacles the path has to avoid."""
    rng, cfg, drive, objects = place.rng, place.cfg, place.drive, place.objects
    normal = drive.normal()
    n = rng.poisson(cfg.obstacles_per_100m * drive.length / 100.0)
    for _ in range(n):
        i = int(rng.uniform(0.0, 1.0) * (len(drive.xz) - 1))
        side = rng.choice([-1, 1])
        xz = drive.xz[i] + normal[i] * side * rng.uniform(cfg.vehicle.width_m / 2 + 1.5, 10.0)
        if place.blocked(xz):
            continue
        y = place.ground_y(xz)
        grey = rng.uniform(0.3, 0.8)
        colour = np.asarray(BASE_COLORS[OBSTACLE]) * grey / 0.5 * rng.uniform(0.85, 1.15, 3)
        kind = rng.choice(["post", "box", "fence"], p=[0.35, 0.35, 0.3])
        if kind == "post":
            objects.add_cylinder(xz, (y - rng.uniform(0.8, 1.5), y + 0.2), rng.uniform(0.06, 0.15), OBSTACLE, colour)
        elif kind == "box":
            half = rng.uniform([0.25, 0.2, 0.25], [0.7, 0.6, 0.9])
            objects.add_box(np.array([xz[0], y - half[1] + 0.05, xz[1]]), half, rng.uniform(0, np.pi), OBSTACLE, colour)
        else:
            _fence(place, i, side, colour)


def _fence(place: Placement, i: int, side: int, colour: np.ndarray) -> None:
    """A fence beside the drive from its point i: posts every 2.5 m and two rails between them."""
    drive, objects = place.drive, place.objects
    offset = side * place.rng.uniform(place.cfg.vehicle.width_m / 2 + 2.0, 7.0)
    span_steps = int(place.rng.uniform(8.0, 20.0) / ARC_STEP_M)
    post_every = int(2.5 / ARC_STEP_M)
    posts = []
    for j in range(i, min(i + span_steps, len(drive.xz) - 1), post_every):
        xz = drive.xz[j] + drive.normal()[j] * offset
        if place.blocked(xz):
            break
        posts.append((xz, place.ground_y(xz)))
        objects.add_box(np.array([xz[0], posts[-1][1] - 0.55, xz[1]]), np.array([0.06, 0.6, 0.06]), drive.heading[j], OBSTACLE, colour)
    for (a, ya), (b, yb) in itertools.pairwise(posts):
        mid, length = (a + b) / 2, norm_rows(b - a)
        yaw = np.arctan2(-(b[1] - a[1]), b[0] - a[0])  # rail's local x, (cos, 0, -sin), along a -> b
        for height in (0.45, 0.95):
            y = (ya + yb) / 2 - height
            objects.add_box(np.array([mid[0], y, mid[1]]), np.array([length / 2, 0.05, 0.025]), yaw, OBSTACLE, colour * 0.9)
