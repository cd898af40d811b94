"""The block bootstrap against cases whose answer is known: two blocks computed by hand, a method
against itself, and the coverage of its intervals when the truth is known."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.evaluation.bootstrap import Interval, Resampling, block_sums, interval, mean, paired_interval
from offroad_path.evaluation.scores import iou

A = [60, 20, 900, 20]  # tp fp tn fn of one block: IoU 60 / 100 = 0.6
B = [90, 5, 900, 5]  # IoU 90 / 100 = 0.9


def test_two_blocks_by_hand():
    # Two images per block; the block sums are A and B.
    per_image = np.array([[30, 10, 450, 10], [30, 10, 450, 10], [45, 2, 450, 3], [45, 3, 450, 2]])
    sums = block_sums(per_image, ["a", "a", "b", "b"])
    np.testing.assert_array_equal(sums, [A, B])
    # A resample of two blocks is AA (IoU 0.6), AB or BA (150 / 200 = 0.75) or BB (0.9); with 1000
    # draws of seed 0, AA and BB each hold far more than the 2.5 % in each tail.
    drawn = Resampling(1000, seed=0).indices(2)
    aa, bb = int((drawn.sum(axis=1) == 0).sum()), int((drawn.sum(axis=1) == 2).sum())
    assert aa > 25 and bb > 25
    assert interval(sums, iou, Resampling(1000, seed=0)) == Interval(0.75, 0.6, 0.9)


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
    found = interval(sums, mean, Resampling(1000, seed=1))
    assert (found.estimate, found.low, found.high) == pytest.approx((0.2, 0.1, 0.3))


def test_too_few_blocks_or_mismatched_labels_are_refused():
    with pytest.raises(ValueError, match="at least 2 blocks"):
        interval(np.array([A], float), iou)
    with pytest.raises(ValueError, match="3 items but 2 block labels"):
        block_sums(np.zeros((3, 4)), ["a", "b"])
