"""Real-footage rows: a trained network and the mean-path prior scored on the real KITTI snippet's
VO labels, against each frame's own label and against the other frames' labels."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.evaluation.metrics import counts, per_image_iou, pooled
from offroad_path.evaluation.real import RealFrames, score_real
from offroad_path.label import label

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
    frames = RealFrames.read(kitti_labels)
    n, h, w = frames.labels.shape
    assert n >= 5 and (h, w) == (370, 1226) and len(frames.images) == n  # the snippet's own frame size
    prior = np.zeros((288, 512), bool)
    prior[144:, 128:384] = True  # the bottom half's middle, at the synthetic label size
    rows = score_real({"unet-none": checkpoint}, frames, prior, 0.5)
    assert list(rows) == ["unet-none", "mean_path_prior"]
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
    assert net.perception == pytest.approx(net.iou - net.non_corresponding_iou)
