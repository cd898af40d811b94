"""Scoring the steering baseline as the thesis did (section 5.1.2): mean absolute error of the
normalised angle, its spread over the true angle's magnitude, the largest predicted magnitude,
and predicted against true angle as a scatter plot (the thesis's Fig. 5.4)."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

MAGNITUDE_EDGES = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 1.0)


def steering_metrics(true: np.ndarray, predicted: np.ndarray, lock_deg: float, steering_ratio: float) -> dict:
    """Errors of normalised steering, and in degrees: at the road wheels (times the lock) and at the
    steering wheel (times the steering ratio too), the paper's reading of its 0.097."""
    error = np.abs(predicted - true)
    return {
        "test_frames": len(true),
        "mean_absolute_error": float(error.mean()),
        "mean_absolute_error_road_wheel_deg": float(error.mean() * lock_deg),
        "mean_absolute_error_steering_wheel_deg": float(error.mean() * lock_deg * steering_ratio),
        "largest_predicted_magnitude": float(np.abs(predicted).max()),
        "largest_true_magnitude": float(np.abs(true).max()),
        # what always predicting straight ahead would score: the bias the thesis saw
        "straight_ahead_mean_absolute_error": float(np.abs(true).mean()),
    }


# A PilotNet has collapsed when its output hardly moves or does not move with the truth: the spread of
# its predictions below COLLAPSE_SPREAD of the truth's, or their correlation with the truth at or below
# COLLAPSE_CORRELATION. One that moves with the truth but too little (under-steering) has not: whether
# it beats straight ahead is a separate finding, from the margin's interval.
COLLAPSE_SPREAD = 0.25
COLLAPSE_CORRELATION = 0.1


def collapse_check(true: np.ndarray, predicted: np.ndarray, worlds: list[str], resamples: int = 2000, seed: int = 0) -> dict:
    """Whether a PilotNet predicts a near-constant (collapsed: by the spread and the correlation of its
    predictions against the truth's, not by one extreme value) and whether it steers closer to the true
    angle than straight ahead (beats_straight_ahead: the margin's 95 % paired interval above 0, the test
    worlds drawn with replacement, each world's frames with it). The margin is straight ahead's error
    minus the network's: above 0 where the network steers better."""
    margin = np.abs(true) - np.abs(predicted - true)  # per frame: straight ahead's error minus the network's
    names, world_of = np.unique(np.asarray(worlds), return_inverse=True)
    sums, counts = np.bincount(world_of, margin, len(names)), np.bincount(world_of, minlength=len(names))
    drawn = np.random.default_rng(seed).integers(0, len(names), (resamples, len(names)))
    means = sums[drawn].sum(axis=1) / counts[drawn].sum(axis=1)
    low, high = (float(v) for v in np.quantile(means, [0.025, 0.975]))
    true_sd, predicted_sd = (float(np.std(v)) if np.ptp(v) > 0 else 0.0 for v in (true, predicted))  # a constant: exactly 0
    spread = predicted_sd / true_sd if true_sd > 0 else float("nan")
    # a constant output has no correlation with anything: 0, not NaN
    correlation = float(np.corrcoef(true, predicted)[0, 1]) if predicted_sd > 0 and true_sd > 0 else 0.0
    reasons = ([f"predictions' spread below {COLLAPSE_SPREAD:g} of the truth's"] if not spread >= COLLAPSE_SPREAD else []) + (
        [f"correlation with the truth at or below {COLLAPSE_CORRELATION:g}"] if correlation <= COLLAPSE_CORRELATION else []
    )
    return {
        "straight_ahead_margin": float(margin.mean()),
        "straight_ahead_margin_interval": [low, high],
        "beats_straight_ahead": low > 0,
        "prediction_spread_ratio": spread,
        "correlation_with_truth": correlation,
        "collapsed": bool(reasons),
        "collapse_reasons": reasons,
    }


def error_by_magnitude(true: np.ndarray, predicted: np.ndarray, edges: tuple[float, ...] = MAGNITUDE_EDGES) -> list[dict]:
    """Mean absolute error and mean predicted magnitude per bin of true magnitude [lo, hi)."""
    rows = []
    magnitude = np.abs(true)
    for lo, hi in itertools.pairwise(edges):
        inside = (magnitude >= lo) & ((magnitude < hi) | (hi == edges[-1]))
        rows.append(
            {
                "true_magnitude": f"{lo:.1f}-{hi:.1f}",
                "frames": int(inside.sum()),
                "mean_absolute_error": float(np.abs(predicted - true)[inside].mean()) if inside.any() else None,
                "mean_predicted_magnitude": float(np.abs(predicted)[inside].mean()) if inside.any() else None,
            }
        )
    return rows


def scatter_plot(true: np.ndarray, predicted: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 4.5), dpi=120)
    ax.scatter(true, predicted, s=6, alpha=0.5)
    ax.plot([-1, 1], [-1, 1], color="grey", lw=0.8, label="perfect")
    ax.axhspan(-0.5, 0.5, color="orange", alpha=0.08, label="|prediction| <= 0.5")
    ax.set(
        xlim=(-1, 1),
        ylim=(-1, 1),
        xlabel="true normalised steering",
        ylabel="predicted",
        title=f"PilotNet, {len(true)} test frames, MAE {np.abs(predicted - true).mean():.3f}",
    )
    ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
