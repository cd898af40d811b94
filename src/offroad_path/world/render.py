"""A vectorised ray caster for the off-road world: exact depth, semantic class and a shaded image.

Terrain: each pixel's ray marches the height field with steps no longer than the clearance over
the slope bound allows (relaxed with distance), longer where the ray is above all terrain within
4 m or 16 m (max-filtered copies of the height field); the crossing is then refined by bisection
and false position, so the hit lies on the bilinear surface to well under a millimetre (a test
checks 1 mm). Objects: exact analytic intersections, each object only on the pixels of its
tangent-plane screen bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.geometry.exact import dot_rows, matmul, norm_rows
from offroad_path.world.classes import SKY, TEXTURE_CONTRAST, WATER
from offroad_path.world.kernels import sample_bilinear
from offroad_path.world.objects import intersect
from offroad_path.world.scene import World
from offroad_path.world.sensor import expose, record
from offroad_path.world.terrain import Terrain

NEAR_M = 0.3
RELAX = 0.02  # march step at least 2 % of the distance: thinner distant bumps than that are skipped
MIN_STEP_M = 0.02
BISECTIONS = 4
REFINEMENTS = 8
COMPACT_BELOW = 0.75  # the march keeps only the live rays once fewer than this share are
MAX_TAN_ANGLE = 1.5  # radians: a sphere's pixel range is clipped short of the image plane's horizon
# Linear light to 8-bit sRGB-like gamma 2.2; a table is much faster than a power per channel.
GAMMA = np.clip(255.0 * np.linspace(0.0, 1.0, 16384) ** (1 / 2.2) + 0.5, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class PinholeCamera:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> PinholeCamera:
        f = (width / 2) / np.tan(np.deg2rad(hfov_deg) / 2)
        return cls(width, height, f, f, (width - 1) / 2, (height - 1) / 2)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def rays(self) -> np.ndarray:
        """Ray directions (H*W, 3) through pixel centres, scaled to z = 1 so that t is depth."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u, float)], axis=-1).reshape(-1, 3)


@dataclass
class View:
    image: np.ndarray  # (H, W, 3) uint8 RGB
    depth: np.ndarray  # (H, W) float64 metres along the optical axis, 0 where nothing was hit
    semantic: np.ndarray  # (H, W) uint8 class ids


def march_terrain(terrain: Terrain, origin: np.ndarray, dirs: np.ndarray, max_t: float) -> np.ndarray:
    """Depth t of the first terrain crossing for each ray o + t*d, inf where none within max_t.
    Port: world.trace_torch.march_terrain (render_torch.PORTS).
    """
    # float32 throughout: half the memory traffic, and ~1e-5 m rounding at these distances.
    ox, oy, oz = (np.float32(v) for v in origin)
    dirs = dirs.astype(np.float32)

    def clearance(t: np.ndarray, dx: np.ndarray, dy: np.ndarray, dz: np.ndarray) -> np.ndarray:
        return -(oy + t * dy) - terrain.elevation(ox + t * dx, oz + t * dz)

    horizontal = np.hypot(dirs[:, 0], dirs[:, 2])
    # Clearance c(t) = -y - elevation falls no faster than `rate` per unit t.
    rate = dirs[:, 1] + np.float32(terrain.max_slope) * horizontal
    t_hit = np.full(len(dirs), np.inf)
    # A rising ray can only meet ground higher than the camera: above the highest terrain within
    # reach, it is sky. Rays climbing faster than any slope never reach the ground at all.
    top = terrain.max_elevation_near(ox, oz, max_t)
    with np.errstate(divide="ignore"):
        t_limit = np.where(dirs[:, 1] < 0, np.minimum((top + oy) / -dirs[:, 1], max_t), max_t).astype(np.float32)
        inv_sink = np.where(dirs[:, 1] > 0, 1.0 / dirs[:, 1], np.inf).astype(np.float32)
    idx = np.flatnonzero((rate > 0) & (t_limit > NEAR_M))
    # Per-ray constants, compacted together with the ray state as rays finish.
    per_ray = [dirs[idx, 0], dirs[idx, 1], dirs[idx, 2], 1.0 / rate[idx], t_limit[idx], inv_sink[idx]]
    per_ray += [radius / horizontal[idx] for radius, _ in terrain.max_levels]
    brackets = _march(terrain, (ox, oy, oz), idx, per_ray)
    if not brackets:
        return t_hit
    idx, lo, hi, c_lo, c_hi = (np.concatenate(parts) for parts in zip(*brackets, strict=True))
    t_hit[idx] = _refine(clearance, dirs[idx], lo, hi, (c_lo, c_hi))
    return t_hit


