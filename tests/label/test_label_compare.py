"""label.compare: two label runs of the same recordings, frame by frame (mean and minimum IoU,
frames only one labelled), and its command."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from helpers import command

from offroad_path.label.compare import compare


def write(path, mask) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.where(mask, 255, 0).astype(np.uint8))


def test_iou_per_common_frame_by_hand(tmp_path):
    a, b = np.zeros((4, 4), bool), np.zeros((4, 4), bool)
    a[0, :3] = True  # 3 pixels
    b[0, 1:] = True  # 3 pixels, 2 shared: IoU 2 / 4
    write(tmp_path / "A" / "s" / "label" / "000000.png", a)
    write(tmp_path / "B" / "s" / "label" / "000000.png", b)
    write(tmp_path / "A" / "s" / "label" / "000007.png", a)
    write(tmp_path / "B" / "s" / "label" / "000007.png", a)  # identical: IoU 1
    write(tmp_path / "A" / "s" / "label" / "000009.png", a)  # only in A
    result = compare(tmp_path / "A", tmp_path / "B")
    assert result == {"common": 2, "only_a": 1, "only_b": 0, "mean_iou": pytest.approx(0.75), "min_iou": pytest.approx(0.5)}
    run = command("offroad_path.label.compare", tmp_path / "A", tmp_path / "B")
    assert run.returncode == 0 and "2 frames labelled in both: mean IoU 0.7500, min 0.5000" in run.stdout
