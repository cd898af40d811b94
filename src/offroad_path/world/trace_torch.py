"""What each ray of world/render_torch.py's batches hits, ported step by step from world/render.py:
the world's arrays on the device, the terrain march (clearance steps, the 4 m and 16 m height
bounds, bisection then false position) and the analytic objects. The views of a batch march
together: each ray carries its own camera's origin.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from offroad_path.world.classes import TEXTURE_CONTRAST
from offroad_path.world.objects import BOX, CYLINDER, SPHERE
from offroad_path.world.objects import NEAR_M as OBJECT_NEAR_M
from offroad_path.world.render import BISECTIONS, COMPACT_BELOW, MAX_TAN_ANGLE, MIN_STEP_M, NEAR_M, REFINEMENTS, RELAX, PinholeCamera
from offroad_path.world.scene import World
from offroad_path.world.terrain import CELL_MARGIN

F32, F64 = torch.float32, torch.float64


class DeviceWorld:
    """One world's arrays on a device, moved once and shared by every batch of its views."""

    def __init__(self, world: World, device: str | torch.device):
        self.world, self.device = world, torch.device(device)
        terrain = world.terrain

        def put(array: np.ndarray, dtype: torch.dtype | None = None) -> Tensor:
            return torch.as_tensor(np.ascontiguousarray(array), device=self.device, dtype=dtype)

        self.corners = put(terrain.corners)  # (cells, 4) float32: h00, h01, h10, h11
        self.levels = [(radius, put(flat)) for radius, flat in terrain.max_levels]
        self.grad = put(terrain.gradient)  # (rows, cols, 2) float32
        self.materials = put(world.materials)
        self.shadow = put(world.shadow, F32)
        self.wear = None if world.wear is None else put(world.wear)
        self.palette = put(world.palette, F64)
        self.contrast = put(TEXTURE_CONTRAST if world.contrast is None else world.contrast, F64)
        self.textures = {name: put(texture, F32) for name, texture in world.textures.items()}
        objects = world.objects.arrays()
        self.kind, self.params, self.bounds = put(objects.kind), put(objects.params, F64), put(objects.bounds, F64)
        self.object_cls, self.object_colour = put(objects.cls), put(objects.color, F64)

    def vector(self, values: np.ndarray | list[float]) -> Tensor:
        return torch.as_tensor(np.asarray(values, np.float64), device=self.device)


def bilinear(image: Tensor, mx: Tensor, my: Tensor, wrap: bool = False) -> Tensor:
    """world.kernels.sample_bilinear: values (N,) or (N, C) float32 of `image` (rows, cols[, C]) at
    fractional pixels; outside, the border replicated or the image tiled (wrap)."""
    rows, cols = image.shape[:2]
    flat = image.reshape(rows * cols, -1)
    x, y = mx.to(F32), my.to(F32)
    x0f, y0f = torch.floor(x), torch.floor(y)
    ax, ay = (x - x0f)[:, None], (y - y0f)[:, None]
    x0, y0 = x0f.long(), y0f.long()
    if wrap:
        x0, y0 = torch.remainder(x0, cols), torch.remainder(y0, rows)
        x1, y1 = torch.where(x0 == cols - 1, 0, x0 + 1), torch.where(y0 == rows - 1, 0, y0 + 1)
    else:
        x1, y1 = (x0 + 1).clamp(0, cols - 1), (y0 + 1).clamp(0, rows - 1)
        x0, y0 = x0.clamp(0, cols - 1), y0.clamp(0, rows - 1)
    top = flat[y0 * cols + x0] + (flat[y0 * cols + x1] - flat[y0 * cols + x0]) * ax
    bottom = flat[y1 * cols + x0] + (flat[y1 * cols + x1] - flat[y1 * cols + x0]) * ax
    out = (top + (bottom - top) * ay).to(F32)
    return out[:, 0] if image.ndim == 2 else out


