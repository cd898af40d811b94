"""Real-footage rows: every trained network scored on a labelled real recording (the label
stage's labels of e.g. the KITTI snippet, from the poses its summary.json names: the VO's or a
file's), beside two numbers that need no perception: the same predictions against the labels of
the recording's other frames (the non-corresponding baseline) and the mean path of the synthetic
training labels. A network that perceives the path beats both; one that paints its prior scores the
same against any frame's label.

Perception is measured label by label (the label-centred gain): for each labelled frame, the IoU of
its own prediction against its label minus the mean IoU of the predictions of the frames that bend
the other way (left, straight, right from the labels' poses) against the same label. A constant
prediction scores exactly 0, whatever it paints; a network that follows the path scores above 0.
The row's estimate is the mean gain over the frames that have such frames, and its interval is the
block bootstrap of that same mean (one estimand, its interval around it).

Whether a recording can show perception at all: when its labels all look alike (a straight road),
even a perfect predictor gains little over the other frames' labels. The label diversity (mean IoU
between the labels of different frames) bounds that gain at 1 - diversity. How precisely the
recording measures an IoU: the widest 95 % block-bootstrap interval of an IoU in its table (the
networks' and the mean-path prior's). When the largest gain is below that width, the recording
cannot separate perception from a prior, and the report says so. A recording is one world: its
intervals resample its blocks of driving alone, and with few blocks they understate what another
recording would show (the report says how many)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import torch

from offroad_path.data.labels import read_label_run
from offroad_path.data.loading import read
from offroad_path.data.splitting import block_of
from offroad_path.evaluate.pixel_scores import counts, non_corresponding, pooled
from offroad_path.report.tables import method_title
from offroad_path.statistics.bootstrap import Resampling, block_sums, mean, score_draws
from offroad_path.statistics.scores import iou

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RealRow:
    method: str
    iou: float = field(metadata={"title": "IoU against its own frame's label"})
    iou_low: float = field(metadata={"title": "IoU, 95 % low"})
    iou_high: float = field(metadata={"title": "IoU, 95 % high"})
    non_corresponding_iou: float = field(metadata={"title": "IoU against other frames' labels"})
    gain: float = field(metadata={"title": "label-centred gain over frames bending the other way"})
    gain_low: float = field(default=float("nan"), metadata={"title": "gain, 95 % low"})
    gain_high: float = field(default=float("nan"), metadata={"title": "gain, 95 % high"})
    far_end: float = field(default=float("nan"), metadata={"title": "far-end correlation with the label's"})
    far_end_low: float = field(default=float("nan"), metadata={"title": "far end, 95 % low"})
    far_end_high: float = field(default=float("nan"), metadata={"title": "far end, 95 % high"})


@dataclass
class RealFrames:
    """The labelled frames of a label run: RGB images and their path labels (N, H, W) bool."""

    name: str  # the label run's folder name, for the report
    poses: str  # where its labels' poses came from (summary.json's poses_source of each sequence)
    images: list[np.ndarray]
    labels: np.ndarray
    groups: list[tuple[str, int]]  # (sequence, f0) of each frame
    blocks: list[tuple[str, int]] = field(default_factory=list)  # each frame's block of driving
    direction: list[int] = field(default_factory=list)  # -1 left, 0 straight, 1 right over the label's drive

    @classmethod
    def read(cls, labels_dir: Path, block_m: float, distance_m: float) -> RealFrames:
        """block_m: the blocks the bootstrap resamples (split.block_m); distance_m: how far ahead the
        direction is read (label.distance_m)."""
        images, labels, groups, blocks, direction = [], [], [], [], []
        for run in read_label_run(labels_dir):
            travelled = run.distance()
            for path in run.labels():
                f0 = int(path.stem)
                images.append(cv2.cvtColor(read(str(run.sequence.left[f0]), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))
                labels.append(read(str(path), cv2.IMREAD_GRAYSCALE) > 0)
                groups.append((run.name, f0))
                blocks.append(block_of(run.name, travelled[f0], block_m))
                ahead = min(int(np.searchsorted(travelled, travelled[f0] + distance_m)), len(travelled) - 1)
                direction.append(bend_direction(run.poses[f0], run.poses[ahead]))
        if len(labels) < 2:
            raise ValueError(f"{labels_dir}: holds {len(labels)} labelled frame(s); real-footage rows need at least 2")
        summary = json.loads((labels_dir / "summary.json").read_text())
        sources = sorted({entry.get("poses_source", "vo") for entry in summary["sequences"]})
        poses = ", ".join(
            {"vo": "the label stage's visual odometry", "file": "a pose file (label.poses.source=file)"}.get(x, x) for x in sources
        )
        return cls(labels_dir.name, poses, images, np.stack(labels), groups, blocks, direction)


STRAIGHT_DEG = 5.0  # a heading change smaller than this over the label's drive: straight


def bend_direction(start: np.ndarray, end: np.ndarray) -> int:
    """-1 left, 0 straight, 1 right: the heading change from camera pose `start` to `end` (4x4,
    camera to world; x right, y down, z forward), about the camera's vertical axis."""
    forward = (np.linalg.inv(start) @ end)[:3, 2]  # end's viewing direction in start's frame
    yaw = np.degrees(np.arctan2(forward[0], forward[2]))
    return 0 if abs(yaw) < STRAIGHT_DEG else int(np.sign(yaw))


