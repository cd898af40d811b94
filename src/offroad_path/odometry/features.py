"""The odometry front end shared by both estimators: bucketed corners, stereo matches along the row,
and Lucas-Kanade tracks checked forward and backward (after Geiger et al.'s StereoScan)."""

from __future__ import annotations

import cv2
import numpy as np

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.sequence.calibration import StereoCalibration


class FrontEnd:
    """Image measurements for a rectified stereo rig; all points are (N, 2) float32 pixel arrays."""

    def __init__(self, calibration: StereoCalibration, cfg: OdometryConfig):
        self.cfg = cfg
        self.fx, self.fy = calibration.K[0, 0], calibration.K[1, 1]
        self.cx, self.cy = calibration.K[0, 2], calibration.K[1, 2]
        self.K = np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])  # the left camera's, for PnP
        self.baseline = calibration.baseline_m
        # The rig's rectification residuals, when an estimator knows them: observed minus true
        # disparity, and right-image rows below the left's. They move the right camera's principal
        # point to (cx - disparity_offset, cy + row_offset).
        self.disparity_offset, self.row_offset = 0.0, 0.0
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        self.lk = {"winSize": (cfg.lk_window, cfg.lk_window), "maxLevel": cfg.lk_levels, "criteria": criteria}

    def corners(self, image: np.ndarray, max_features: int, quality: float, taken: np.ndarray | None = None) -> np.ndarray:
        """The strongest corners of each image bucket, so that features cover the whole view.

        Corners are local maxima of the Shi-Tomasi response (the smaller eigenvalue of the structure
        tensor) above `quality` times the image's strongest response. `taken` (M, 2): points already
        held; a bucket's quota counts them, so new corners go where the view has few.
        """
        cfg = self.cfg
        response = cv2.cornerMinEigenVal(image, 3, 3)
        peaks = (response == cv2.dilate(response, np.ones((5, 5), np.uint8))) & (response > quality * response.max())
        rows, cols = np.nonzero(peaks)
        if len(rows) == 0 or response.max() <= 0:
            return np.zeros((0, 2), np.float32)
        h, w = image.shape[:2]
        n_buckets = cfg.bucket_rows * cfg.bucket_cols
        bucket = (rows * cfg.bucket_rows // h) * cfg.bucket_cols + cols * cfg.bucket_cols // w
        order = np.lexsort((-response[rows, cols], bucket))
        bucket, rows, cols = bucket[order], rows[order], cols[order]
        rank = np.arange(len(bucket)) - np.searchsorted(bucket, bucket)  # position within its bucket
        quota = np.full(n_buckets, max(1, max_features // n_buckets))
        if taken is not None and len(taken):
            held = (np.clip(taken[:, 1], 0, h - 1).astype(int) * cfg.bucket_rows // h) * cfg.bucket_cols
            held += np.clip(taken[:, 0], 0, w - 1).astype(int) * cfg.bucket_cols // w
            quota = np.maximum(quota - np.bincount(held, minlength=n_buckets), 0)
        keep = rank < quota[bucket]
        return np.stack([cols[keep], rows[keep]], axis=1).astype(np.float32)

    def track(
        self, a: np.ndarray, b: np.ndarray, pts: np.ndarray, guess: np.ndarray | None = None, wide: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lucas-Kanade from image a into b, from `guess` when given; (tracked points, ok mask).

        ok: the track stays in the image and comes back to where it started (forward-backward).
        `wide`: twice the window and two more pyramid levels, for motion the usual search misses.
        """
        if len(pts) == 0:
            return pts.copy(), np.zeros(0, bool)
        lk = self.lk
        if wide:
            lk = {**lk, "winSize": (2 * self.cfg.lk_window + 1,) * 2, "maxLevel": self.cfg.lk_levels + 2}
        if guess is None:
            moved, _, _ = cv2.calcOpticalFlowPyrLK(a, b, pts, pts.copy(), **lk)
        else:
            moved, _, _ = cv2.calcOpticalFlowPyrLK(a, b, pts, guess.astype(np.float32), **lk, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        back, status, _ = cv2.calcOpticalFlowPyrLK(b, a, moved, pts.copy(), **lk)
        h, w = a.shape[:2]
        inside = (moved[:, 0] >= 0) & (moved[:, 0] <= w - 1) & (moved[:, 1] >= 0) & (moved[:, 1] <= h - 1)
        return moved, (status[:, 0] == 1) & inside & (np.linalg.norm(back - pts, axis=1) < self.cfg.forward_backward_px)

    def stereo_match(
        self, left: np.ndarray, right: np.ndarray, pts: np.ndarray, guess: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each left point's match in the right image; ok where it stays on its row and its
        disparity is in range (not nearer than min_disparity_px nor farther than max_depth_m)."""
        matched, ok = self.track(left, right, pts, guess)
        if len(pts) == 0:
            return matched, ok
        disparity = pts[:, 0] - matched[:, 0]
        ok &= np.abs(pts[:, 1] - matched[:, 1]) < self.cfg.max_row_error_px
        ok &= disparity > max(self.cfg.min_disparity_px, self.fx * self.baseline / self.cfg.max_depth_m)
        return matched, ok

    def triangulate(self, pts_l: np.ndarray, pts_r: np.ndarray) -> np.ndarray:
        """(N, 3) points in the left camera's frame from stereo pairs."""
        z = self.fx * self.baseline / (pts_l[:, 0] - pts_r[:, 0] - self.disparity_offset).astype(np.float64)
        return np.stack([(pts_l[:, 0] - self.cx) * z / self.fx, (pts_l[:, 1] - self.cy) * z / self.fy, z], axis=1)

    def project(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame points (N, 3) to left and right pixels, float32 (N, 2) each."""
        z = np.maximum(xyz[:, 2], 0.1)
        u = self.fx * xyz[:, 0] / z + self.cx
        v = self.fy * xyz[:, 1] / z + self.cy
        left = np.stack([u, v], axis=1).astype(np.float32)
        right = np.stack([u - self.fx * self.baseline / z - self.disparity_offset, v + self.row_offset], axis=1).astype(np.float32)
        return left, right

    def pnp(self, xyz: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """RANSAC PnP: (the 4x4 transform taking xyz's frame into the camera, or None; inlier mask)."""
        keep = np.zeros(len(xyz), bool)
        if len(xyz) < 6:
            return None, keep
        found, rvec, tvec, inliers = cv2.solvePnPRansac(
            xyz.astype(np.float64),
            uv.astype(np.float64),
            self.K,
            None,
            iterationsCount=self.cfg.ransac_iterations,
            reprojectionError=self.cfg.ransac_reprojection_px,
            confidence=0.999,
            flags=cv2.SOLVEPNP_ITERATIVE,
        )
        if not found or inliers is None:
            return None, keep
        keep[inliers[:, 0]] = True
        transform = np.eye(4)
        transform[:3, :3], transform[:3, 3] = cv2.Rodrigues(rvec)[0], tvec[:, 0]
        return transform, keep
