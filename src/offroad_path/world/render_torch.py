"""world/render.py's ray caster in torch: many views of one world in one batch, on a GPU.

The reference is world/render.py, ported step by step (world/trace_torch.py: the terrain march and
the objects; world/shading_torch.py: shading, textures, sky and the sensor's exposure);
tests/world/test_render_torch.py holds the two to agreement on the same views. What differs: the
views of a batch march together (each ray carries its own camera's origin), and float sums run in
the device's order, so the bytes are not the reference's, and on a GPU they are that GPU's. The
sensor's last step (noise and compression, world/sensor.py's `record`) runs in NumPy on the host,
from the same noise key: its draws are the reference's.
"""

from __future__ import annotations

import numpy as np
import torch

from offroad_path.world.render import PinholeCamera, View
from offroad_path.world.sensor import record
from offroad_path.world.shading_torch import Hits, expose, gamma_encode, shade
from offroad_path.world.trace_torch import F64, DeviceWorld, march_terrain, trace_objects

__all__ = ["PORTS", "DeviceWorld", "render_views", "torch_device"]

# Each port and the reference it follows step by step (world.<module>.<name>): a fix to one is owed to the other.
# Each names the other in its docstring; tests/world/test_render_torch.py walks the table.
PORTS = (
    ("kernels.sample_bilinear", "trace_torch.bilinear"),
    ("terrain.Terrain", "trace_torch._Terrain"),
    ("render.march_terrain", "trace_torch.march_terrain"),
    ("render._refine", "trace_torch._refine"),
    ("render._tangent_range", "trace_torch._tangent_range"),
    ("objects.intersect", "trace_torch.intersect"),
    ("render.trace_objects", "trace_torch.trace_objects"),
    ("render.render_view", "render_torch.render_views"),
    ("render.render_view", "shading_torch.shade"),
    ("terrain.Grid.coords", "shading_torch._grid_coords"),
    ("terrain.Terrain.normals", "shading_torch._terrain_normals"),
    ("render._detail", "shading_torch._detail"),
    ("render._sky_colour", "shading_torch._sky_colour"),
    ("sensor.expose", "shading_torch.expose"),
    ("sensor._motion_blur", "shading_torch._motion_blur"),
    ("render._gamma_encode", "shading_torch.gamma_encode"),
)


def render_views(  # noqa: PLR0913
    dw: DeviceWorld,
    camera: PinholeCamera,
    poses: np.ndarray,
    max_t: float,
    *,
    motion_m: np.ndarray | None = None,
    noise_keys: list[tuple[int, ...]] | None = None,
) -> list[View]:
    """render.render_view of each camera-to-world pose (V, 4, 4), together: what the reference renders
    for each (pose, motion_m[k], noise_keys[k]), to the agreement tests/world/test_render_torch.py checks."""
    count = len(poses)
    motion_m = np.zeros(count) if motion_m is None else np.asarray(motion_m, np.float64)
    noise_keys = [(0,)] * count if noise_keys is None else noise_keys
    world, device = dw.world, dw.device
    poses_t = torch.as_tensor(np.asarray(poses, np.float64), device=device)
    rays = torch.as_tensor(camera.rays(), dtype=F64, device=device)  # (H * W, 3)
    pixels = len(rays)
    dirs = torch.einsum("pk,vjk->vpj", rays, poses_t[:, :3, :3]).reshape(-1, 3)  # (V * H * W, 3), t = depth
    origin = poses_t[:, :3, 3].repeat_interleave(pixels, 0)  # each ray's camera
    top = [world.terrain.max_elevation_near(p[0, 3], p[2, 3], max_t) for p in np.asarray(poses)]
    top = torch.as_tensor(top, dtype=F64, device=device).repeat_interleave(pixels)
    t_ground = march_terrain(dw, origin, dirs, top, max_t)
    t, n_obj, obj_index = trace_objects(dw, camera, poses_t, dirs, t_ground, max_t=max_t)
    hit = torch.isfinite(t) & (t < max_t)
    t = torch.where(hit, t, 0.0)
    rgb, semantic = shade(dw, camera, Hits(origin, dirs, t, hit, n_obj, obj_index))
    shape = (count, camera.height, camera.width)
    depth = t.reshape(shape)
    linear = rgb.reshape(*shape, 3)
    if world.look is None:
        images = gamma_encode(linear).cpu().numpy()
    else:
        exposed = expose(dw, linear, depth, torch.as_tensor(motion_m, device=device))
        encoded = gamma_encode(exposed).cpu().numpy()
        images = np.stack([record(encoded[k], world.look.sensor, noise_keys[k]) for k in range(count)])
    depth, semantic = depth.cpu().numpy(), semantic.reshape(shape).cpu().numpy()
    return [View(image=images[k], depth=depth[k], semantic=semantic[k]) for k in range(count)]


def torch_device(name: str) -> torch.device:
    """conf/render's device: auto is the GPU where there is one, else the CPU."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)
