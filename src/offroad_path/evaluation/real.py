"""Real-footage rows: every trained network scored on a labelled real recording (the label
stage's VO labels of e.g. the KITTI snippet), beside two numbers that need no perception: the
same predictions against the labels of the recording's other frames (the non-corresponding
baseline) and the mean path of the synthetic training labels. A network that perceives the
path beats both; one that paints its prior scores the same against any frame's label."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from offroad_path.data.labels import read_label_run
from offroad_path.data.loading import read
from offroad_path.evaluation.metrics import counts, non_corresponding, pooled
from offroad_path.evaluation.tables import method_title

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RealRow:
    method: str
    iou: float = field(metadata={"title": "IoU against its own frame's label"})
    non_corresponding_iou: float = field(metadata={"title": "IoU against other frames' labels"})
    perception: float = field(metadata={"title": "difference (perception)"})


@dataclass
class RealFrames:
    """The labelled frames of a label run: RGB images and their path labels (N, H, W) bool."""

    name: str  # the label run's folder name, for the report
    images: list[np.ndarray]
    labels: np.ndarray
    groups: list[tuple[str, int]]  # (sequence, f0) of each frame

    @classmethod
    def read(cls, labels_dir: Path) -> RealFrames:
        images, labels, groups = [], [], []
        for run in read_label_run(labels_dir):
            for path in run.labels():
                f0 = int(path.stem)
                images.append(cv2.cvtColor(read(str(run.sequence.left[f0]), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB))
                labels.append(read(str(path), cv2.IMREAD_GRAYSCALE) > 0)
                groups.append((run.name, f0))
        if len(labels) < 2:
            raise ValueError(f"{labels_dir}: holds {len(labels)} labelled frame(s); real-footage rows need at least 2")
        return cls(labels_dir.name, images, np.stack(labels), groups)


def real_row(method: str, predicted: np.ndarray, frames: RealFrames) -> RealRow:
    """predicted: (N, H, W) bool paths on the frames."""
    own = pooled(counts(predicted.astype(np.float32), frames.labels)).iou
    other = non_corresponding(predicted, frames.labels, frames.groups).iou
    return RealRow(method, own, other, own - other)


def score_real(checkpoints: dict[str, Path], frames: RealFrames, prior: np.ndarray, threshold: float) -> dict[str, RealRow]:
    """Rows keyed by run (checkpoints: run -> its network), then 'mean_path_prior' (prior: (h, w)
    bool at the training labels' size, stretched to the recording's frame)."""
    from offroad_path.inference.runners import TorchModel

    rows = {}
    for run, checkpoint in checkpoints.items():
        model = TorchModel(checkpoint)
        confidence = model.predict_all(frames.images)
        rows[run] = real_row(method_title(run), confidence > threshold, frames)
        log.info("%s on %s: IoU %.3f, against other frames' labels %.3f", run, frames.name, rows[run].iou, rows[run].non_corresponding_iou)
    h, w = frames.labels.shape[1:]
    stretched = cv2.resize(prior.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    everywhere = np.broadcast_to(stretched, frames.labels.shape)
    rows["mean_path_prior"] = real_row("mean path prior (synthetic training labels)", everywhere, frames)
    return rows
