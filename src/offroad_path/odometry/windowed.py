"""Keyframe stereo visual odometry with a sliding-window bundle adjustment (the default,
`label.odometry.method=windowed`).

Landmarks are tracked from frame to frame by Lucas-Kanade (the front end of `features.py`); each
frame's pose comes from RANSAC PnP against the landmarks' world positions; every keyframe joins a
window of the last `window` keyframes, whose poses and landmarks are refined together by
Levenberg-Marquardt in GTSAM on left and right reprojections (`GenericStereoFactor3D`, Huber loss),
in the spirit of ORB-SLAM2's local bundle adjustment and SOFT's careful feature handling.

The rig's disparity offset: a real rig's rectified images disagree by a fraction of a pixel (about
-0.2 px of disparity on the KITTI snippet, docs/odometry.md), and depth error grows as z^2 / (f B),
so far points pull the translation long. Every `disparity_offset_every`-th window estimates the
offset (and the rows' misalignment) as the principal point of a right camera with a calibration of
its own, under a prior that starts at 0 and narrows as windows accumulate; the other windows and
the front end correct every disparity by the estimate. What the estimate leaves, the far points'
down-weighting takes: in those windows, a right-image residual's sigma grows as
(z / stereo_depth_m)^2 beyond `stereo_depth_m`, so far points still fix rotation (their left
reprojections are untouched) and near points fix scale.

A weak step is retried with more features, then with a wider search, then skipped (the next frame
is matched to the last good one and the skipped pose interpolated); only then does the step fail,
which ends a piece of the trajectory: the next frame starts a new one and no segment spans the break.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import gtsam
import numpy as np
from gtsam_unstable import ProjectionFactorPPPCCal3_S2

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.geometry.exact import matmul, power, rigid_inverse
from offroad_path.odometry.features import FrontEnd
from offroad_path.odometry.steps import FALLBACKS, StepResult
from offroad_path.sequence.calibration import StereoCalibration


@dataclass
class _Reference:
    """The last frame that was tracked: where the next frame's tracks start."""

    frame: int
    left: np.ndarray
    right: np.ndarray
    ids: np.ndarray  # (M,) landmark ids of the tracks
    uv: np.ndarray  # (M, 2) float32 left pixels


@dataclass
class _Keyframe:
    frame: int
    ids: np.ndarray  # (M,) landmarks seen with a stereo match
    uv_l: np.ndarray  # (M, 2)
    uv_r: np.ndarray  # (M, 2)


@dataclass
class _Step:
    features: int = 0
    tracked: int = 0
    inliers: int = 0
    ok: bool = True
    reason: str = ""
    fallback: str = ""
    keyframe: bool = False
    disparity_offset_px: float = float("nan")


