"""Pixel counts and the paper's scores (Holder & Breckon 2018, section V).

The paper pools tp, fp, tn, fn over the whole test set before computing accuracy, recall,
precision and IoU; a per-image mean IoU is reported beside it, labelled as such, because the two
differ when images have paths of very different sizes.
"""

from __future__ import annotations

import numpy as np
import torch
from torchmetrics.functional.classification.precision_recall_curve import _adjust_threshold_arg, _binary_precision_recall_curve_compute

from offroad_path.statistics.scores import SCORES, Scores, iou_per_image


def counts(confidence: np.ndarray, target: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Per-image pixel counts (N, 4) int64 columns tp, fp, tn, fn; path where confidence > threshold.

    confidence: (N, H, W) float in [0, 1]; target: (N, H, W) bool or 0/1.
    Counted with NumPy: torchmetrics' binary_stat_scores gives the same integers
    (tests/evaluate/test_metrics.py), but through int64 copies of every pixel; with it, the committed
    run's evaluate stage took 213 s instead of 167 s.
    """
    if confidence.shape != target.shape:
        raise ValueError(f"predictions {confidence.shape} and ground truth {target.shape} differ in shape")
    n = len(confidence)
    if n == 0 or confidence.size == 0:
        return np.zeros((n, 4), np.int64)
    predicted = (np.asarray(confidence, np.float32) > threshold).reshape(n, -1)  # the paper's rule: C > threshold, in float32
    truth = binary_truth(target).numpy().astype(bool, copy=False).reshape(n, -1)
    tp = np.count_nonzero(predicted & truth, axis=1)
    fp = np.count_nonzero(predicted, axis=1) - tp
    fn = np.count_nonzero(truth, axis=1) - tp
    tn = predicted.shape[1] - tp - fp - fn
    return np.stack([tp, fp, tn, fn], axis=1).astype(np.int64)


def binary_truth(target: np.ndarray) -> torch.Tensor:
    """Ground truth as a tensor, checked to be bool or 0/1 (min and max: far cheaper than torch.unique)."""
    truth = torch.from_numpy(np.ascontiguousarray(target))
    if truth.dtype != torch.bool and truth.numel() and (truth.min() < 0 or truth.max() > 1):
        raise ValueError(f"ground truth must be bool or 0/1; it holds values from {truth.min()} to {truth.max()}")
    return truth


def pooled(per_image: np.ndarray) -> Scores:
    """Scores of the counts summed over all images (the paper's convention)."""
    return Scores.of(per_image.sum(axis=0))


def per_image_iou(per_image: np.ndarray) -> np.ndarray:
    """IoU of each image (N,); an image with no path in either prediction or truth scores 1."""
    return iou_per_image(per_image.astype(np.float64))


def precision_recall_curve(confidence: np.ndarray, target: np.ndarray, thresholds: int = 101, batch: int = 16) -> dict[str, np.ndarray]:
    """Pooled precision and recall at `thresholds` evenly spaced thresholds in [0, 1] (binned, so
    memory does not grow with the test set). Returns arrays threshold, precision, recall.

    torchmetrics' BinaryPrecisionRecallCurve, exactly (a test compares them), with its counting
    done in one pass: each pixel's threshold index found by binary search, then counted, instead of
    one pass over every pixel per threshold (17 s of the evaluate stage for six runs at 101 thresholds).
    """
    grid = _adjust_threshold_arg(thresholds)  # float32, as torchmetrics compares
    confmat = torch.zeros(len(grid), 2, 2, dtype=torch.int64)  # [threshold, truth, predicted]
    for start in range(0, len(confidence), batch):
        c = torch.from_numpy(np.ascontiguousarray(confidence[start : start + batch], np.float32)).flatten()
        confmat += threshold_confusion(c, binary_truth(target[start : start + batch]).flatten(), grid)
    precision, recall, threshold = _binary_precision_recall_curve_compute(confmat, grid)
    # torchmetrics appends the (precision 1, recall 0) end point without a threshold, and gives nan
    # precision where nothing is predicted: 1 by the same convention (no false positives).
    return {"threshold": threshold.numpy(), "precision": np.nan_to_num(precision[:-1].numpy(), nan=1.0), "recall": recall[:-1].numpy()}


def threshold_confusion(confidence: torch.Tensor, truth: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """Confusion matrices (T, 2, 2) [truth, predicted] at each threshold of the increasing `grid`,
    predicted where confidence >= threshold; confidence (M,) in [0, 1], truth (M,) bool or 0/1."""
    if confidence.numel() and not (confidence.min() >= 0 and confidence.max() <= 1):
        raise ValueError(f"confidence must lie in [0, 1]; it holds values from {confidence.min()} to {confidence.max()}")
    n = len(grid)
    # Pixel j is predicted at threshold i exactly when grid[i] <= c_j, i.e. when i < above_j.
    above = torch.searchsorted(grid, confidence, right=True)  # (M,) in 0..n
    histogram = torch.bincount(above + (n + 1) * truth.long(), minlength=2 * (n + 1)).reshape(2, n + 1)
    predicted = histogram.flip(1).cumsum(1).flip(1)[:, 1:]  # (2, T): [truth, threshold] pixels with above > i
    totals = histogram.sum(1, keepdim=True)  # (2, 1): negatives, positives
    confmat = torch.empty(n, 2, 2, dtype=torch.int64)
    confmat[:, :, 1] = predicted.T
    confmat[:, :, 0] = (totals - predicted).T
    return confmat


def non_corresponding(predicted: np.ndarray, target: np.ndarray, groups: list) -> Scores:
    """The paper's baseline: every prediction scored against every ground truth of a different
    input image, averaged over those pairs. Images of one group (a frame and its mirrored copy)
    are not scored against each other.

    predicted, target: (N, H, W) bool; groups: N hashable ids.
    """
    n = len(predicted)
    P = torch.from_numpy(np.ascontiguousarray(predicted)).flatten(1).double()  # (N, HW)
    T = torch.from_numpy(np.ascontiguousarray(target)).flatten(1).double()  # (N, HW)
    tp = P @ T.T  # (N, N): prediction i against truth j
    fp = P.sum(1, keepdim=True) - tp
    fn = T.sum(1)[None, :] - tp
    tn = P.shape[1] - tp - fp - fn
    pair_counts = torch.stack([tp, fp, tn, fn], dim=-1)  # (N, N, 4)
    codes = {g: i for i, g in enumerate(dict.fromkeys(groups))}
    g = torch.tensor([codes[x] for x in groups])
    pairs = g[:, None] != g[None, :]  # (N, N)
    if n < 2 or not pairs.any():
        raise ValueError("the non-corresponding baseline needs images of at least two different frames")
    # Each pair is one image scored against one truth: IoU by the per-image convention, and the
    # mean over pairs skips a pair whose score is undefined (nan: no path in it).
    per_pair = {name: iou_per_image(pair_counts) if name == "iou" else score(pair_counts) for name, score in SCORES.items()}
    return Scores({name: float(torch.nanmean(value[pairs])) for name, value in per_pair.items()})


def mean_path(labels: np.ndarray) -> np.ndarray:
    """The 'mean path' prior: the per-pixel average of training labels (N, H, W) -> (H, W) in [0, 1]."""
    return labels.mean(axis=0, dtype=np.float64).astype(np.float32)