def iou_matrix(predicted: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N, N) IoU of prediction i against label j; 1 where both are empty. predicted, target: (N, H, W) bool."""
    P = torch.from_numpy(np.ascontiguousarray(predicted)).flatten(1).double()
    T = torch.from_numpy(np.ascontiguousarray(target)).flatten(1).double()
    tp = P @ T.T
    union = P.sum(1, keepdim=True) + T.sum(1)[None, :] - tp
    return torch.where(union > 0, tp / union.clamp(min=1), torch.ones_like(tp)).numpy()


@dataclass(frozen=True)
class Separability:
    """Whether the recording can show perception: diversity of its labels, the largest gain any
    predictor could show over the other frames' labels, and the narrowest interval a network's
    measured gain got."""

    diversity: float  # mean IoU between labels of different frames
    largest_gain: float  # 1 - diversity: a perfect predictor's gain
    width: float  # of the widest 95 % interval of an IoU on the recording
    resampled: str  # what the bootstrap resampled

    @property
    def separable(self) -> bool:
        return bool(self.largest_gain > self.width)

    def sentence(self) -> str:
        head = (
            f"Label diversity (mean IoU between different frames' labels): {self.diversity:.3f}; the largest gain a perfect "
            f"predictor could show over the other frames' labels: {self.largest_gain:.3f}; the widest 95 % interval of an IoU "
            f"below ({self.resampled}) is {self.width:.3f} wide."
        )
        if self.separable:
            return head + " The recording can separate perception from a prior."
        return head + " **This recording cannot separate perception from a prior**: no result below says whether a network perceives."


def label_centred_gain(matrix: np.ndarray, frames: RealFrames) -> np.ndarray:
    """Per labelled frame j: IoU(prediction j, label j) minus the mean IoU of the predictions of the
    frames bending the other way against label j (matrix: (N, N) prediction i against label j); nan
    for a frame with no such frame."""
    direction = np.array(frames.direction)
    turned = _different(frames.groups) & (direction[:, None] != direction[None, :])  # (i, j): i bends another way than j
    against = np.where(turned, matrix, np.nan)
    with np.errstate(invalid="ignore"):
        others = np.nanmean(against, axis=0) if turned.any() else np.full(len(matrix), np.nan)
    return np.where(turned.any(axis=0), np.diag(matrix) - others, np.nan)


FAR_ROWS = 0.1  # the far end of a path: its pixels in the top tenth of the rows it covers


def far_end(paths: np.ndarray) -> np.ndarray:
    """(..., N) the far end of each path (..., N, H, W) bool: the mean column of its pixels in the top
    FAR_ROWS of the rows it covers, from -1 (left edge) to 1 (right edge); nan for an empty path."""
    h, w = paths.shape[-2:]
    flat = paths.reshape(-1, h, w)
    out = np.full(len(flat), np.nan)
    for i, path in enumerate(flat):
        rows = np.flatnonzero(path.any(axis=1))
        if len(rows):
            top = rows[: max(1, int(np.ceil(FAR_ROWS * len(rows))))]
            out[i] = np.nonzero(path[top])[1].mean() / (w - 1) * 2 - 1
    return out.reshape(paths.shape[:-2])


def correlation(s: np.ndarray) -> np.ndarray:
    """Pearson's r from statistics (..., 6) = sums of (x, y, x^2, y^2, xy, 1): resampled like a pooled score."""
    n = s[..., 5]
    with np.errstate(invalid="ignore", divide="ignore"):
        mx, my = s[..., 0] / n, s[..., 1] / n
        cov = s[..., 4] / n - mx * my
        var = (s[..., 2] / n - mx**2) * (s[..., 3] / n - my**2)
        return np.where(var > 1e-12, cov / np.sqrt(np.maximum(var, 1e-300)), np.nan)