class _Terrain:
    """The height field's lookups (world.terrain.Terrain's) on a DeviceWorld's tensors."""

    def __init__(self, dw: DeviceWorld):
        terrain = dw.world.terrain
        self.dw, self.grid = dw, terrain.grid
        self.rows, self.cols = terrain.heights.shape

    def cells(self, x: Tensor, z: Tensor) -> tuple[Tensor, Tensor]:
        g = self.grid
        fx = ((x - g.x0) * (1.0 / g.step)).clamp(0.0, self.cols - CELL_MARGIN).to(F32)
        fz = ((z - g.z0) * (1.0 / g.step)).clamp(0.0, self.rows - CELL_MARGIN).to(F32)
        return fx, fz

    def elevation_at(self, fx: Tensor, fz: Tensor) -> Tensor:
        ix, iz = fx.int(), fz.int()
        ax, az = fx - ix, fz - iz
        c = self.dw.corners[(iz * self.cols + ix).long()]
        top = c[:, 0] + (c[:, 1] - c[:, 0]) * ax
        bottom = c[:, 2] + (c[:, 3] - c[:, 2]) * ax
        return top + (bottom - top) * az

    def max_within(self, level: int, fx: Tensor, fz: Tensor) -> Tensor:
        nearest = (fz + 0.5).int().long() * self.cols + (fx + 0.5).int().long()
        return self.dw.levels[level][1][nearest]


def march_terrain(dw: DeviceWorld, origin: Tensor, dirs: Tensor, top: Tensor, max_t: float) -> Tensor:
    """Depth (R,) float64 of each ray's first terrain crossing, inf where none within max_t: rays from
    origins (R, 3) along dirs (R, 3) (t = depth), `top` (R,) the highest terrain near each ray's camera.
    Reference: world.render.march_terrain.
    """
    terrain = _Terrain(dw)
    origin, dirs = origin.to(F32), dirs.to(F32)
    horizontal = torch.hypot(dirs[:, 0], dirs[:, 2])
    rate = dirs[:, 1] + float(np.float32(dw.world.terrain.max_slope)) * horizontal  # the reference's float32 bound
    t_hit = torch.full((len(dirs),), math.inf, dtype=F64, device=dw.device)
    rising = dirs[:, 1] < 0
    t_limit = torch.where(rising, ((top.to(F32) + origin[:, 1]) / -dirs[:, 1]).clamp(max=max_t), max_t)
    inv_sink = torch.where(dirs[:, 1] > 0, 1.0 / dirs[:, 1], math.inf)
    idx = torch.nonzero((rate > 0) & (t_limit > NEAR_M))[:, 0]
    per_ray = [origin[idx, 0], origin[idx, 1], origin[idx, 2], dirs[idx, 0], dirs[idx, 1], dirs[idx, 2]]
    per_ray += [1.0 / rate[idx], t_limit[idx], inv_sink[idx]] + [radius / horizontal[idx] for radius, _ in dw.levels]
    t = torch.full((len(idx),), NEAR_M, dtype=F32, device=dw.device)
    t_prev, c_prev = t.clone(), torch.full_like(t, math.inf)
    alive = torch.ones(len(idx), dtype=torch.bool, device=dw.device)
    brackets = []
    while len(idx):
        ox, oy, oz, dx, dy, dz, inv_rate, limit, sink = per_ray[:9]
        y = oy + t * dy
        fx, fz = terrain.cells(ox + t * dx, oz + t * dz)
        c = -y - terrain.elevation_at(fx, fz)
        crossed = alive & (c <= 0)
        brackets.append((idx[crossed], t_prev[crossed], t[crossed], c_prev[crossed], c[crossed]))
        step = torch.maximum(c * inv_rate, RELAX * t).clamp_min(MIN_STEP_M)
        for level, reach_flat in enumerate(per_ray[9:]):
            headroom = -y - terrain.max_within(level, fx, fz)
            reach = torch.minimum(reach_flat, headroom * sink)  # NaN where 0 x inf, masked below
            step = torch.where(headroom > 0, torch.maximum(step, reach), step)
        t_prev, c_prev = t, c
        t = t + step
        alive &= ~crossed & (t < limit)
        if alive.sum() < COMPACT_BELOW * len(alive):  # compact, as the reference does
            keep = torch.nonzero(alive)[:, 0]
            idx, t, t_prev, c_prev, alive = idx[keep], t[keep], t_prev[keep], c_prev[keep], alive[keep]
            per_ray = [a[keep] for a in per_ray]
    idx, lo, hi, c_lo, c_hi = (torch.cat(parts) for parts in zip(*brackets, strict=True))
    if len(idx):
        t_hit[idx] = _refine(terrain, origin[idx], dirs[idx], (lo, hi, c_lo, c_hi)).to(F64)
    return t_hit


