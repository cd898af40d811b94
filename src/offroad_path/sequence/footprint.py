"""The vehicle's future footprint, projected into the image it was seen from (Holder & Breckon
2018, Sec. III-A): the ground rectangle under the vehicle in frames f1..fn, carried into f0's
camera by the poses, clipped at the near plane, projected with K and filled, together with the
area swept between consecutive footprints.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.errors import InputError
from offroad_path.geometry.exact import dot_rows, matmul, norm_rows, rigid_inverse
from offroad_path.sequence.meta import FOOTPRINT
from offroad_path.sequence.reader import Sequence

NEAR_M = 0.3
SUBPIXEL_BITS = 4


@dataclass(frozen=True)
class VehicleFootprint:
    width_m: float
    front_m: float  # front of the vehicle ahead of the camera (along the vehicle's forward axis)
    rear_m: float  # rear of the vehicle, negative: behind the camera
    camera_height_m: float  # camera above the ground under the vehicle
    camera_pitch_deg: float = 0.0  # optical axis tilted down from the vehicle's forward axis

    def corners(self) -> np.ndarray:
        """Rear-left, rear-right, front-right, front-left on the ground, in the camera frame (4, 3)."""
        w = self.width_m / 2
        level = np.array(
            [
                [-w, self.camera_height_m, self.rear_m],
                [w, self.camera_height_m, self.rear_m],
                [w, self.camera_height_m, self.front_m],
                [-w, self.camera_height_m, self.front_m],
            ]
        )
        tilt = math.radians(self.camera_pitch_deg)  # math's cos and sin: correctly rounded on every CPU
        # Vehicle-level (x, down, forward) to the camera pitched down by `tilt` about x.
        rotation = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(tilt), -math.sin(tilt)], [0.0, math.sin(tilt), math.cos(tilt)]])
        return matmul(level, rotation.T)


def footprint_for(seq: Sequence, cfg) -> VehicleFootprint:
    """The vehicle footprint from config, else from the sequence's meta.json."""
    values, source = {}, {}
    for key, meta_key in FOOTPRINT.items():
        value, source[key] = cfg.get(key), f"label.footprint.{key}"
        if value is None:
            value, source[key] = seq.meta.get(meta_key, 0.0 if key == "camera_pitch_deg" else None), f"{seq.root / 'meta.json'} {meta_key}"
        if value is None:
            raise InputError(seq.root / "meta.json", f"gives no {meta_key}: set label.footprint.{key} for this recording")
        try:
            values[key] = float(value)
        except (TypeError, ValueError):
            values[key] = float("nan")
        if not np.isfinite(values[key]):
            raise InputError(source[key], f"{value!r} is not a number")
    for key in ("width_m", "camera_height_m"):
        if values[key] <= 0:
            raise InputError(source[key], f"{values[key]:g} must be > 0 (metres)")
    if values["front_m"] <= values["rear_m"]:
        raise InputError(source["front_m"], f"{values['front_m']:g} must lie ahead of the vehicle's rear ({values['rear_m']:g} m)")
    if abs(values["camera_pitch_deg"]) >= 90:
        raise InputError(source["camera_pitch_deg"], f"{values['camera_pitch_deg']:g} must lie in (-90, 90) degrees")
    return VehicleFootprint(**values)


def clip_near(polygon: np.ndarray, near: float = NEAR_M) -> np.ndarray:
    """Sutherland-Hodgman clip of a 3D polygon (N, 3) to z >= near; (0, 3) if nothing is left.

    A footprint partly behind the camera keeps only its visible part, instead of being mirrored
    through the camera centre by the projection.
    """
    out = []
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        a_in, b_in = a[2] >= near, b[2] >= near
        if a_in:
            out.append(a)
        if a_in != b_in:
            s = (near - a[2]) / (b[2] - a[2])
            out.append(a + s * (b - a))
    return np.array(out).reshape(-1, 3)


