"""The results table in the layout of the paper's Table 5.1, from a test set and runs' confidence maps."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from offroad_path.data.dataset import read
from offroad_path.data.manifest import Sample
from offroad_path.evaluation.metrics import Scores, counts, per_image_iou, pooled


@dataclass(frozen=True)
class ResultRow:
    network: str
    pretraining: str
    postprocessing: str
    accuracy: float
    recall: float
    precision: float
    iou: float
    mean_image_iou: float  # per-image IoU averaged over images: not the paper's pooled IoU


def split_run_name(run: str) -> tuple[str, str]:
    """'unet-segmentation' -> ('unet', 'segmentation')."""
    model, _, pretraining = run.partition("-")
    if not pretraining:
        raise ValueError(f"run name {run!r} is not <model>-<pretraining>")
    return model, pretraining


def network_name(model: str) -> str:
    """The registered network's title ('unet' -> 'U-Net')."""
    from offroad_path.models import MODELS

    return (MODELS[model].title if model in MODELS else "") or model


def load_labels(samples: list[Sample]) -> np.ndarray:
    """Path labels (N, H, W) bool, mirrored where a sample says so."""
    labels = [read(s.label, cv2.IMREAD_GRAYSCALE) > 0 for s in samples]
    return np.stack([m[:, ::-1] if s.mirrored else m for s, m in zip(samples, labels, strict=True)])


def load_maps(paths: list[str]) -> np.ndarray:
    """Confidence maps (N, H, W) float32 from .npy files."""
    maps = []
    for path in paths:
        try:
            maps.append(np.load(path).astype(np.float32))
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not a readable confidence map ({e})") from e
    return np.stack(maps)


def score(
    network: str, pretraining: str, postprocessing: str, maps: np.ndarray, labels: np.ndarray, threshold: float
) -> tuple[ResultRow, np.ndarray]:
    """One table row, and the per-image IoU (N,) behind its mean."""
    per_image = counts(maps, labels, threshold)
    ious = per_image_iou(per_image)
    s = pooled(per_image)
    return ResultRow(network, pretraining, postprocessing, s.accuracy, s.recall, s.precision, s.iou, float(ious.mean())), ious


def fmt(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{x:.3f}"


def markdown_table(rows: list[ResultRow]) -> str:
    lines = ["| network | pretraining | post-processing | accuracy | recall | precision | IoU | per-image mean IoU |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    for r in rows:
        lines.append(f"| {r.network} | {r.pretraining} | {r.postprocessing} | {fmt(r.accuracy)} | {fmt(r.recall)} | "
                     f"{fmt(r.precision)} | {fmt(r.iou)} | {fmt(r.mean_image_iou)} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def baseline_name(key: str) -> str:
    """'non_corresponding.unet-none' -> 'U-Net (none) against non-corresponding ground truth'."""
    if key.startswith("non_corresponding."):
        model, pretraining = split_run_name(key.removeprefix("non_corresponding."))
        return f"{network_name(model)} ({pretraining}) against non-corresponding ground truth"
    return {"mean_path_prior": "mean path prior (average training label)"}.get(key, key)


def baseline_table(baselines: dict[str, Scores]) -> str:
    lines = ["| baseline | accuracy | recall | precision | IoU |", "| --- | --- | --- | --- | --- |"]
    for key, s in baselines.items():
        lines.append(f"| {baseline_name(key)} | {fmt(s.accuracy)} | {fmt(s.recall)} | {fmt(s.precision)} | {fmt(s.iou)} |")
    return "\n".join(lines) + "\n"


def csv_text(rows: list[ResultRow]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=list(asdict(rows[0])), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(r).items()} for r in rows)
    return out.getvalue()
