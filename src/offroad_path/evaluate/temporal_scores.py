"""Temporal consistency on video: every frame of the test blocks, not only the labelled ones.

Each frame from the first to the last test f0 of a block of driving gets an exact label from the
world's true poses and depth (the label stage's footprint and occlusion rules, with D ahead).
Every network runs on every such frame, and the temporal filter (offroad_path.inference.temporal_filter,
with the label stage's VO poses and stereo depth, as a vehicle would have them) fuses each
prediction with the previous ones. Scores, with and without the filter:

- IoU pooled over every frame;
- stability: the mean IoU between each thresholded prediction and the previous one carried into
  its frame with the true pose and depth (1: the path stays put on the ground from frame to frame).

Synthetic only: a sequence without true poses or depth gives no temporal rows.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from omegaconf import DictConfig

from offroad_path.data.labels import LabelledSequence, read_label_run
from offroad_path.data.manifest import Sample
from offroad_path.data.splitting import block_of
from offroad_path.evaluate.pixel_scores import counts, pooled
from offroad_path.geometry.path import label_end
from offroad_path.geometry.stereo import compute_disparity, depth_from_disparity, sgbm
from offroad_path.inference.temporal_filter import TemporalFilter, warp_previous
from offroad_path.report.tables import TemporalRow, method_title
from offroad_path.sequence.footprint import Occlusion, footprint_for, path_label
from offroad_path.statistics.bootstrap import Resampling, block_sums, paired_interval
from offroad_path.statistics.scores import iou

log = logging.getLogger(__name__)


@dataclass
class Block:
    """Consecutive frames of one sequence, with what scoring and filtering them needs."""

    run: LabelledSequence
    frames: list[int]
    images: list[np.ndarray] = field(default_factory=list)  # RGB
    labels: np.ndarray | None = None  # (n, H, W) bool, exact
    stereo_depth: list[np.ndarray] = field(default_factory=list)  # for the filter
    true_depth: list[np.ndarray] = field(default_factory=list)  # for the stability score


def last_labellable(poses: np.ndarray, distance_m: float) -> int:
    """The last frame a label of distance_m can be made at (label_end's rule; -1: none)."""
    positions = poses[:, :3, 3]
    return next((f for f in range(len(positions) - 1, -1, -1) if label_end(positions, f, distance_m) is not None), -1)


def held_out_blocks(samples: list[Sample], labels_dir: Path, block_m: float, distance_m: float) -> list[Block] | None:
    """The test set's blocks of driving (the split's block_m along the label run's poses), each
    every frame from its first to its last test f0; None when a sequence lacks true poses or depth.
    Frames with less than distance_m of true driving after them are left out: the label stage chose
    its f0s by the VO's distances, which may run a little long."""
    runs = {r.name: r for r in read_label_run(labels_dir)}
    groups: dict[tuple[str, int], list[int]] = {}
    for sample in samples:
        run = runs[sample.sequence]
        if run.sequence.poses is None or run.sequence.depth is None:
            return None
        groups.setdefault(block_of(sample.sequence, run.distance()[sample.f0], block_m), []).append(sample.f0)
    last = {name: last_labellable(runs[name].sequence.poses, distance_m) for name, _ in groups}
    blocks = [Block(runs[name], list(range(min(f0s), min(max(f0s), last[name]) + 1))) for (name, _), f0s in sorted(groups.items())]
    return [b for b in blocks if b.frames]


def load_block(block: Block, label: DictConfig) -> None:
    """Images, exact labels, stereo and true depth of every frame of `block` (label: the label stage's settings)."""
    seq = block.run.sequence
    footprint = footprint_for(seq, label.footprint)
    positions = seq.poses[:, :3, 3]
    matcher = sgbm(label.disparity)
    labels = []
    for f in block.frames:
        fn = label_end(positions, f, label.distance_m)
        if fn is None:
            raise ValueError(f"{seq.root}: frame {f} has no frame {label.distance_m:g} m ahead to label it with")
        true_depth = seq.load_depth(f)
        o = label.occlusion
        occlusion = Occlusion(true_depth, o.margin_m, o.margin_rel) if o.enabled else None
        labels.append(path_label(seq, seq.poses, (f, fn), footprint, occlusion) > 0)
        disparity = compute_disparity(matcher, seq.load_left(f, grey=True), seq.load_right(f, grey=True))
        block.stereo_depth.append(depth_from_disparity(disparity, seq.calibration.fx, seq.calibration.baseline_m))
        block.true_depth.append(true_depth)
        block.images.append(cv2.cvtColor(seq.load_left(f), cv2.COLOR_BGR2RGB))
    block.labels = np.stack(labels)


def stability(paths: np.ndarray, block: Block) -> list[float]:
    """IoU of each thresholded path (n, H, W) bool with the previous one carried into its frame by
    the true pose and depth, over the pixels the previous frame saw."""
    seq, K = block.run.sequence, block.run.sequence.calibration.K
    out = []
    for i in range(1, len(block.frames)):
        previous_from_current = np.linalg.inv(seq.poses[block.frames[i - 1]]) @ seq.poses[block.frames[i]]
        previous, depth = paths[i - 1].astype(np.float32), block.true_depth[i]
        warped, valid = warp_previous(previous, depth, K, previous_from_current, block.true_depth[i - 1])
        a, b = paths[i] & valid, (warped > 0.5) & valid
        union = np.count_nonzero(a | b)
        out.append(np.count_nonzero(a & b) / union if union else 1.0)
    return out


def filtered(confidence: np.ndarray, block: Block, alpha: float) -> np.ndarray:
    """The temporal filter over a block's confidence maps (n, H, W), with VO poses and stereo depth."""
    K, vo = block.run.sequence.calibration.K, block.run.poses
    f = TemporalFilter(alpha)
    fused = [
        f(c, d, K, np.linalg.inv(vo[a]) @ vo[b])
        for c, d, a, b in zip(confidence, block.stereo_depth, [block.frames[0], *block.frames[:-1]], block.frames, strict=True)
    ]
    return np.stack(fused)


def score_temporal(
    e: DictConfig, label: DictConfig, block_m: float, checkpoints: dict[str, Path], samples: list[Sample]
) -> dict[str, TemporalRow] | None:
    """Rows keyed by run (checkpoints: run -> its network); None when evaluate.temporal.enabled is
    false or the test set is not synthetic. e: conf/evaluate; label: conf/label (exact labels follow
    its rules); block_m: the split's blocks. The filter's IoU gain gets a paired block-bootstrap
    interval (evaluate.bootstrap: the filter's and the raw counts on the same resamples of blocks)."""
    from offroad_path.inference.runners import TorchModel

    temporal = e.temporal
    if not temporal.enabled:
        return None
    blocks = held_out_blocks([s for s in samples if not s.mirrored], Path(e.labels_dir), block_m, label.distance_m)
    if blocks is None:
        log.info("temporal consistency: the test sequences have no true poses and depth; skipped")
        return None
    for block in blocks:
        load_block(block, label)
    labels = np.concatenate([b.labels for b in blocks])
    frame_blocks = [i for i, b in enumerate(blocks) for _ in b.frames]
    worlds = [b.run.name for b in blocks]  # each block's test world, for the hierarchical draw
    resampling = Resampling(e.bootstrap.resamples, e.bootstrap.seed, e.bootstrap.level)
    rows = {}
    for run, checkpoint in checkpoints.items():
        model = TorchModel(checkpoint)
        raw, fused, steady, steady_fused = [], [], [], []
        for block in blocks:
            confidence = model.predict_all(block.images)
            smooth = filtered(confidence, block, temporal.alpha)
            raw.append(confidence)
            fused.append(smooth)
            steady += stability(confidence > e.threshold, block)
            steady_fused += stability(smooth > e.threshold, block)
        raw_counts, fused_counts = counts(np.concatenate(raw), labels, e.threshold), counts(np.concatenate(fused), labels, e.threshold)
        gain = (
            paired_interval(block_sums(fused_counts, frame_blocks), block_sums(raw_counts, frame_blocks), iou, resampling, worlds)
            if len(blocks) >= 2
            else None
        )
        rows[run] = TemporalRow(
            method_title(run),
            len(labels),
            pooled(raw_counts).iou,
            pooled(fused_counts).iou,
            float(np.mean(steady)),
            float(np.mean(steady_fused)),
            *((gain.low, gain.high) if gain is not None else ()),
        )
        log.info(
            "%s on every test-block frame: IoU %.3f (filtered %.3f), stability %.3f (filtered %.3f)",
            run,
            *(getattr(rows[run], k) for k in ("iou", "iou_filtered", "stability", "stability_filtered")),
        )
    return rows
