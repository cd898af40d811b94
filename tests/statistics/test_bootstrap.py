"""The block bootstrap against cases whose answer is known: two blocks computed by hand, a method
against itself, and the coverage of its intervals when the truth is known."""

from __future__ import annotations

import numpy as np
import pytest
from bootstrap_coverage import test_set as simulated_test_set

from offroad_path.statistics.bootstrap import (
    Draws,
    Interval,
    Resampling,
    block_sums,
    interval,
    mean,
    paired_draws,
    paired_interval,
    score_draws,
    small_sample_factor,
    two_level_factor,
)
from offroad_path.statistics.scores import iou

A = [60, 20, 900, 20]  # tp fp tn fn of one block: IoU 60 / 100 = 0.6
B = [90, 5, 900, 5]  # IoU 90 / 100 = 0.9


def test_two_blocks_by_hand():
    # Two images per block; the block sums are A and B.
    per_image = np.array([[30, 10, 450, 10], [30, 10, 450, 10], [45, 2, 450, 3], [45, 3, 450, 2]])
    sums = block_sums(per_image, ["a", "a", "b", "b"])
    np.testing.assert_array_equal(sums, [A, B])
    # A resample of two blocks is AA (IoU 0.6), AB or BA (150 / 200 = 0.75) or BB (0.9); with 1000
    # draws of seed 0, AA and BB each hold far more than the 2.5 % in each tail.
    drawn, _ = Resampling(1000, seed=0).weights([0, 1])  # each block its own world: a flat draw
    np.testing.assert_array_equal(drawn.sum(axis=1), 2)
    aa, bb = int((drawn[:, 0] == 2).sum()), int((drawn[:, 1] == 2).sum())
    assert aa > 25 and bb > 25
    percentile = score_draws(sums, iou, Resampling(1000, seed=0))
    assert Draws(percentile.estimate, percentile.values, percentile.resampling).interval() == Interval(0.75, 0.6, 0.9)
    # two worlds: each side stretched by Student's t with 1 degree of freedom over the normal quantile,
    # 12.706 / 1.960 at 95 %, and by the bootstrap's small-sample bias, sqrt(2 / 1)
    widened = interval(sums, iou, Resampling(1000, seed=0))
    stretch = 12.7062 / 1.95996 * 2**0.5
    assert widened.estimate == 0.75 and widened.low == pytest.approx(0.75 - 0.15 * stretch, abs=1e-4)
    assert widened.high == pytest.approx(0.75 + 0.15 * stretch, abs=1e-4)


def test_the_small_sample_widening_and_the_p_value_agree():
    assert small_sample_factor(7, 0.95) == pytest.approx(2.4469 / 1.95996 * (7 / 6) ** 0.5, abs=1e-4)
    assert small_sample_factor(1, 0.95) == 1.0 and small_sample_factor(10_000, 0.95) == pytest.approx(1.0, abs=1e-3)
    values = np.random.default_rng(4).normal(0.02, 0.01, 4000)
    found = Draws(0.02, values, Resampling(4000), worlds=7)
    p = found.p_value()
    # the p-value is the level at which the widened interval just reaches 0; wider than the percentile one's
    assert not found.interval(1 - p * 1.02).contains_zero and found.interval(1 - p * 0.98).contains_zero
    assert p > Draws(0.02, values, Resampling(4000)).p_value()


def test_a_method_against_itself_differs_by_exactly_nothing():
    rng = np.random.default_rng(3)
    sums = rng.integers(0, 1000, (30, 4)).astype(float)
    assert paired_interval(sums, sums, iou) == Interval(0.0, 0.0, 0.0)
    assert paired_interval(sums, sums, iou).difference_text() == "no difference measured (+0.000 [+0.000, +0.000])"


def test_a_paired_interval_sees_a_difference_that_unpaired_intervals_hide():
    # Blocks that differ a lot in difficulty; method b is method a with 5 more false positives in each.
    rng = np.random.default_rng(4)
    tp = rng.integers(20, 200, 30).astype(float)
    a = np.stack([tp, 200 - tp, np.full(30, 5000.0), 200 - tp], axis=1)
    b = a + np.array([0, 5, -5, 0])
    difference = paired_interval(a, b, iou)
    assert difference.low > 0 and "no difference" not in difference.difference_text()
    ia, ib = interval(a, iou), interval(b, iou)
    assert ia.low < ib.high  # separately, their intervals overlap


