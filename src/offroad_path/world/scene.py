"""A procedural off-road world: terrain, ground materials, a track with forks and detours,
puddles, paved stretches, vegetation, man-made obstacles, sun and sky, and the drive through it.

Everything is drawn from one seed, so a world is a pure function of (config, seed).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.config.world_schema import WorldConfig
from offroad_path.geometry.exact import matmul, norm_rows
from offroad_path.world.appearance import LIGHTS, TRACKS, Appearance, appearance_rng, draw_appearance, rut_colour
from offroad_path.world.appearance import palette as look_palette
from offroad_path.world.classes import BASE_COLORS, DIRT, GRASS, PAVED, TEXTURE_CONTRAST, WATER
from offroad_path.world.dressing import add_undergrowth, reshape_vegetation, rut_map
from offroad_path.world.kernels import gaussian_blur, resize_cubic
from offroad_path.world.objects import Objects
from offroad_path.world.placement import Placement, place_objects
from offroad_path.world.slip import SLIP_STREAM, Slip, make_slip
from offroad_path.world.terrain import Grid, Terrain, fourier_hills, polyline_mask, value_noise
from offroad_path.world.trajectory import (
    ARC_STEP_M,
    Curve,
    VehicleGeometry,
    camera_poses,
    frame_arc_lengths,
    normalised_steering,
    random_drive,
    smooth_random,
)

HEIGHT_STEP_M = 0.25
MATERIAL_STEP_M = 0.05


@dataclass
class Sky:
    sun: np.ndarray  # unit vector toward the sun, world frame (y down)
    zenith: np.ndarray
    horizon: np.ndarray
    cloud_cover: float
    sun_strength: float = 0.9  # direct light; 0 under overcast
    ambient: float = 0.35  # the sky's light, times `zenith`
    sun_colour: np.ndarray | None = None  # None: white
    fog_m: float = 220.0  # distance at which 63 % of the light is haze
    glow: float = 0.6  # the sun's disc and halo in the sky


@dataclass
class World:
    terrain: Terrain
    materials: np.ndarray  # (rows, cols) uint8 class ids on `material_grid`
    material_grid: Grid
    shadow: np.ndarray  # (rows, cols) float32 in [0, 1], 1 = lit, on `material_grid`
    objects: Objects
    palette: np.ndarray  # (8, 3) albedo per class
    sky: Sky
    drive: Curve
    track: Curve
    frame_s: np.ndarray  # arc length of the drive at each frame
    poses: np.ndarray  # (frames, 4, 4) left camera to world
    steering: np.ndarray  # (frames,) normalised steering
    textures: dict[str, np.ndarray]
    forks: list[Curve]  # side tracks the drive does not take
    slip: Slip | None = None  # traction below the bicycle model's (world.slip); None: none
    look: Appearance | None = None  # world.appearance; None: the single look of the worlds before it
    contrast: np.ndarray | None = None  # (8,) texture contrast per class; None: classes.TEXTURE_CONTRAST
    wear: np.ndarray | None = None  # (rows, cols) uint8 on material_grid: the track's ruts, 255 = fully worn
    rut_colour: np.ndarray | None = None  # the ruts' albedo, blended in by wear x rut_strength
    rut_strength: float = 0.0

    def surface(self, xz: np.ndarray) -> np.ndarray:
        """Class ids (N,) of the ground at points xz (N, 2)."""
        row, col = self.material_grid.nearest(xz[:, 0], xz[:, 1])
        return self.materials[row, col]


def build_world(cfg: WorldConfig, seed: int, draw: str = "training", *, textures: bool = True) -> World:
    """The world drawn from `seed`; `draw`: how its appearance is drawn (world.appearance.DRAWS):
    by world.appearance.weights, from every value alike, or one of world.appearance.held_out's
    combinations (the held-out-appearance test worlds). textures=False leaves out the surface
    textures, a third of the time, for a world that is surveyed and never rendered: they are the
    last draws of the world's generator, so everything else is the same world."""
    rng = np.random.default_rng(seed)
    look = draw_appearance(seed, held_out_combinations(cfg), draw, appearance_weights(cfg)) if cfg.appearance.enabled else None
    dress = appearance_rng(seed) if look else None
    density = rng.uniform(1 - cfg.density_jitter, 1 + cfg.density_jitter, size=4)
    frame_s = frame_arc_lengths(rng, cfg.frames, cfg.fps, (cfg.speed_min_mps, cfg.speed_max_mps))
    drive_len = frame_s[-1] + cfg.max_distance_m + 20.0
    drive = random_drive(rng, drive_len, cfg.max_curvature)
    track = _track_from_drive(rng, drive, cfg)

    margin = cfg.max_distance_m + 10.0
    lo = drive.xz.min(axis=0) - margin
    hi = drive.xz.max(axis=0) + margin
    hgrid = _grid(lo, hi, HEIGHT_STEP_M)
    mgrid = _grid(lo, hi, MATERIAL_STEP_M)

    heights = fourier_hills(rng, hgrid, cfg.hill_height_m, (30.0, 120.0), 6)
    heights += cfg.bump_height_m * value_noise(rng, hgrid.shape, 1.5 / HEIGHT_STEP_M)
    heights += 0.3 * cfg.bump_height_m * value_noise(rng, hgrid.shape, 0.6 / HEIGHT_STEP_M)
    # A track bed is smoother than the land around it.
    bed = polyline_mask(hgrid, track.xz, cfg.track_width_m + 2.0)
    bed = gaussian_blur(bed.astype(np.float32) / 255.0, 1.0 / HEIGHT_STEP_M)
    smooth = gaussian_blur(heights.astype(np.float32), 2.0 / HEIGHT_STEP_M).astype(np.float64)
    heights = heights + 0.8 * bed * (smooth - heights)

    materials = np.full(mgrid.shape, GRASS, np.uint8)
    forks = _forks(rng, track, cfg.forks_per_100m * density[0])
    for fork in forks:
        _paint_ragged(rng, materials, mgrid, (fork.xz, cfg.track_width_m * 0.8), DIRT)
    _paint_ragged(rng, materials, mgrid, (track.xz, cfg.track_width_m), DIRT)
    _paint_paved(rng, materials, mgrid, track, cfg)
    puddles = _puddles(rng, track, cfg.puddles_per_100m * density[1], cfg.track_width_m)
    puddles += _puddles(dress, track, 2 * cfg.puddles_per_100m, cfg.track_width_m) if look and look.wet else []  # wet: more
    for centre, axes, angle in puddles:
        c = tuple(int(v) for v in np.rint(mgrid.to_pixel(centre[None])[0]))
        ax = tuple(int(v) for v in np.rint(np.asarray(axes) / MATERIAL_STEP_M))
        cv2.ellipse(materials, c, ax, angle, 0, 360, WATER, -1)
    heights = _flatten_puddles(heights, hgrid, puddles)
    terrain = Terrain(heights, hgrid)

    vehicle = VehicleGeometry.of(cfg.vehicle)
    poses = camera_poses(drive, frame_s, terrain, vehicle)
    frame_xz, _, frame_curvature = drive.at(frame_s)
    slip = make_slip(cfg.slip, seed, lo, hi) if cfg.slip.enabled else None
    if slip is not None:
        # The recorded steering is the driver's input that made the true motion on this ground: the
        # bicycle model's angle for the curvature over the factor (its noise drawn per frame).
        noise = np.random.default_rng(np.random.SeedSequence([seed, SLIP_STREAM, 1])).normal(0.0, slip.noise, len(frame_s))
        factor = np.maximum(slip.factor(materials[mgrid.nearest(frame_xz[:, 0], frame_xz[:, 1])], frame_xz) * (1 + noise), 0.05)
        frame_curvature = frame_curvature / factor
    steering = normalised_steering(frame_curvature, vehicle)

    sky = _sky(rng, cfg)
    objects = place_objects(Placement(rng, cfg, terrain, drive), track, density)
    palette = _palette(rng)
    surface = _textures(rng) if textures else {}  # the generator's last draws (the look draws from its own)
    world = World(
        terrain,
        materials,
        mgrid,
        np.ones(0, np.float32),
        objects,
        palette,
        sky,
        drive,
        track,
        frame_s,
        poses,
        steering,
        surface,
        forks,
        slip,
    )
    if look:
        _apply_look(world, look, dress, cfg)
    world.shadow = (
        _shadow_map(mgrid, terrain, world.objects, world.sky.sun) if world.sky.sun_strength > 0 else np.ones(mgrid.shape, np.float32)
    )
    return world


