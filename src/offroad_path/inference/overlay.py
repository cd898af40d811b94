"""The predicted path tinted over the image it was predicted for."""

from __future__ import annotations

import numpy as np

TINT = np.array([0, 255, 0], np.float32)


def tint(image: np.ndarray, path: np.ndarray, alpha: float = 0.45) -> np.ndarray:
    """RGB image with the pixels where `path` is True blended toward green; all others untouched."""
    out = image.copy()
    out[path] = np.rint((1 - alpha) * image[path].astype(np.float32) + alpha * TINT).astype(np.uint8)
    return out
