"""What one odometry step reports, whichever estimator made it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FALLBACKS = ("more_features", "wide_search", "skipped_frame")  # in the order a weak step tries them


@dataclass
class StepResult:
    """The motion from frame k to k+1: `motion` maps camera-k points into camera k+1.

    A failed step's motion is only a guess that keeps the trajectory in one array (the identity
    from the frame-to-frame VO, the last velocity from the windowed one); segments never span it
    and drift is scored on the pieces between failures.
    """

    ok: bool
    motion: np.ndarray  # (4, 4)
    features: int  # points with a stereo match in frame k (landmarks held, for the windowed VO)
    tracked: int  # of those, tracked into frame k+1
    inliers: int
    reason: str = ""  # why the step failed
    fallback: str = ""  # the fallback that made the step: more_features, wide_search, skipped_frame
    keyframe: bool = False  # frame k+1 joined the windowed estimator's keyframes
    disparity_offset_px: float = float("nan")  # the windowed estimator's estimate after adjusting keyframe k+1
