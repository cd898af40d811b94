"""Scores against counts made by hand on small arrays; the baselines on hand-made images."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torchmetrics.classification import BinaryPrecisionRecallCurve
from torchmetrics.functional.classification import binary_stat_scores

from offroad_path.evaluate.pixel_scores import counts, mean_path, non_corresponding, per_image_iou, pooled, precision_recall_curve

# Two 2 x 3 images. Image 0: truth has 3 path pixels, the prediction hits 2 and adds 1.
# Image 1: truth has 1 path pixel, the prediction covers 4 pixels including it.
TRUTH = np.array([[[1, 1, 1], [0, 0, 0]], [[0, 0, 0], [0, 1, 0]]], bool)
CONFIDENCE = np.array([[[0.9, 0.6, 0.5], [0.7, 0.1, 0.0]], [[0.0, 0.0, 0.0], [0.8, 0.99, 0.51]]], np.float32)
# Image 0 at C > 0.5: predicted path (0,0),(0,1),(1,0); 0.5 itself is not path.
#   tp 2, fp 1, tn 2, fn 1.  Image 1: predicted (1,0),(1,1),(1,2): tp 1, fp 2, tn 3, fn 0.


def test_counts_follow_the_papers_threshold_rule():
    np.testing.assert_array_equal(counts(CONFIDENCE, TRUTH), [[2, 1, 2, 1], [1, 2, 3, 0]])


def test_counts_are_torchmetrics_stat_scores_at_the_papers_rule():
    """The NumPy counts against torchmetrics on random maps, with values on the threshold itself
    (torchmetrics thresholds with >=, the paper with >: the predictions go in already thresholded)."""
    rng = np.random.default_rng(0)
    confidence = np.round(rng.random((5, 24, 40)), 1).astype(np.float32)  # many pixels exactly 0.5
    truth = rng.random((5, 24, 40)) < 0.3
    for threshold in (0.5, 0.25, 0.0, 1.0):
        predicted = torch.from_numpy(confidence > np.float32(threshold)).flatten(1).long()
        expected = binary_stat_scores(predicted, torch.from_numpy(truth).flatten(1).long(), multidim_average="samplewise")
        np.testing.assert_array_equal(counts(confidence, truth, threshold), expected[:, :4].numpy())
    np.testing.assert_array_equal(counts(confidence, truth.astype(np.uint8)), counts(confidence, truth))
    assert counts(np.zeros((0, 4, 4), np.float32), np.zeros((0, 4, 4), bool)).shape == (0, 4)


def test_pooled_scores_versus_per_image_mean_iou():
    per_image = counts(CONFIDENCE, TRUTH)
    s = pooled(per_image)  # pooled: tp 3, fp 3, tn 5, fn 1
    assert s.accuracy == pytest.approx(8 / 12)
    assert s.recall == pytest.approx(3 / 4)
    assert s.precision == pytest.approx(3 / 6)
    assert s.iou == pytest.approx(3 / 7)
    # Per image: 2/4 and 1/3; their mean differs from the pooled 3/7.
    np.testing.assert_allclose(per_image_iou(per_image), [2 / 4, 1 / 3])
    assert per_image_iou(per_image).mean() == pytest.approx((0.5 + 1 / 3) / 2) != pytest.approx(3 / 7)


def test_an_image_without_path_in_either_scores_iou_one_and_undefined_scores_are_nan():
    empty = np.zeros((1, 2, 2), bool)
    assert per_image_iou(counts(np.zeros((1, 2, 2)), empty)).tolist() == [1.0]
    s = pooled(counts(np.zeros((1, 2, 2)), empty))
    assert s.accuracy == 1.0 and math.isnan(s.precision) and math.isnan(s.recall) and math.isnan(s.iou)
    with pytest.raises(ValueError, match="differ in shape"):
        counts(np.zeros((1, 2, 2)), np.zeros((1, 2, 3), bool))


def test_precision_recall_curve_agrees_with_the_counts_at_each_threshold():
    curve = precision_recall_curve(CONFIDENCE, TRUTH, thresholds=11)
    np.testing.assert_allclose(curve["threshold"], np.linspace(0, 1, 11), atol=1e-6)
    for t, p, r in zip(curve["threshold"], curve["precision"], curve["recall"], strict=True):
        # torchmetrics' binned curve counts C >= t as path
        tp, fp, _, fn = counts(CONFIDENCE, TRUTH, threshold=float(t) - 1e-6).sum(0)
        assert r == pytest.approx(tp / (tp + fn))
        assert p == pytest.approx(tp / (tp + fp) if tp + fp else 1.0)


def test_precision_recall_curve_is_torchmetrics_curve_exactly():
    # 3 x 120 x 160 pixels: over torchmetrics' 50,000-element limit, so its own per-threshold loop
    # runs; a quarter of the confidences sit exactly on a threshold, where >= must decide.
    rng = np.random.default_rng(3)
    shape = (3, 120, 160)
    confidence = rng.random(shape, dtype=np.float32)
    on_grid = rng.random(shape) < 0.25
    confidence[on_grid] = torch.linspace(0, 1, 101).numpy()[rng.integers(0, 101, on_grid.sum())]
    truth = rng.random(shape) < confidence  # path where confident, mostly
    reference = BinaryPrecisionRecallCurve(thresholds=101)
    reference.update(torch.from_numpy(confidence).flatten(), torch.from_numpy(truth).flatten().long())
    precision, recall, threshold = reference.compute()
    curve = precision_recall_curve(confidence, truth, batch=2)
    assert np.array_equal(curve["threshold"], threshold.numpy())
    assert np.array_equal(curve["recall"], recall[:-1].numpy())
    assert np.array_equal(curve["precision"], np.nan_to_num(precision[:-1].numpy(), nan=1.0))


def test_ground_truth_other_than_0_1_and_confidence_outside_0_1_are_refused():
    with pytest.raises(ValueError, match="bool or 0/1; it holds values from 0 to 255"):
        counts(CONFIDENCE, TRUTH.astype(np.uint8) * 255)
    with pytest.raises(ValueError, match="bool or 0/1"):
        precision_recall_curve(CONFIDENCE, TRUTH.astype(np.int64) * 2)
    with pytest.raises(ValueError, match=r"confidence must lie in \[0, 1\]"):
        precision_recall_curve(CONFIDENCE * 3 - 1, TRUTH)


def test_non_corresponding_baseline_on_three_hand_made_images():
    # 1 x 4 images; image i's prediction is compared with the truths of the two other images.
    predicted = np.array([[[1, 1, 0, 0]], [[0, 1, 1, 0]], [[0, 0, 0, 1]]], bool)
    truth = np.array([[[1, 0, 0, 0]], [[0, 1, 1, 0]], [[0, 0, 1, 1]]], bool)
    # pairs (prediction, truth): (0,1) tp1 fp1 fn1 tn1 -> iou 1/3 acc 2/4; (0,2) tp0 fp2 fn2 -> iou 0 acc 0
    # (1,0) tp0 fp2 fn1 tn1 -> iou 0 acc 1/4; (1,2) tp1 fp1 fn1 tn1 -> iou 1/3 acc 2/4
    # (2,0) tp0 fp1 fn1 tn2 -> iou 0 acc 2/4; (2,1) tp0 fp1 fn2 tn1 -> iou 0 acc 1/4
    s = non_corresponding(predicted, truth, groups=[0, 1, 2])
    assert s.iou == pytest.approx((1 / 3 + 1 / 3) / 6)
    assert s.accuracy == pytest.approx((2 / 4 + 0 + 1 / 4 + 2 / 4 + 2 / 4 + 1 / 4) / 6)
    assert s.recall == pytest.approx((1 / 2 + 0 + 0 + 1 / 2 + 0 + 0) / 6)
    # A mirrored copy (same group) is never scored against its own frame: images 1 and 2 as one
    # frame leave the pairs (0,1), (0,2), (1,0), (2,0).
    s = non_corresponding(predicted, truth, groups=["a", "b", "b"])
    assert s.iou == pytest.approx((1 / 3) / 4)
    with pytest.raises(ValueError, match="two different frames"):
        non_corresponding(predicted, truth, groups=[0, 0, 0])


def test_mean_path_prior_is_the_pixel_average_of_the_labels():
    labels = np.array([[[1, 1, 0]], [[1, 0, 0]], [[1, 1, 1]], [[0, 1, 0]]], bool)
    np.testing.assert_allclose(mean_path(labels), [[0.75, 0.75, 0.25]])
