"""The drift metric against hand-computed values: a trajectory 2 % too long, and pieces between
odometry failures that no segment may span."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.odometry.sequence_trajectory import drift


def straight(n: int, step_m: float) -> np.ndarray:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 2, 3] = np.arange(n) * step_m  # driving along the camera's z
    return poses


def test_a_trajectory_two_percent_long_drifts_two_percent():
    reference = straight(61, 1.0)
    estimate = straight(61, 1.02)
    result, problem = drift(estimate, reference, 20.0)
    assert problem is None
    # Every segment (0-20 ... 40-60, then 41-60 and 42-60: evo admits 18 to 22 m) ends 2 % too far.
    assert [(s["from"], s["to"]) for s in result.segments] == [(i, i + 20) for i in range(41)] + [(41, 60), (42, 60)]
    assert result.translation_drift_pct == pytest.approx(2.0)
    assert result.rotation_drift_deg_per_m == pytest.approx(0.0, abs=1e-9)
    assert result.scale_ratio_min == pytest.approx(1.02) and result.scale_ratio_max == pytest.approx(1.02)
    assert result.step_scale_ratio_min == pytest.approx(1.02) and result.step_scale_ratio_max == pytest.approx(1.02)


def test_no_segment_spans_a_break_between_pieces():
    reference = straight(61, 1.0)
    estimate = reference.copy()
    estimate[31:, 2, 3] += 5.0  # a failed step from frame 30 to 31 made a 5 m jump
    whole = drift(estimate, reference, 20.0)[0]
    assert whole.translation_drift_pct > 10
    pieces = drift(estimate, reference, 20.0, [(0, 30), (31, 60)])[0]
    assert pieces.translation_drift_pct == pytest.approx(0.0, abs=1e-9)
    assert all(s["to"] <= 30 or s["from"] >= 31 for s in pieces.segments)
    assert {(0, 20), (10, 30), (31, 51), (40, 60)} <= {(s["from"], s["to"]) for s in pieces.segments}


def test_a_path_too_short_for_one_segment_gives_the_reason():
    result, problem = drift(straight(15, 1.0), straight(15, 1.0), 20.0)
    assert result is None and "14.0 m" in problem
