"""render.py's shading, textures, sky and sensor in torch, for world/render_torch.py's batches of views:
the colour and class of each ray from what it hit, then each view through its camera's exposure."""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import Tensor

from offroad_path.world.classes import SKY, WATER
from offroad_path.world.render import (
    CLOUD_COLOUR,
    CLOUD_EDGE,
    CLOUD_FADE_IN,
    CLOUD_MIN_UP,
    CLOUD_OFFSET,
    CLOUD_PLANE_M,
    CLOUD_SLOPE,
    COARSE_GAIN,
    COARSE_TEXEL_M,
    DAPPLE_TEXEL_M,
    FINE_FADE,
    FINE_GAIN,
    FINE_TEXEL_M,
    GAMMA,
    HUE_SHIFT,
    MIN_FOOTPRINT_M,
    MIN_GAIN,
    MIN_GRAZING,
    SUN_GLOW_POWER,
    TEXTURE_SIZE,
    WATER_MIX,
    PinholeCamera,
)
from offroad_path.world.sensor import BLUR_SAMPLES, GAIN_RANGE, LUMA, LUMA_STEPS, MIN_MEAN
from offroad_path.world.terrain import Grid
from offroad_path.world.trace_torch import F32, F64, DeviceWorld, bilinear


class Hits(NamedTuple):
    """What each ray (R of them) of a batch met."""

    origin: Tensor  # (R, 3) its camera's centre
    dirs: Tensor  # (R, 3) t = depth
    t: Tensor  # (R,) depth, 0 where nothing was hit
    hit: Tensor  # (R,) bool
    normal: Tensor  # (R, 3) the object's normal where it hit one
    object_index: Tensor  # (R,) the object hit, -1 where none (terrain or sky)


def shade(dw: DeviceWorld, camera: PinholeCamera, hits: Hits) -> tuple[Tensor, Tensor]:
    """The linear colour (R, 3) float64 and class (R,) uint8 of every ray: render.render_view's shading."""
    world, sky = dw.world, dw.world.sky
    origin, dirs, t, hit, n_obj, obj_index = hits
    lit = torch.nonzero(hit)[:, 0]
    t_lit, d_lit = t[lit], dirs[lit]
    points = origin[lit] + t_lit[:, None] * d_lit
    ground = obj_index[lit] < 0
    g, o = torch.nonzero(ground)[:, 0], torch.nonzero(~ground)[:, 0]
    cls = torch.empty(len(lit), dtype=torch.uint8, device=dw.device)
    albedo = torch.empty(len(lit), 3, dtype=F64, device=dw.device)
    normal = torch.empty(len(lit), 3, dtype=F64, device=dw.device)
    mgrid = world.material_grid
    col = torch.round((points[g, 0] - mgrid.x0) / mgrid.step).clamp(0, mgrid.shape[1] - 1).long()
    row = torch.round((points[g, 2] - mgrid.z0) / mgrid.step).clamp(0, mgrid.shape[0] - 1).long()
    cls[g] = dw.materials[row, col]
    albedo[g] = dw.palette[cls[g].long()]
    if dw.wear is not None:
        worn = dw.wear[row, col].to(F64)[:, None] * (world.rut_strength / 255.0)
        albedo[g] = albedo[g] * (1 - worn) + dw.vector(world.rut_colour) * worn
    normal[g] = _terrain_normals(dw, points[g])
    which = obj_index[lit[o]]
    cls[o], albedo[o], normal[o] = dw.object_cls[which], dw.object_colour[which], n_obj[lit[o]]
    semantic = torch.full((len(dirs),), SKY, dtype=torch.uint8, device=dw.device)
    semantic[lit] = cls

    distance = torch.linalg.vector_norm(d_lit, dim=1)
    unit = d_lit / distance[:, None]
    footprint = t_lit / camera.fx / torch.sqrt(torch.clamp((unit * normal).sum(1).abs(), min=MIN_GRAZING))
    detail = _detail(dw, points, cls, footprint, ground)
    sun_vis = torch.ones(len(lit), dtype=F64, device=dw.device)
    gx, gz = _grid_coords(mgrid, points[g, 0], points[g, 2])
    sun_vis[g] = bilinear(dw.shadow, gx, gz).to(F64)
    if "dapple" in dw.textures:
        du = torch.remainder(points[g, 0] / DAPPLE_TEXEL_M, TEXTURE_SIZE).to(F32)
        dv = torch.remainder(points[g, 2] / DAPPLE_TEXEL_M, TEXTURE_SIZE).to(F32)
        gaps = bilinear(dw.textures["dapple"], du, dv, wrap=True).to(F64)
        sun_vis[g] = 1 - (1 - sun_vis[g]) * (1 - gaps)
    sun = torch.clamp(normal @ dw.vector(sky.sun), min=0.0) * sun_vis
    direct = sky.sun_strength * sun[:, None] * (1.0 if sky.sun_colour is None else dw.vector(sky.sun_colour))
    colour = albedo * detail * (sky.ambient * dw.vector(sky.zenith) + direct)
    water = torch.nonzero(cls == WATER)[:, 0]
    if len(water):
        reflected = unit[water] * dw.vector([1.0, -1.0, 1.0])
        own, sky_share, shade, lit_share = WATER_MIX
        colour[water] = own * colour[water] + sky_share * _sky_colour(dw, reflected) * (shade + lit_share * sun_vis[water, None])
    fog = (1.0 - torch.exp(-t_lit * distance / sky.fog_m))[:, None]
    rgb = torch.empty(len(dirs), 3, dtype=F64, device=dw.device)
    rgb[lit] = colour * (1 - fog) + dw.vector(sky.horizon) * fog
    open_sky = torch.nonzero(~hit)[:, 0]
    sky_dirs = dirs[open_sky]
    rgb[open_sky] = _sky_colour(dw, sky_dirs / torch.linalg.vector_norm(sky_dirs, dim=1)[:, None])
    return rgb, semantic


