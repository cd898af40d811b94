"""How the project draws what it makes: the path over an image, semantic classes and depth in
colour. Used by the label overlays, training's sample images, `predict` and the previews."""

from __future__ import annotations

import cv2
import numpy as np

PATH_TINT = np.array([0, 255, 0], np.float32)  # green
OUTLINE = (255, 255, 0)  # yellow
# RGB per class id: sky, water, dirt, paved road, grass, foliage, tree, man-made obstacle.
CLASS_COLOURS = np.array(
    [[135, 190, 235], [30, 80, 200], [150, 100, 50], [110, 110, 110], [90, 190, 60], [30, 120, 30], [10, 70, 10], [230, 40, 40]], np.uint8
)


def overlay(image: np.ndarray, path: np.ndarray, alpha: float = 0.45, outline: bool = True) -> np.ndarray:
    """(H, W, 3) RGB image with the path (path > 0) blended toward green, optionally outlined;
    every other pixel untouched."""
    out = image.copy()
    inside = path > 0
    out[inside] = np.rint((1 - alpha) * image[inside].astype(np.float32) + alpha * PATH_TINT).astype(np.uint8)
    if outline:
        contours, _ = cv2.findContours(inside.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(out, contours, -1, OUTLINE, 1, cv2.LINE_AA)
    return out


def colour_semantic(semantic: np.ndarray) -> np.ndarray:
    """(H, W) class ids -> (H, W, 3) RGB."""
    return CLASS_COLOURS[np.minimum(semantic, len(CLASS_COLOURS) - 1)]


def colour_depth(depth_m: np.ndarray, near_m: float = 2.0, far_m: float = 60.0) -> np.ndarray:
    """Inverse depth in a perceptual colour map; black where there is no depth."""
    inv = (1 / np.clip(depth_m, near_m, far_m) - 1 / far_m) / (1 / near_m - 1 / far_m)
    rgb = cv2.applyColorMap(np.uint8(255 * inv), cv2.COLORMAP_TURBO)[:, :, ::-1]
    return np.where(depth_m[..., None] > 0, rgb, 0).astype(np.uint8)
