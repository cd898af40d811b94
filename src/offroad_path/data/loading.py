"""A sample's files read from disk as numpy arrays: image, path label or semantic map, stereo depth,
and the confidence maps the train and postprocess stages write. No torch here, so that postprocess,
which only reads, filters and writes maps, starts without importing it (2 s less per stage)."""

from __future__ import annotations

import cv2
import numpy as np

from offroad_path.data.manifest import Sample
from offroad_path.geometry.path import mirror
from offroad_path.geometry.stereo import decode_disparity, depth_from_disparity

TARGETS = ("path", "semantic")


def read(path: str, flags: int) -> np.ndarray:
    image = cv2.imread(path, flags)
    if image is None:
        raise FileNotFoundError(f"{path}: missing or not an image")
    return image


def load_sample(sample: Sample, target: str) -> tuple[np.ndarray, np.ndarray]:
    """(RGB image (H, W, 3) uint8, target (H, W) int64), mirrored when the sample says so.

    target 'path': 1 where the label says path; 'semantic': the world's class ids 0..7.
    """
    image = cv2.cvtColor(read(sample.image, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    if target == "path":
        mask = (read(sample.label, cv2.IMREAD_GRAYSCALE) > 0).astype(np.int64)
    elif target == "semantic":
        if not sample.semantic:
            raise ValueError(f"{sample.image}: no semantic map to pretrain on (real recordings have none)")
        mask = read(sample.semantic, cv2.IMREAD_UNCHANGED).astype(np.int64)
    else:
        raise ValueError(f"unknown target {target!r}; valid: {', '.join(TARGETS)}")
    if sample.mirrored:
        image, mask = mirror(image), mirror(mask)
    return np.ascontiguousarray(image), np.ascontiguousarray(mask)


def load_depth(sample: Sample) -> np.ndarray:
    """Stereo depth of the sample's frame (H, W) float32 metres, 0 unknown, mirrored with it."""
    depth = depth_from_disparity(decode_disparity(read(sample.disparity, cv2.IMREAD_UNCHANGED)), sample.fx, sample.baseline_m)
    return mirror(depth) if sample.mirrored else depth


def load_labels(samples: list[Sample]) -> np.ndarray:
    """Path labels (N, H, W) bool, mirrored where a sample says so."""
    labels = [read(s.label, cv2.IMREAD_GRAYSCALE) > 0 for s in samples]
    return np.stack([mirror(m) if s.mirrored else m for s, m in zip(samples, labels, strict=True)])


def load_maps(paths: list[str]) -> np.ndarray:
    """Confidence maps (N, H, W) float32 from .npy files (the train and postprocess stages' predictions)."""
    maps = []
    for path in paths:
        try:
            maps.append(np.load(path).astype(np.float32))
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not a readable confidence map ({e})") from e
    return np.stack(maps)