class WindowedOdometry:
    """Feed grey frames in order with `start` then `step`; `finish` gives every frame's pose."""

    def __init__(self, calibration: StereoCalibration, cfg: OdometryConfig):
        self.cfg = cfg
        self.front = FrontEnd(calibration, cfg)
        f = self.front
        self._left = gtsam.Cal3_S2(f.fx, f.fy, 0.0, f.cx, f.cy)
        self._stereo = gtsam.Cal3_S2Stereo(f.fx, f.fy, 0.0, f.cx, f.cy, f.baseline)
        self._windows = 0  # windows adjusted so far
        self._calibrations = 0  # of them, those that estimated the offsets
        self._points = np.zeros((1024, 3))  # landmark positions in the world (first camera) frame
        self._n_points = 0  # rows of _points in use; the array doubles when full
        self._poses: list[np.ndarray | None] = []  # camera-to-world per frame; None while skipped
        self._anchors: dict[int, tuple[int, np.ndarray]] = {}  # non-keyframe -> (its keyframe, pose in it)
        self._steps: list[_Step] = []
        self._window: list[_Keyframe] = []
        self._velocity = np.eye(4)  # the last motion from one frame to the next (camera k to k+1)
        self._ref: _Reference | None = None
        self._noise: dict[tuple[int, int], gtsam.noiseModel.Base] = {}

    # --- the per-frame loop -------------------------------------------------------------------

    def start(self, left: np.ndarray, right: np.ndarray) -> int:
        """Begin at a frame; returns how many landmarks it has."""
        self._poses.append(np.eye(4))
        return self._begin_piece(0, left, right)

    def step(self, left: np.ndarray, right: np.ndarray) -> None:
        """Track frame k (grey uint8 images) from the last tracked frame."""
        if self._ref is None:
            raise RuntimeError("call start() with the first frame before step()")
        k = len(self._poses)
        self._poses.append(None)
        step = _Step()
        self._steps.append(step)
        try:
            located = self._locate(k, left, step)
        except cv2.error as e:  # degenerate geometry inside OpenCV: a weak step, not a crash
            located, step.reason = None, f"OpenCV failed: {e.err}"
        if located is not None:
            self._accept(k, left, right, *located)
            return
        if k - self._ref.frame <= self.cfg.max_skipped_frames:
            step.fallback = "skipped_frame"
            return
        for s in self._steps[self._ref.frame : k]:  # every step since the last tracked frame
            s.ok, s.reason = False, s.reason or step.reason
        self._poses[k] = matmul(self._poses[self._ref.frame], power(rigid_inverse(self._velocity), k - self._ref.frame))
        self._interpolate_skipped(self._ref.frame, k)
        self._begin_piece(k, left, right)

    def finish(self) -> tuple[np.ndarray, list[StepResult]]:
        """(N, 4, 4) camera-to-first-camera poses and the N-1 steps between them."""
        last = self._ref.frame if self._ref is not None else 0
        n = len(self._poses)
        if last < n - 1:  # skipped frames at the very end: nothing to interpolate towards
            for s in self._steps[last:]:
                s.ok, s.reason = False, s.reason or "the sequence ended on frames that could not be tracked"
            for k in range(last + 1, n):
                self._poses[k] = matmul(self._poses[k - 1], rigid_inverse(self._velocity))
        for k, (keyframe, relative) in self._anchors.items():  # follow their keyframes' adjustments
            self._poses[k] = matmul(self._poses[keyframe], relative)
        poses = np.array(self._poses)
        steps = [
            StepResult(
                s.ok,
                matmul(rigid_inverse(poses[k + 1]), poses[k]),
                s.features,
                s.tracked,
                s.inliers,
                s.reason,
                s.fallback,
                s.keyframe,
                s.disparity_offset_px,
            )
            for k, s in enumerate(self._steps)
        ]
        return poses, steps

    def rig_offsets(self) -> tuple[float | None, float | None]:
        """(disparity offset, row offset) in pixels as the last window estimated them; (None, None)
        with label.odometry.disparity_offset_sigma_px = 0 (not estimated)."""
        if self.cfg.disparity_offset_sigma_px == 0:
            return None, None
        return self.front.disparity_offset, self.front.row_offset

    # --- locating a frame ---------------------------------------------------------------------

    def _locate(self, k: int, left: np.ndarray, step: _Step) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(camera-to-world pose, landmark ids, left pixels of the PnP inliers) of frame k, trying
        the fallbacks in order; None, with step.reason, when all fail."""
        ref, cfg = self._ref, self.cfg
        gap = k - ref.frame
        predicted = matmul(self._poses[ref.frame], power(rigid_inverse(self._velocity), gap))
        for fallback, wide in [("", False), (FALLBACKS[0], False), (FALLBACKS[1], True)]:
            if fallback == "more_features":
                self._add_landmarks(ref, factor=cfg.fallback_feature_factor)
            xyz = self._points[ref.ids]
            guess = self.front.project(_transform(rigid_inverse(predicted), xyz))[0]
            uv, ok = self.front.track(ref.left, left, ref.uv, guess, wide=wide)
            step.features, step.tracked = len(ref.ids), int(ok.sum())
            world_to_camera, inlier = self.front.pnp(xyz[ok], uv[ok])
            step.inliers = int(inlier.sum())
            if world_to_camera is not None and step.inliers >= cfg.min_inliers:
                step.fallback = fallback if gap == 1 else "skipped_frame"
                chosen = np.flatnonzero(ok)[inlier]
                return rigid_inverse(world_to_camera), ref.ids[chosen], uv[chosen]
            step.reason = f"only {step.inliers} PnP inliers of {step.tracked} tracks after more features and a wider search"
        return None

    def _accept(self, k: int, left: np.ndarray, right: np.ndarray, *located: np.ndarray) -> None:
        """Frame k is tracked. A keyframe's stereo observations join the window, which is adjusted,
        and it gets new landmarks; another frame is anchored to the last keyframe. Its tracks are
        where the next frame starts."""
        pose, ids, uv = located
        ref = self._ref
        self._poses[k] = pose
        if self._is_keyframe(pose, len(ids)):
            self._steps[k - 1].keyframe = True
            # Stereo matches start where the landmark's current depth says they should be.
            guess = self.front.project(_transform(rigid_inverse(pose), self._points[ids]))[1]
            uv_r, ok = self.front.stereo_match(left, right, uv, guess)
            self._window.append(_Keyframe(k, ids[ok], uv[ok], uv_r[ok]))
            self._window = self._window[-self.cfg.window :]
            self._adjust()
        else:
            keyframe = self._window[-1].frame
            self._anchors[k] = (keyframe, matmul(rigid_inverse(self._poses[keyframe]), pose))
        self._interpolate_skipped(ref.frame, k)
        if k - ref.frame == 1:
            self._velocity = matmul(rigid_inverse(self._poses[k]), self._poses[ref.frame])
        self._ref = _Reference(k, left, right, ids, uv)
        if self._window[-1].frame == k:
            self._add_landmarks(self._ref, factor=1)

    def _is_keyframe(self, pose: np.ndarray, inliers: int) -> bool:
        """A frame joins the window when it moved keyframe_distance_m from the last keyframe, or when
        its tracks run thin (fewer than twice min_inliers)."""
        if not self._window:
            return True
        last = self._poses[self._window[-1].frame]
        moved = np.linalg.norm(pose[:3, 3] - last[:3, 3])
        return bool(moved >= self.cfg.keyframe_distance_m or inliers < 2 * self.cfg.min_inliers)

    def _begin_piece(self, k: int, left: np.ndarray, right: np.ndarray) -> int:
        """Start tracking afresh at frame k (the first frame, or after a failure)."""
        self._window = []
        self._ref = _Reference(k, left, right, np.zeros(0, int), np.zeros((0, 2), np.float32))
        self._add_landmarks(self._ref, factor=1)
        return len(self._ref.ids)

    def _add_landmarks(self, ref: _Reference, factor: int) -> None:
        """New landmarks from stereo matches of fresh corners where ref's view has few tracks;
        `factor` > 1 asks for that many times the features, down to a lower corner quality."""
        cfg = self.cfg
        corners = self.front.corners(ref.left, cfg.max_features * factor, cfg.corner_quality / factor, taken=ref.uv)
        if len(ref.uv) and len(corners):  # not on top of a track
            near = np.min(np.linalg.norm(corners[:, None] - ref.uv[None], axis=2), axis=1) < 3.0
            corners = corners[~near]
        matched, ok = self.front.stereo_match(ref.left, ref.right, corners)
        xyz = _transform(self._poses[ref.frame], self.front.triangulate(corners[ok], matched[ok]))
        ids = np.arange(self._n_points, self._n_points + len(xyz))
        while len(self._points) < self._n_points + len(xyz):
            self._points = np.concatenate([self._points, np.zeros_like(self._points)])
        self._points[ids] = xyz
        self._n_points += len(xyz)
        ref.ids, ref.uv = np.concatenate([ref.ids, ids]), np.concatenate([ref.uv, corners[ok]])
        if not self._window or self._window[-1].frame != ref.frame:  # a fallback's landmarks make ref a keyframe
            self._window.append(_Keyframe(ref.frame, ids[:0], corners[:0], corners[:0]))
            self._anchors.pop(ref.frame, None)  # adjusted from now on, not carried by another keyframe
            if ref.frame > 0:
                self._steps[ref.frame - 1].keyframe = True
        kf = self._window[-1]
        kf.ids, kf.uv_l, kf.uv_r = (
            np.concatenate([kf.ids, ids]),
            np.concatenate([kf.uv_l, corners[ok]]),
            np.concatenate([kf.uv_r, matched[ok]]),
        )

    def _interpolate_skipped(self, a: int, b: int) -> None:
        """Poses of the frames skipped between tracked frames a and b, spaced evenly on the motion."""
        if b - a < 2:
            return
        motion = matmul(rigid_inverse(self._poses[a]), self._poses[b])  # frame b in frame a
        rvec = cv2.Rodrigues(motion[:3, :3])[0]
        for k in range(a + 1, b):
            s = (k - a) / (b - a)
            part = np.eye(4)
            part[:3, :3], part[:3, 3] = cv2.Rodrigues(rvec * s)[0], motion[:3, 3] * s
            self._poses[k] = matmul(self._poses[a], part)
            if self._window:  # follow the latest keyframe's later adjustments, as located frames do
                keyframe = self._window[-1].frame
                self._anchors[k] = (keyframe, matmul(rigid_inverse(self._poses[keyframe]), self._poses[k]))

    # --- bundle adjustment --------------------------------------------------------------------

    def _adjust(self) -> None:
        """Levenberg-Marquardt over the window's poses and the landmarks seen at least twice in it;
        the oldest keyframe's pose is held fixed. Every `disparity_offset_every`-th window also
        estimates the rig's offsets (`_calibrating_graph`); the others take them as known."""
        if len(self._window) < 2:
            return
        landmarks, count = np.unique(np.concatenate([kf.ids for kf in self._window]), return_counts=True)
        shared = landmarks[count >= 2]
        if not len(shared):
            return
        cfg = self.cfg
        calibrating = cfg.disparity_offset_sigma_px > 0 and self._windows % cfg.disparity_offset_every == 0
        self._windows += 1
        graph, values = self._calibrating_graph(shared) if calibrating else self._stereo_graph(shared)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(cfg.window_iterations)
        # Cholesky is 3x faster here than the multifrontal default. The calibrating window's reduced
        # system is nearly singular along the offset (a disparity offset and a change of every depth
        # explain the same pixels) and its Cholesky can fail at the first step, leaving the window
        # unadjusted or not depending on the last bits of the inputs; QR solves it as fast.
        params.setLinearSolverType("SEQUENTIAL_QR" if calibrating else "SEQUENTIAL_CHOLESKY")
        if calibrating:  # landmarks first, the variables every observation shares last: a small reduced system
            ordering = gtsam.Ordering()
            for key in [*(gtsam.symbol("l", i) for i in shared.tolist()), *(gtsam.symbol("x", kf.frame) for kf in self._window)]:
                ordering.push_back(key)
            ordering.push_back(_RIGHT_OF_LEFT)
            ordering.push_back(_RIGHT_CALIBRATION)
            params.setOrdering(ordering)
        try:
            result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        except RuntimeError:  # an indeterminate system (too few shared landmarks): keep the PnP poses
            return
        for kf in self._window:
            self._poses[kf.frame] = result.atPose3(gtsam.symbol("x", kf.frame)).matrix()
        for i in shared.tolist():
            self._points[i] = result.atPoint3(gtsam.symbol("l", i))
        if calibrating:
            f, right = self.front, result.atCal3_S2(_RIGHT_CALIBRATION)
            f.disparity_offset, f.row_offset = f.cx - right.px(), right.py() - f.cy
            self._calibrations += 1
        if cfg.disparity_offset_sigma_px > 0:
            self._steps[self._window[-1].frame - 1].disparity_offset_px = self.front.disparity_offset

    def _stereo_graph(self, shared: np.ndarray) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """Stereo reprojection factors of the window's observations of `shared` landmarks, with the
        rig's offsets taken as known, and the current poses and positions as the starting point."""
        graph, values = gtsam.NonlinearFactorGraph(), self._window_values(shared)
        f = self.front
        self._add_fixed_pose(graph)
        for kf in self._window:
            key = gtsam.symbol("x", kf.frame)
            levels = self._noise_levels(np.maximum(kf.uv_l[:, 0] - kf.uv_r[:, 0] - f.disparity_offset, 1e-3))
            for j in np.flatnonzero(np.isin(kf.ids, shared)).tolist():
                measured = gtsam.StereoPoint2(kf.uv_l[j, 0], kf.uv_r[j, 0] + f.disparity_offset, kf.uv_l[j, 1])
                landmark = gtsam.symbol("l", int(kf.ids[j]))
                graph.add(gtsam.GenericStereoFactor3D(measured, self._noise_model(3, levels[j]), key, landmark, self._stereo))
        return graph, values

    def _calibrating_graph(self, shared: np.ndarray) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """Left and right reprojection factors of the same observations, the right camera a camera
        of its own: held to the left one by the baseline, with a calibration variable whose principal
        point is free. Its horizontal offset from the left's is the disparity offset (observed
        disparity = f B / z + offset), its vertical offset the rows' misalignment.

        The offsets' prior is a Kalman filter's for a constant: centred on the estimate so far, its
        1 / sigma^2 grows by the starting prior's worth with every calibrating window, about what
        one window's observations are worth here. Far points keep their full weight here: with
        parallax they measure the offset best.
        """
        graph, values = gtsam.NonlinearFactorGraph(), self._window_values(shared)
        f, cfg = self.front, self.cfg
        right_of_left = gtsam.Pose3(gtsam.Rot3(), np.array([f.baseline, 0.0, 0.0]))
        values.insert(_RIGHT_OF_LEFT, right_of_left)  # a variable only because the factor wants one
        graph.add(gtsam.PriorFactorPose3(_RIGHT_OF_LEFT, right_of_left, gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
        right = gtsam.Cal3_S2(f.fx, f.fy, 0.0, f.cx - f.disparity_offset, f.cy + f.row_offset)
        values.insert(_RIGHT_CALIBRATION, right)
        sigma = cfg.disparity_offset_sigma_px / np.sqrt(1 + self._calibrations)
        fixed = 1e-3  # px: focal lengths and skew are the left camera's
        prior = gtsam.noiseModel.Diagonal.Sigmas(np.array([fixed, fixed, fixed, sigma, sigma]))
        graph.add(gtsam.PriorFactorCal3_S2(_RIGHT_CALIBRATION, right, prior))
        self._add_fixed_pose(graph)
        for kf in self._window:
            key = gtsam.symbol("x", kf.frame)
            uv_l, uv_r = kf.uv_l.astype(np.float64), kf.uv_r.astype(np.float64)
            for j in np.flatnonzero(np.isin(kf.ids, shared)).tolist():
                landmark = gtsam.symbol("l", int(kf.ids[j]))
                graph.add(gtsam.GenericProjectionFactorCal3_S2(uv_l[j], self._noise_model(2, 0), key, landmark, self._left))
                graph.add(ProjectionFactorPPPCCal3_S2(uv_r[j], self._noise_model(2, 0), key, _RIGHT_OF_LEFT, landmark, _RIGHT_CALIBRATION))
        return graph, values

    def _window_values(self, shared: np.ndarray) -> gtsam.Values:
        values = gtsam.Values()
        for kf in self._window:
            values.insert(gtsam.symbol("x", kf.frame), gtsam.Pose3(self._poses[kf.frame]))
        for i in shared.tolist():
            values.insert(gtsam.symbol("l", i), self._points[i])
        return values

    def _add_fixed_pose(self, graph: gtsam.NonlinearFactorGraph) -> None:
        """The oldest keyframe anchors the window."""
        first = self._window[0].frame
        graph.add(gtsam.NonlinearEqualityPose3(gtsam.symbol("x", first), gtsam.Pose3(self._poses[first])))

    def _noise_levels(self, disparity: np.ndarray) -> np.ndarray:
        """Per observation, the right image's sigma level: 0 up to stereo_depth_m, then one level
        per doubling of (z / stereo_depth_m)^2, i.e. per sqrt(2) in depth."""
        z = self.front.fx * self.front.baseline / disparity
        ratio = np.maximum(z / self.cfg.stereo_depth_m, 1.0)
        return np.round(4 * np.log2(ratio)).astype(int)  # quarter-octaves of sigma = ratio^2

    def _noise_model(self, dim: int, level: int) -> gtsam.noiseModel.Base:
        """Huber on unit sigmas, but a stereo factor's right-image u (row 1 of u_l, u_r, v) has
        sigma 2^(level / 2)."""
        if (dim, level) not in self._noise:
            sigmas = np.ones(dim)
            if dim == 3:
                sigmas[1] = 2.0 ** (level / 2)
            huber = gtsam.noiseModel.mEstimator.Huber.Create(self.cfg.huber_px)
            self._noise[dim, level] = gtsam.noiseModel.Robust.Create(huber, gtsam.noiseModel.Diagonal.Sigmas(sigmas))
        return self._noise[dim, level]


# The calibrating window's right camera: where it sits on the left one, and its calibration.
_RIGHT_OF_LEFT, _RIGHT_CALIBRATION = gtsam.symbol("e", 0), gtsam.symbol("c", 0)


def _transform(T: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Apply a 4x4 rigid transform to (N, 3) points."""
    return matmul(xyz, T[:3, :3].T) + T[:3, 3]
