"""A stereo rig with a known rectification error, made from any sequence: the right image resampled
a fraction of a pixel to the side (a disparity offset) and, optionally, up or down (a row offset).

Real rigs have such residuals (about -0.2 px of disparity on the KITTI snippet, docs/odometry.md);
this is how the odometry's self-calibration is tested against a known one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.sequence.reader import Sequence


@dataclass
class MisalignedSequence(Sequence):
    disparity_offset_px: float = 0.0  # observed minus true disparity
    row_offset_px: float = 0.0  # right-image rows below the left's

    def load_right(self, i: int, grey: bool = False) -> np.ndarray:
        # Disparity is u_left - u_right: a negative offset moves the right image's content right.
        return shifted(super().load_right(i, grey), -self.disparity_offset_px, self.row_offset_px)


def shifted(image: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """uint8 image content moved dx px right and dy px down by cubic convolution with exact weights
    (cv2.warpAffine and cv2.remap round sub-pixel positions to 1/32 px)."""
    out = cv2.sepFilter2D(image.astype(np.float32), -1, _cubic_taps(dx), _cubic_taps(dy), borderType=cv2.BORDER_REFLECT_101)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def _cubic_taps(t: float) -> np.ndarray:
    """Taps j = 0..4 of out(x) = sum_j tap[j] in(x + j - 2) = in(x - t), |t| <= 1: Keys' cubic
    convolution with a = -0.5, which reproduces linear brightness exactly, so a smooth image moves by
    exactly t (OpenCV's cubic, a = -0.75, does not)."""
    if not -1 <= t <= 1:
        raise ValueError(f"a shift of {t:g} px: at most 1 px either way")
    x = np.abs(2 - np.arange(5) - t)
    a = -0.5
    near = (a + 2) * x**3 - (a + 3) * x**2 + 1
    far = a * x**3 - 5 * a * x**2 + 8 * a * x - 4 * a
    return np.where(x <= 1, near, np.where(x < 2, far, 0.0)).astype(np.float32)


def misaligned(sequence: Sequence, disparity_offset_px: float, row_offset_px: float = 0.0) -> MisalignedSequence:
    """`sequence` as a rig with these rectification errors would have recorded it."""
    fields = {f.name: getattr(sequence, f.name) for f in dataclasses.fields(Sequence)}
    return MisalignedSequence(**fields, disparity_offset_px=disparity_offset_px, row_offset_px=row_offset_px)