def test_the_95_percent_interval_covers_the_truth_95_percent_of_the_time():
    """200 test sets of 40 blocks, each block's rates drawn around known means (blocks differ more
    than their pixels' noise, as stretches of driving do): the pooled IoU's interval holds the
    population's IoU in 92-98 % of them (93.5 % with these seeds)."""
    mean_tp, mean_fp, mean_fn = 0.6, 0.15, 0.15  # per pixel of a block, expected
    truth = mean_tp / (mean_tp + mean_fp + mean_fn)
    covered = 0
    for trial in range(200):
        rng = np.random.default_rng(1000 + trial)
        size = rng.uniform(500, 1500, 40)
        rates = np.stack([rng.uniform(0.3, 0.9, 40), rng.uniform(0.05, 0.25, 40), rng.uniform(0.05, 0.25, 40)], axis=1)
        tp, fp, fn = (size[:, None] * rates).T
        sums = np.stack([tp, fp, np.zeros(40), fn], axis=1)
        found = interval(sums, iou, Resampling(1000, seed=trial))
        covered += found.low <= truth <= found.high
    assert 0.92 <= covered / 200 <= 0.98, covered


def test_a_mean_error_per_frame_by_blocks():
    errors = np.array([0.1, 0.3, 0.2, 0.4, 0.0, 0.2])
    sums = block_sums(np.stack([errors, np.ones(6)], axis=1), [0, 0, 1, 1, 2, 2])
    np.testing.assert_allclose(sums, [[0.4, 2], [0.6, 2], [0.2, 2]])
    # Three blocks of means 0.2, 0.3 and 0.1: a resample of one block thrice (1 in 27, more than
    # the 2.5 % tails) sets each end.
    draws = score_draws(sums, mean, Resampling(1000, seed=1))
    found = Draws(draws.estimate, draws.values, draws.resampling).interval()  # the percentile interval
    assert (found.estimate, found.low, found.high) == pytest.approx((0.2, 0.1, 0.3))
    # three blocks, each its own world: stretched by Student's t with 2 degrees of freedom, 4.303 / 1.960,
    # and the bootstrap's bias, sqrt(3 / 2)
    widened = interval(sums, mean, Resampling(1000, seed=1))
    stretch = 4.3027 / 1.95996 * 1.5**0.5
    assert (widened.low, widened.high) == pytest.approx((0.2 - 0.1 * stretch, 0.2 + 0.1 * stretch), abs=1e-4)


def test_too_few_blocks_or_mismatched_labels_are_refused():
    with pytest.raises(ValueError, match="at least 2 blocks"):
        interval(np.array([A], float), iou)
    with pytest.raises(ValueError, match="3 items but 2 block labels"):
        block_sums(np.zeros((3, 4)), ["a", "b"])


def test_the_hierarchical_interval_covers_the_truth_at_the_committed_design():
    """300 test sets of the committed run's design, 7 worlds and 2 training seeds, whose worlds and
    seeds shift every block of theirs (world sd 0.08, block 0.03, seed 0.03 in the path rate): the
    percentile interval of the hierarchical bootstrap alone under-covers the population's IoU (about
    90 %; benchmarks/bootstrap_coverage.py); widened by Student's t for 7 worlds it holds it in at
    least 93 % (about 95 %); resampling blocks alone, as if they were independent, in far fewer."""
    truth = 0.6 / (0.6 + 0.15 + 0.15)
    widened = percentile = flat = 0
    for trial in range(300):
        sums, worlds = simulated_test_set(np.random.default_rng(2000 + trial), (0.08, 0.03, 0.03), worlds=7, seeds=2)
        draws = score_draws(sums, iou, Resampling(1000, seed=trial), worlds)
        found, plain = draws.interval(), Draws(draws.estimate, draws.values, draws.resampling).interval()
        widened += found.low <= truth <= found.high
        percentile += plain.low <= truth <= plain.high
        blocks_only = interval(sums.sum(axis=0), iou, Resampling(1000, seed=trial))
        flat += blocks_only.low <= truth <= blocks_only.high
    assert widened / 300 >= 0.93 and percentile / 300 < 0.93, (widened, percentile)
    assert flat / 300 < 0.85, flat


