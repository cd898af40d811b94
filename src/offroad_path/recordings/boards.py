"""Stereo calibration from views of a chessboard or ChArUco board seen by both cameras (OpenCV):
each camera's intrinsics first, then the rig's rotation and translation with them fixed."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offroad_path.errors import InputError, one_line
from offroad_path.recordings.rig_calibration import CameraModel, StereoRig
from offroad_path.sequence.reader import check_pixels, png_size

MIN_VIEWS = 6


@dataclass(frozen=True)
class Board:
    """A chessboard of `columns` x `rows` squares (inner corners: one fewer each way) or, with a
    marker size, a ChArUco board of OpenCV's `dictionary`."""

    columns: int
    rows: int
    square_m: float
    marker_m: float | None = None
    dictionary: str = "DICT_5X5_100"

    def charuco(self) -> cv2.aruco.CharucoBoard:
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.columns, self.rows), self.square_m, self.marker_m, dictionary)

    def corners_3d(self) -> np.ndarray:
        """(N, 3) inner corners on the board plane (z = 0), in metres, in OpenCV's detection order."""
        if self.marker_m is not None:
            return self.charuco().getChessboardCorners().astype(np.float32)
        grid = np.mgrid[0 : self.columns - 1, 0 : self.rows - 1].T.reshape(-1, 2)
        return np.hstack([grid * self.square_m, np.zeros((len(grid), 1))]).astype(np.float32)

    def detect(self, grey: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(ids, (n, 2) image corners) of the inner corners found, or None."""
        if self.marker_m is not None:
            corners, ids, *_ = cv2.aruco.CharucoDetector(self.charuco()).detectBoard(grey)
            return None if ids is None or len(ids) < 6 else (ids.ravel(), corners.reshape(-1, 2))
        found, corners = cv2.findChessboardCornersSB(grey, (self.columns - 1, self.rows - 1), flags=cv2.CALIB_CB_ACCURACY)
        return (np.arange(len(corners)), corners.reshape(-1, 2)) if found else None


@dataclass
class Calibration:
    rig: StereoRig
    rms_px: float  # stereo reprojection error
    views: int


def read_view(path: Path) -> np.ndarray:
    """A calibration view in grey; InputError naming the file when it cannot be decoded or (a PNG)
    declares more pixels than a sequence may have (a decompression bomb is not decoded)."""
    if path.suffix.lower() == ".png":
        check_pixels(path, *png_size(path))
    try:
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    except cv2.error as e:  # OpenCV's own size limit, among others
        raise InputError(path, f"cannot be decoded as an image ({one_line(e)})") from e
    if image is None:
        raise InputError(path, "cannot be decoded as an image")
    return image


def calibrate_stereo(left: list[Path], right: list[Path], board: Board, out: Path) -> Calibration:
    """Calibrate from image pairs (same names in both lists' order); views where either camera
    misses the board are skipped."""
    object_points, left_points, right_points, size = [], [], [], None
    corners = board.corners_3d()
    for lp, rp in zip(left, right, strict=True):
        images = [read_view(p) for p in (lp, rp)]
        for p, image in zip((lp, rp), images, strict=True):
            if size is not None and image.shape[::-1] != size:
                raise InputError(p, f"is {image.shape[1]}x{image.shape[0]}, the first view {size[0]}x{size[1]}")
            size = image.shape[::-1]
        found = [board.detect(image) for image in images]
        if found[0] is None or found[1] is None:
            continue
        common = np.intersect1d(found[0][0], found[1][0])  # ChArUco: corners both cameras see
        if len(common) < 6:
            continue
        pick = [dict(zip(ids.tolist(), range(len(ids)), strict=True)) for ids, _ in found]
        object_points.append(corners[common])
        left_points.append(found[0][1][[pick[0][i] for i in common]].astype(np.float32))
        right_points.append(found[1][1][[pick[1][i] for i in common]].astype(np.float32))
    if len(object_points) < MIN_VIEWS:
        raise InputError(
            left[0].parent,
            f"the board is found in both cameras in {len(object_points)} of {len(left)} views; calibration needs {MIN_VIEWS}",
        )
    cameras = []
    for points in (left_points, right_points):
        _, K, D, *_ = cv2.calibrateCamera(object_points, points, size, None, None)
        cameras.append((K, D))
    (K1, D1), (K2, D2) = cameras
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-9)
    rms, K1, D1, K2, D2, R, T, *_ = cv2.stereoCalibrate(
        object_points, left_points, right_points, K1, D1, K2, D2, size, flags=cv2.CALIB_USE_INTRINSIC_GUESS, criteria=criteria
    )
    rig = StereoRig(CameraModel(K1, D1.ravel(), size), CameraModel(K2, D2.ravel(), size), R, T.ravel(), out)
    return Calibration(rig.checked(), float(rms), len(object_points))