def _march(terrain: Terrain, origin: tuple, idx: np.ndarray, per_ray: list[np.ndarray]) -> list[tuple]:
    """Step each ray (indices idx) along, as far as the terrain's clearance and the height bounds
    allow, until its clearance turns negative or it passes its limit: the brackets (rays, t and
    clearance before and after the crossing) in which each crossing ray meets the ground."""
    ox, oy, oz = origin
    t = np.full(len(idx), NEAR_M, np.float32)
    t_prev, c_prev = t.copy(), np.full(len(idx), np.inf, np.float32)
    alive = np.ones(len(idx), bool)
    brackets = []
    while len(idx):
        dx, dy, dz, inv_rate, limit, sink = per_ray[:6]
        y = oy + t * dy
        fx, fz = terrain.cell_coords(ox + t * dx, oz + t * dz)
        c = -y - terrain.elevation_at_cells(fx, fz)
        crossed = alive & (c <= 0)
        if crossed.any():
            brackets.append((idx[crossed], t_prev[crossed], t[crossed], c_prev[crossed], c[crossed]))
        step = np.maximum(c * inv_rate, RELAX * t)
        np.maximum(step, MIN_STEP_M, out=step)
        # Where the ray is above all terrain within a radius, it may go that far (or until it
        # sinks to that height) in one step.
        for level, reach_flat in enumerate(per_ray[6:]):
            headroom = -y - terrain.max_within_at_cells(level, fx, fz)
            with np.errstate(invalid="ignore"):  # 0 headroom x infinite sink: NaN, masked by `where` below
                reach = np.minimum(reach_flat, headroom * sink)
            np.maximum(step, reach, out=step, where=headroom > 0)
        t_prev, c_prev = t, c
        t = t + step
        alive &= ~crossed & (t < limit)
        # Finished rays ride along until a quarter of the batch is dead: compaction costs a copy.
        if alive.sum() < COMPACT_BELOW * len(alive):
            keep = np.flatnonzero(alive)
            idx, t, t_prev, c_prev, alive = idx[keep], t[keep], t_prev[keep], c_prev[keep], alive[keep]
            per_ray = [a[keep] for a in per_ray]
    return brackets


