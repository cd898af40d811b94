"""Frame-to-frame stereo visual odometry (`label.odometry.method=frame_to_frame`), built on OpenCV.

The anchor is Geiger et al.'s StereoScan (libviso2), which Holder & Breckon used. Per frame:
Shi-Tomasi corners bucketed over the image; stereo matches along the row by pyramidal Lucas-Kanade;
3D points from disparity; the same corners tracked into the next left (and right) image with a
forward-backward check; pose from PnP with RANSAC; then Gauss-Newton with Huber weights on the
inliers' reprojection error in both next images. A step with too few inliers is flagged failed,
never given a made-up pose. The windowed estimator (`windowed.py`) is the default; this one stays
for comparison.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.geometry.exact import matmul, rigid_inverse
from offroad_path.odometry.features import FrontEnd, twist_jacobian, weighted_step
from offroad_path.odometry.steps import StepResult
from offroad_path.sequence.calibration import StereoCalibration


@dataclass
class _Frame:
    left: np.ndarray
    right: np.ndarray
    points_l: np.ndarray  # (N, 2) corners in the left image with a stereo match
    points_r: np.ndarray  # (N, 2) their matches in the right image
    xyz: np.ndarray  # (N, 3) in this camera's frame


class FrameToFrameOdometry:
    """Frame-to-frame stereo odometry; feed grey frames in order with `start` then `step`; `finish`
    gives every frame's pose."""

    def __init__(self, calibration: StereoCalibration, cfg: OdometryConfig):
        self.cfg = cfg
        self.front = FrontEnd(calibration, cfg)
        f = self.front
        self.fx, self.fy, self.cx, self.cy, self.baseline = f.fx, f.fy, f.cx, f.cy, f.baseline
        self._previous: _Frame | None = None
        self._velocity = np.eye(4)  # the last successful motion
        self._poses = [np.eye(4)]  # camera to first camera; a failed step adds no motion
        self._steps: list[StepResult] = []

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
            result = self._motion(prev, left, right)
        except cv2.error as e:  # degenerate geometry inside OpenCV: a failed step, not a crash
            result = StepResult(False, np.eye(4), len(prev.xyz), 0, 0, f"OpenCV failed: {e.err}")
        self._steps.append(result)
        self._poses.append(matmul(self._poses[-1], rigid_inverse(result.motion)))
        return result

    def finish(self) -> tuple[np.ndarray, list[StepResult]]:
        """(N, 4, 4) camera-to-first-camera poses and the N-1 steps between them."""
        return np.array(self._poses), self._steps

    def rig_offsets(self) -> tuple[None, None]:
        """This estimator takes the rig's rectification as given."""
        return None, None

    def _frame(self, left: np.ndarray, right: np.ndarray) -> _Frame:
        corners = self.front.corners(left, self.cfg.max_features, self.cfg.corner_quality)
        matched, good = self.front.stereo_match(left, right, corners)
        pl, pr = corners[good], matched[good]
        return _Frame(left, right, pl, pr, self.front.triangulate(pl, pr))

    def _motion(self, prev: _Frame, left: np.ndarray, right: np.ndarray) -> StepResult:
        cfg = self.cfg
        n = len(prev.xyz)
        if n < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, 0, 0, f"only {n} stereo features in the previous frame")
        # Constant-velocity prediction as the trackers' starting point: large image motion near
        # the bottom of the view is then a small correction, which Lucas-Kanade does without bias.
        guess_l, guess_r = self.front.project(matmul(prev.xyz, self._velocity[:3, :3].T) + self._velocity[:3, 3])
        next_l, ok_l = self.front.track(prev.left, left, prev.points_l, guess_l)
        next_r, ok_r = self.front.track(prev.right, right, prev.points_r, guess_r)
        ok_r &= ok_l
        tracked = int(ok_l.sum())
        if tracked < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, tracked, 0, f"only {tracked} features tracked into this frame")
        xyz, uv = prev.xyz[ok_l], next_l[ok_l].astype(np.float64)
        motion, keep = self.front.pnp(xyz, uv)
        inliers = int(keep.sum())
        if motion is None or inliers < cfg.min_inliers:
            return StepResult(False, np.eye(4), n, tracked, inliers, f"only {inliers} PnP inliers")
        right_uv = np.where(ok_r[ok_l][:, None], next_r[ok_l], np.nan).astype(np.float64)
        motion = self._refine(motion, xyz[keep], uv[keep], right_uv[keep])
        self._velocity = motion
        return StepResult(True, motion, n, tracked, inliers)

    def _refine(self, motion: np.ndarray, xyz: np.ndarray, uv_l: np.ndarray, uv_r: np.ndarray) -> np.ndarray:
        """Gauss-Newton on the left and right reprojection errors, Huber-weighted, 6-DoF."""
        has_right = ~np.isnan(uv_r[:, 0])
        fb = self.fx * self.baseline
        for _ in range(self.cfg.refine_iterations):
            p = matmul(xyz, motion[:3, :3].T) + motion[:3, 3]
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
            jac = [twist_jacobian(du, p), twist_jacobian(dv, p), twist_jacobian(dur[has_right], p[has_right])]
            r = np.concatenate(res)
            J = np.concatenate(jac)
            weight = np.where(np.abs(r) <= self.cfg.huber_px, 1.0, self.cfg.huber_px / np.abs(r))
            step = weighted_step(motion, J, weight, r)
            if step is None:
                break
            motion, delta = step
            if np.linalg.norm(delta) < 1e-8:
                break
        return motion