def _refine(terrain: _Terrain, origin: Tensor, dirs: Tensor, bracket: tuple[Tensor, Tensor, Tensor, Tensor]) -> Tensor:
    """The crossing inside each bracket (lo, hi, c_lo, c_hi): [lo, hi] with clearance c_lo > 0 >= c_hi; render._refine."""
    lo, hi, c_lo, c_hi = bracket
    below = ~torch.isfinite(c_lo)  # below ground at the near plane: report it
    lo, c_lo = torch.where(below, hi, lo), torch.where(below, 0.0, c_lo)
    for i in range(REFINEMENTS):
        if i < BISECTIONS:
            mid = 0.5 * (lo + hi)
        else:
            denom = c_lo - c_hi
            mid = lo + torch.where(denom > 0, c_lo / torch.where(denom > 0, denom, 1.0), 0.5) * (hi - lo)
        fx, fz = terrain.cells(origin[:, 0] + mid * dirs[:, 0], origin[:, 2] + mid * dirs[:, 2])
        c = -(origin[:, 1] + mid * dirs[:, 1]) - terrain.elevation_at(fx, fz)
        above = c > 0
        lo, c_lo = torch.where(above, mid, lo), torch.where(above, c, c_lo)
        hi, c_hi = torch.where(above, hi, mid), torch.where(above, c_hi, c)
    denom = c_lo - c_hi
    return lo + torch.where(denom > 0, c_lo / torch.where(denom > 0, denom, 1.0), 0.0) * (hi - lo)


def _tangent_range(a: Tensor, z: Tensor, r: Tensor, f: float, c: float) -> tuple[Tensor, Tensor]:
    """render._tangent_range: the pixel range along one axis that rays meeting a sphere can have."""
    dist = torch.hypot(a, z)
    half = torch.asin((r / dist).nan_to_num(nan=0.0, posinf=1.0).clamp(0.0, 1.0))
    centre = torch.atan2(a, z)
    lo_angle, hi_angle = centre - half, centre + half
    lo = torch.where(lo_angle <= -math.pi / 2, -math.inf, f * torch.tan(lo_angle.clamp(-MAX_TAN_ANGLE, MAX_TAN_ANGLE)) + c)
    hi = torch.where(hi_angle >= math.pi / 2, math.inf, f * torch.tan(hi_angle.clamp(-MAX_TAN_ANGLE, MAX_TAN_ANGLE)) + c)
    behind = (hi_angle <= -math.pi / 2) | (lo_angle >= math.pi / 2)
    surrounds = dist <= r
    lo = torch.where(surrounds, -math.inf, torch.where(behind, math.inf, lo))
    hi = torch.where(surrounds, math.inf, torch.where(behind, -math.inf, hi))
    return lo, hi


def intersect(kind: int, p: Tensor, o: Tensor, d: Tensor) -> tuple[Tensor, Tensor]:
    """world.objects.intersect with an origin per ray: depth (M,) and outward normals (M, 3)."""
    if kind == SPHERE:
        centre, r = p[:, :3], p[:, 3]
        oc = o - centre
        a, b = (d * d).sum(1), (d * oc).sum(1)
        disc = b * b - a * ((oc * oc).sum(1) - r * r)
        root = disc.clamp_min(0.0).sqrt()
        t = (-b - root) / a
        t = torch.where(t > OBJECT_NEAR_M, t, (-b + root) / a)
        t = torch.where((disc >= 0) & (t > OBJECT_NEAR_M), t, math.inf)
        return t, (oc + t[:, None] * d) / r[:, None]
    if kind == CYLINDER:
        x, z, y_top, y_bottom, r = p[:, :5].T
        ox, oz, oy = o[:, 0] - x, o[:, 2] - z, o[:, 1]
        dx, dz = d[:, 0], d[:, 2]
        a, b = dx * dx + dz * dz, ox * dx + oz * dz
        disc = b * b - a * (ox * ox + oz * oz - r * r)
        t_side = (-b - disc.clamp_min(0.0).sqrt()) / a
        t_cap = (y_top - oy) / d[:, 1]
        y_side = oy + t_side * d[:, 1]
        side_ok = (disc >= 0) & (a > 0) & (t_side > OBJECT_NEAR_M) & (y_side >= y_top) & (y_side <= y_bottom)
        cap_x, cap_z = ox + t_cap * dx, oz + t_cap * dz
        cap_ok = (t_cap > OBJECT_NEAR_M) & (cap_x * cap_x + cap_z * cap_z <= r * r)
        t_side, t_cap = torch.where(side_ok, t_side, math.inf), torch.where(cap_ok, t_cap, math.inf)
        use_cap = t_cap < t_side
        t = torch.where(use_cap, t_cap, t_side)
        normal = torch.stack([(ox + t * dx) / r, torch.zeros_like(t), (oz + t * dz) / r], dim=1)
        return t, torch.where(use_cap[:, None], normal.new_tensor([0.0, -1.0, 0.0]), normal)
    assert kind == BOX, kind
    centre, half, yaw = p[:, :3], p[:, 3:6], p[:, 6]
    c, s = torch.cos(yaw)[:, None], torch.sin(yaw)[:, None]

    def to_box(v: Tensor) -> Tensor:  # world to box axes: the box's x is world (c, 0, -s)
        return torch.cat([c * v[:, :1] - s * v[:, 2:], v[:, 1:2], s * v[:, :1] + c * v[:, 2:]], dim=1)

    lo, ld = to_box(o - centre), to_box(d)
    inv = 1.0 / ld
    t1, t2 = (-half - lo) * inv, (half - lo) * inv
    t_near = torch.minimum(t1, t2).nan_to_num(nan=-math.inf, posinf=math.inf, neginf=-math.inf)
    t_far = torch.maximum(t1, t2).nan_to_num(nan=math.inf, posinf=math.inf, neginf=-math.inf)
    t_enter, axis = t_near.max(dim=1)
    t = torch.where((t_enter <= t_far.min(dim=1).values) & (t_enter > OBJECT_NEAR_M), t_enter, math.inf)
    n = torch.zeros_like(ld).scatter_(1, axis[:, None], -torch.sign(ld.gather(1, axis[:, None])))
    return t, torch.cat([c * n[:, :1] + s * n[:, 2:], n[:, 1:2], -s * n[:, :1] + c * n[:, 2:]], dim=1)


