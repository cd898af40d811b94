"""Confidence intervals by a hierarchical bootstrap: test worlds, then blocks of driving within them,
then training seeds, each drawn with replacement.

What varies between two runs of this pipeline is which worlds were rendered for testing (each with
its own sun, palette and vegetation), which stretches of driving in them were tested, and which
seed trained a network. Blocks of one world are not independent samples (they share its look, and a
20 m label reaches into the next block), so resampling blocks alone counts the worlds' variation
too little; and a seed's network is one draw of the training's randomness. So a resample draws as
many worlds as the test set has, with replacement; within each drawn world as many of its blocks as
it has, with replacement; and as many training seeds as there are, with replacement (Davison &
Hinkley 1997, section 3.8, for the two-stage draw; Kuensch 1989 for blocks). A score is recomputed
from the counts summed over the drawn blocks and seeds, and the interval is the percentile interval
of those scores (Efron & Tibshirani 1993, ch. 13), widened for the few worlds it rests on
(`small_sample_factor`). A comparison of two methods is **paired**: both
are scored on the same draw of worlds, blocks and seed indices, and the interval is that of the
difference, so what the two share (the same hard worlds and frames) cancels. A method without seeds
(a prior, a baseline) is scored on the same worlds and blocks.

Every score here is a ratio of sums of per-item statistics (pooled IoU: tp / (tp + fp + fn); a
mean error: sum of errors / count), so a block is summarised by its sums per seed and a resample
by a weighted sum of them: `block_sums` once, the draw's weights once, then any score at little cost.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from offroad_path.statistics.scores import Score, ratio

RESAMPLES = 1000
LEVEL = 0.95


def two_level_factor(world_var: float, seed_var: float, worlds: int, seeds: int, level: float) -> float:
    """The widening of an interval that resamples `worlds` worlds and `seeds` seeds, each level a few
    units: each level's bootstrap variance (world_var with the seeds held, seed_var with the worlds
    held) scaled by n / (n - 1), the bootstrap's small-sample bias at that level, and Student's t with
    the Welch-Satterthwaite degrees of freedom of the two (Satterthwaite 1946) over the normal
    quantile. A comparison whose spread is the seeds' (two seeds: one degree of freedom) gets the
    wide interval two seeds can give; one whose spread is the worlds' gets small_sample_factor."""
    from scipy.stats import norm, t

    parts = [(v * n / (n - 1), n - 1) for v, n in ((world_var, worlds), (seed_var, seeds)) if n >= 2 and v > 0]
    if not parts:
        return small_sample_factor(worlds, level)
    corrected = sum(v for v, _ in parts)
    df = corrected**2 / sum(v**2 / d for v, d in parts)
    tail = 1.0 - (1.0 - level) / 2.0
    return float(t.ppf(tail, df) / norm.ppf(tail) * math.sqrt(corrected / (world_var + seed_var)))


def small_sample_factor(worlds: int, level: float) -> float:
    """How much wider than the percentile interval an interval over `worlds` resampled worlds is drawn:
    Student's t quantile with worlds - 1 degrees of freedom over the normal one, the small-sample
    correction of an interval whose spread is estimated from few independent units (Davison & Hinkley
    1997, section 5.2), times sqrt(n / (n - 1)), the bootstrap's own bias: resampling n worlds gives
    the spread of their mean with divisor n, not n - 1 (ibid., section 3.2). With 7 worlds at 95 %:
    1.35; it tends to 1 as worlds grow. Without it the interval under-covers at the committed number
    of worlds (benchmarks/bootstrap_coverage.py). A single world gets 1: nothing to widen by (the
    reports say such an interval rests on one world)."""
    from scipy.stats import norm, t

    if worlds < 2:
        return 1.0
    tail = 1.0 - (1.0 - level) / 2.0
    return float(t.ppf(tail, worlds - 1) / norm.ppf(tail) * math.sqrt(worlds / (worlds - 1)))


def mean(s: np.ndarray) -> np.ndarray:
    """The mean of a per-item value, from statistics (..., 2) = (sum of values, count): a mean error
    resampled like a pooled score (the confusion scores themselves are statistics.scores')."""
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
    """Per-item statistics (N, k), or per seed (S, N, k), summed per block: (B, k) or (S, B, k),
    blocks in order of first appearance."""
    per_item = np.asarray(per_item, np.float64)
    if per_item.ndim == 1:
        per_item = per_item[:, None]
    if len(blocks) != per_item.shape[-2]:
        raise ValueError(f"{per_item.shape[-2]} items but {len(blocks)} block labels")
    order = {b: i for i, b in enumerate(dict.fromkeys(blocks))}
    index = np.fromiter((order[b] for b in blocks), np.intp, len(blocks))
    sums = np.zeros((*per_item.shape[:-2], len(order), per_item.shape[-1]))
    np.add.at(sums, (..., index, slice(None)), per_item)
    return sums