def _apply_look(world: World, look: Appearance, dress: np.random.Generator, cfg: WorldConfig) -> None:
    """Dress `world` in `look`, drawing from the appearance's generator `dress` (before its shadows are cast)."""
    world.look = look
    world.sky = light_sky(look, dress)
    world.palette = look_palette(look, dress, world.palette)
    world.objects = reshape_vegetation(world.objects, look, dress, world.palette)
    add_undergrowth(Placement(dress, cfg, world.terrain, world.drive, world.objects), look, world.palette)
    world.textures["dapple"] = np.clip(value_noise(dress, (512, 512), 10.0) * 2.0 - 0.3, 0.0, 1.0)  # sun through gaps in crowns
    world.contrast = TEXTURE_CONTRAST.copy()
    world.contrast[GRASS] = dress.uniform(0.3, 0.7)
    world.contrast[DIRT] = TRACKS[look.track]["contrast"] or world.contrast[GRASS]
    if ruts := rut_colour(look, world.palette):
        world.wear, (world.rut_colour, world.rut_strength) = rut_map(world.material_grid, world.track, world.materials), ruts


def held_out_combinations(cfg: WorldConfig) -> list[dict[str, str]]:
    return [dict(c) for c in cfg.appearance.held_out]


def appearance_weights(cfg: WorldConfig) -> dict[str, dict[str, float]]:
    """world.appearance.weights as plain dicts (a composed config's or a schema's)."""
    return {axis: dict(values) for axis, values in (cfg.appearance.weights or {}).items()}


