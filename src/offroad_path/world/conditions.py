"""What the world knows about each frame's next metres of driving, for results by condition.

Holder & Breckon name shadows across the path, water and forks as their networks' failure cases;
the rendered world knows each exactly, so every frame gets one row of `conditions.csv`:

- shadow: the fraction of the vehicle's corridor (its width, the next `distance_m` of the drive)
  that objects shade;
- water: whether water lies in the corridor or within `near_m` of its sides;
- fork: whether a side track the vehicle does not take is in the camera's field of view, 3 to
  30 m ahead (hills and trees that hide it are not checked);
- surface: what the corridor's centre line mostly drives on: paved, dirt or grass (grass: off
  the track, on a detour), or mixed when no class covers half of it;
- bend_radius_m: the drive's radius over the corridor, 1 / mean |curvature|;
- track, light, look, canopy: the world's appearance (offroad_path.world.appearance), the same on
  every frame: the track's surface, the light, "held_out" for a combination no training drive
  shows ("seen" otherwise), "tree_lined" where trees along the track dapple it ("open" otherwise).
  A world without one (world.appearance.enabled false) is the old look: dirt, clear, seen, open.
"""

from __future__ import annotations

import numpy as np

from offroad_path.config.world_schema import WorldConfig
from offroad_path.geometry.exact import matmul, rigid_inverse
from offroad_path.world.classes import DIRT, GRASS, PAVED, WATER
from offroad_path.world.groups import SINGLE_LOOK
from offroad_path.world.kernels import sample_bilinear
from offroad_path.world.scene import World
from offroad_path.world.trajectory import ARC_STEP_M

COLUMNS = ("frame", "shadow", "water", "fork", "surface", "bend_radius_m", "track", "light", "look", "canopy")
SURFACES = {PAVED: "paved", DIRT: "dirt", GRASS: "grass"}
STRAIGHT_RADIUS_M = 10_000.0  # the radius written for a straight drive
FORK_RANGE_M = (3.0, 30.0)


def frame_conditions(world: World, cfg: WorldConfig, distance_m: float = 20.0, near_m: float = 2.0) -> list[dict]:
    """One row per frame (see the module docstring), in COLUMNS order."""
    half = cfg.vehicle.width_m / 2
    tan_half_fov = np.tan(np.deg2rad(cfg.hfov_deg) / 2)
    fork_points = _fork_points(world)
    look = SINGLE_LOOK if world.look is None else world.look.tags() | {"canopy": "tree_lined" if world.look.tree_lined else "open"}
    rows = []
    for k, s0 in enumerate(world.frame_s):
        s = s0 + np.arange(0.0, distance_m + 1e-9, 0.25)
        xz, heading, curvature = world.drive.at(s)
        corridor = _across(xz, heading, np.linspace(-half, half, 5))
        lit = sample_bilinear(world.shadow, *world.material_grid.coords(corridor[:, 0], corridor[:, 1]))
        wide = _across(xz, heading, np.linspace(-half - near_m, half + near_m, 9))
        water = bool(np.any(world.materials[world.material_grid.nearest(wide[:, 0], wide[:, 1])] == WATER))
        centre = world.materials[world.material_grid.nearest(xz[:, 0], xz[:, 1])]
        classes, count = np.unique(centre, return_counts=True)
        top = int(np.argmax(count))
        surface = SURFACES.get(int(classes[top]), "mixed") if count[top] >= len(centre) / 2 else "mixed"
        mean_curvature = float(np.mean(np.abs(curvature)))
        radius = min(1.0 / mean_curvature, STRAIGHT_RADIUS_M) if mean_curvature > 0 else STRAIGHT_RADIUS_M
        fork = _in_view(fork_points, world.poses[k], tan_half_fov) if len(fork_points) else False
        rows.append(
            {
                "frame": k,
                "shadow": round(float(np.mean(lit < 0.5)), 4),
                "water": water,
                "fork": fork,
                "surface": surface,
                "bend_radius_m": round(radius, 2),
            }
            | look
        )
    return rows


def conditions_csv(rows: list[dict]) -> str:
    """The text of conditions.csv: a header of COLUMNS, one line per frame."""
    return ",".join(COLUMNS) + "\n" + "".join(",".join(str(row[c]) for c in COLUMNS) + "\n" for row in rows)


def _across(xz: np.ndarray, heading: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Points (N * len(offsets), 2) at `offsets` metres to the right of each centre point."""
    normal = np.stack([np.cos(heading), -np.sin(heading)], axis=1)
    return (xz[:, None, :] + offsets[None, :, None] * normal[:, None, :]).reshape(-1, 2)


def _fork_points(world: World) -> np.ndarray:
    """World points (N, 4) homogeneous, on the ground, of every fork from 4 m past its branch point
    (nearer, it overlaps the track) to 20 m."""
    parts = [fork.xz[int(4.0 / ARC_STEP_M) : int(20.0 / ARC_STEP_M)] for fork in world.forks]
    xz = np.concatenate(parts) if parts else np.zeros((0, 2))
    y = -world.terrain.elevation(xz[:, 0], xz[:, 1])  # the world's y points down
    return np.stack([xz[:, 0], y, xz[:, 1], np.ones(len(xz))], axis=1)


def _in_view(points: np.ndarray, camera_to_world: np.ndarray, tan_half_fov: float) -> bool:
    x, _, z, _ = matmul(rigid_inverse(camera_to_world), points.T)
    ahead = (z > FORK_RANGE_M[0]) & (z < FORK_RANGE_M[1])
    return bool(np.any(ahead & (np.abs(x) < z * tan_half_fov)))
