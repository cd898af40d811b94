"""Temporal consistency: the warp carries a mask between two rendered frames with the true pose
and depth to within a pixel, the filter averages as stated, and the scores on every frame of the
test blocks (exact labels are steady; shaking them is measured)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from offroad_path.data.manifest import read_manifest
from offroad_path.evaluate.temporal_scores import held_out_blocks, last_labellable, load_block, score_temporal, stability
from offroad_path.inference.temporal_filter import TemporalFilter, warp_previous
from offroad_path.sequence.reader import open_sequence


def ground_disc(seq, k: int, centre: np.ndarray, radius_m: float = 3.0) -> np.ndarray:
    """Pixels of frame k whose surface point lies within radius_m of `centre` (world x, z)."""
    depth, K = seq.load_depth(k), seq.calibration.K
    v, u = np.indices(depth.shape)
    camera = np.stack([(u - K[0, 2]) / K[0, 0] * depth, (v - K[1, 2]) / K[1, 1] * depth, depth, np.ones_like(depth)], axis=-1)
    world = camera @ seq.poses[k].T
    return (depth > 0) & (np.hypot(world[..., 0] - centre[0], world[..., 2] - centre[2]) < radius_m)


@pytest.mark.parametrize("k", [5, 20])
def test_warp_carries_a_ground_mask_to_the_next_frame_within_a_pixel(drive, k):
    seq = open_sequence(drive / "drive")
    centre = seq.poses[k] @ np.array([0.0, 1.8, 12.0, 1.0])  # on the ground 12 m ahead of frame k
    before, after = ground_disc(seq, k, centre), ground_disc(seq, k + 1, centre)
    previous_from_current = np.linalg.inv(seq.poses[k]) @ seq.poses[k + 1]
    warped, valid = warp_previous(before.astype(np.float32), seq.load_depth(k + 1), seq.calibration.K, previous_from_current,
                                  seq.load_depth(k))  # fmt: skip
    assert after.sum() > 1000 and valid[after].mean() > 0.99
    wrong = ((warped > 0.5) != after) & valid
    kernel = np.ones((3, 3), np.uint8)
    boundary = cv2.dilate(after.astype(np.uint8), kernel).astype(bool) & ~cv2.erode(after.astype(np.uint8), kernel).astype(bool)
    assert not (wrong & ~boundary).any()  # every disagreement lies on the disc's one-pixel boundary band
    assert wrong.sum() < 0.05 * after.sum()
    # Without the pose the disc does not land: the check can fail.
    unmoved, _ = warp_previous(before.astype(np.float32), seq.load_depth(k + 1), seq.calibration.K, np.eye(4))
    assert (((unmoved > 0.5) != after) & ~boundary).sum() > 100


def test_filter_is_an_exponential_average_where_the_warp_holds():
    f, K, depth = TemporalFilter(alpha=0.5), np.array([[100.0, 0, 16], [0, 100, 12], [0, 0, 1]]), np.full((24, 32), 10.0)
    fused = [f(np.full((24, 32), c, np.float32), depth, K, np.eye(4))[12, 16] for c in (1.0, 0.0, 1.0)]
    assert fused == pytest.approx([1.0, 0.5, 0.75])
    unknown = f(np.zeros((24, 32), np.float32), np.zeros((24, 32)), K, np.eye(4))  # no depth: the current prediction alone
    assert unknown.max() == 0.0
    f.reset()
    assert f(np.ones((24, 32), np.float32), depth, K, np.eye(4)).min() == 1.0


def test_exact_labels_of_every_test_block_frame_are_steady(compose_config, labelled_drive, split_dir):
    cfg = compose_config()
    samples = read_manifest(split_dir / "test.csv")
    blocks = held_out_blocks([s for s in samples if not s.mirrored], labelled_drive, block_m=4.0, distance_m=cfg.label.distance_m)
    every = [f for b in blocks for f in b.frames]
    assert {s.f0 for s in samples} <= set(every) and len(every) == len(set(every))  # each test frame once, with the frames between
    assert all(b.frames == list(range(b.frames[0], b.frames[-1] + 1)) for b in blocks)
    block = max(blocks, key=lambda b: len(b.frames))
    load_block(block, cfg.label)
    assert block.labels.shape[0] == len(block.frames) and block.labels.any(axis=(1, 2)).all()
    steady = stability(block.labels, block)
    shaken = stability(np.stack([np.roll(m, 12 * (-1) ** i, axis=1) for i, m in enumerate(block.labels)]), block)
    assert min(steady) > 0.85 and np.mean(shaken) < np.mean(steady) - 0.05


def test_blocks_end_where_the_true_poses_leave_no_label_distance(labelled_drive, split_dir):
    straight = np.stack([np.eye(4)] * 30)
    straight[:, 2, 3] = np.arange(30.0)  # a frame every metre
    assert last_labellable(straight, 20.0) == 8 and last_labellable(straight, 29.0) == -1  # 29 - 8 = 21 > 20; nothing is > 29 m
    samples = [s for s in read_manifest(split_dir / "test.csv") if not s.mirrored]
    (seq,) = {b.run.sequence.root: b.run.sequence for b in held_out_blocks(samples, labelled_drive, 4.0, 20.0)}.values()
    top = max(s.f0 for s in samples)
    # A label distance a little longer than the true driving after the last test f0: it and the frames
    # just before it cannot be labelled exactly (the VO's distances may run that long), so the blocks end earlier.
    distance = np.linalg.norm(seq.poses[top + 1 :, :3, 3] - seq.poses[top, :3, 3], axis=1).max() + 0.5
    short = held_out_blocks(samples, labelled_drive, 4.0, distance)
    assert short and max(f for b in short for f in b.frames) == last_labellable(seq.poses, distance) < top


def test_every_network_scored_on_every_test_block_frame(compose_config, labelled_drive, split_dir, trained, tmp_path):
    checkpoint, _, _ = trained
    cfg = compose_config(f"evaluate.labels_dir={labelled_drive}", "split.block_m=4")
    samples = read_manifest(split_dir / "test.csv")
    rows = score_temporal(cfg.evaluate, cfg.label, cfg.split.block_m, {"unet-none": checkpoint, "unet-copy": checkpoint}, samples)
    frames = sum(len(b.frames) for b in held_out_blocks([s for s in samples if not s.mirrored], labelled_drive, 4.0, cfg.label.distance_m))
    assert list(rows) == ["unet-none", "unet-copy"] and rows["unet-none"].frames == frames
    assert rows["unet-none"].method == "U-Net (none)" and rows["unet-none"].iou == rows["unet-copy"].iou  # same weights, same scores
    assert all(0 <= getattr(rows["unet-none"], k) <= 1 for k in ("iou", "iou_filtered", "stability", "stability_filtered"))
    off = compose_config("evaluate.temporal.enabled=false")
    assert score_temporal(off.evaluate, off.label, off.split.block_m, ["unet-none"], samples) is None
