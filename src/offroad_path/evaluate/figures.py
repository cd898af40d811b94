"""Figures like the paper's: rows of input / confidence / ground truth panels (Fig. 8) and
before / after post-processing (Fig. 5), composed with OpenCV."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from offroad_path.data.loading import load_sample
from offroad_path.data.manifest import Sample

CAPTION_PX = 22


def tile(cell: np.ndarray, scale: float) -> np.ndarray:
    """An RGB uint8 image, or a (H, W) map in [0, 1] / bool mask shown in grey, resized by scale."""
    if cell.ndim == 2:
        cell = np.repeat((np.clip(cell.astype(np.float32), 0, 1) * 255).astype(np.uint8)[..., None], 3, axis=2)
    h, w = cell.shape[:2]
    return cv2.resize(cell, (round(w * scale), round(h * scale)), interpolation=cv2.INTER_AREA)


def caption(text: str, width: int) -> np.ndarray:
    bar = np.full((CAPTION_PX, width, 3), 255, np.uint8)
    cv2.putText(bar, text, (4, CAPTION_PX - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    return bar


def panel(rows: list[list[np.ndarray]], captions: list[str], headers: list[str], scale: float) -> np.ndarray:
    """Rows of equally sized cells with a caption over each row and column headers on top: RGB uint8."""
    blocks = []
    for cells, text in zip(rows, captions, strict=True):
        row = np.hstack([tile(c, scale) for c in cells])
        blocks += [caption(text, row.shape[1]), row]
    width = blocks[1].shape[1]
    column = width // len(headers)
    header = np.hstack([caption(h, column) for h in headers])
    header = np.pad(header, ((0, 0), (0, width - header.shape[1]), (0, 0)), constant_values=255)
    return np.vstack([header, *blocks])


def save_png(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"{path}: could not write the figure")


def good_and_bad_cases(cases: list[tuple[str, Sample, np.ndarray, float]], scale: float) -> np.ndarray:
    """Fig. 8: one row per (caption, sample, confidence map, IoU): input, network output, ground truth."""
    rows, captions = [], []
    for text, sample, confidence, iou in cases:
        image, label = load_sample(sample, "path")
        rows.append([image, confidence, label.astype(bool)])
        captions.append(f"{text}: {sample.sequence}/{sample.f0:06d}{' mirrored' if sample.mirrored else ''}, IoU {iou:.2f}")
    return panel(rows, captions, ["input image", "path confidence", "ground truth"], scale)


def before_and_after(cases: list[tuple[Sample, np.ndarray, np.ndarray, float, float]], scale: float) -> np.ndarray:
    """Fig. 5: one row per (sample, raw map, post-processed map, IoU before, IoU after)."""
    rows, captions = [], []
    for sample, raw, post, before, after in cases:
        image, label = load_sample(sample, "path")
        rows.append([image, raw, post, label.astype(bool)])
        captions.append(f"{sample.sequence}/{sample.f0:06d}{' mirrored' if sample.mirrored else ''}: IoU {before:.2f} -> {after:.2f}")
    return panel(rows, captions, ["input image", "confidence", "post-processed", "ground truth"], scale)