def worlds_of(blocks: Sequence[Hashable]) -> list[Hashable]:
    """The world of each distinct block (in block_sums' order): a block label (sequence, index)'s
    sequence, since every test world is one rendered sequence; any other label is its own world."""
    return [b[0] if isinstance(b, tuple) else b for b in dict.fromkeys(blocks)]


@dataclass(frozen=True)
class Resampling:
    """How many resamples, from which seed, and the interval's level."""

    count: int = RESAMPLES
    seed: int = 0
    level: float = LEVEL

    def weights(self, worlds: Sequence[Hashable], seeds: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The hierarchical draw: (count, B) how often each block is drawn (worlds, then blocks within
        each drawn world) and (count, S) how often each seed is; `worlds`: each block's world."""
        if len(worlds) < 2:
            raise ValueError(f"a block bootstrap needs at least 2 blocks, has {len(worlds)}")
        rng = np.random.default_rng(self.seed)
        names = list(dict.fromkeys(worlds))
        members = [np.flatnonzero([w == name for w in worlds]) for name in names]
        times = np.zeros((self.count, len(names)), np.intp)  # how often each world is drawn
        np.add.at(times, (np.arange(self.count)[:, None], rng.integers(0, len(names), (self.count, len(names)))), 1)
        blocks = np.zeros((self.count, len(worlds)))
        for w, own in enumerate(members):
            draws = times[:, w] * len(own)  # each drawn copy of the world draws as many blocks as it has
            rows = np.repeat(np.arange(self.count), draws)
            np.add.at(blocks, (rows, own[rng.integers(0, len(own), draws.sum())]), 1.0)
        seed_weights = np.zeros((self.count, seeds))
        np.add.at(seed_weights, (np.arange(self.count)[:, None], rng.integers(0, seeds, (self.count, seeds))), 1.0)
        return blocks, seed_weights

    def percentiles(self, values: np.ndarray, level: float | None = None) -> tuple[float, float]:
        values = values[np.isfinite(values)]
        if not len(values):
            return float("nan"), float("nan")
        tail = (1.0 - (self.level if level is None else level)) / 2.0
        low, high = np.quantile(values, [tail, 1.0 - tail])
        return float(low), float(high)


def drawn(sums: np.ndarray, blocks: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(count, k) statistics of each resample: block sums (B, k) or per seed (S, B, k) weighted by
    the draw's block weights (count, B) and, with seeds, seed weights (count, S)."""
    if sums.ndim == 2:
        return blocks @ sums
    return np.einsum("rs,rb,sbk->rk", seeds, blocks, sums)


def whole(sums: np.ndarray) -> np.ndarray:
    """(k,) statistics of the whole test set: over blocks and seeds."""
    return sums.reshape(-1, sums.shape[-1]).sum(axis=0)


@dataclass(frozen=True)
class Draws:
    """A score's (or a paired difference's) estimate on the whole test set and its value on every
    resample: intervals at any level and a two-sided bootstrap p-value (for Holm's correction)."""

    estimate: float
    values: np.ndarray  # (count,)
    resampling: Resampling
    worlds: int = 0  # the worlds the top level resamples (small_sample_factor); 0: the plain percentile interval
    # With several training seeds: the bootstrap variance of the worlds' level (seeds held) and of the
    # seeds' (worlds and blocks held), and the seeds' number, for two_level_factor.
    levels: tuple[float, float, int] | None = None

    def interval(self, level: float | None = None) -> Interval:
        """The percentile interval at `level` (the resampling's by default), each side's distance from
        the estimate stretched by small_sample_factor, or with seeds two_level_factor."""
        level = self.resampling.level if level is None else level
        low, high = self.resampling.percentiles(self.values, level)
        if self.levels is not None and self.worlds >= 2:
            widen = two_level_factor(self.levels[0], self.levels[1], self.worlds, self.levels[2], level)
        else:
            widen = small_sample_factor(self.worlds, level)
        return Interval(self.estimate, self.estimate - widen * (self.estimate - low), self.estimate + widen * (high - self.estimate))

    def p_value(self) -> float:
        """The smallest 1 - level at which the interval excludes 0 (at most 1; at least 1 / resamples,
        the least the resamples can show: 0 of them on one side is not p = 0). Without the widening,
        twice the smaller share of resamples on either side of 0."""
        values = self.values[np.isfinite(self.values)]
        if not len(values):
            return float("nan")
        least = 1.0 / len(values)
        if self.worlds < 2:
            share = min(np.mean(values <= 0.0), np.mean(values >= 0.0))
            return float(min(1.0, max(2.0 * share, least)))

        def excludes(alpha: float) -> bool:  # the interval at 1 - alpha: wider as alpha falls
            return not self.interval(1.0 - alpha).contains_zero

        if excludes(least):
            return least
        if not excludes(1.0 - 1e-9):
            return 1.0
        low, high = least, 1.0 - 1e-9  # excludes(high), not excludes(low)
        for _ in range(40):
            middle = (low + high) / 2.0
            low, high = (low, middle) if excludes(middle) else (middle, high)
        return float(high)


def _level_variances(score_of, blocks: np.ndarray, seed_weights: np.ndarray) -> tuple[float, float, int] | None:
    """(variance with the seeds held, variance with the worlds and blocks held, seeds) of a score over
    the same draw; None with one seed. score_of(blocks, seed weights) -> (count,) values."""
    count, seeds = seed_weights.shape
    if seeds < 2:
        return None

    def variance(values: np.ndarray) -> float:
        finite = values[np.isfinite(values)]
        return float(finite.var()) if len(finite) > 1 else 0.0

    held_seeds, held_blocks = np.ones((count, seeds)), np.ones_like(blocks)
    return variance(score_of(blocks, held_seeds)), variance(score_of(held_blocks, seed_weights)), seeds


def score_draws(sums: np.ndarray, score: Score, resampling: Resampling, worlds: Sequence[Hashable] | None = None) -> Draws:
    """`score` over hierarchical resamples of `sums` ((B, k) or (S, B, k)); worlds: each block's
    (None: every block its own world, a flat block bootstrap)."""
    seeds = sums.shape[0] if sums.ndim == 3 else 1
    worlds = list(range(sums.shape[-2])) if worlds is None else worlds
    blocks, seed_weights = resampling.weights(worlds, seeds)

    def score_of(b: np.ndarray, s: np.ndarray) -> np.ndarray:
        return score(drawn(sums, b, s))

    levels = _level_variances(score_of, blocks, seed_weights)
    return Draws(float(score(whole(sums))), score_of(blocks, seed_weights), resampling, len(set(worlds)), levels)


def paired_draws(a: np.ndarray, b: np.ndarray, score: Score, resampling: Resampling, worlds: Sequence[Hashable] | None = None) -> Draws:
    """score(a) - score(b) on the same resamples: `a` and `b` are two methods' block sums on the same
    blocks in the same order, (B, k) or per seed (S, B, k); seed index s of both is drawn together."""
    if a.shape[-2:] != b.shape[-2:]:
        raise ValueError(f"paired block sums must have one shape, have {a.shape} and {b.shape}")
    seeds = max(a.shape[0] if a.ndim == 3 else 1, b.shape[0] if b.ndim == 3 else 1)
    for side in (a, b):
        if side.ndim == 3 and side.shape[0] != seeds:
            raise ValueError(f"paired runs must have one number of seeds, have {a.shape[0]} and {b.shape[0]}")
    worlds = list(range(a.shape[-2])) if worlds is None else worlds
    blocks, seed_weights = resampling.weights(worlds, seeds)

    def difference(w: np.ndarray, s: np.ndarray) -> np.ndarray:
        return score(drawn(a, w, s)) - score(drawn(b, w, s))

    levels = _level_variances(difference, blocks, seed_weights)
    return Draws(float(score(whole(a)) - score(whole(b))), difference(blocks, seed_weights), resampling, len(set(worlds)), levels)


def interval(sums: np.ndarray, score: Score, resampling: Resampling = Resampling(), worlds: Sequence[Hashable] | None = None) -> Interval:
    """The percentile interval of `score` over resamples of `sums` (score_draws)."""
    return score_draws(sums, score, resampling, worlds).interval()


def paired_interval(
    a: np.ndarray, b: np.ndarray, score: Score, resampling: Resampling = Resampling(), worlds: Sequence[Hashable] | None = None
) -> Interval:
    """The interval of score(a) - score(b) over the same resamples of both (paired_draws)."""
    return paired_draws(a, b, score, resampling, worlds).interval()
