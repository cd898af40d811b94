"""Running odometry over a whole sequence, and scoring a trajectory against ground truth."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from offroad_path.config import OdometryConfig
from offroad_path.geometry.path import path_length
from offroad_path.odometry.stereo_vo import StepResult, StereoOdometry
from offroad_path.sequence.reader import Sequence

log = logging.getLogger(__name__)


@dataclass
class OdometryRun:
    poses: np.ndarray  # (N, 4, 4) camera to first camera; a failed step contributes no motion
    steps: list[StepResult]  # steps[k] is the motion from frame k to k+1

    @property
    def failed(self) -> np.ndarray:
        """failed[k]: the step from frame k to k+1 failed."""
        return np.array([not s.ok for s in self.steps], bool)


def run_odometry(sequence: Sequence, cfg: OdometryConfig) -> OdometryRun:
    vo = StereoOdometry(sequence.calibration, cfg)
    vo.start(sequence.load_left(0, grey=True), sequence.load_right(0, grey=True))
    poses = [np.eye(4)]
    steps = []
    for k in range(1, len(sequence)):
        result = vo.step(sequence.load_left(k, grey=True), sequence.load_right(k, grey=True))
        if not result.ok:
            log.warning("%s: odometry failed from frame %d to %d: %s", sequence.name, k - 1, k, result.reason)
        steps.append(result)
        poses.append(poses[-1] @ np.linalg.inv(result.motion))
    return OdometryRun(np.array(poses), steps)


def drift(estimate: np.ndarray, reference: np.ndarray, segment_m: float = 20.0) -> tuple[dict[str, float] | None, str | None]:
    """Relative pose error over `segment_m` stretches, with evo (KITTI-style drift).

    Segments are taken on the ground-truth path (evo's pairs_from_reference), the standard way: taken
    on the estimate, a VO that overestimates scale would be scored over shorter true stretches.
    Returns (translation drift in % of distance travelled and rotation drift in deg/m, means over all
    segment pairs; None) or (None, why there is no figure); it never raises on a short or failed path.
    """
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D
    from evo.core.units import Unit

    travelled = path_length(reference)
    if travelled <= segment_m:
        return None, f"the true path is {travelled:.1f} m, not longer than one {segment_m:g} m segment"
    est, ref = PosePath3D(poses_se3=list(estimate)), PosePath3D(poses_se3=list(reference))
    out = {}
    for name, relation, scale in (
        ("translation_drift_pct", metrics.PoseRelation.translation_part, 100.0 / segment_m),
        ("rotation_drift_deg_per_m", metrics.PoseRelation.rotation_angle_deg, 1.0 / segment_m),
    ):
        rpe = metrics.RPE(relation, delta=segment_m, delta_unit=Unit.meters, rel_delta_tol=0.1, all_pairs=True, pairs_from_reference=True)
        try:
            rpe.process_data((ref, est))
        except Exception as e:  # evo's FilterException / MetricsException: no pair of frames fits
            return None, f"evo found no {segment_m:g} m segment ({e})"
        out[name] = float(rpe.get_statistic(metrics.StatisticsType.mean)) * scale
    return out, None