def _refine(clearance, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray, c: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The crossing t inside each bracket [lo, hi] (clearance c_lo > 0 >= c_hi) of rays `dirs`.
    Port: world.trace_torch._refine (render_torch.PORTS).
    """
    c_lo, c_hi = c
    # A ray already below ground at NEAR_M has no bracket: report the near plane.
    below = ~np.isfinite(c_lo)
    lo[below], c_lo[below] = hi[below], 0.0
    dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    for i in range(REFINEMENTS):
        # Bisection first (robust on any bracket), then false position (fast once it is tight).
        if i < BISECTIONS:
            mid = 0.5 * (lo + hi)
        else:
            denom = c_lo - c_hi
            mid = lo + np.where(denom > 0, c_lo / np.where(denom > 0, denom, 1.0), 0.5) * (hi - lo)
        c = clearance(mid, dx, dy, dz)
        above = c > 0
        under = ~above
        # In place: the same values as np.where, without four new arrays per iteration.
        np.copyto(lo, mid, where=above)
        np.copyto(c_lo, c, where=above)
        np.copyto(hi, mid, where=under)
        np.copyto(c_hi, c, where=under)
    denom = c_lo - c_hi
    frac = np.where(denom > 0, c_lo / np.where(denom > 0, denom, 1.0), 0.0)
    return lo + frac * (hi - lo)


def _tangent_range(a: np.ndarray, z: np.ndarray, r: np.ndarray, f: float, c: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel range along one image axis that rays hitting a sphere can have.

    A ray meets the sphere only if its projection onto the (a, z) plane meets the sphere's
    shadow there, a disc: so its angle lies between the disc's two tangents from the camera.
    Port: world.trace_torch._tangent_range (render_torch.PORTS).
    """
    dist = np.hypot(a, z)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.arcsin(np.clip(r / dist, 0.0, 1.0))
    centre = np.arctan2(a, z)
    lo_angle, hi_angle = centre - half, centre + half
    lo = np.where(lo_angle <= -np.pi / 2, -np.inf, f * np.tan(np.clip(lo_angle, -MAX_TAN_ANGLE, MAX_TAN_ANGLE)) + c)
    hi = np.where(hi_angle >= np.pi / 2, np.inf, f * np.tan(np.clip(hi_angle, -MAX_TAN_ANGLE, MAX_TAN_ANGLE)) + c)
    behind = (hi_angle <= -np.pi / 2) | (lo_angle >= np.pi / 2)
    surrounds = dist <= r
    lo = np.where(surrounds, -np.inf, np.where(behind, np.inf, lo))
    hi = np.where(surrounds, np.inf, np.where(behind, -np.inf, hi))
    return lo, hi


@dataclass(frozen=True)
class Shot:
    """One camera at one pose, with its pixels' ray directions in the world (t = depth)."""

    camera: PinholeCamera
    pose: np.ndarray  # (4, 4) camera to world
    dirs: np.ndarray  # (H * W, 3)


def trace_objects(world: World, shot: Shot, t_bound: np.ndarray, max_t: float):
    """Object hits nearer than t_bound per pixel: (t, normal, object index); index -1 where none.

    Each object is tested only on the pixels of its projected bounding sphere, and only where
    nothing already found is nearer than the whole object; all (pixel, object) pairs of one kind
    go through its intersection function at once.
    Port: world.trace_torch.trace_objects (render_torch.PORTS).
    """
    camera, pose, dirs = shot.camera, shot.pose, shot.dirs
    h, w = camera.height, camera.width
    t_best = t_bound.copy()
    normal = np.zeros((h * w, 3))
    index = np.full(h * w, -1, np.int64)
    objects = world.objects.arrays()
    if not len(objects.kind):
        return t_best, normal, index
    origin, rot = pose[:3, 3], pose[:3, :3]
    x, y, z = matmul(objects.bounds[:, :3] - origin, rot).T  # centres in the camera frame
    r = objects.bounds[:, 3]
    near = z - r
    u_lo, u_hi = _tangent_range(x, z, r, camera.fx, camera.cx)
    v_lo, v_hi = _tangent_range(y, z, r, camera.fy, camera.cy)
    visible = (z + r > NEAR_M) & (near < max_t) & (u_hi >= 0) & (u_lo <= w - 1) & (v_hi >= 0) & (v_lo <= h - 1)
    r0 = np.floor(np.clip(v_lo, 0, h)).astype(np.int64)
    r1 = np.ceil(np.clip(v_hi + 1, 0, h)).astype(np.int64)
    c0 = np.floor(np.clip(u_lo, 0, w)).astype(np.int64)
    c1 = np.ceil(np.clip(u_hi + 1, 0, w)).astype(np.int64)
    for kind in np.unique(objects.kind):
        obj = np.flatnonzero(visible & (objects.kind == kind))
        widths, sizes = c1[obj] - c0[obj], (r1[obj] - r0[obj]) * (c1[obj] - c0[obj])
        # Every pixel of every object's box, as (pixel, object) pairs.
        local = np.arange(sizes.sum()) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        width_each = np.repeat(widths, sizes)
        obj = np.repeat(obj, sizes)
        pix = (r0[obj] + local // width_each) * w + c0[obj] + local % width_each
        keep = t_best[pix] > near[obj]
        obj, pix = obj[keep], pix[keep]
        t, n = intersect(int(kind), objects.params[obj], origin, dirs[pix])
        closer = t < t_best[pix]
        obj, pix, t, n = obj[closer], pix[closer], t[closer], n[closer]
        np.minimum.at(t_best, pix, t)
        won = t == t_best[pix]
        index[pix[won]] = obj[won]
        normal[pix[won]] = n[won]
    return t_best, normal, index


def render_view(  # noqa: PLR0913, PLR0915, PLR0917 (the renderer's one entry point, read top to bottom)
    world: World,
    camera: PinholeCamera,
    pose: np.ndarray,
    max_t: float,
    cam_rays: np.ndarray | None = None,
    motion_m: float = 0.0,
    noise_key: tuple[int, ...] = (0,),
) -> View:
    """Render one camera with camera-to-world `pose` (4x4). A world with a look (world.appearance) goes
    through its sensor: motion_m metres driven while the shutter is open, noise drawn from noise_key.
    Port: world.render_torch.render_views, world.shading_torch.shade (render_torch.PORTS).
    """
    rays = camera.rays() if cam_rays is None else cam_rays
    dirs = matmul(rays, pose[:3, :3].T)  # (M, 3) world directions, t = depth
    origin = pose[:3, 3]
    t_ground = march_terrain(world.terrain, origin, dirs, max_t)
    t, n_obj, obj_index = trace_objects(world, Shot(camera, pose, dirs), t_ground, max_t)
    use_obj = obj_index >= 0
    hit = np.isfinite(t) & (t < max_t)
    t = np.where(hit, t, 0.0)

    lit = np.flatnonzero(hit)
    t_lit, d_lit = t[lit], dirs[lit]
    points = origin + t_lit[:, None] * d_lit
    ground = ~use_obj[lit]
    g, o = np.flatnonzero(ground), np.flatnonzero(~ground)
    cls = np.empty(len(lit), np.uint8)
    albedo = np.empty((len(lit), 3))
    normal = np.empty((len(lit), 3))
    row, col = world.material_grid.nearest(points[g, 0], points[g, 2])
    cls[g] = world.materials[row, col]
    albedo[g] = _ground_albedo(world, cls[g], row, col)
    normal[g] = world.terrain.normals(points[g, 0], points[g, 2])
    objects = world.objects.arrays()
    which = obj_index[lit[o]]
    cls[o] = objects.cls[which]
    albedo[o] = objects.color[which]
    normal[o] = n_obj[lit[o]]
    semantic = np.full(len(dirs), SKY, np.uint8)
    semantic[lit] = cls

    distance = norm_rows(d_lit)
    unit = d_lit / distance[:, None]
    # A pixel's footprint on the surface: the geometric mean of its two axes picks the mip level.
    footprint = t_lit / camera.fx / np.sqrt(np.maximum(np.abs(dot_rows(unit, normal)), MIN_GRAZING))
    detail = _detail(world, points, cls, footprint, ground)
    sun_vis = np.ones(len(lit))
    sun_vis[g] = sample_bilinear(world.shadow, *world.material_grid.coords(points[g, 0], points[g, 2]))
    if "dapple" in world.textures:  # sun through gaps in the crowns
        texel = np.mod(points[g][:, [0, 2]] / DAPPLE_TEXEL_M, TEXTURE_SIZE).astype(np.float32)
        gaps = sample_bilinear(world.textures["dapple"], *texel.T, wrap=True)
        sun_vis[g] = 1 - (1 - sun_vis[g]) * (1 - gaps)
    sky = world.sky
    sun = np.maximum(matmul(normal, sky.sun), 0.0) * sun_vis
    direct = sky.sun_strength * sun[:, None] if sky.sun_colour is None else sky.sun_strength * sun[:, None] * sky.sun_colour
    colour = albedo * detail * (sky.ambient * sky.zenith + direct)
    water = np.flatnonzero(cls == WATER)
    if len(water):
        reflected = unit[water] * np.array([1.0, -1.0, 1.0])
        own, sky_share, shade, lit_share = WATER_MIX
        colour[water] = own * colour[water] + sky_share * _sky_colour(world, reflected) * (shade + lit_share * sun_vis[water, None])
    fog = 1.0 - np.exp(-t_lit * distance / sky.fog_m)
    rgb = np.empty((len(dirs), 3))
    rgb[lit] = colour * (1 - fog[:, None]) + world.sky.horizon * fog[:, None]
    sky = np.flatnonzero(~hit)
    sky_dirs = dirs[sky]
    rgb[sky] = _sky_colour(world, sky_dirs / norm_rows(sky_dirs)[:, None])

    shape = (camera.height, camera.width)
    depth = t.reshape(shape)
    return View(image=_film(world, rgb.reshape(*shape, 3), depth, motion_m, noise_key), depth=depth, semantic=semantic.reshape(shape))


def _ground_albedo(world: World, cls: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """(N, 3) albedo of ground points of classes `cls` at material cells (row, col): the palette's, with
    the track's ruts blended in where it is worn."""
    albedo = world.palette[cls]
    if world.wear is not None:
        worn = world.wear[row, col].astype(np.float64)[:, None] * (world.rut_strength / 255.0)
        albedo = albedo * (1 - worn) + world.rut_colour * worn
    return albedo


def _film(world: World, linear: np.ndarray, depth: np.ndarray, motion_m: float, noise_key: tuple[int, ...]) -> np.ndarray:
    """Linear light (H, W, 3) to the 8-bit image: gamma alone without a look, else through its sensor."""
    shape = linear.shape
    if world.look is None:
        return _gamma_encode(linear.reshape(-1, 3)).reshape(shape)
    sensor = world.look.sensor
    exposed = expose(linear, depth, sensor, motion_m).reshape(-1, 3)
    return record(_gamma_encode(exposed).reshape(shape), sensor, noise_key)


def _gamma_encode(rgb: np.ndarray) -> np.ndarray:
    """Linear light (N, 3) float64 to 8-bit, through the GAMMA table; rgb is overwritten (in place:
    the same values as clip, scale and round into new arrays, without three image-sized temporaries).
    Port: world.shading_torch.gamma_encode (render_torch.PORTS).
    """
    np.clip(rgb, 0.0, 1.0, out=rgb)
    rgb *= len(GAMMA) - 1
    rgb += 0.5
    return GAMMA[rgb.astype(np.int32)]


# Texture detail and sky (_detail, _sky_colour; shading_torch's ports import these, never a copy).
TEXTURE_SIZE = 512  # pixels of every tiled texture (fine, coarse, cloud)
FINE_TEXEL_M, COARSE_TEXEL_M = 0.01, 0.08  # metres of surface per texel
MIN_FOOTPRINT_M = 1e-4  # a pixel's footprint on the surface, at least (log2 of 0 is none)
FINE_FADE = (1.2, 0.4, 0.3, 1.0)  # fine detail x clip(a - footprint / b, c, d): it fades where pixels are large
FINE_GAIN, COARSE_GAIN, HUE_SHIFT, MIN_GAIN = 0.5, 0.35, 0.25, 0.05
SUN_GLOW_POWER = 64
CLOUD_PLANE_M, CLOUD_MIN_UP, CLOUD_EDGE, CLOUD_FADE_IN = 40.0, 0.02, 0.5, 8
CLOUD_OFFSET, CLOUD_SLOPE = 2, 4  # cloud where the noise exceeds offset - slope x sky.cloud_cover
CLOUD_COLOUR = (0.95, 0.95, 0.97)
MIN_GRAZING = 0.1  # |cos| of the view to the surface, at least, in a pixel's footprint
DAPPLE_TEXEL_M = 0.05  # the sun's gaps through the crowns, metres per texel
WATER_MIX = (0.45, 0.55, 0.4, 0.6)  # water: a x its colour + b x the reflected sky x (c + d x sun)


def _detail(world: World, points: np.ndarray, cls: np.ndarray, footprint: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Multiplicative texture detail (N, 3), mip-blended by the pixel's footprint on the surface.
    Port: world.shading_torch._detail (render_torch.PORTS).
    """
    tex = world.textures
    # Ground textures lie in x-z; objects use x+z along their sides and y up them.
    a = np.where(ground, points[:, 0], points[:, 0] + points[:, 2])
    b = np.where(ground, points[:, 2], points[:, 1])
    fine_u = np.mod(a / FINE_TEXEL_M, TEXTURE_SIZE).astype(np.float32)
    fine_v = np.mod(b / FINE_TEXEL_M, TEXTURE_SIZE).astype(np.float32)
    level = np.clip(np.log2(np.maximum(footprint, MIN_FOOTPRINT_M) / FINE_TEXEL_M) / 2, 0.0, 2.0)
    mips = [sample_bilinear(tex[f"fine{k}"], fine_u, fine_v, wrap=True) for k in range(3)]
    w1 = np.clip(level, 0, 1)
    w2 = np.clip(level - 1, 0, 1)
    fine = mips[0] * (1 - w1) + mips[1] * (w1 - w2) + mips[2] * w2
    start, scale, low, high = FINE_FADE
    fine *= np.clip(start - footprint / scale, low, high)
    coarse_u = np.mod(a / COARSE_TEXEL_M, TEXTURE_SIZE).astype(np.float32)
    coarse = sample_bilinear(tex["coarse"], coarse_u, np.mod(b / COARSE_TEXEL_M, TEXTURE_SIZE).astype(np.float32), wrap=True)
    contrast = (TEXTURE_CONTRAST if world.contrast is None else world.contrast)[cls]
    gain = 1.0 + contrast * (FINE_GAIN * fine + COARSE_GAIN * coarse)
    # Coarse patches also shift hue a little (dry grass, wet dirt).
    hue = np.stack([1 + HUE_SHIFT * contrast * coarse, np.ones_like(coarse), 1 - HUE_SHIFT * contrast * coarse], axis=1)
    return np.maximum(gain, MIN_GAIN)[:, None] * hue


def _sky_colour(world: World, unit: np.ndarray) -> np.ndarray:
    """The sky's colour (N, 3) in unit directions (N, 3).
    Port: world.shading_torch._sky_colour (render_torch.PORTS).
    """
    sky = world.sky
    up = np.clip(-unit[:, 1], 0.0, 1.0)
    base = sky.horizon + (sky.zenith - sky.horizon) * np.sqrt(up)[:, None]
    sun_glow = np.clip(matmul(unit, sky.sun), 0, 1) ** SUN_GLOW_POWER
    colour = base + sky.glow * sun_glow[:, None]
    # Clouds on a plane far overhead: a function of direction only, identical in both cameras.
    rising = up > CLOUD_MIN_UP
    k = np.flatnonzero(rising)
    scale = CLOUD_PLANE_M / np.maximum(up[k], CLOUD_MIN_UP)
    cu = np.mod(unit[k, 0] * scale, TEXTURE_SIZE).astype(np.float32)
    cv = np.mod(unit[k, 2] * scale, TEXTURE_SIZE).astype(np.float32)
    density = sample_bilinear(world.textures["cloud"], cu, cv, wrap=True)
    cover = np.clip((density - (CLOUD_OFFSET - CLOUD_SLOPE * sky.cloud_cover)) * CLOUD_EDGE, 0, 1) * np.clip(up[k] * CLOUD_FADE_IN, 0, 1)
    colour[k] = colour[k] * (1 - cover[:, None]) + np.array(CLOUD_COLOUR) * cover[:, None]
    return colour
