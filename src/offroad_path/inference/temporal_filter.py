"""Temporal consistency across video frames, the paper's future work: the previous frame's path
confidence carried into the current frame with the camera's motion and the current frame's depth,
and fused with the current prediction by an exponential average.

A pixel of the current frame with depth Z is lifted to 3D, moved into the previous camera by the
relative pose, and projected there; the previous confidence is sampled at that point (backward
warping: every current pixel gets a value, none is splatted twice). Pixels without depth, or
whose point leaves the previous image or lies behind it, keep the current prediction alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

OCCLUSION_M, OCCLUSION_REL = 0.3, 0.05  # how far a point may lie from the previous frame's surface and still be seen


def warp_previous(
    previous: np.ndarray, depth: np.ndarray, K: np.ndarray, previous_from_current: np.ndarray, previous_depth: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(previous (H, W) sampled at each current pixel, valid (H, W) bool).

    depth: (H, W) z of the current frame in metres, 0 where unknown; K: 3x3 intrinsics of both
    frames; previous_from_current: 4x4, a current-camera point into the previous camera;
    previous_depth: the previous frame's depth, to drop points the previous camera did not see
    (something nearer stood in front of them).
    """
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    z = depth.astype(np.float64)
    points = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=-1)  # (H, W, 3)
    R, t = previous_from_current[:3, :3], previous_from_current[:3, 3]
    moved = points @ R.T + t  # (H, W, 3) in the previous camera
    zp = moved[..., 2]
    in_front = (z > 0) & (zp > 1e-3)
    safe = np.where(in_front, zp, 1.0)
    map_x = (K[0, 0] * moved[..., 0] / safe + K[0, 2]).astype(np.float32)
    map_y = (K[1, 1] * moved[..., 1] / safe + K[1, 2]).astype(np.float32)
    valid = in_front & (map_x >= 0) & (map_x <= w - 1) & (map_y >= 0) & (map_y <= h - 1)
    if previous_depth is not None:
        seen = cv2.remap(previous_depth.astype(np.float32), map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_REPLICATE)
        valid &= (seen > 0) & (np.abs(seen - zp) <= OCCLUSION_REL * zp + OCCLUSION_M)
    warped = cv2.remap(previous.astype(np.float32), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.where(valid, warped, 0.0).astype(np.float32), valid


@dataclass
class TemporalFilter:
    """Exponential average in the current frame: fused = alpha * current + (1 - alpha) * warped
    previous fused, where the warp is valid; the current prediction elsewhere. reset() at a cut."""

    alpha: float
    _fused: np.ndarray | None = field(default=None, repr=False)
    _depth: np.ndarray | None = field(default=None, repr=False)

    def reset(self) -> None:
        self._fused = self._depth = None

    def __call__(self, confidence: np.ndarray, depth: np.ndarray, K: np.ndarray, previous_from_current: np.ndarray) -> np.ndarray:
        """confidence, depth: (H, W) of the current frame; the pose as in warp_previous."""
        if self._fused is None:
            self._fused = confidence.astype(np.float32)
        else:
            warped, valid = warp_previous(self._fused, depth, K, previous_from_current, self._depth)
            self._fused = np.where(valid, self.alpha * confidence + (1 - self.alpha) * warped, confidence).astype(np.float32)
        self._depth = depth
        return self._fused
