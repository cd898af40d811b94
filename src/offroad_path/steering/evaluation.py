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


COLLAPSE_RANGE = 0.5  # a largest predicted magnitude below this fraction of the true one: a near-constant output


def collapse_check(true: np.ndarray, predicted: np.ndarray, worlds: list[str], resamples: int = 2000, seed: int = 0) -> dict:
    """Whether a PilotNet predicts a near-constant: its largest magnitude below COLLAPSE_RANGE of the
    true one, or its mean absolute error not below straight ahead's with a 95 % paired interval
    (the test worlds drawn with replacement, each world's frames with it). The margin is straight
    ahead's error minus the network's: above 0 where the network steers better."""
    margin = np.abs(true) - np.abs(predicted - true)  # per frame: straight ahead's error minus the network's
    names, world_of = np.unique(np.asarray(worlds), return_inverse=True)
    sums, counts = np.bincount(world_of, margin, len(names)), np.bincount(world_of, minlength=len(names))
    drawn = np.random.default_rng(seed).integers(0, len(names), (resamples, len(names)))
    means = sums[drawn].sum(axis=1) / counts[drawn].sum(axis=1)
    low, high = (float(v) for v in np.quantile(means, [0.025, 0.975]))
    narrow = np.abs(predicted).max() < COLLAPSE_RANGE * np.abs(true).max()
    reasons = (["largest predicted magnitude below half the true one"] if narrow else []) + (
        ["error not below straight ahead's (95 % interval of the margin reaches 0)"] if low <= 0 else []
    )
    return {
        "straight_ahead_margin": float(margin.mean()),
        "straight_ahead_margin_interval": [low, high],
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
