"""The rule for changes that alter results (statistics.noninferiority, benchmarks/noninferiority.py --compare): non-inferiority by a
one-sided 95 % bound of the paired difference over seeds, and no seed collapsing, on hand-made runs."""

from __future__ import annotations

import json

import common as noninferiority
import pytest

SEEDS = [0, 1, 2, 3, 4]
T_95_4 = 2.131847  # Student's t, 95th percentile, 4 degrees of freedom


def per_image(iou: float) -> dict[str, list[int]]:
    """Two test images whose pooled IoU is `iou`: tp of 1000 path pixels, the rest false positives."""
    tp = round(1000 * iou)
    return {"s/0/0": [tp // 2, (1000 - tp) // 2, 5000, 0], "s/1/0": [tp - tp // 2, (1000 - tp) - (1000 - tp) // 2, 5000, 0]}


def steering(errors: list[float]) -> dict[str, float]:
    return {f"s/{i}/0": e for i, e in enumerate(errors)}


def preset(ious: list[float], maes: list[float]) -> dict:
    path = {"seeds": SEEDS, "score": ious, "epochs": [6] * 5, "seconds": [0] * 5, "counts": [per_image(i) for i in ious]}
    pilot = {"seeds": SEEDS, "score": maes, "epochs": [6] * 5, "seconds": [0] * 5, "counts": [steering([m, m]) for m in maes],
             "straight": steering([0.2, 0.2])}  # fmt: skip
    return {"overrides": [], "labels": "own test labels", "prior": per_image(0.55), "models": {"unet": path, "pilotnet": pilot}}


def test_a_small_loss_within_the_margin_is_admissible_and_a_larger_one_is_not(capsys):
    reference = preset([0.80, 0.81, 0.82, 0.80, 0.81], [0.10] * 5)
    close = preset([0.79, 0.80, 0.82, 0.79, 0.81], [0.105, 0.10, 0.11, 0.10, 0.10])  # differences -0.01, -0.01, 0, -0.01, 0
    assert noninferiority.compare(reference, close)
    diffs = [-0.01, -0.01, 0.0, -0.01, 0.0]
    mean = sum(diffs) / 5
    sd = (sum((d - mean) ** 2 for d in diffs) / 4) ** 0.5
    assert f"{mean - T_95_4 * sd / 5**0.5:+.4f}" in capsys.readouterr().out  # the lower bound, by hand: -0.0112
    far = preset([0.78, 0.79, 0.80, 0.77, 0.79], [0.10] * 5)  # 0.02 to 0.03 worse on every seed
    assert not noninferiority.compare(reference, far)
    assert noninferiority.compare(reference, far, margin=0.05)


def test_a_collapsed_seed_or_a_worse_pilotnet_is_not_admissible():
    reference = preset([0.80, 0.81, 0.82, 0.80, 0.81], [0.10] * 5)
    assert not noninferiority.compare(reference, preset([0.80, 0.81, 0.82, 0.80, 0.50], [0.10] * 5))  # below the prior's 0.55
    assert not noninferiority.compare(reference, preset([0.80, 0.81, 0.82, 0.80, 0.81], [0.12, 0.11, 0.12, 0.12, 0.11]))
    assert not noninferiority.compare(reference, preset([0.80, 0.81, 0.82, 0.80, 0.81], [0.10, 0.10, 0.10, 0.10, 0.25]))  # > straight


def test_merge_joins_seeds_in_order_and_refuses_a_seed_twice(tmp_path):
    whole = preset([0.80, 0.81, 0.82, 0.80, 0.81], [0.10] * 5)
    parts = []
    for keep in ([3, 4], [0, 1, 2]):
        part = json.loads(json.dumps(whole))
        for row in part["models"].values():
            for key in ("seeds", "score", "epochs", "seconds", "counts"):
                row[key] = [row[key][i] for i in keep]
        parts.append(part)
    assert noninferiority.merge(parts) == whole
    with pytest.raises(ValueError, match="twice"):
        noninferiority.merge([parts[0], parts[0]])
