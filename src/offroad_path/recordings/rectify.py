"""Stereo rectification at the output size (OpenCV), and the checks that it worked; one camera's
undistortion to a pinhole image of the output size."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.recordings.rig_calibration import CameraModel, StereoRig
from offroad_path.sequence.calibration import StereoCalibration


class Rectifier:
    """Undistort and row-align a raw stereo pair, resampled to `output_size` (width, height).

    `alpha` is OpenCV's free scaling: 0 keeps only valid pixels (no black border), 1 keeps every
    source pixel; for fisheye rigs it is `balance`, with the same meaning."""

    def __init__(self, rig: StereoRig, input_size: tuple[int, int], output_size: tuple[int, int], alpha: float):
        left, right = rig.left.at_size(input_size, rig.source), rig.right.at_size(input_size, rig.source)
        T = rig.T.reshape(3, 1)
        if left.fisheye:
            R1, R2, P1, P2, _ = cv2.fisheye.stereoRectify(
                left.K,
                left.D,
                right.K,
                right.D,
                input_size,
                rig.R,
                T,
                cv2.CALIB_ZERO_DISPARITY,
                newImageSize=output_size,
                balance=alpha,
                fov_scale=1.0,
            )
            undistort = cv2.fisheye.initUndistortRectifyMap
        else:
            R1, R2, P1, P2, *_ = cv2.stereoRectify(
                left.K,
                left.D,
                right.K,
                right.D,
                input_size,
                rig.R,
                T,
                flags=cv2.CALIB_ZERO_DISPARITY,
                alpha=alpha,
                newImageSize=output_size,
            )
            undistort = cv2.initUndistortRectifyMap
        self.maps = [undistort(cam.K, cam.D, Ri, Pi, output_size, cv2.CV_16SC2) for cam, Ri, Pi in ((left, R1, P1), (right, R2, P2))]
        self.R_left, self.R_right = R1, R2  # (3, 3): a point in the raw camera, in the rectified camera
        self.calibration = StereoCalibration(P1, P2)
        self.output_size = output_size

    def __call__(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return tuple(cv2.remap(image, mx, my, cv2.INTER_LINEAR) for image, (mx, my) in zip((left, right), self.maps, strict=True))

    @property
    def pitch_change_deg(self) -> float:
        """How much further down the rectified optical axis points than the raw left camera's."""
        axis = self.R_left[2]  # the rectified z axis in raw left coordinates
        return math.degrees(math.atan2(axis[1], axis[2]))


class Undistorter:
    """One camera's raw frame as a distortion-free pinhole image of `output_size` (the mono sequence's
    calib.txt holds its one projection); `camera` at the raw frames' `input_size`, `alpha` as Rectifier's."""

    def __init__(self, camera: CameraModel, input_size: tuple[int, int], output_size: tuple[int, int], alpha: float):
        if camera.fisheye:
            new_K = cv2.fisheye.estimateNewCameraMatrixForUndistortRectify(
                camera.K, camera.D, input_size, np.eye(3), balance=alpha, new_size=output_size
            )
            self.map = cv2.fisheye.initUndistortRectifyMap(camera.K, camera.D, np.eye(3), new_K, output_size, cv2.CV_16SC2)
        else:
            new_K, _ = cv2.getOptimalNewCameraMatrix(camera.K, camera.D, input_size, alpha, output_size)
            self.map = cv2.initUndistortRectifyMap(camera.K, camera.D, np.eye(3), new_K, output_size, cv2.CV_16SC2)
        self.R_left = np.eye(3)  # no rotation: the image keeps the camera's own axes
        self.calibration = StereoCalibration(np.hstack([new_K, np.zeros((3, 1))]), None)
        self.output_size = output_size
        self.pitch_change_deg = 0.0

    def __call__(self, image: np.ndarray, _: None = None) -> tuple[np.ndarray]:
        return (cv2.remap(image, *self.map, cv2.INTER_LINEAR),)


@dataclass
class EpipolarCheck:
    median_px: float  # median |y_left - y_right| of matched features
    matches: int


def epipolar_error(left: np.ndarray, right: np.ndarray, max_disparity_px: float) -> EpipolarCheck | None:
    """Vertical disparity of features matched between a rectified pair (0 for a perfect
    rectification); None when too few features match to tell. ORB matches place each feature;
    Lucas-Kanade refines its right position to a fraction of a pixel."""
    grey = [image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) for image in (left, right)]
    orb = cv2.ORB_create(nfeatures=1500, fastThreshold=10)
    (kl, dl), (kr, dr) = (orb.detectAndCompute(g, None) for g in grey)
    if dl is None or dr is None:
        return None
    matches = [p[0] for p in cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(dl, dr, k=2) if len(p) == 2 and p[0].distance < 0.75 * p[1].distance]
    if len(matches) < 20:
        return None
    pl = np.float32([kl[m.queryIdx].pt for m in matches]).reshape(-1, 1, 2)
    pr = np.float32([kr[m.trainIdx].pt for m in matches]).reshape(-1, 1, 2)
    refined, status, _ = cv2.calcOpticalFlowPyrLK(
        grey[0], grey[1], pl, pr.copy(), winSize=(15, 15), maxLevel=1, flags=cv2.OPTFLOW_USE_INITIAL_FLOW
    )
    disparity = (pl - refined).reshape(-1, 2)
    good = (
        (status.ravel() == 1)
        & (np.abs(refined - pr).reshape(-1, 2).max(axis=1) < 2.0)  # LK stayed on the ORB match
        & (disparity[:, 0] >= -1.0)
        & (disparity[:, 0] <= max_disparity_px)
        & (np.abs(disparity[:, 1]) < 8.0)  # a far-off row is a false match
    )
    if good.sum() < 20:
        return None
    return EpipolarCheck(float(np.median(np.abs(disparity[good, 1]))), int(good.sum()))


def contact_sheet(pairs: list[tuple[np.ndarray, ...]], width: int = 1024, line_every_px: int = 24) -> np.ndarray:
    """Rectified pairs side by side (or one camera's frames), one per row, with horizontal lines: in
    a good rectification a feature sits on the same line in both images."""
    rows = []
    for images in pairs:
        row = np.hstack([cv2.cvtColor(im, cv2.COLOR_GRAY2BGR) if im.ndim == 2 else im for im in images])
        for y in range(line_every_px // 2, row.shape[0], line_every_px):
            cv2.line(row, (0, y), (row.shape[1] - 1, y), (0, 255, 0), 1)
        rows.append(row)
    sheet = np.vstack(rows)
    return cv2.resize(sheet, (width, round(sheet.shape[0] * width / sheet.shape[1])), interpolation=cv2.INTER_AREA)