def light_sky(look: Appearance, rng: np.random.Generator) -> Sky:
    """The sky of the look's light: sun direction and strength, sky light, haze and clouds."""
    elevation_deg, strength, ambient, sun_colour, fog_m, cloud = LIGHTS[look.light]
    elevation = np.deg2rad(rng.uniform(*elevation_deg))
    azimuth = rng.uniform(0, 2 * np.pi)
    sun = np.array([np.cos(elevation) * np.sin(azimuth), -np.sin(elevation), np.cos(elevation) * np.cos(azimuth)])
    grey = look.light in ("overcast", "hazy")
    zenith = (np.array([0.62, 0.64, 0.68]) if grey else np.array([0.25, 0.45, 0.85])) * rng.uniform(0.8, 1.1)
    horizon = (np.array([0.80, 0.80, 0.80]) if grey else np.array([0.75, 0.82, 0.90])) * rng.uniform(0.85, 1.05)
    if look.light == "low_sun":
        horizon = horizon * np.array([1.1, 0.9, 0.75])
    return Sky(
        sun=sun,
        zenith=zenith,
        horizon=horizon,
        cloud_cover=float(rng.uniform(*cloud)),
        sun_strength=strength * rng.uniform(0.9, 1.1),
        ambient=ambient * rng.uniform(0.9, 1.1),
        sun_colour=np.asarray(sun_colour),
        fog_m=float(rng.uniform(*fog_m)),
        glow=0.6 * strength,
    )


def _grid(lo: np.ndarray, hi: np.ndarray, step: float) -> Grid:
    cols = int(np.ceil((hi[0] - lo[0]) / step)) + 1
    rows = int(np.ceil((hi[1] - lo[1]) / step)) + 1
    return Grid(x0=float(lo[0]), z0=float(lo[1]), step=step, shape=(rows, cols))


def _track_from_drive(rng: np.random.Generator, drive: Curve, cfg: WorldConfig) -> Curve:
    """The track follows the drive with a small wobble, except on detours the vehicle cuts across grass."""
    s = np.arange(len(drive.xz)) * ARC_STEP_M
    offset = 0.35 * smooth_random(rng, s, (15.0, 40.0), 3)
    n_detours = rng.poisson(cfg.offtrack_per_100m * s[-1] / 100.0)
    for _ in range(n_detours):
        start = rng.uniform(15.0, max(s[-1] - 60.0, 16.0))
        length = rng.uniform(25.0, 45.0)
        amplitude = rng.choice([-1, 1]) * (cfg.track_width_m / 2 + cfg.vehicle.width_m / 2 + rng.uniform(2.0, 6.0))
        inside = (s > start) & (s < start + length)
        offset[inside] += amplitude * 0.5 * (1 - np.cos(2 * np.pi * (s[inside] - start) / length))
    xz = drive.xz + offset[:, None] * drive.normal()
    d = np.gradient(xz, axis=0)
    heading = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
    return Curve(xz=xz, heading=heading, curvature=np.gradient(heading) / ARC_STEP_M)


def _forks(rng: np.random.Generator, track: Curve, per_100m: float) -> list[Curve]:
    """Side tracks branching off the track that the vehicle does not take."""
    forks = []
    for _ in range(rng.poisson(per_100m * track.length / 100.0)):
        i = int(rng.uniform(0.1, 0.9) * (len(track.xz) - 1))
        angle = track.heading[i] + rng.choice([-1, 1]) * rng.uniform(0.4, 1.1)
        n = int(rng.uniform(40.0, 90.0) / ARC_STEP_M)
        curvature = 0.02 * smooth_random(rng, np.arange(n) * ARC_STEP_M, (30.0, 80.0), 2)
        heading = angle + np.concatenate([[0.0], np.cumsum(curvature[:-1]) * ARC_STEP_M])
        steps = ARC_STEP_M * np.stack([np.sin(heading), np.cos(heading)], axis=1)
        xz = track.xz[i] + np.cumsum(steps, axis=0)
        forks.append(Curve(xz=xz, heading=heading, curvature=curvature))
    return forks


