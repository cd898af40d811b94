"""Stereo visual odometry on rectified pairs, built on OpenCV.

The anchor is Geiger et al.'s StereoScan (libviso2), which Holder & Breckon used. Per frame:
Shi-Tomasi corners bucketed over the image; stereo matches along the row by pyramidal Lucas-Kanade;
3D points from disparity; the same corners tracked into the next left (and right) image with a
forward-backward check; pose from PnP with RANSAC; then Gauss-Newton with Huber weights on the
inliers' reprojection error in both next images. A step with too few inliers is flagged failed,
never given a made-up pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.config import OdometryConfig
from offroad_path.sequence.calibration import StereoCalibration


@dataclass
class StepResult:
    """The motion from frame k to k+1: `motion` maps camera-k points into camera k+1."""

    ok: bool
    motion: np.ndarray  # (4, 4); the identity when the step failed
    features: int  # corners with a stereo match in frame k
    tracked: int  # of those, tracked into frame k+1
    inliers: int
    reason: str = ""


@dataclass
class _Frame:
    left: np.ndarray
    right: np.ndarray
    points_l: np.ndarray  # (N, 2) corners in the left image with a stereo match
    points_r: np.ndarray  # (N, 2) their matches in the right image
    xyz: np.ndarray  # (N, 3) in this camera's frame


class StereoOdometry:
    """Frame-to-frame stereo odometry; feed grey frames in order with `step`."""

    def __init__(self, calibration: StereoCalibration, cfg: OdometryConfig):
        self.cfg = cfg
        self.K = calibration.K
        self.fx, self.fy = calibration.K[0, 0], calibration.K[1, 1]
        self.cx, self.cy = calibration.K[0, 2], calibration.K[1, 2]
        self.baseline = calibration.baseline_m
        win = (self.cfg.lk_window, self.cfg.lk_window)
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        self._lk = {"winSize": win, "maxLevel": self.cfg.lk_levels, "criteria": criteria}
        self._previous: _Frame | None = None
        self._velocity = np.eye(4)  # the last successful motion

    def start(self, left: np.ndarray, right: np.ndarray) -> int:
        """Begin at a frame; returns how many stereo features it has."""
        self._previous = self._frame(left, right)
        return len(self._previous.xyz)

    def step(self, left: np.ndarray, right: np.ndarray) -> StepResult:
        """Motion from the previous frame to this one (grey uint8 images)."""
        if self._previous is None:
            raise RuntimeError("call start() with the first frame before step()")
        prev = self._previous
        current = self._frame(left, right)
        self._previous = current
        try:
            return self._motion(prev, left, right)
        except cv2.error as e:  # degenerate geometry inside OpenCV: a failed step, not a crash
            return StepResult(False, np.eye(4), len(prev.xyz), 0, 0, f"OpenCV failed: {e.err}")

    def _frame(self, left: np.ndarray, right: np.ndarray) -> _Frame:
        corners = self._bucketed_corners(left)
        empty = np.zeros((0, 2), np.float32)
        if len(corners) == 0:
            return _Frame(left, right, empty, empty, np.zeros((0, 3)))
        matched, _, _ = cv2.calcOpticalFlowPyrLK(left, right, corners, corners.copy(), **self._lk)
        status = self._fb_ok(left, right, corners, matched)
        disparity = corners[:, 0] - matched[:, 0]
        good = status & (np.abs(corners[:, 1] - matched[:, 1]) < self.cfg.max_row_error_px)
        good &= disparity > max(self.cfg.min_disparity_px, self.fx * self.baseline / self.cfg.max_depth_m)
        pl, pr, d = corners[good], matched[good], disparity[good]
        z = self.fx * self.baseline / d
        xyz = np.stack([(pl[:, 0] - self.cx) * z / self.fx, (pl[:, 1] - self.cy) * z / self.fy, z], axis=1).astype(np.float64)
        return _Frame(left, right, pl, pr, xyz)

    def _bucketed_corners(self, image: np.ndarray) -> np.ndarray:
        """The strongest corners of each image bucket, so that features cover the whole view.

        Corners are local maxima of the Shi-Tomasi response (the smaller eigenvalue of the
        structure tensor), kept above a fraction of the image's strongest response.
        """
        response = cv2.cornerMinEigenVal(image, 3, 3)
        peaks = (response == cv2.dilate(response, np.ones((5, 5), np.uint8))) & (response > self.cfg.corner_quality * response.max())
        rows, cols = np.nonzero(peaks)
        if len(rows) == 0 or response.max() <= 0:
            return np.zeros((0, 2), np.float32)
        strength = response[rows, cols]
        h, w = image.shape[:2]
        bucket = (rows * self.cfg.bucket_rows // h) * self.cfg.bucket_cols + cols * self.cfg.bucket_cols // w
        order = np.lexsort((-strength, bucket))
        bucket, rows, cols = bucket[order], rows[order], cols[order]
        rank = np.arange(len(bucket)) - np.searchsorted(bucket, bucket)  # position within its bucket
        per_bucket = max(1, self.cfg.max_features // (self.cfg.bucket_rows * self.cfg.bucket_cols))
        keep = rank < per_bucket
        return np.stack([cols[keep], rows[keep]], axis=1).astype(np.float32)

    def _fb_ok(self, a: np.ndarray, b: np.ndarray, pts: np.ndarray, tracked: np.ndarray) -> np.ndarray:
        """Lucas-Kanade tracks that come back to where they started (forward-backward check)."""
        back, status, _ = cv2.calcOpticalFlowPyrLK(b, a, tracked, pts.copy(), **self._lk)
        h, w = a.shape[:2]
        inside = (tracked[:, 0] >= 0) & (tracked[:, 0] <= w - 1) & (tracked[:, 1] >= 0) & (tracked[:, 1] <= h - 1)
        return (status[:, 0] == 1) & inside & (np.linalg.norm(back - pts, axis=1) < self.cfg.forward_backward_px)

    def _motion(self, prev: _Frame, left: np.ndarray, right: np.ndarray) -> StepResult:
        cfg = self.cfg
        n = len(prev.xyz)
        if n < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, 0, 0, f"only {n} stereo features in the previous frame")
        # Constant-velocity prediction as the trackers' starting point: large image motion near
        # the bottom of the view is then a small correction, which Lucas-Kanade does without bias.
        guess_l, guess_r = self._predict(prev)
        flags = {"flags": cv2.OPTFLOW_USE_INITIAL_FLOW}
        next_l, _, _ = cv2.calcOpticalFlowPyrLK(prev.left, left, prev.points_l, guess_l, **self._lk, **flags)
        next_r, _, _ = cv2.calcOpticalFlowPyrLK(prev.right, right, prev.points_r, guess_r, **self._lk, **flags)
        ok_l = self._fb_ok(prev.left, left, prev.points_l, next_l)
        ok_r = self._fb_ok(prev.right, right, prev.points_r, next_r) & ok_l
        tracked = int(ok_l.sum())
        if tracked < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, tracked, 0, f"only {tracked} features tracked into this frame")
        xyz, uv = prev.xyz[ok_l], next_l[ok_l].astype(np.float64)
        found, rvec, tvec, inlier_idx = cv2.solvePnPRansac(
            xyz, uv, self.K, None, iterationsCount=cfg.ransac_iterations, reprojectionError=cfg.ransac_reprojection_px,
            confidence=0.999, flags=cv2.SOLVEPNP_ITERATIVE,
        )  # fmt: skip
        inliers = 0 if inlier_idx is None else len(inlier_idx)
        if not found or inliers < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, tracked, inliers, f"only {inliers} PnP inliers")
        R, _ = cv2.Rodrigues(rvec)
        motion = np.eye(4)
        motion[:3, :3], motion[:3, 3] = R, tvec[:, 0]
        keep = np.zeros(len(xyz), bool)
        keep[inlier_idx[:, 0]] = True
        right_uv = np.where(ok_r[ok_l][:, None], next_r[ok_l], np.nan).astype(np.float64)
        motion = self._refine(motion, xyz[keep], uv[keep], right_uv[keep])
        self._velocity = motion
        return StepResult(True, motion, n, tracked, inliers)

    def _predict(self, prev: _Frame) -> tuple[np.ndarray, np.ndarray]:
        """Where the previous frame's points land if the last motion repeats (left, right)."""
        p = prev.xyz @ self._velocity[:3, :3].T + self._velocity[:3, 3]
        z = np.maximum(p[:, 2], 0.1)
        u = self.fx * p[:, 0] / z + self.cx
        v = self.fy * p[:, 1] / z + self.cy
        left = np.stack([u, v], axis=1).astype(np.float32)
        right = np.stack([u - self.fx * self.baseline / z, v], axis=1).astype(np.float32)
        return left, right

    def _refine(self, motion: np.ndarray, xyz: np.ndarray, uv_l: np.ndarray, uv_r: np.ndarray) -> np.ndarray:
        """Gauss-Newton on the left and right reprojection errors, Huber-weighted, 6-DoF."""
        has_right = ~np.isnan(uv_r[:, 0])
        fb = self.fx * self.baseline
        for _ in range(self.cfg.refine_iterations):
            p = xyz @ motion[:3, :3].T + motion[:3, 3]
            x, y, z = p.T
            iz = 1.0 / z
            # Residuals: left u, v; right u (its v equals the left v on rectified images).
            u = self.fx * x * iz + self.cx
            v = self.fy * y * iz + self.cy
            res = [u - uv_l[:, 0], v - uv_l[:, 1], (u - fb * iz - uv_r[:, 0])[has_right]]
            # d(u, v)/d(point), then d(point)/d(twist) = [I | -[p]x] for a left-multiplied update.
            du = np.stack([self.fx * iz, np.zeros_like(z), -self.fx * x * iz * iz], axis=1)
            dv = np.stack([np.zeros_like(z), self.fy * iz, -self.fy * y * iz * iz], axis=1)
            dur = du + np.stack([np.zeros_like(z), np.zeros_like(z), fb * iz * iz], axis=1)
            jac = [_twist_jacobian(du, p), _twist_jacobian(dv, p), _twist_jacobian(dur[has_right], p[has_right])]
            r = np.concatenate(res)
            J = np.concatenate(jac)
            weight = np.where(np.abs(r) <= self.cfg.huber_px, 1.0, self.cfg.huber_px / np.abs(r))
            H = J.T @ (J * weight[:, None])
            g = J.T @ (weight * r)
            try:
                delta = -np.linalg.solve(H, g)
            except np.linalg.LinAlgError:
                break
            update = np.eye(4)
            update[:3, :3] = cv2.Rodrigues(delta[3:])[0]
            update[:3, 3] = delta[:3]
            motion = update @ motion
            if np.linalg.norm(delta) < 1e-8:
                break
        return motion


def _twist_jacobian(d_point: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Chain a residual's gradient w.r.t. the point (N, 3) through p' = p + w x p + t: (N, 6)."""
    return np.concatenate([d_point, np.cross(p, d_point)], axis=1)
