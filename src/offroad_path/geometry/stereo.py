"""Dense stereo disparity of a rectified pair (OpenCV StereoSGBM), stored KITTI-style."""

from __future__ import annotations

import cv2
import numpy as np


def sgbm(cfg) -> cv2.StereoSGBM:
    """A matcher from DisparityConfig; P1 and P2 follow OpenCV's recommendation for one channel."""
    area = cfg.block_size * cfg.block_size
    return cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=cfg.num_disparities,
        blockSize=cfg.block_size,
        P1=8 * area,
        P2=32 * area,
        uniquenessRatio=cfg.uniqueness_ratio,
        speckleWindowSize=cfg.speckle_window,
        speckleRange=cfg.speckle_range,
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    )


def compute_disparity(matcher: cv2.StereoSGBM, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Disparity in pixels (float32), 0 where unknown."""
    raw = matcher.compute(left, right).astype(np.float32) / 16.0
    return np.where(raw > 0, raw, 0.0).astype(np.float32)


def encode_disparity(disparity: np.ndarray) -> np.ndarray:
    """KITTI's stereo format: uint16 of disparity x 256, 0 for unknown."""
    return np.clip(np.rint(disparity * 256.0), 0, 65535).astype(np.uint16)


def decode_disparity(raw: np.ndarray) -> np.ndarray:
    return raw.astype(np.float32) / 256.0


def depth_from_disparity(disparity: np.ndarray, fx: float, baseline_m: float) -> np.ndarray:
    """z = f*B/d, 0 where the disparity is unknown."""
    with np.errstate(divide="ignore"):
        return np.where(disparity > 0, fx * baseline_m / disparity, 0.0).astype(np.float32)
