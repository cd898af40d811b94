"""Remedies for the straight-ahead bias of end-to-end steering, both named by Holder & Breckon
(2018, section V): most frames drive nearly straight, so an MSE-trained network learns to predict
small angles. `oversample` draws training frames with probability inverse to how common their
steering magnitude is; `weighted` weights each frame's squared error by its distance from the mean
angle. Weights average 1 over the training frames, so the learning rate keeps its meaning."""

from __future__ import annotations

import numpy as np

from offroad_path.config.training_schema import BALANCES

BIN_WIDTH = 0.1  # of |normalised steering|: the bins of data/steering/error_by_magnitude.csv


def inverse_frequency(steering: np.ndarray, bin_width: float = BIN_WIDTH) -> np.ndarray:
    """Per frame, 1 / (frames in its |steering| bin), scaled to mean 1: every bin is drawn equally often."""
    bins = np.floor(np.abs(steering) / bin_width).astype(int)
    counts = np.bincount(bins)
    weights = 1.0 / counts[bins]
    return weights / weights.mean()


def distance_from_mean(steering: np.ndarray) -> np.ndarray:
    """Per frame, 1 + |s - mean| / mean |s - mean|, scaled to mean 1: a frame at the mean counts
    half as much as an average one, a sharp turn several times more."""
    distance = np.abs(steering - steering.mean())
    spread = distance.mean()
    weights = 1.0 + (distance / spread if spread > 0 else 0.0)
    return weights / weights.mean()


def balance_weights(steering: np.ndarray, balance: str) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(sampling weights, loss weights) of the training frames for `balance`; None where unused."""
    if balance not in BALANCES:
        raise ValueError(f"unknown steering.balance {balance!r}; valid: {', '.join(BALANCES)}")
    if balance == "oversample":
        return inverse_frequency(steering), None
    if balance == "weighted":
        return None, distance_from_mean(steering)
    return None, None
