"""Running odometry over a whole sequence, and scoring a trajectory against ground truth."""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import numpy as np

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.geometry.path import path_length
from offroad_path.odometry.frame_to_frame import FrameToFrameOdometry
from offroad_path.odometry.steps import StepResult
from offroad_path.odometry.windowed import WindowedOdometry
from offroad_path.sequence.reader import Sequence

log = logging.getLogger(__name__)


@dataclass
class OdometryRun:
    poses: np.ndarray  # (N, 4, 4) camera to first camera; across a failed step only a guess
    steps: list[StepResult]  # steps[k] is the motion from frame k to k+1
    disparity_offset_px: float | None = None  # the rig's, as the estimator found it; None: not estimated
    row_offset_px: float | None = None

    @property
    def failed(self) -> np.ndarray:
        """failed[k]: the step from frame k to k+1 failed."""
        return np.array([not s.ok for s in self.steps], bool)

    @property
    def pieces(self) -> list[tuple[int, int]]:
        """(first, last) frames of each stretch with no failed step, at least two frames long."""
        breaks = [-1, *np.flatnonzero(self.failed).tolist(), len(self.steps)]
        return [(a + 1, b) for a, b in itertools.pairwise(breaks) if b > a + 1]


ESTIMATORS = {"windowed": WindowedOdometry, "frame_to_frame": FrameToFrameOdometry}  # label.odometry.method


def run_odometry(sequence: Sequence, cfg: OdometryConfig) -> OdometryRun:
    """Poses of every frame of `sequence` by the estimator cfg.method names."""
    if cfg.method not in ESTIMATORS:
        raise ValueError(f"unknown label.odometry.method {cfg.method!r}; valid: {', '.join(ESTIMATORS)}")
    sequence.require_stereo("the stereo odometry and its disparity offset")
    vo = ESTIMATORS[cfg.method](sequence.calibration, cfg)
    vo.start(sequence.load_left(0, grey=True), sequence.load_right(0, grey=True))
    for k in range(1, len(sequence)):
        vo.step(sequence.load_left(k, grey=True), sequence.load_right(k, grey=True))
    run = OdometryRun(*vo.finish(), *vo.rig_offsets())
    for k, s in enumerate(run.steps):
        if not s.ok:
            log.warning("%s: odometry failed from frame %d to %d: %s", sequence.name, k, k + 1, s.reason)
    return run


@dataclass
class Drift:
    """KITTI-style drift of an estimated trajectory over segments of one length."""

    translation_drift_pct: float  # mean over segments of the end-point error, % of the segment
    rotation_drift_deg_per_m: float
    scale_ratio_median: float  # estimated over true length of each segment
    scale_ratio_min: float
    scale_ratio_max: float
    step_scale_ratio_min: float  # estimated over true length of each frame-to-frame step that moved
    step_scale_ratio_max: float
    segments: list[dict]  # per segment: from, to, length_m, translation_pct, rotation_deg_per_m, scale_ratio

    def summary(self) -> dict[str, float]:
        return {k: v for k, v in self.__dict__.items() if k != "segments"}


def drift(
    estimate: np.ndarray, reference: np.ndarray, segment_m: float = 20.0, pieces: list[tuple[int, int]] | None = None
) -> tuple[Drift | None, str | None]:
    """Relative pose error over `segment_m` stretches with evo (the KITTI odometry metric).

    Segments are taken on the ground-truth path (evo's pairs_from_reference), the standard way: taken
    on the estimate, a VO that overestimates scale would be scored over shorter true stretches. With
    `pieces` (frame ranges between odometry failures) no segment spans a failure. Returns
    (the drift; None) or (None, why there is no figure); it never raises on a short or failed path.
    """
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D
    from evo.core.units import Unit

    travelled = path_length(reference)
    if travelled <= segment_m:
        return None, f"the true path is {travelled:.1f} m, not longer than one {segment_m:g} m segment"
    segments = []
    for first, last in pieces or [(0, len(reference) - 1)]:
        ref, est = reference[first : last + 1], estimate[first : last + 1]
        if path_length(ref) <= segment_m:
            continue
        errors = {}
        for name, relation in (
            ("translation", metrics.PoseRelation.translation_part),
            ("rotation", metrics.PoseRelation.rotation_angle_deg),
        ):
            rpe = metrics.RPE(
                relation, delta=segment_m, delta_unit=Unit.meters, rel_delta_tol=0.1, all_pairs=True, pairs_from_reference=True
            )
            try:
                rpe.process_data((PosePath3D(poses_se3=list(ref)), PosePath3D(poses_se3=list(est))))
            except Exception:  # evo's FilterException / MetricsException: no pair of frames fits
                break
            errors[name] = np.asarray(rpe.error)
        if len(errors) < 2:
            continue
        pairs = metrics.id_pairs_from_delta(list(ref), segment_m, Unit.meters, 0.1, all_pairs=True)  # RPE's pairs, in its order
        for (i, j), t, r in zip(pairs, errors["translation"], errors["rotation"], strict=True):
            # Each error over the segment's own true length (evo admits lengths within 10 % of segment_m).
            true = path_length(ref[i : j + 1])
            ratio = np.linalg.norm(est[j, :3, 3] - est[i, :3, 3]) / np.linalg.norm(ref[j, :3, 3] - ref[i, :3, 3])
            segments.append(
                {
                    "from": first + i,
                    "to": first + j,
                    "length_m": float(true),
                    "translation_pct": float(100 * t / true),
                    "rotation_deg_per_m": float(r / true),
                    "scale_ratio": float(ratio),
                }
            )
    if not segments:
        return None, f"evo found no {segment_m:g} m segment within a piece of odometry without failure"
    ratios = [s["scale_ratio"] for s in segments]
    steps = _step_scale_ratios(estimate, reference, pieces or [(0, len(reference) - 1)])
    return Drift(
        float(np.mean([s["translation_pct"] for s in segments])),
        float(np.mean([s["rotation_deg_per_m"] for s in segments])),
        float(np.median(ratios)),
        float(np.min(ratios)),
        float(np.max(ratios)),
        float(steps.min()),
        float(steps.max()),
        segments,
    ), None


def _step_scale_ratios(estimate: np.ndarray, reference: np.ndarray, pieces: list[tuple[int, int]], min_step_m: float = 0.1) -> np.ndarray:
    """Estimated over true length of each step inside a piece where the true camera moved at least
    min_step_m (a standing vehicle has no scale to get wrong)."""
    true = np.linalg.norm(np.diff(reference[:, :3, 3], axis=0), axis=1)
    est = np.linalg.norm(np.diff(estimate[:, :3, 3], axis=0), axis=1)
    inside = np.zeros(len(true), bool)
    for first, last in pieces:
        inside[first:last] = True
    moved = inside & (true >= min_step_m)
    return est[moved] / true[moved] if moved.any() else np.array([np.nan])
