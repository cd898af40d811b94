"""conf/render's renderer for one world: the one place a backend is chosen.

`render.backend=numpy` is the reference (world/render.py), one view at a time, the same bytes on every
CPU; `torch` is its port (world/render_torch.py), render.views_per_batch views at once on
render.device. The synthesize stage's drives (world.record) and the drive stage's rigs
(drive.policies.StereoRig) render through it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from offroad_path.world.render import PinholeCamera, View, render_view
from offroad_path.world.scene import World


class Renderer:
    """Views of one world through one camera, out to max_distance_m."""

    def __init__(self, world: World, camera: PinholeCamera, max_distance_m: float, render: Any = None) -> None:
        self.world, self.camera, self.max_distance_m = world, camera, max_distance_m
        self.device_world = None
        self.views_per_batch = 1
        if render is not None and render.backend == "torch":
            from offroad_path.world.render_torch import DeviceWorld, torch_device  # torch only for this backend

            self.device_world = DeviceWorld(world, torch_device(render.device))
            self.views_per_batch = render.views_per_batch
        else:
            self.rays = camera.rays()

    def views(self, poses: np.ndarray, motion_m: np.ndarray | None = None, noise_keys: list[tuple[int, ...]] | None = None) -> list[View]:
        """A View per camera-to-world pose (V, 4, 4), with each view's shutter motion (m) and noise key
        (the reference's defaults when None), in the poses' order."""
        if self.device_world is None:
            if motion_m is None:
                return [render_view(self.world, self.camera, pose, self.max_distance_m, self.rays) for pose in poses]
            views = zip(poses, motion_m, noise_keys, strict=True)
            return [render_view(self.world, self.camera, pose, self.max_distance_m, self.rays, m, key) for pose, m, key in views]
        from offroad_path.world.render_torch import render_views

        out: list[View] = []
        for start in range(0, len(poses), self.views_per_batch):
            batch = slice(start, start + self.views_per_batch)
            more = {} if motion_m is None else {"motion_m": motion_m[batch], "noise_keys": noise_keys[batch]}
            out += render_views(self.device_world, self.camera, np.stack(poses[batch]), self.max_distance_m, **more)
        return out
