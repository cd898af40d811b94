"""The seed check: a training that failed on one seed is named, a healthy spread is not."""

from __future__ import annotations

from offroad_path.report.rendering import seed_check_text
from offroad_path.statistics.seed_check import FAILED_BELOW_MEDIAN, failed_seeds


def test_a_seed_far_below_its_siblings_median_is_a_failed_training():
    # the committed run before the fix: SegNet with segmentation pretraining, 0.79 and 0.59 (median 0.69)
    assert failed_seeds({0: 0.79, 1: 0.59}) == [1]
    assert failed_seeds({0: 0.78, 1: 0.77, 2: 0.70, 3: 0.79, 4: 0.78}) == [2]  # 0.08 below the median 0.78
    assert failed_seeds({0: 0.78, 1: 0.74, 2: 0.80}) == []  # 0.04 below: a healthy spread
    assert failed_seeds({0: 0.5}) == []  # one seed: nothing to compare with
    assert failed_seeds({0: 0.80, 1: 0.70}, margin=0.06) == []  # 0.05 below the median of two
    assert FAILED_BELOW_MEDIAN == 0.05


def test_the_report_names_each_failed_training_or_says_none_failed():
    assert "Seed check: no seed of any network lies more than 0.05 IoU below" in seed_check_text({}, 0.05)
    text = seed_check_text({"segnet-segmentation": [1]}, 0.05)
    assert text.startswith("**Seed check: failed trainings**") and "SegNet (segmentation): seed 1" in text