def real_row(method: str, predicted: np.ndarray, frames: RealFrames, resampling: Resampling | None = None) -> RealRow:
    """predicted: (N, H, W) bool paths on the frames, or (S, N, H, W) one per training seed. The pooled
    IoU, the mean label-centred gain and the far-end correlation each get a bootstrap interval with
    `resampling` over the recording's blocks and the seeds."""
    seeds = predicted if predicted.ndim == 4 else predicted[None]
    confusion = np.stack([counts(p.astype(np.float32), frames.labels) for p in seeds])  # (S, N, 4)
    other = float(np.mean([non_corresponding(p, frames.labels, frames.groups).iou for p in seeds]))
    gain = np.stack([label_centred_gain(iou_matrix(p, frames.labels), frames) for p in seeds])  # (S, N)
    kept = np.isfinite(gain[0])
    x, y = far_end(seeds), far_end(frames.labels)[None].repeat(len(seeds), 0)  # (S, N)
    ends = np.isfinite(x).all(axis=0) & np.isfinite(y[0])
    ends_stats = np.stack([x, y, x * x, y * y, x * y, np.ones_like(x)], -1)[:, ends]  # (S, N', 6)
    blocks = frames.blocks if len(set(frames.blocks)) >= 2 else frames.groups
    estimates = [
        pooled(confusion.reshape(-1, 4)).iou,
        float(gain[:, kept].mean()) if kept.any() else float("nan"),
        float(correlation(ends_stats.sum(axis=(0, 1)))) if ends.any() else float("nan"),
    ]
    bounds = [(float("nan"), float("nan"))] * 3
    if resampling is not None:
        bounds[0] = _bounds(confusion, blocks, iou, resampling, low=0.0)
        if kept.any():
            bounds[1] = _bounds(np.stack([gain[:, kept], np.ones_like(gain[:, kept])], -1), _pick(blocks, kept), mean, resampling)
        if ends.any():
            bounds[2] = _bounds(ends_stats, _pick(blocks, ends), correlation, resampling)
    return RealRow(method, estimates[0], *bounds[0], other, estimates[1], *bounds[1], estimates[2], *bounds[2])


def _pick(blocks: list, keep: np.ndarray) -> list:
    return [b for b, k in zip(blocks, keep, strict=True) if k]


def _bounds(per_item: np.ndarray, blocks: list, score, resampling: Resampling, low: float = -1.0) -> tuple[float, float]:
    """The 95 % interval of `score` over the blocks (each its own unit: one recording) and the seeds,
    within the score's range [low, 1] (widened for few blocks, it may reach past it: statistics.bootstrap)."""
    if len(set(blocks)) < 2:
        return float("nan"), float("nan")
    sums = block_sums(per_item, blocks)
    found = score_draws(sums if len(sums) > 1 else sums[0], score, resampling).interval()
    return max(found.low, low), min(found.high, 1.0)


def leave_one_out_labels(frames: RealFrames) -> np.ndarray:
    """(N, H, W) bool: for each frame, the mean of the other frames' labels (its own frame's mirrored
    copy left out too) above 0.5: a baseline that knows the recording's paths but not the image."""
    different = _different(frames.groups)
    labels = frames.labels.reshape(len(frames.labels), -1).astype(np.float64)
    totals = different.astype(np.float64) @ labels  # (N, H*W) sums over the other frames
    return (totals / different.sum(1, keepdims=True) > 0.5).reshape(frames.labels.shape)


def _different(groups: list) -> np.ndarray:
    """(N, N): pairs of images of different frames (a frame and its mirrored copy are one)."""
    codes = {g: i for i, g in enumerate(dict.fromkeys(groups))}
    g = np.array([codes[x] for x in groups])
    return g[:, None] != g[None, :]


def separability(frames: RealFrames, rows: dict[str, RealRow]) -> Separability:
    """The recording's label diversity against how precisely it measures an IoU: the widest 95 %
    interval of an IoU among `rows` (score_real's, with intervals)."""
    matrix = iou_matrix(frames.labels, frames.labels)
    diversity = float(matrix[_different(frames.groups)].mean())
    widths = [r.iou_high - r.iou_low for r in rows.values() if r.iou_low == r.iou_low]
    blocks = len(set(frames.blocks))
    resampled = f"{blocks} blocks" if blocks >= 2 else "single frames: too short for blocks, which understates it"
    return Separability(diversity, 1.0 - diversity, max(widths) if widths else float("nan"), resampled)


def score_real(
    checkpoints: dict[str, Path | list[Path]], frames: RealFrames, prior: np.ndarray, threshold: float, resampling: Resampling | None = None
) -> dict[str, RealRow]:
    """Rows keyed by run (checkpoints: run -> its network, or one per training seed), then
    'mean_path_prior' (prior: (h, w) bool at the training labels' size, stretched to the recording's
    frame) and 'other_labels' (leave_one_out_labels)."""
    from offroad_path.inference.runners import TorchModel

    rows = {}
    for run, found in checkpoints.items():
        paths = found if isinstance(found, list) else [found]
        predicted = np.stack([TorchModel(path).predict_all(frames.images) > threshold for path in paths])
        rows[run] = real_row(method_title(run), predicted, frames, resampling)
        log.info("%s on %s: IoU %.3f, against other frames' labels %.3f", run, frames.name, rows[run].iou, rows[run].non_corresponding_iou)
    h, w = frames.labels.shape[1:]
    stretched = cv2.resize(prior.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    everywhere = np.broadcast_to(stretched, frames.labels.shape)
    rows["mean_path_prior"] = real_row("mean path prior (synthetic training labels)", everywhere, frames, resampling)
    other = leave_one_out_labels(frames)
    rows["other_labels"] = real_row("the other frames' mean label (knows the recording, not the image)", other, frames, resampling)
    return rows