def _grid_coords(grid: Grid, x: Tensor, z: Tensor) -> tuple[Tensor, Tensor]:
    """terrain.Grid.coords: fractional (col, row) float32 of world points."""
    return ((x - grid.x0) / grid.step).to(F32), ((z - grid.z0) / grid.step).to(F32)


def _terrain_normals(dw: DeviceWorld, points: Tensor) -> Tensor:
    """terrain.Terrain.normals: unit normals (N, 3) float64, pointing up (negative y)."""
    grad = bilinear(dw.grad, *_grid_coords(dw.world.terrain.grid, points[:, 0], points[:, 2]))
    n = torch.stack([-grad[:, 0], -torch.ones(len(grad), dtype=F32, device=dw.device), -grad[:, 1]], dim=1).to(F64)
    return n / torch.linalg.vector_norm(n, dim=1)[:, None]


def _detail(dw: DeviceWorld, points: Tensor, cls: Tensor, footprint: Tensor, ground: Tensor) -> Tensor:
    """render._detail: the multiplicative texture detail (N, 3), mip-blended by the pixel's footprint."""
    tex = dw.textures
    a = torch.where(ground, points[:, 0], points[:, 0] + points[:, 2])
    b = torch.where(ground, points[:, 2], points[:, 1])
    fine_u = torch.remainder(a / FINE_TEXEL_M, TEXTURE_SIZE).to(F32)
    fine_v = torch.remainder(b / FINE_TEXEL_M, TEXTURE_SIZE).to(F32)
    level = torch.clamp(torch.log2(torch.clamp(footprint, min=MIN_FOOTPRINT_M) / FINE_TEXEL_M) / 2, 0.0, 2.0)
    mips = [bilinear(tex[f"fine{k}"], fine_u, fine_v, wrap=True).to(F64) for k in range(3)]
    w1, w2 = level.clamp(0, 1), (level - 1).clamp(0, 1)
    fine = mips[0] * (1 - w1) + mips[1] * (w1 - w2) + mips[2] * w2
    start, scale, low, high = FINE_FADE
    fine = fine * torch.clamp(start - footprint / scale, low, high)
    coarse_u = torch.remainder(a / COARSE_TEXEL_M, TEXTURE_SIZE).to(F32)
    coarse_v = torch.remainder(b / COARSE_TEXEL_M, TEXTURE_SIZE).to(F32)
    coarse = bilinear(tex["coarse"], coarse_u, coarse_v, wrap=True).to(F64)
    contrast = dw.contrast[cls.long()]
    gain = 1.0 + contrast * (FINE_GAIN * fine + COARSE_GAIN * coarse)
    hue = torch.stack([1 + HUE_SHIFT * contrast * coarse, torch.ones_like(coarse), 1 - HUE_SHIFT * contrast * coarse], dim=1)
    return torch.clamp(gain, min=MIN_GAIN)[:, None] * hue