def _paint_ragged(rng: np.random.Generator, materials: np.ndarray, grid: Grid, band: tuple[np.ndarray, float], cls: int) -> None:
    """Paint `cls` on a band (polyline xz, width m), with edges frayed by noise like a worn track."""
    mask = polyline_mask(grid, *band)
    ys, xs = np.nonzero(cv2.dilate(mask, np.ones((15, 15), np.uint8)))
    if len(ys) == 0:
        return
    r0, r1, c0, c1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    window = gaussian_blur(mask[r0:r1, c0:c1].astype(np.float32) / 255.0, 3.0)
    window += 0.3 * value_noise(rng, window.shape, 0.35 / grid.step)
    materials[r0:r1, c0:c1][window > 0.5] = cls


def _paint_paved(rng: np.random.Generator, materials: np.ndarray, grid: Grid, track: Curve, cfg: WorldConfig) -> None:
    """Some stretches of the track are paved, and there may be a paved pad beside it."""
    length = track.length
    paved = 0.0
    while paved < cfg.paved_fraction * length * rng.uniform(0.3, 1.7):
        start = rng.uniform(0.0, length)
        span = rng.uniform(8.0, 25.0)
        i0, i1 = int(start / ARC_STEP_M), int(min(start + span, length) / ARC_STEP_M)
        if i1 - i0 > 2:
            mask = polyline_mask(grid, track.xz[i0:i1], cfg.track_width_m + 0.4)
            materials[mask > 0] = PAVED
        paved += span
    if rng.uniform() < 0.5:
        i = int(rng.uniform(0.2, 0.8) * (len(track.xz) - 1))
        centre = track.xz[i] + track.normal()[i] * rng.choice([-1, 1]) * rng.uniform(6.0, 12.0)
        size = rng.uniform(5.0, 12.0, 2)
        box = cv2.boxPoints(((*grid.to_pixel(centre[None])[0],), tuple(size / grid.step), rng.uniform(0, 180)))
        cv2.fillConvexPoly(materials, np.rint(box).astype(np.int32), PAVED)


def _puddles(rng: np.random.Generator, track: Curve, per_100m: float, width_m: float) -> list:
    out = []
    for _ in range(rng.poisson(per_100m * track.length / 100.0)):
        i = int(rng.uniform(0.02, 0.95) * (len(track.xz) - 1))
        centre = track.xz[i] + track.normal()[i] * rng.uniform(-0.3, 0.3) * width_m
        axes = (rng.uniform(0.6, 2.2), rng.uniform(0.4, 1.2))
        out.append((centre, axes, float(rng.uniform(0, 180))))
    return out


def _flatten_puddles(heights: np.ndarray, grid: Grid, puddles: list) -> np.ndarray:
    """Water lies flat: set the terrain under each puddle to one level, blended at the rim."""
    for centre, axes, angle in puddles:
        mask = np.zeros(grid.shape, np.uint8)
        c = tuple(int(v) for v in np.rint(grid.to_pixel(centre[None])[0]))
        ax = tuple(int(np.ceil((a + 0.3) / grid.step)) for a in axes)
        cv2.ellipse(mask, c, ax, angle, 0, 360, 255, -1)
        inside = mask > 0
        if not inside.any():
            continue
        level = heights[inside].mean() - 0.04
        weight = gaussian_blur(inside.astype(np.float32), 0.4 / grid.step)
        weight = np.maximum(weight, inside)
        heights = heights + weight * (level - heights)
    return heights


def _sky(rng: np.random.Generator, cfg: WorldConfig) -> Sky:
    elevation = np.deg2rad(rng.uniform(*cfg.sun_elevation_deg))
    azimuth = rng.uniform(0, 2 * np.pi)
    sun = np.array([np.cos(elevation) * np.sin(azimuth), -np.sin(elevation), np.cos(elevation) * np.cos(azimuth)])
    zenith = np.array([0.25, 0.45, 0.85]) * rng.uniform(0.8, 1.1)
    horizon = np.array([0.75, 0.82, 0.90]) * rng.uniform(0.85, 1.05)
    return Sky(sun=sun, zenith=zenith, horizon=horizon, cloud_cover=float(rng.uniform(0.2, 0.7)))


