"""Stereo rectification at the output size (OpenCV), and the checks that it worked; one camera's
undistortion to a pinhole image of the output size."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.geometry.exact import matmul
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
            # OpenCV computes the new principal points from float32 pixels (cx, cy rounded to
            # float32, and fx off by about 2e-8 of itself with them); the same definition in float64.
            P1, P2 = rectified_projections(((left, R1), (right, R2)), matmul(R2, T), input_size, output_size, alpha)
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


def rectified_projections(
    views: tuple[tuple[CameraModel, np.ndarray], tuple[CameraModel, np.ndarray]],
    t_rectified: np.ndarray,
    input_size: tuple[int, int],
    output_size: tuple[int, int],
    alpha: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The rectified cameras' 3x4 projections (P1, P2) as cv2.stereoRectify defines them for a
    horizontal rig with CALIB_ZERO_DISPARITY, computed in float64 throughout.

    The focal length is the cameras' mean fy scaled to the output height; the principal point
    centres the undistorted, rotated image corners (the mean over both cameras); `alpha` then scales
    the focal length between keeping only valid pixels (0) and every source pixel (1), judged on
    the undistorted image border. `views`: (left camera, its rectifying rotation R1) and (right
    camera, R2); t_rectified (3, 1): the rig's translation in the rectified frame, R2 T.
    """
    (nx, ny), (new_w, new_h) = input_size, output_size
    fc = (views[0][0].K[1, 1] + views[1][0].K[1, 1]) * new_h / ny / 2
    corners = np.array([[0, 0], [nx - 1, 0], [0, ny - 1], [nx - 1, ny - 1]], np.float64)
    centres = []
    for camera, R in views:
        normal = cv2.undistortPoints(corners[:, None], camera.K, camera.D)[:, 0]  # (4, 2) on the plane z = 1
        rotated = matmul(np.concatenate([normal, np.ones((4, 1))], axis=1), R.T)  # (4, 3)
        projected = fc * rotated[:, :2] / rotated[:, 2:]
        centres.append([(nx - 1) / 2 - projected[:, 0].mean(), (ny - 1) / 2 - projected[:, 1].mean()])
    cx0, cy0 = np.mean(centres, axis=0)  # zero disparity: one principal point for both
    P = np.array([[fc, 0.0, cx0, 0.0], [0.0, fc, cy0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    cx, cy = new_w * cx0 / nx, new_h * cy0 / ny
    s = 1.0
    if alpha >= 0:
        alpha = min(alpha, 1.0)
        inner_scales, outer_scales = [], []
        for camera, R in views:
            inner, outer = _undistorted_border(camera, R, P, input_size)
            for rect, scales in ((inner, inner_scales), (outer, outer_scales)):
                x0, y0, x1, y1 = rect
                scales.append([cx / (cx0 - x0), cy / (cy0 - y0), (new_w - 1 - cx) / (x1 - cx0), (new_h - 1 - cy) / (y1 - cy0)])
        s = max(map(max, inner_scales)) * (1 - alpha) + min(map(min, outer_scales)) * alpha
    P1 = np.array([[fc * s, 0.0, cx, 0.0], [0.0, fc * s, cy, 0.0], [0.0, 0.0, 1.0, 0.0]])
    P2 = P1.copy()
    P2[0, 3] = float(t_rectified[0, 0]) * fc * s  # -baseline times the focal length
    return P1, P2


def _undistorted_border(camera: CameraModel, R: np.ndarray, P: np.ndarray, size: tuple[int, int]) -> tuple[tuple[float, ...], ...]:
    """((x0, y0, x1, y1) of the largest rectangle inside, and of the smallest around) a 9 x 9 grid
    over the image, corner pixel to corner pixel, undistorted into P: this OpenCV's rectangles to
    float32 rounding (tests/recordings/test_rectify.py)."""
    w, h = size
    xs, ys = np.meshgrid(np.arange(9) * (w - 1) / 8, np.arange(9) * (h - 1) / 8)  # (9, 9) each
    grid = np.stack([xs, ys], axis=-1).reshape(-1, 1, 2)
    p = cv2.undistortPoints(grid, camera.K, camera.D, R=R, P=P[:, :3]).reshape(9, 9, 2)  # [row, column]
    inner = (p[:, 0, 0].max(), p[0, :, 1].max(), p[:, -1, 0].min(), p[-1, :, 1].min())
    outer = (p[..., 0].min(), p[..., 1].min(), p[..., 0].max(), p[..., 1].max())
    return inner, outer


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
