"""The odometry front end shared by both estimators: bucketed corners, stereo matches along the row,
and Lucas-Kanade tracks checked forward and backward (after Geiger et al.'s StereoScan)."""

from __future__ import annotations

import cv2
import numpy as np

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.geometry.exact import matmul, solve
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
        # Lucas-Kanade stops when a step is under 1e-4 px (OpenCV squares the epsilon), not 0.01: a
        # track then ends where the image says, not where the start happened to leave it.
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
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
        """PnP: (the 4x4 transform taking xyz's frame into the camera, or None; inlier mask).

        RANSAC finds the pose; the robust refinement (`_robust_pose`) moves it to the minimum of a
        smooth loss over all points, and the inliers are the points within the RANSAC threshold of
        that pose. Where the refined pose keeps fewer than min_inliers and RANSAC's more, RANSAC's
        consensus stands: the step is weak, but it is not made a failure.
        """
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
        transform = np.eye(4)
        transform[:3, :3], transform[:3, 3] = cv2.Rodrigues(rvec)[0], tvec[:, 0]
        keep[inliers[:, 0]] = True
        robust = self._robust_pose(transform, xyz.astype(np.float64), uv.astype(np.float64))
        robust_keep = self._reprojection_error(robust, xyz, uv) < self.cfg.ransac_reprojection_px
        if robust_keep.sum() < min(self.cfg.min_inliers, keep.sum()):  # a weak view: RANSAC's consensus, not a failed step
            return transform, keep
        return robust, robust_keep

    def _reprojection_error(self, transform: np.ndarray, xyz: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(N,) left-image distance in pixels between xyz seen from `transform` and uv."""
        p = matmul(xyz, transform[:3, :3].T) + transform[:3, 3]
        z = np.maximum(p[:, 2], 1e-6)
        return np.hypot(self.fx * p[:, 0] / z + self.cx - uv[:, 0], self.fy * p[:, 1] / z + self.cy - uv[:, 1])

    def _robust_pose(self, transform: np.ndarray, xyz: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """The pose minimising a Cauchy loss of every point's reprojection error, from RANSAC's pose.

        RANSAC's answer is a discrete choice: which sample won, which points fell under the
        threshold. A change of the inputs far below the image noise (a calibration rounded to
        float32, a track moved by a thousandth of a pixel) can flip it and move the pose by
        centimetres. The minimum of a smooth loss over all points moves only as much as its inputs
        did, so RANSAC only picks the basin; Gauss-Newton with Cauchy weights (scale: the RANSAC
        threshold, so outliers fade out smoothly) converges to the minimum in it.
        """
        c2 = self.cfg.ransac_reprojection_px**2
        for _ in range(_ROBUST_ITERATIONS):
            p = matmul(xyz, transform[:3, :3].T) + transform[:3, 3]  # (N, 3) in the camera
            x, y, z = p.T
            if np.any(z <= 0):
                break
            iz = 1.0 / z
            r = np.concatenate([self.fx * x * iz + self.cx - uv[:, 0], self.fy * y * iz + self.cy - uv[:, 1]])  # (2N,)
            zero = np.zeros_like(z)
            du = np.stack([self.fx * iz, zero, -self.fx * x * iz * iz], axis=1)  # (N, 3) d(u)/d(point)
            dv = np.stack([zero, self.fy * iz, -self.fy * y * iz * iz], axis=1)
            J = np.concatenate([twist_jacobian(du, p), twist_jacobian(dv, p)])  # (2N, 6)
            n = len(z)
            weight = np.tile(1.0 / (1.0 + (r[:n] ** 2 + r[n:] ** 2) / c2), 2)  # per point, on both rows
            step = weighted_step(transform, J, weight, r)
            if step is None:
                break
            transform, delta = step
            if np.abs(delta).max() < 1e-12:
                break
        return transform


# Gauss-Newton steps of the robust PnP at most; it stops earlier once a step is under 1e-12.
_ROBUST_ITERATIONS = 50


def weighted_step(transform: np.ndarray, J: np.ndarray, weight: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """One weighted Gauss-Newton step on a 4x4 transform, left-multiplied: (the new transform, the
    twist (6,) it took), or None when J^T W J is singular. J (M, 6): the residuals' twist Jacobian;
    weight, r (M,)."""
    # J^T W J and J^T W r as sums over the rows, in row order: no BLAS (geometry.exact)
    H = (J[:, :, None] * (J * weight[:, None])[:, None, :]).sum(axis=0)  # (6, 6)
    g = (J * (weight * r)[:, None]).sum(axis=0)  # (6,)
    try:
        delta = -solve(H, g)
    except np.linalg.LinAlgError:
        return None
    update = np.eye(4)
    update[:3, :3], update[:3, 3] = cv2.Rodrigues(delta[3:])[0], delta[:3]
    return matmul(update, transform), delta


def twist_jacobian(d_point: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Chain a residual's gradient w.r.t. the point (N, 3) through p' = p + w x p + t: (N, 6)."""
    return np.concatenate([d_point, np.cross(p, d_point)], axis=1)