def test_the_hierarchical_draw_resamples_worlds_then_their_blocks_then_seeds():
    worlds = ["w0", "w0", "w0", "w1"]  # world w0 has three blocks, w1 one
    blocks, seeds = Resampling(2000, seed=5).weights(worlds, seeds=3)
    assert blocks.shape == (2000, 4) and seeds.shape == (2000, 3)
    np.testing.assert_array_equal(seeds.sum(axis=1), 3)  # three seeds drawn each time
    # Two worlds drawn: w0 twice (6 blocks), w0 and w1 (4) or w1 twice (2); w0's blocks come in threes.
    assert set(blocks.sum(axis=1)) == {2.0, 4.0, 6.0}
    np.testing.assert_array_equal(blocks[:, :3].sum(axis=1) % 3, 0)
    assert (blocks[:, 3] % 1 == 0).all() and 0.2 < np.mean(blocks[:, 3] == 0) < 0.3  # w1 left out in 1 of 4


def test_a_paired_difference_pairs_seed_by_seed_and_a_seedless_method_on_the_same_blocks():
    rng = np.random.default_rng(6)
    a = rng.integers(50, 500, (3, 10, 4)).astype(float)
    worlds = [k // 2 for k in range(10)]
    same = paired_draws(a, a, iou, Resampling(500, seed=1), worlds)
    assert same.estimate == 0.0 and np.all(same.values == 0.0) and same.p_value() == 1.0
    # A seedless method (a prior) on the same blocks: nothing between it and three identical seeds of it.
    prior = a[0]
    against = paired_draws(np.stack([prior] * 3), prior, iou, Resampling(500, seed=1), worlds)
    np.testing.assert_allclose(against.values, 0.0, atol=1e-12)
    # Seeds that differ add their spread: the seeded side's resamples move, the prior's counts do not.
    assert np.std(paired_draws(a, prior, iou, Resampling(500, seed=1), worlds).values) > 0


def test_a_bootstrap_p_value_is_the_level_at_which_the_interval_reaches_zero():
    values = np.concatenate([np.full(30, -1.0), np.full(970, 1.0)])  # 3 % of resamples at or below 0
    found = Draws(1.0, values, Resampling(1000))
    assert found.p_value() == pytest.approx(0.06)
    assert found.interval(0.95).low < 0 < found.interval(0.90).low
    assert Draws(1.0, np.ones(4000), Resampling(4000)).p_value() == 1 / 4000  # no resample at 0: the least it can show


def test_the_two_level_widening_is_the_worlds_when_seeds_do_not_vary_and_wide_when_two_seeds_do():
    assert two_level_factor(1e-4, 0.0, 7, 2, 0.95) == pytest.approx(small_sample_factor(7, 0.95))
    # all of the spread the seeds': t with 1 degree of freedom over z, times sqrt(2 / 1)
    assert two_level_factor(0.0, 1e-4, 20, 2, 0.95) == pytest.approx(12.7062 / 1.95996 * 2**0.5, rel=1e-4)
    between = two_level_factor(1e-4, 1e-4, 20, 2, 0.95)
    assert small_sample_factor(20, 0.95) < between < 12.7062 / 1.95996 * 2**0.5


@pytest.mark.slow(seconds=10)
def test_the_paired_interval_covers_the_true_difference_at_the_committed_design():
    """300 pairs of methods on test sets of the committed design (20 worlds, 2 seeds), the second one's
    path rate the first's plus 0.02 and its own world, block and seed effects: the paired interval,
    widened at both levels, holds the true difference in at least 93 % (about 94 %,
    benchmarks/bootstrap_coverage.py --paired); the percentile interval alone in fewer."""
    truth = 0.62 / 0.92 - 0.6 / 0.9
    widened = percentile = 0
    for trial in range(300):
        sums, worlds = simulated_test_set(np.random.default_rng(2000 + trial), (0.08, 0.03, 0.03), worlds=20, seeds=2, paired=True)
        draws = paired_draws(sums[1], sums[0], iou, Resampling(1000, seed=trial), worlds)
        found, plain = draws.interval(), Draws(draws.estimate, draws.values, draws.resampling).interval()
        widened += found.low <= truth <= found.high
        percentile += plain.low <= truth <= plain.high
    assert widened / 300 >= 0.93 and percentile / 300 < widened / 300 - 0.03, (widened, percentile)
