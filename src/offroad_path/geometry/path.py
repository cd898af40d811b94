"""The driven path's geometry, in one place: distance travelled along camera positions, and the
horizontal mirroring that doubles the training data (mirrored image, label and steering)."""

from __future__ import annotations

import numpy as np


def distance_along(positions: np.ndarray) -> np.ndarray:
    """Distance driven (m) at each of (N, 3) positions, or of (N, 4, 4) poses; 0 at the first."""
    xyz = positions[:, :3, 3] if positions.ndim == 3 else positions
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=1))])


def path_length(positions: np.ndarray) -> float:
    """Length (m) of the path through (N, 3) positions, or (N, 4, 4) poses."""
    xyz = positions[:, :3, 3] if positions.ndim == 3 else positions
    return float(np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum())


def mirror(image: np.ndarray) -> np.ndarray:
    """Left-right mirror of an (H, W, ...) image or map, contiguous (as torch and OpenCV want)."""
    return np.ascontiguousarray(image[:, ::-1])
