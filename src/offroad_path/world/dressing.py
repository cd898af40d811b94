"""A world dressed in its appearance (world/appearance.py): vegetation shapes in place of spheres on
sticks, trees along the track, tall grass and fallen wood, and the ruts a track is worn into.

Everything here draws from the appearance's own generator, after the world's geometry is drawn.
"""

from __future__ import annotations

import numpy as np

from offroad_path.world.appearance import Appearance
from offroad_path.world.classes import BASE_COLORS, DIRT, FOLIAGE, TREE, TRUNK_COLOR
from offroad_path.world.objects import CYLINDER, SPHERE, Objects
from offroad_path.world.placement import Placement
from offroad_path.world.terrain import Grid, polyline_mask
from offroad_path.world.trajectory import ARC_STEP_M, Curve

RUT_OFFSET_M = 0.8  # half the wheel track of the vehicles that wore it
RUT_WIDTH_M = 0.45


def _crown(objects: Objects, rng: np.random.Generator, ball: tuple[np.ndarray, float], style: str, colour: np.ndarray) -> None:
    """A tree crown filling the old crown's `ball` (centre, radius) in `style`: broadleaf lumps or conifer tiers."""
    centre, radius = ball
    if style == "conifer":
        # Tiers narrowing upwards from below the old crown's centre to above its top (y points down).
        for k, scale in enumerate((1.0, 0.78, 0.56, 0.34)):
            y = centre[1] + 0.9 * radius - k * 0.75 * radius
            objects.add_sphere(np.array([centre[0], y, centre[2]]), scale * radius * 0.85, TREE, colour * rng.uniform(0.9, 1.1))
        return
    for _ in range(int(rng.integers(3, 6))):  # broadleaf: lumps around the centre, an irregular outline
        offset = rng.uniform(-0.55, 0.55, 3) * radius * np.array([1.0, 0.6, 1.0])
        objects.add_sphere(centre + offset, radius * rng.uniform(0.45, 0.7), TREE, colour * rng.uniform(0.85, 1.15))


def reshape_vegetation(objects: Objects, look: Appearance, rng: np.random.Generator, palette: np.ndarray) -> Objects:
    """The same trees, bushes and obstacles, with crowns and bushes in the look's shapes and the
    season's colours (palette (8, 3)); scrub: two trees in three become bushes."""
    out = Objects()
    scrub_ground_y = None  # where a tree turned into a bush stood
    for kind, params, cls, colour in zip(objects.kind, objects.params, objects.cls, objects.color, strict=True):
        colour = np.asarray(colour)
        if cls in (TREE, FOLIAGE) and kind == SPHERE:  # the season's hue, each plant's own jitter kept
            colour = colour / np.asarray(BASE_COLORS[cls]) * palette[cls]
        if kind == CYLINDER and cls == TREE:  # a trunk; its crown follows
            if look.vegetation == "scrub" and rng.uniform() < 0.67:
                scrub_ground_y = params[3] - 0.3  # the trunk's foot is 0.3 m below the ground
                continue
            out.add_cylinder(np.array(params[:2]), (params[2], params[3]), params[4], cls, colour)
        elif kind == SPHERE and cls == TREE:
            centre, radius = np.array(params[:3]), params[3]
            if scrub_ground_y is not None:  # a bush on the ground where the tree stood
                _bush(out, rng, np.array([centre[0], scrub_ground_y - 0.2 * radius, centre[2]]), radius * 0.6, colour)
                scrub_ground_y = None
                continue
            style = rng.choice(["broadleaf", "conifer"]) if look.vegetation == "mixed" else look.vegetation
            _crown(out, rng, (centre, radius), "conifer" if style == "conifer" else "broadleaf", colour)
        elif kind == SPHERE and cls == FOLIAGE:
            _bush(out, rng, np.array(params[:3]), params[3], colour)
        else:
            out.add(kind, params, cls, colour)
    return out


def _bush(objects: Objects, rng: np.random.Generator, centre: np.ndarray, radius: float, colour: np.ndarray) -> None:
    """Two to four overlapping lumps, wider than tall."""
    for _ in range(int(rng.integers(2, 5))):
        offset = rng.uniform(-0.6, 0.6, 3) * radius * np.array([1.0, 0.2, 1.0])
        objects.add_sphere(
            centre + offset + np.array([0.0, 0.25 * radius, 0.0]), radius * rng.uniform(0.5, 0.8), FOLIAGE, colour * rng.uniform(0.85, 1.15)
        )


def add_undergrowth(place: Placement, look: Appearance, palette: np.ndarray) -> None:
    """Trees along the track (tree_lined), tufts of tall grass and fallen logs beside the drive, in the
    world's colours (palette (8, 3))."""
    rng, drive, objects = place.rng, place.drive, place.objects
    normal = drive.normal()
    steps = len(drive.xz)
    colours = {"crown": palette[TREE], "tuft": palette[FOLIAGE] * 1.2}
    if look.tree_lined:
        i = int(rng.integers(0, 20))
        while i < steps:
            for side in (-1, 1):
                xz = drive.xz[i] + normal[i] * side * rng.uniform(3.4, 6.0)
                if rng.uniform() < 0.75 and not place.blocked(xz):
                    y, trunk_h, crown_r = place.ground_y(xz), rng.uniform(3.5, 5.5), rng.uniform(2.2, 3.6)
                    objects.add_cylinder(xz, (y - trunk_h - 0.4 * crown_r, y + 0.3), rng.uniform(0.15, 0.35), TREE, np.asarray(TRUNK_COLOR))
                    style = "conifer" if look.vegetation == "conifer" else "broadleaf"
                    _crown(objects, rng, (np.array([xz[0], y - trunk_h - 0.5 * crown_r, xz[1]]), crown_r), style, colours["crown"])
            i += int(rng.uniform(5.0, 11.0) / ARC_STEP_M)
    for _ in range(rng.poisson(25 * drive.length / 100.0)):  # tall grass
        i = int(rng.integers(0, steps))
        xz = drive.xz[i] + normal[i] * rng.choice([-1, 1]) * rng.uniform(2.6, 9.0)
        if not place.blocked(xz):
            y, height = place.ground_y(xz), rng.uniform(0.35, 1.1)
            objects.add_cylinder(xz, (y - height, y + 0.1), rng.uniform(0.12, 0.4), FOLIAGE, colours["tuft"] * rng.uniform(0.8, 1.2))
    for _ in range(rng.poisson(3 * drive.length / 100.0)):  # fallen wood
        i = int(rng.integers(0, steps))
        xz = drive.xz[i] + normal[i] * rng.choice([-1, 1]) * rng.uniform(3.0, 12.0)
        if not place.blocked(xz):
            r = rng.uniform(0.1, 0.22)
            half = np.array([rng.uniform(0.8, 2.5), r, r])
            objects.add_box(
                np.array([xz[0], place.ground_y(xz) - r + 0.03, xz[1]]),
                half,
                rng.uniform(0, np.pi),
                TREE,
                np.asarray(TRUNK_COLOR) * rng.uniform(0.7, 1.2),
            )


def rut_map(grid: Grid, track: Curve, materials: np.ndarray) -> np.ndarray:
    """uint8 (rows, cols): 255 on the two wheel ruts of the track, on its DIRT cells only."""
    normal = track.normal()
    wear = np.zeros(grid.shape, np.uint8)
    for side in (-1, 1):
        np.maximum(wear, polyline_mask(grid, track.xz + side * RUT_OFFSET_M * normal, RUT_WIDTH_M), out=wear)
    wear[materials != DIRT] = 0
    return wear
