"""Traction: off road the vehicle turns less than the kinematic bicycle model says (Holder & Breckon
2018's argument (c) against end-to-end steering: steering input and actual motion disagree).

The yaw rate is the bicycle model's times a factor: the surface's (config `world.slip.factors`, per
class name) times a jitter drawn once per square patch of ground (`patch_m`), plus per-step noise.
A factor of 1 everywhere is today's world. The patches come from their own generator (seeded by
the world's seed), so turning slip on changes nothing else in a world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.world.classes import CLASS_NAMES

SLIP_STREAM = 5113  # the patches' generator: SeedSequence([world seed, SLIP_STREAM])


@dataclass(frozen=True)
class Slip:
    by_class: np.ndarray  # (classes,) mean yaw-rate factor per surface class
    patches: np.ndarray  # (rows, cols) multiplicative jitter per patch, about 1
    origin: tuple[float, float]  # (x, z) of patch (0, 0)'s corner
    patch_m: float
    noise: float  # standard deviation of the per-step factor noise

    def factor(self, classes: np.ndarray, xz: np.ndarray) -> np.ndarray:
        """Yaw-rate factors (N,) at ground points xz (N, 2) whose surface classes are `classes` (N,)."""
        col = np.clip(((xz[:, 0] - self.origin[0]) // self.patch_m).astype(np.intp), 0, self.patches.shape[1] - 1)
        row = np.clip(((xz[:, 1] - self.origin[1]) // self.patch_m).astype(np.intp), 0, self.patches.shape[0] - 1)
        return self.by_class[classes] * self.patches[row, col]


def make_slip(cfg, seed: int, lo: np.ndarray, hi: np.ndarray) -> Slip:
    """The slip of the world of `seed` over the ground box lo..hi (x, z), from a `world.slip` config node."""
    unknown = sorted(set(cfg.factors) - set(CLASS_NAMES))
    if unknown:
        raise ValueError(f"world.slip.factors: unknown surface class {unknown[0]!r} (classes: {', '.join(CLASS_NAMES)})")
    by_class = np.array([float(cfg.factors.get(name, 1.0)) for name in CLASS_NAMES])
    rng = np.random.default_rng(np.random.SeedSequence([seed, SLIP_STREAM]))
    shape = (int(np.ceil((hi[1] - lo[1]) / cfg.patch_m)) + 1, int(np.ceil((hi[0] - lo[0]) / cfg.patch_m)) + 1)
    patches = 1.0 + cfg.jitter * rng.uniform(-1.0, 1.0, shape)
    return Slip(by_class, patches, (float(lo[0]), float(lo[1])), float(cfg.patch_m), float(cfg.noise))
