"""The sequence reader: both layouts, and a clear error naming the file for every kind of bad input."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import command

from offroad_path.errors import InputError
from offroad_path.sequence import open_sequence

K_ROW = "700 0 320 0 0 700 180 0 0 0 1 0"
P_RIGHT = "700 0 320 -280 0 700 180 0 0 0 1 0"  # baseline 280 / 700 = 0.4 m


def write_frames(folder: Path, n: int, size=(640, 360), start: int = 0) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(start)
    for i in range(start, start + n):
        cv2.imwrite(str(folder / f"{i:06d}.png"), rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8))


def pose_rows(n: int) -> str:
    return "".join(f"1 0 0 0 0 1 0 0 0 0 1 {0.5 * i}\n" for i in range(n))


@pytest.fixture
def sequence(tmp_path) -> Path:
    root = tmp_path / "seq"
    write_frames(root / "image_l", 4)
    write_frames(root / "image_r", 4)
    (root / "calib.txt").write_text(f"{K_ROW}\n{P_RIGHT}\n")
    (root / "poses.txt").write_text(pose_rows(4))
    return root


def test_reads_the_project_layout(sequence):
    seq = open_sequence(sequence)
    assert len(seq) == 4 and seq.image_size == (640, 360)
    assert seq.calibration.baseline_m == pytest.approx(0.4)
    assert seq.poses[3, 2, 3] == pytest.approx(1.5)
    assert seq.load_left(2).shape == (360, 640, 3)


def test_reads_kitti_odometry_layout(tmp_path):
    root = tmp_path / "dataset" / "sequences" / "05"
    write_frames(root / "image_2", 3)
    write_frames(root / "image_3", 3)
    keyed = {
        "P0": K_ROW,
        "P1": "700 0 320 -378 0 700 180 0 0 0 1 0",
        "P2": "700 0 320 46 0 700 180 0.2 0 0 1 0.004",
        "P3": "700 0 320 -238 0 700 180 0.9 0 0 1 0.003",
    }
    (root / "calib.txt").write_text("".join(f"{k}: {v}\n" for k, v in keyed.items()) + "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    (tmp_path / "dataset" / "poses").mkdir()
    (tmp_path / "dataset" / "poses" / "05.txt").write_text(pose_rows(3))
    seq = open_sequence(root)
    assert seq.left[0].parent.name == "image_2"
    assert seq.calibration.baseline_m == pytest.approx((46 + 238) / 700)  # from P2 and P3, not P0/P1
    assert seq.poses_path == tmp_path / "dataset" / "poses" / "05.txt"


def test_reads_the_real_kitti_snippet(kitti_snippet):
    seq = open_sequence(kitti_snippet)
    assert len(seq) == 51 and seq.image_size == (1226, 370)
    assert seq.calibration.fx == pytest.approx(707.0912)
    assert seq.calibration.baseline_m == pytest.approx(379.8145 / 707.0912)
    np.testing.assert_allclose(seq.poses[0], np.eye(4), atol=1e-6)
    assert seq.load_left(50, grey=True).shape == (370, 1226)


BAD_INPUTS = {
    "missing calib": (lambda r: (r / "calib.txt").unlink(), "calib.txt", "is missing"),
    "calib row of 11": (lambda r: (r / "calib.txt").write_text(f"{K_ROW}\n{P_RIGHT[:-2]}\n"), "calib.txt", "11 numbers, expected 12"),
    "calib not numbers": (
        lambda r: (r / "calib.txt").write_text(f"{K_ROW}\n{P_RIGHT.replace('280', 'abc')}\n"),
        "calib.txt",
        "not a number",
    ),
    "calib one row": (lambda r: (r / "calib.txt").write_text(f"{K_ROW}\n"), "calib.txt", "two rows"),
    "no baseline": (lambda r: (r / "calib.txt").write_text(f"{K_ROW}\n{K_ROW}\n"), "calib.txt", "no baseline"),
    "right image missing": (lambda r: (r / "image_r" / "000002.png").unlink(), "image_r", "lacks 1 right image"),
    "sizes differ": (
        lambda r: write_frames(r / "image_r", 1, size=(32, 32), start=1),
        "image_r/000001.png",
        "every image must have one size",
    ),
    "unreadable png": (
        lambda r: (r / "image_l" / "000003.png").write_bytes(b"not a png at all, just text"),
        "image_l/000003.png",
        "not a PNG",
    ),
    "pose row of 11": (
        lambda r: (r / "poses.txt").write_text(pose_rows(3) + "1 0 0 0 0 1 0 0 0 0 1\n"),
        "poses.txt",
        "row 4 has 11 numbers",
    ),
    "pose not finite": (
        lambda r: (r / "poses.txt").write_text(pose_rows(3) + "1 0 0 0 0 1 0 0 0 0 1 nan\n"),
        "poses.txt",
        "row 4 has a non-finite",
    ),
    "pose count": (lambda r: (r / "poses.txt").write_text(pose_rows(3)), "poses.txt", "has 3 poses, expected 4"),
    "pose not rotation": (
        lambda r: (r / "poses.txt").write_text(pose_rows(3) + "2 0 0 0 0 1 0 0 0 0 1 0\n"),
        "poses.txt",
        "row 4 is not a rotation",
    ),
}


@pytest.mark.parametrize("case", BAD_INPUTS)
def test_bad_input_names_the_file(sequence, case):
    damage, file, problem = BAD_INPUTS[case]
    damage(sequence)
    with pytest.raises(InputError) as info:
        open_sequence(sequence)
    message = str(info.value)
    assert str(sequence / file) in message and problem in message


def test_undecodable_image_names_the_file(sequence):
    path = sequence / "image_l" / "000001.png"
    path.write_bytes(path.read_bytes()[:60])  # a valid header, then the data is cut off
    seq = open_sequence(sequence)
    with pytest.raises(InputError, match=r"000001\.png: cannot be decoded"):
        seq.load_left(1)


def test_cli_checks_recordings_and_exits_non_zero_on_bad_input(sequence):
    ok = command("offroad_path.sequence", sequence)
    assert ok.returncode == 0 and "4 stereo pairs 640x360" in ok.stdout and "baseline 0.400 m" in ok.stdout
    (sequence / "calib.txt").write_text(f"{K_ROW}\n{K_ROW}\n")
    bad = command("offroad_path.sequence", sequence)
    assert bad.returncode == 2
    assert (
        bad.stderr.strip()
        == f"error: {sequence / 'calib.txt'}: the right matrix has no baseline (B = 0 m): P_right[0,3] must be -fx*B with B > 0"
    )