def _sky_colour(dw: DeviceWorld, unit: Tensor) -> Tensor:
    """render._sky_colour: the sky's colour (N, 3) in unit directions (N, 3)."""
    sky = dw.world.sky
    up = torch.clamp(-unit[:, 1], 0.0, 1.0)
    horizon, zenith = dw.vector(sky.horizon), dw.vector(sky.zenith)
    colour = horizon + (zenith - horizon) * torch.sqrt(up)[:, None]
    colour = colour + sky.glow * (torch.clamp(unit @ dw.vector(sky.sun), 0, 1) ** SUN_GLOW_POWER)[:, None]
    k = torch.nonzero(up > CLOUD_MIN_UP)[:, 0]
    scale = CLOUD_PLANE_M / torch.clamp(up[k], min=CLOUD_MIN_UP)
    cu, cv = torch.remainder(unit[k, 0] * scale, TEXTURE_SIZE).to(F32), torch.remainder(unit[k, 2] * scale, TEXTURE_SIZE).to(F32)
    density = bilinear(dw.textures["cloud"], cu, cv, wrap=True).to(F64)
    cover = (
        torch.clamp((density - (CLOUD_OFFSET - CLOUD_SLOPE * sky.cloud_cover)) * CLOUD_EDGE, 0, 1)
        * torch.clamp(up[k] * CLOUD_FADE_IN, 0, 1)
    )[:, None]
    colour[k] = colour[k] * (1 - cover) + dw.vector(list(CLOUD_COLOUR)) * cover
    return colour


def expose(dw: DeviceWorld, linear: Tensor, depth: Tensor, motion_m: Tensor) -> Tensor:
    """sensor.expose of V views (V, H, W, 3): gain, white balance, vignetting, motion blur."""
    sensor = dw.world.look.sensor
    _, h, w, _ = linear.shape
    out = linear * (dw.vector(sensor.white_balance) * sensor.exposure)
    if sensor.auto_gain:
        luma = out[..., 0] * float(LUMA[0]) + out[..., 1] * float(LUMA[1]) + out[..., 2] * float(LUMA[2])
        total = torch.clamp(torch.round(luma * LUMA_STEPS), 0, 1 << 20).long().sum(dim=(1, 2))  # integer sums: any order
        mean = total.to(F64) / (LUMA_STEPS * h * w)
        out = out * torch.clamp(sensor.target / torch.clamp(mean, min=MIN_MEAN), *GAIN_RANGE)[:, None, None, None]
    v, u = torch.meshgrid(torch.arange(h, device=dw.device, dtype=F64), torch.arange(w, device=dw.device, dtype=F64), indexing="ij")
    r2 = ((u - (w - 1) / 2) / (w / 2)) ** 2 + ((v - (h - 1) / 2) / (h / 2)) ** 2
    out = out * (1 - sensor.vignetting * r2 / 2)[None, ..., None]
    moving = motion_m > 0
    if bool(moving.any()):
        blurred = _motion_blur(out, depth, motion_m, u, v)
        out = torch.where(moving[:, None, None, None], blurred, out)
    return out


def _motion_blur(image: Tensor, depth: Tensor, motion_m: Tensor, u: Tensor, v: Tensor) -> Tensor:
    """sensor._motion_blur of V views: the average over the shutter of each camera driving motion_m[k]."""
    count, h, w, _ = image.shape
    cx, cy = (w - 1) / 2, (h - 1) / 2
    hit = depth > 0
    z = torch.where(hit, depth, 1.0)
    acc = image.to(F32)
    for i in range(1, BLUR_SAMPLES):
        scale = torch.where(hit, z / (z + motion_m[:, None, None] * i / (BLUR_SAMPLES - 1)), 1.0)
        mx, my = (cx + (u - cx) * scale).to(F32), (cy + (v - cy) * scale).to(F32)
        acc = acc + torch.stack([bilinear(image[k], mx[k].ravel(), my[k].ravel()).reshape(h, w, 3) for k in range(count)])
    return (acc / BLUR_SAMPLES).to(F64)


def gamma_encode(rgb: Tensor) -> Tensor:
    """render._gamma_encode: linear light to 8-bit through the gamma table."""
    table = torch.as_tensor(GAMMA, device=rgb.device)
    return table[(rgb.clamp(0.0, 1.0) * (len(GAMMA) - 1) + 0.5).int().long()]