def trace_objects(  # noqa: PLR0913
    dw: DeviceWorld, camera: PinholeCamera, poses: Tensor, dirs: Tensor, t_bound: Tensor, *, max_t: float
) -> tuple[Tensor, Tensor, Tensor]:
    """render.trace_objects for V views at once: poses (V, 4, 4), dirs (V * H * W, 3); object hits
    nearer than t_bound: (t, normal, object index, -1 where none), each (V * H * W[, 3])."""
    h, w = camera.height, camera.width
    t_best, normal = t_bound.clone(), torch.zeros(len(dirs), 3, dtype=F64, device=dw.device)
    index = torch.full((len(dirs),), -1, dtype=torch.long, device=dw.device)
    if not len(dw.kind):
        return t_best, normal, index
    origin, rot = poses[:, :3, 3], poses[:, :3, :3]
    centres = torch.einsum("vnk,vkj->vnj", dw.bounds[None, :, :3] - origin[:, None], rot)  # (V, N, 3) in each camera
    x, y, z = centres.unbind(-1)
    r = dw.bounds[:, 3].expand_as(z)
    near = z - r
    u_lo, u_hi = _tangent_range(x, z, r, camera.fx, camera.cx)
    v_lo, v_hi = _tangent_range(y, z, r, camera.fy, camera.cy)
    visible = (z + r > NEAR_M) & (near < max_t) & (u_hi >= 0) & (u_lo <= w - 1) & (v_hi >= 0) & (v_lo <= h - 1)
    r0, r1 = torch.floor(v_lo.clamp(0, h)).long(), torch.ceil((v_hi + 1).clamp(0, h)).long()
    c0, c1 = torch.floor(u_lo.clamp(0, w)).long(), torch.ceil((u_hi + 1).clamp(0, w)).long()
    for kind in torch.unique(dw.kind).tolist():
        view, obj = torch.nonzero(visible & (dw.kind == kind)[None], as_tuple=True)
        widths = c1[view, obj] - c0[view, obj]
        sizes = (r1[view, obj] - r0[view, obj]) * widths
        # Every pixel of every (view, object) box, as (ray, object) pairs.
        local = torch.arange(int(sizes.sum()), device=dw.device) - torch.repeat_interleave(torch.cumsum(sizes, 0) - sizes, sizes)
        width_each = torch.repeat_interleave(widths, sizes)
        view, obj = torch.repeat_interleave(view, sizes), torch.repeat_interleave(obj, sizes)
        ray = view * (h * w) + (r0[view, obj] + local // width_each) * w + c0[view, obj] + local % width_each
        keep = t_best[ray] > near[view, obj]
        view, obj, ray = view[keep], obj[keep], ray[keep]
        t, n = intersect(kind, dw.params[obj], origin[view], dirs[ray])
        closer = t < t_best[ray]
        obj, ray, t, n = obj[closer], ray[closer], t[closer], n[closer]
        t_best.scatter_reduce_(0, ray, t, "amin")
        won = t == t_best[ray]
        index[ray[won]] = obj[won]
        normal[ray[won]] = n[won]
    return t_best, normal, index
