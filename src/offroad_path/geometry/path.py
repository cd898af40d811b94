"""The driven path's geometry, in one place: distance travelled along camera positions, the frame a
label of the next distance_m ends at, and the horizontal mirroring that doubles the training data
(mirrored image, label and steering)."""

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


def label_end(positions: np.ndarray, f0: int, distance_m: float) -> int | None:
    """The last frame fn of the label made at f0: the first frame after f0 whose camera lies more than
    distance_m (straight line) from f0's (the label stage's rule, and the exact labels' of the temporal
    scores); None when no frame does. positions: (N, 3)."""
    beyond = np.flatnonzero(np.linalg.norm(positions[f0 + 1 :] - positions[f0], axis=1) > distance_m)
    return f0 + 1 + int(beyond[0]) if len(beyond) else None


def mirror(image: np.ndarray) -> np.ndarray:
    """Left-right mirror of an (H, W, ...) image or map, contiguous (as torch and OpenCV want)."""
    return np.ascontiguousarray(image[:, ::-1])