def swept_polygons(poses: np.ndarray, f0: int, fn: int, footprint: VehicleFootprint) -> list[np.ndarray]:
    """Polygons in f0's camera frame covering the ground the vehicle occupies over frames f0+1..fn.

    Each frame's footprint, plus the quads its left and right edges sweep from one frame to the
    next (on a turn, consecutive rectangles leave gaps at their corners without them).
    """
    f0_from_world = rigid_inverse(poses[f0])
    corners = np.c_[footprint.corners(), np.ones(4)]
    frames = [matmul(matmul(f0_from_world, poses[j]), corners.T).T[:, :3] for j in range(f0 + 1, fn + 1)]
    polygons = list(frames)
    for prev, cur in itertools.pairwise(frames):
        polygons.append(np.array([prev[0], prev[3], cur[3], cur[0]]))  # left edge, rear to front
        polygons.append(np.array([prev[1], prev[2], cur[2], cur[1]]))  # right edge
    return polygons


def project(K: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.stack([K[0, 0] * points[:, 0] / points[:, 2] + K[0, 2], K[1, 1] * points[:, 1] / points[:, 2] + K[1, 2]], axis=1)


def footprint_depth(polygons: list[np.ndarray], K: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Depth (z) of the nearest footprint surface per pixel, inf where none; size = (width, height).

    Polygons are clipped at the near plane and cut into triangles (a swept quad spans two frames
    and need not be planar); each triangle's plane gives the depth of the pixels it covers.
    """
    width, height = size
    depth = np.full((height, width), np.inf)
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], axis=-1)
    for polygon in polygons:
        clipped = clip_near(polygon)
        for i in range(1, len(clipped) - 1):
            tri = clipped[[0, i, i + 1]]
            normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            if norm_rows(normal) < 1e-12:
                continue
            uv = np.clip(project(K, tri), -1e6, 1e6)
            c0, r0 = np.maximum(np.floor(uv.min(axis=0)).astype(int), 0)
            c1, r1 = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + 1, (width, height))
            if c0 >= c1 or r0 >= r1:
                continue
            mask = np.zeros((r1 - r0, c1 - c0), np.uint8)
            pts = np.rint((uv - (c0, r0)) * (1 << SUBPIXEL_BITS)).astype(np.int64).astype(np.int32)
            cv2.fillPoly(mask, [pts], 1, cv2.LINE_8, shift=SUBPIXEL_BITS)
            inside = mask.astype(bool)
            ray = rays[r0:r1, c0:c1][inside]
            denom = dot_rows(ray, normal)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(np.abs(denom) > 1e-12, dot_rows(tri[0], normal) / denom, np.inf)
            window = depth[r0:r1, c0:c1]
            window[inside] = np.minimum(window[inside], np.where(z > 0, z, np.inf))
    return depth


@dataclass(frozen=True)
class Occlusion:
    """What the camera saw at f0: footprint farther than the measured surface by more than
    margin_m + margin_rel * depth is hidden (behind a crest or an obstacle)."""

    measured_depth: np.ndarray  # (H, W) z at f0, 0 where unknown
    margin_m: float
    margin_rel: float


def path_mask(footprint_z: np.ndarray, occlusion: Occlusion | None = None) -> np.ndarray:
    """Binary path label (H, W) uint8 0/255 from the swept footprint's depth at f0 (footprint_depth
    of swept_polygons, inf off the path); hidden footprint is not path when `occlusion` is given."""
    path = np.isfinite(footprint_z)
    if occlusion is not None:
        measured = occlusion.measured_depth
        hidden = (measured > 0) & (footprint_z > measured * (1 + occlusion.margin_rel) + occlusion.margin_m)
        path &= ~hidden
    return np.where(path, 255, 0).astype(np.uint8)


def path_label(
    seq: Sequence, poses: np.ndarray, segment: tuple[int, int], footprint: VehicleFootprint, occlusion: Occlusion | None = None
) -> np.ndarray:
    """The path label of frame f0 of `seq` (H, W) uint8 0/255, segment = (f0, fn): the ground the vehicle
    covers over frames f0+1..fn by `poses` (estimated or true), swept and projected into f0's image,
    less what `occlusion` hides. The label stage's labels and the temporal scores' exact ones are both this."""
    f0, fn = segment
    return path_mask(footprint_depth(swept_polygons(poses, f0, fn, footprint), seq.calibration.K, seq.image_size), occlusion)
