"""What a drive is judged against in a world: the drivable corridor, the objects the body can hit,
the water, and progress along the reference drive (the recorded one, whose future path labelled
the training images).

The corridor is every point within `corridor_m` of a centre line: the track's, any fork's, or the
reference drive's (a detour across grass that the driver took is drivable too). The body is the
vehicle's footprint rectangle; an object is hit when its cross-section at the body's height band
(above ground) overlaps it; tree crowns and bushes only when foliage counts (drive.foliage_is_obstacle).
Water counts where a wheel touches it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from offroad_path.world.classes import WATER
from offroad_path.world.objects import BOX, CYLINDER, SPHERE
from offroad_path.world.trajectory import ARC_STEP_M, Curve, VehicleGeometry


@dataclass(frozen=True)
class Footprint:
    """An object's cross-section in the body's height band: a disc (half = None) or a yawed box."""

    xz: np.ndarray  # (2,) centre
    radius: float  # the disc's radius, or the box's bounding radius
    half: tuple[float, float] | None = None  # box half-extents along its own x and z
    yaw: float = 0.0


def _band_overlap(bottom: float, top: float, band: tuple[float, float]) -> bool:
    return bottom < band[1] and top > band[0]


def footprints(objects, ground_y, band: tuple[float, float], foliage: bool) -> list[Footprint]:
    """Cross-sections of `objects` (world.objects.arrays()) between band[0] and band[1] metres above
    the ground (ground_y: (x, z) -> the ground's y, down-positive). The world's spheres are tree
    crowns and bushes: with foliage False they are brushed through, not hit."""
    out = []
    for kind, p in zip(objects.kind, objects.params, strict=True):
        if kind == SPHERE and foliage:
            cx, cy, cz, r = p[:4]
            centre = ground_y(cx, cz) - cy  # height of the centre above the ground
            nearest = float(np.clip(centre, *band))
            if abs(nearest - centre) < r:
                out.append(Footprint(np.array([cx, cz]), math.sqrt(r * r - (nearest - centre) ** 2)))
        elif kind == CYLINDER:
            x, z, y_top, y_bottom, r = p[:5]
            g = ground_y(x, z)
            if _band_overlap(g - y_bottom, g - y_top, band):
                out.append(Footprint(np.array([x, z]), r))
        elif kind == BOX:
            cx, cy, cz, hx, hy, hz, yaw = p[:7]
            centre = ground_y(cx, cz) - cy
            if _band_overlap(centre - hy, centre + hy, band):
                out.append(Footprint(np.array([cx, cz]), math.hypot(hx, hz), (hx, hz), yaw))
    return out


def _rectangle_axes(heading: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit (right, forward) of a rectangle whose forward axis has `heading` (from +z toward +x)."""
    return np.array([math.cos(heading), -math.sin(heading)]), np.array([math.sin(heading), math.cos(heading)])


Rectangle = tuple[np.ndarray, tuple[float, float], float]  # centre (2,), half-extents along its (right, forward), heading


def _boxes_overlap(a: Rectangle, b: Rectangle) -> bool:
    """Separating-axis test of two rectangles."""
    a_axes, b_axes = _rectangle_axes(a[2]), _rectangle_axes(b[2])
    d = b[0] - a[0]
    for axis in (*a_axes, *b_axes):
        ra = sum(h * abs(axis @ u) for h, u in zip(a[1], a_axes, strict=True))
        rb = sum(h * abs(axis @ u) for h, u in zip(b[1], b_axes, strict=True))
        if abs(d @ axis) > ra + rb:
            return False
    return True


class Course:
    """One world's corridor, objects and water for a vehicle of `geometry`, and the reference drive."""

    def __init__(self, world, geometry: VehicleGeometry, corridor_m: float, band_m: tuple[float, float], foliage: bool = False):
        self.world, self.geometry, self.corridor_m = world, geometry, corridor_m
        self.reference: Curve = world.drive
        lines = [world.track.xz, world.drive.xz, *(fork.xz for fork in world.forks)]
        self._lines = cKDTree(np.concatenate(lines))
        self._drive = cKDTree(world.drive.xz)

        def ground_y(x: float, z: float) -> float:
            return -float(world.terrain.elevation(np.array([x]), np.array([z]))[0])

        self.footprints = footprints(world.objects.arrays(), ground_y, band_m, foliage)
        self._objects = cKDTree(np.array([f.xz for f in self.footprints])) if self.footprints else None
        self._reach = max((f.radius for f in self.footprints), default=0.0) + math.hypot(geometry.width_m, geometry.length_m) / 2

    @property
    def length_m(self) -> float:
        return self.reference.length

    def offset(self, xz: np.ndarray) -> np.ndarray:
        """Distance (N,) of body centres xz (N, 2) from the nearest centre line."""
        return self._lines.query(xz)[0]

    def progress(self, xz: np.ndarray, previous_s: float, window_m: float = 15.0) -> float:
        """Arc length of the reference drive's point nearest xz within window_m of previous_s; the
        previous value when the vehicle is off the corridor (e.g. down a fork)."""
        lo = max(int((previous_s - window_m) / ARC_STEP_M), 0)
        hi = min(int((previous_s + window_m) / ARC_STEP_M) + 1, len(self.reference.xz))
        d = np.linalg.norm(self.reference.xz[lo:hi] - xz, axis=1)
        i = int(np.argmin(d))
        return (lo + i) * ARC_STEP_M if d[i] <= self.corridor_m else previous_s

    def on_reference(self, s: float) -> tuple[np.ndarray, float]:
        """(body centre xz (2,), heading) on the reference drive at arc length s."""
        xz, heading, _ = self.reference.at(np.array([s]))
        return xz[0], float(heading[0])

    def reference_ahead(self, s: float, length_m: float) -> np.ndarray:
        """The reference drive's points (N, 2) from arc length s to s + length_m."""
        i = int(s / ARC_STEP_M)
        return self.reference.xz[i : i + int(length_m / ARC_STEP_M) + 1]

    def in_water(self, centres: np.ndarray, heading: float) -> bool:
        """Whether a wheel of the body at any of centres (n, 2) touches water."""
        g = self.geometry
        right, forward = _rectangle_axes(heading)
        wheels = np.array([a * forward * g.wheelbase_m / 2 + b * right * g.track_m / 2 for a in (-1, 1) for b in (-1, 1)])
        return bool(np.any(self.world.surface((centres[:, None] + wheels[None]).reshape(-1, 2)) == WATER))

    def event(self, centres: np.ndarray, heading: float) -> str | None:
        """Why the body at centres (n, 2) (the sub-steps of one period, all with about `heading`)
        needs an intervention, or None: off the corridor or into an object."""
        if np.any(self.offset(centres) > self.corridor_m):
            return "corridor"
        g = self.geometry
        half = (g.width_m / 2, g.length_m / 2)
        if self._objects is not None:
            for centre in centres:
                for k in self._objects.query_ball_point(centre, self._reach):
                    f = self.footprints[k]
                    body = (centre, half, heading)
                    hit = _boxes_overlap(body, (f.xz, f.half, f.yaw)) if f.half is not None else _disc_overlaps(body, f.xz, f.radius)
                    if hit:
                        return "object"
        return None


def _disc_overlaps(body: Rectangle, disc: np.ndarray, radius: float) -> bool:
    centre, half, heading = body
    right, forward = _rectangle_axes(heading)
    d = disc - centre
    local = np.array([d @ right, d @ forward])
    nearest = np.clip(local, [-half[0], -half[1]], [half[0], half[1]])
    return float(np.hypot(*(local - nearest))) < radius
