"""Confidence intervals by block bootstrap: the test set resampled by whole blocks of driving.

Frames of one stretch of road are not independent samples (neighbouring frames see the same
ground), so the unit resampled is the block (20 m of test driving, the split's `block_m`), drawn
with replacement as many times as there are blocks; a score is recomputed from the counts summed
over each resample, and the interval is the percentile interval of those scores (Efron & Tibshirani
1993, ch. 13; Kuensch 1989 for blocks). A comparison of two methods on the same test frames is
**paired**: both are scored on the same resamples and the interval is that of the difference, so
what the two share (the same hard frames) cancels.

Every score here is a ratio of sums of per-item statistics (pooled IoU: tp / (tp + fp + fn); a
mean error: sum of errors / count), so a block is summarised by its sums and a resample by the sum
of its blocks': `block_sums` once, then any number of resamples at little cost.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from offroad_path.evaluation.scores import Score, ratio

RESAMPLES = 1000
LEVEL = 0.95


def mean(s: np.ndarray) -> np.ndarray:
    """The mean of a per-item value, from statistics (..., 2) = (sum of values, count): a mean error
    resampled like a pooled score (the confusion scores themselves are evaluation.scores')."""
    return ratio(s[..., 0], s[..., 1])


@dataclass(frozen=True)
class Interval:
    estimate: float  # the score of the whole test set
    low: float
    high: float

    @property
    def contains_zero(self) -> bool:
        return self.low <= 0.0 <= self.high

    def text(self, digits: int = 3) -> str:
        """ "0.732 [0.701, 0.760]"."""
        return f"{self.estimate:.{digits}f} [{self.low:.{digits}f}, {self.high:.{digits}f}]"

    def difference_text(self, digits: int = 3) -> str:
        """A paired difference as the report states it: the interval, or "no difference measured"
        when it contains 0."""
        shown = f"{self.estimate:+.{digits}f} [{self.low:+.{digits}f}, {self.high:+.{digits}f}]"
        return f"no difference measured ({shown})" if self.contains_zero else shown


def block_sums(per_item: np.ndarray, blocks: Sequence[Hashable]) -> np.ndarray:
    """Per-item statistics (N, k) summed per block (B, k), blocks in order of first appearance."""
    per_item = np.asarray(per_item, np.float64)
    if per_item.ndim == 1:
        per_item = per_item[:, None]
    if len(blocks) != len(per_item):
        raise ValueError(f"{len(per_item)} items but {len(blocks)} block labels")
    order = {b: i for i, b in enumerate(dict.fromkeys(blocks))}
    index = np.fromiter((order[b] for b in blocks), np.intp, len(blocks))
    sums = np.zeros((len(order), per_item.shape[1]))
    np.add.at(sums, index, per_item)
    return sums


@dataclass(frozen=True)
class Resampling:
    """How many resamples, from which seed, and the interval's level."""

    count: int = RESAMPLES
    seed: int = 0
    level: float = LEVEL

    def indices(self, n_blocks: int) -> np.ndarray:
        """(count, n_blocks) block indices drawn with replacement: one resample per row."""
        if n_blocks < 2:
            raise ValueError(f"a block bootstrap needs at least 2 blocks, has {n_blocks}")
        return np.random.default_rng(self.seed).integers(0, n_blocks, (self.count, n_blocks))

    def percentiles(self, values: np.ndarray) -> tuple[float, float]:
        values = values[np.isfinite(values)]
        if not len(values):
            return float("nan"), float("nan")
        tail = (1.0 - self.level) / 2.0
        low, high = np.quantile(values, [tail, 1.0 - tail])
        return float(low), float(high)


def interval(sums: np.ndarray, score: Score, resampling: Resampling = Resampling()) -> Interval:
    """The percentile interval of `score` over block resamples of `sums` (B, k)."""
    drawn = sums[resampling.indices(len(sums))].sum(axis=1)  # (count, k)
    return Interval(float(score(sums.sum(axis=0))), *resampling.percentiles(score(drawn)))


def paired_interval(a: np.ndarray, b: np.ndarray, score: Score, resampling: Resampling = Resampling()) -> Interval:
    """The interval of score(a) - score(b) over the same block resamples of both: `a` and `b` are
    two methods' block sums (B, k) on the same blocks, in the same order."""
    if a.shape != b.shape:
        raise ValueError(f"paired block sums must have one shape, have {a.shape} and {b.shape}")
    index = resampling.indices(len(a))
    difference = score(a[index].sum(axis=1)) - score(b[index].sum(axis=1))
    return Interval(float(score(a.sum(axis=0)) - score(b.sum(axis=0))), *resampling.percentiles(difference))
