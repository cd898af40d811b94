"""The rig's disparity offset: a misaligned rig made from a sequence moves the right image by the
offset asked for; the windowed odometry estimates the offset of such a rig and holds its scale; the
label stage reports the estimate and warns when a rig needs recalibrating."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from offroad_path.config.label_schema import OdometryConfig
from offroad_path.label import offset_metrics
from offroad_path.label.labeller import write_odometry
from offroad_path.odometry.sequence_trajectory import OdometryRun, drift, run_odometry
from offroad_path.odometry.steps import StepResult
from offroad_path.sequence import open_sequence
from offroad_path.sequence.misaligned import misaligned
from offroad_path.sequence.reader import Sequence


def centroid(image: np.ndarray) -> np.ndarray:
    """(x, y) of an image's brightness above its background."""
    weight = image.astype(np.float64) - np.median(image)
    weight[weight < 0] = 0
    rows, cols = np.indices(image.shape)
    return np.array([(cols * weight).sum(), (rows * weight).sum()]) / weight.sum()


@pytest.mark.parametrize(("disparity", "row"), [(-0.3, 0.0), (0.25, 0.5)])
def test_a_misaligned_rig_moves_the_right_image_by_its_offsets(tmp_path, disparity, row):
    """A Gaussian spot at (40.0, 30.0): a disparity offset d moves it to x = 40 - d (disparity is
    u_left - u_right), a row offset r to y = 30 + r."""
    cols, rows = np.meshgrid(np.arange(80), np.arange(60))
    spot = 20 + 200 * np.exp(-((cols - 40.0) ** 2 + (rows - 30.0) ** 2) / (2 * 3.0**2))
    path = tmp_path / "spot.png"
    cv2.imwrite(str(path), np.round(spot).astype(np.uint8))
    seq = Sequence(root=tmp_path, left=[path], right=[path], calibration=None, image_size=(80, 60))
    moved = misaligned(seq, disparity, row).load_right(0, grey=True)
    assert np.allclose(centroid(moved), [40.0 - disparity, 30.0 + row], atol=0.02)
    assert np.array_equal(misaligned(seq, disparity, row).load_left(0, grey=True), seq.load_left(0, grey=True))


def odometry(compose_config, seq, *overrides: str) -> tuple[float, OdometryRun]:
    run = run_odometry(seq, OdometryConfig(**compose_config(*overrides).label.odometry))
    assert not run.failed.any()
    return drift(run.poses, seq.poses, 20.0, run.pieces)[0].translation_drift_pct, run


@pytest.fixture(scope="module")
def own(compose_config, drive) -> OdometryRun:
    """The rendered rig's odometry, offsets estimated: what the tests measure a misaligned rig against."""
    return odometry(compose_config, open_sequence(drive / "drive"))[1]


@pytest.mark.slow(seconds=10)
def test_the_odometry_finds_a_rigs_disparity_offset_and_keeps_its_scale(compose_config, drive, own):
    """Through a rig 0.3 px short of disparity the estimate moves by -0.3 px from the rendered rig's
    own (which is near 0); taken as zero, the same offset makes every depth long and the path with it
    (measured: 0.77 % against 2.96 % on this 40-frame drive, 0.36 % and 0.18 % without the offset)."""
    seq = open_sequence(drive / "drive")
    short = misaligned(seq, -0.3)
    estimated_drift, estimated = odometry(compose_config, short)
    ignored_drift, ignored = odometry(compose_config, short, "label.odometry.disparity_offset_sigma_px=0")
    assert abs(own.disparity_offset_px) < 0.1
    assert estimated.disparity_offset_px - own.disparity_offset_px == pytest.approx(-0.3, abs=0.05)
    assert ignored.disparity_offset_px is None and np.isnan(ignored.steps[-1].disparity_offset_px)
    assert estimated_drift < 1.0 and ignored_drift > 2.5


def test_the_odometry_finds_a_rigs_row_offset(compose_config, drive, own):
    """Right-image rows 0.5 px low: the row offset moves by +0.5 px from the rendered rig's own, the
    disparity offset stays where it was."""
    _, low = odometry(compose_config, misaligned(open_sequence(drive / "drive"), 0.0, row_offset_px=0.5))
    assert low.row_offset_px - own.row_offset_px == pytest.approx(0.5, abs=0.05)
    assert low.disparity_offset_px == pytest.approx(own.disparity_offset_px, abs=0.03)


def test_the_report_carries_the_estimate_and_warns_past_the_threshold(drive, tmp_path):
    seq = open_sequence(drive / "drive")
    steps = [StepResult(True, np.eye(4), 100, 90, 80, disparity_offset_px=-0.1 * k) for k in range(len(seq) - 1)]
    run = OdometryRun(seq.poses.copy(), steps, disparity_offset_px=-0.62, row_offset_px=0.1)
    found = write_odometry(tmp_path, run, seq, 20.0, warn_offset_px=0.5)
    with open(tmp_path / "steps.csv") as f:
        column = [float(r["disparity_offset_px"]) for r in csv.DictReader(f)]
    assert column == pytest.approx([-0.1 * k for k in range(len(seq) - 1)])
    assert found["vo_disparity_offset_px"] == -0.62 and found["vo_row_offset_px"] == 0.1
    assert found["warnings"] == [
        "the odometry estimated a disparity offset of -0.62 px between the rectified images "
        "(beyond label.odometry.disparity_offset_warn_px = 0.5): the rig needs recalibrating"
    ]
    assert write_odometry(tmp_path, run, seq, 20.0, warn_offset_px=0.7)["warnings"] == []


def test_the_stage_metrics_give_the_mean_and_the_largest_offset():
    summaries = [{"vo_disparity_offset_px": -0.2, "vo_row_offset_px": 0.05},
                 {"vo_disparity_offset_px": 0.3, "vo_row_offset_px": -0.01},
                 {"vo_disparity_offset_px": None, "vo_row_offset_px": None}, {}]  # fmt: skip
    expected = {"vo_disparity_offset_px_mean": 0.05, "vo_disparity_offset_px_largest": 0.3,
                "vo_row_offset_px_mean": 0.02, "vo_row_offset_px_largest": 0.05}  # fmt: skip
    assert offset_metrics(summaries) == pytest.approx(expected)
    assert offset_metrics([{}]) == {}
