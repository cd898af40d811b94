"""The paper's four scores (Holder & Breckon 2018, section V), defined once for every place that
scores a path: the results table, the baselines, the block-bootstrap intervals, the conditions,
the real-footage rows and training's logged metrics.

A score is a function of confusion counts (..., 4) in the order tp, fp, tn, fn, vectorised over
the leading axes (a bootstrap's resamples, a matrix of image pairs), for NumPy arrays and torch
tensors alike; a score whose denominator is 0 is nan. Adding a score is this file alone: its
function, its name in SCORES, and a title in TITLES when its name is not its column title. Every
table, interval, metrics file and training log takes its scores from SCORES
(tests/stage/test_extending.py adds one and runs evaluate with it).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

TP, FP, TN, FN = range(4)  # the columns of a count array (evaluate.pixel_scores.counts)

Array = TypeVar("Array", np.ndarray, "torch.Tensor")


def ratio(a: Array, b: Array) -> Array:
    """a / b, nan where b is 0. Integer torch counts divide in float32, as torchmetrics does."""
    torch = sys.modules.get("torch")  # a tensor means torch is imported; the tables need not import it (a stage's --help)
    if torch is not None and isinstance(a, torch.Tensor):
        return torch.where(b > 0, a / torch.where(b > 0, b, 1), torch.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(b > 0, a / np.where(b > 0, b, 1), np.nan)


def accuracy(c: Array) -> Array:
    return ratio(c[..., TP] + c[..., TN], c.sum(-1))


def recall(c: Array) -> Array:
    return ratio(c[..., TP], c[..., TP] + c[..., FN])


def precision(c: Array) -> Array:
    return ratio(c[..., TP], c[..., TP] + c[..., FP])


def iou(c: Array) -> Array:
    return ratio(c[..., TP], c[..., TP] + c[..., FP] + c[..., FN])


def iou_per_image(c: Array) -> Array:
    """IoU of single images: one with no path in either prediction or truth scores 1 (not nan),
    so that a per-image mean counts a correctly empty image as right."""
    found = iou(c)
    found[(c[..., TP] + c[..., FP] + c[..., FN]) == 0] = 1.0
    return found


Score = Callable[[np.ndarray], np.ndarray]
# In the order training has always logged them (metrics.json keys).
SCORES: dict[str, Score] = {"accuracy": accuracy, "precision": precision, "recall": recall, "iou": iou}


TITLES: dict[str, str] = {"iou": "IoU"}  # a score's column title where it is not its name


class Record(dict):
    """A row of named values, read as r["iou"] or r.iou (tables and scores whose columns come from registries)."""

    def __getattr__(self, name: str):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None


class Scores(Record):
    """Every registered score (SCORES) of one set of pooled counts, by name, in SCORES' order."""

    @classmethod
    def of(cls, pooled_counts: np.ndarray) -> Scores:
        """From counts (4,) summed over a test set (the paper pools before scoring)."""
        c = np.asarray(pooled_counts)
        return cls({name: float(score(c)) for name, score in SCORES.items()})

    @classmethod
    def undefined(cls) -> Scores:
        """Every score nan: a set with nothing to score."""
        return cls(dict.fromkeys(SCORES, float("nan")))
