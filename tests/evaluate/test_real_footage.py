"""Real-footage rows: a trained network and the mean-path prior scored on the real KITTI snippet's
VO labels, against each frame's own label, against the other frames' labels, and by the
label-centred gain (0 for any constant prediction)."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.evaluate.pixel_scores import counts, per_image_iou, pooled
from offroad_path.evaluate.real import RealFrames, score_real, separability
from offroad_path.label import label
from offroad_path.statistics.bootstrap import Resampling

KITTI_FOOTPRINT = ("label.footprint.width_m=1.8", "label.footprint.front_m=2.0", "label.footprint.rear_m=-2.7",
                   "label.footprint.camera_height_m=1.65", "label.disparity.num_disparities=128")  # fmt: skip


@pytest.fixture(scope="module")
def kitti_labels(compose_config, kitti_snippet, tmp_path_factory):
    out = tmp_path_factory.mktemp("kitti") / "labels"
    label(compose_config(f"label.in_dir={kitti_snippet}", f"label.out_dir={out}", f"label.metrics_path={out.parent / 'm.json'}",
                         "label.strategy=stride", "label.stride_m=4", "label.workers=1", "mlflow.enabled=false",
                         *KITTI_FOOTPRINT))  # fmt: skip
    return out


def test_a_network_and_the_prior_on_the_real_snippet(kitti_labels, trained, tmp_path):
    checkpoint, _, _ = trained
    frames = RealFrames.read(kitti_labels, block_m=20.0, distance_m=20.0)
    n, h, w = frames.labels.shape
    assert n >= 5 and (h, w) == (370, 1226) and len(frames.images) == n  # the snippet's own frame size
    prior = np.zeros((288, 512), bool)
    prior[144:, 128:384] = True  # the bottom half's middle, at the synthetic label size
    rows = score_real({"unet-none": checkpoint}, frames, prior, 0.5, Resampling(1000, 0))
    assert list(rows) == ["unet-none", "mean_path_prior", "other_labels"]
    # The prior stretched to 1226 x 370 (nearest neighbour) covers rows from 144 * 370 / 288 = 185 and
    # columns from 128 * 1226 / 512 = 306.5 to 384 * 1226 / 512 = 919.5.
    stretched = np.zeros((h, w), bool)
    stretched[185:, 307:920] = True
    everywhere = np.broadcast_to(stretched, frames.labels.shape).astype(np.float32)
    per_image = counts(everywhere, frames.labels)
    assert rows["mean_path_prior"].iou == pytest.approx(pooled(per_image).iou, abs=2e-3)
    # A constant prediction scores each frame's label the same whichever frame it came from: the
    # non-corresponding mean over pairs i != j is the mean per-image IoU over the frames.
    assert rows["mean_path_prior"].non_corresponding_iou == pytest.approx(per_image_iou(per_image).mean(), abs=2e-3)
    net = rows["unet-none"]
    assert 0 <= net.iou <= 1 and 0 <= net.non_corresponding_iou <= 1
    assert frames.poses == "the label stage's visual odometry"
    # Every labelled frame of the snippet bends the same way (a gentle road): no frame has frames that
    # bend the other way, so the label-centred gain is undefined for the network and the prior alike.
    assert len(set(frames.direction)) == 1
    assert all(np.isnan([r.gain, r.gain_low, r.gain_high]).all() for r in rows.values())
    # The snippet's labels (a gentle road) look alike: a perfect predictor could gain 1 - diversity at most.
    s = separability(frames, rows)
    assert 0.9 < s.diversity < 1 and s.largest_gain == pytest.approx(1 - s.diversity)


def hand_frames(labels: list[list[int]], direction: list[int], blocks: list[int]) -> RealFrames:
    n = len(labels)
    return RealFrames("hand", "hand-made", [np.zeros((1, 4, 3), np.uint8)] * n, np.array(labels, bool)[:, None, :],
                      [("s", i) for i in range(n)], [("s", b) for b in blocks], direction)  # fmt: skip


def test_diversity_and_the_label_centred_gain_by_hand():
    from offroad_path.evaluate.real import real_row, separability
    from offroad_path.statistics.bootstrap import Resampling

    frames = hand_frames([[1, 1, 0, 0], [1, 1, 0, 0], [0, 0, 1, 1], [0, 1, 1, 0]], direction=[-1, -1, 1, 0], blocks=[0, 0, 1, 1])
    perfect = real_row("perfect", frames.labels, frames, Resampling(1000, 0))
    # Pairs of different frames: IoU 1, 0, 1/3, 0, 1/3, 1/3.
    assert (perfect.iou, perfect.non_corresponding_iou) == pytest.approx((1.0, 1 / 3))
    # Label by label, 1 minus the mean IoU of the other-bending frames' predictions against it: label 0
    # (left) against frames 2 and 3: 0 and 1/3, gain 5/6; label 1 the same; label 2 (right) against 0, 1, 3:
    # 0, 0, 1/3, gain 8/9; label 3 (straight) against 0, 1, 2: 1/3 each, gain 2/3. Mean 29/36; blocks {0, 1}
    # and {2, 3} hold means 5/6 and 7/9, so resamples give 7/9, 29/36 or 5/6: the percentile interval
    # [7/9, 5/6], each side stretched by Student's t for 2 blocks, 12.706 / 1.960, and the bootstrap's
    # small-sample bias, sqrt(2); a gain is at most 1.
    stretch = 12.7062 / 1.95996 * 2**0.5
    expected = (29 / 36, 29 / 36 - stretch * (29 / 36 - 7 / 9), min(1.0, 29 / 36 + stretch * (5 / 6 - 29 / 36)))
    assert (perfect.gain, perfect.gain_low, perfect.gain_high) == pytest.approx(expected, abs=1e-4)
    constant = real_row("prior", np.broadcast_to(frames.labels[0], frames.labels.shape), frames, Resampling(1000, 0))
    # A painted prior ([1, 1, 0, 0] on every frame) scores every label the same whichever frame it came from.
    assert constant.iou == pytest.approx(5 / 11)
    assert (constant.gain, constant.gain_low, constant.gain_high) == (0.0, 0.0, 0.0)
    # The prior's IoU over blocks {0, 1} (tp, fp, fn: 4, 0, 0) and {2, 3} (1, 3, 3): 1, 5/11 or 1/7; the
    # percentile interval [1/7, 1] stretched for 2 blocks reaches past IoU's range, which bounds it.
    assert (constant.iou_low, constant.iou_high) == (0.0, 1.0)
    s = separability(frames, {"perfect": perfect, "mean_path_prior": constant})
    assert (s.diversity, s.largest_gain, s.width) == pytest.approx((1 / 3, 2 / 3, 1.0)) and not s.separable
    assert "cannot separate perception from a prior" in s.sentence()
    wide = hand_frames([[1, 1, 0, 0], [0, 0, 1, 1], [1, 1, 0, 0], [0, 0, 1, 1]], direction=[-1, 1, -1, 1], blocks=[0, 0, 1, 1])
    rows = {name: real_row(name, m, wide, Resampling(1000, 0)) for name, m in (("perfect", wide.labels),
            ("mean_path_prior", np.broadcast_to(wide.labels[0], wide.labels.shape)))}  # fmt: skip
    opposite = separability(wide, rows)  # labels 0 or 1 alike; the prior scores 0.5 in every block
    assert (opposite.diversity, opposite.width) == pytest.approx((1 / 3, 0.0)) and opposite.separable
    assert rows["perfect"].gain == 1.0 and rows["mean_path_prior"].gain == 0.0
    assert "The recording can separate perception from a prior." in opposite.sentence()
    same = hand_frames([[1, 1, 0, 0]] * 4, direction=[0, 0, 0, 0], blocks=[0, 0, 1, 1])
    row = real_row("perfect", same.labels, same, Resampling(1000, 0))
    alike = separability(same, {"perfect": row})
    assert alike.largest_gain == 0 and np.isnan(row.gain) and not alike.separable
    assert "cannot separate perception from a prior" in alike.sentence()


def test_far_end_correlation_and_the_other_frames_label_by_hand():
    from offroad_path.evaluate.real import correlation, far_end, leave_one_out_labels, real_row

    paths = np.zeros((3, 10, 5), bool)
    paths[0, 2:, 0:2] = True  # far end (rows 2 and 3: ceil(0.1 * 8) = 1 row, row 2) at columns 0, 1
    paths[1, 5:, 4] = True  # column 4
    np.testing.assert_allclose(far_end(paths), [(0.5 / 4) * 2 - 1, 1.0, np.nan])
    x, y = np.array([0.0, 1.0, 2.0, 3.0]), np.array([1.0, 3.0, 2.0, 5.0])
    stats = np.stack([x, y, x * x, y * y, x * y, np.ones(4)], -1).sum(0)
    assert correlation(stats) == pytest.approx(np.corrcoef(x, y)[0, 1])
    assert np.isnan(correlation(np.stack([x * 0, y, x * 0, y * y, x * 0, np.ones(4)], -1).sum(0)))  # a constant: undefined
    # Other frames' mean label: frame 0's copy (same frame, mirrored) is left out with it.
    frames = hand_frames([[1, 1, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 1, 1, 1]], [-1, 0, 1, 1], [0, 0, 1, 1])
    frames.groups = [("s", 0), ("s", 0), ("s", 1), ("s", 2)]
    np.testing.assert_array_equal(leave_one_out_labels(frames)[:, 0], [[0, 0, 1, 1], [0, 0, 1, 1], [0, 1, 1, 0], [0, 1, 1, 0]])
    # A constant prediction: no far-end correlation; every seed scored, the seeds pooled.
    constant = real_row("constant", np.broadcast_to(frames.labels[0], (2, *frames.labels.shape)), frames, Resampling(200, 0))
    assert np.isnan(constant.far_end) and constant.gain == pytest.approx(0.0)