def _palette(rng: np.random.Generator) -> np.ndarray:
    palette = np.zeros((8, 3))
    for cls, rgb in BASE_COLORS.items():
        palette[cls] = np.clip(np.asarray(rgb) * rng.uniform(0.8, 1.2) * rng.uniform(0.9, 1.1, 3), 0.02, 1.0)
    return palette


def _textures(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Tileable detail: `fine` at 1 cm per texel (5.12 m tile), `coarse` at 8 cm (41 m tile)."""

    def octaves(cells: tuple[float, ...]) -> np.ndarray:
        size = 512
        out = np.zeros((size, size), np.float32)
        for i, cell in enumerate(cells):
            n = size // int(cell)
            coarse = rng.uniform(-1, 1, (n, n)).astype(np.float32)
            tiled = np.tile(coarse, (3, 3))  # resize a 3x3 tiling and keep the centre: seamless wrap
            big = resize_cubic(tiled, (3 * size, 3 * size))
            out += big[size : 2 * size, size : 2 * size] * 0.85**i
        return out / out.std()  # unit standard deviation

    def wrapped_blur(tex: np.ndarray, sigma: float) -> np.ndarray:
        size = tex.shape[0]
        return gaussian_blur(np.tile(tex, (3, 3)), sigma)[size : 2 * size, size : 2 * size]

    def pebbles(count: int, radii: tuple[int, int]) -> np.ndarray:
        """Sharp-edged stones and tufts: the corners a feature tracker locks on to."""
        size = 512
        out = np.zeros((size, size), np.float32)
        for x, y, r, value in zip(
            rng.integers(0, size, count), rng.integers(0, size, count), rng.integers(*radii, count), rng.normal(0, 1, count), strict=True
        ):
            cv2.circle(out, (int(x), int(y)), int(r), float(value), -1, cv2.LINE_AA)
        return out

    fine = octaves((64, 16, 4, 2)) + 1.2 * pebbles(2500, (1, 4)) + 1.0 * pebbles(300, (4, 9))
    fine /= fine.std()
    return {
        "fine0": fine,
        "fine1": wrapped_blur(fine, 2.0),
        "fine2": wrapped_blur(fine, 6.0),
        "coarse": octaves((128, 32, 8)),
        "cloud": octaves((128, 64, 16, 4)),
    }


def _shadow_map(grid: Grid, terrain: Terrain, objects: Objects, sun: np.ndarray) -> np.ndarray:
    """Where objects shade the ground: each object's silhouette cast along the sun onto its base level."""
    shadow = np.full(grid.shape, 255, np.uint8)
    up = -sun[1]
    along = np.array([-sun[0], -sun[2]]) / up  # ground displacement per metre of height above it

    def cast(points: np.ndarray) -> None:  # points (N, 3) world; shadow of their convex hull
        xz = points[:, [0, 2]]
        base = -terrain.elevation(xz[:, 0], xz[:, 1])
        height = np.maximum(base - points[:, 1], 0.0)
        shadow_xz = xz + height[:, None] * along
        px = np.rint(grid.to_pixel(np.concatenate([shadow_xz, xz[height < 0.05]])) * 16).astype(np.int32)
        cv2.fillConvexPoly(shadow, cv2.convexHull(px), 0, cv2.LINE_AA, shift=4)

    ring = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    for kind, p in zip(objects.kind, objects.params, strict=True):
        if kind == 0:
            cx, cy, cz, r = p
            # The sphere's silhouette seen from the sun: its rim perpendicular to the sun.
            e1 = np.cross(sun, [0.0, 1.0, 0.0])
            e1 /= norm_rows(e1)
            e2 = np.cross(sun, e1)
            pts = np.array([cx, cy, cz]) + r * (np.cos(ring)[:, None] * e1 + np.sin(ring)[:, None] * e2)
        elif kind == 1:
            x, z, y_top, y_bottom, r = p
            circle = np.stack([x + r * np.cos(ring), z + r * np.sin(ring)], axis=1)
            pts = np.concatenate(
                [
                    np.stack([circle[:, 0], np.full(16, y_top), circle[:, 1]], axis=1),
                    np.stack([circle[:, 0], np.full(16, y_bottom), circle[:, 1]], axis=1),
                ]
            )
        else:
            centre, half, yaw = np.array(p[:3]), np.array(p[3:6]), p[6]
            c, s = np.cos(yaw), np.sin(yaw)
            rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # box to world
            corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)]) * half
            pts = centre + matmul(corners, rot.T)
        cast(pts)
    soft = gaussian_blur(shadow, 0.08 / grid.step)
    return soft.astype(np.float32) / 255.0
