"""The networks learn: each one overfits a single batch, and a U-Net trained on the tiny test drive
scores its held-out frames above the mean-path prior (the average training label), the baseline
every network of the results table must beat."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from offroad_path.data.manifest import read_manifest, read_predictions_manifest
from offroad_path.evaluate.pixel_scores import counts, mean_path, pooled
from offroad_path.models import MODELS
from offroad_path.training.task import SegmentationTask

STEPS = 100
LOSS_FACTOR = 2.5  # the loss falls at least this much in STEPS steps on one batch (cross-entropy + Dice, AdamW: 2.7x to 46x measured)


def one_batch() -> tuple[torch.Tensor, torch.Tensor]:
    """Two 64 x 48 images with a bright trapezoid (the path) on noise, and its mask as the target."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0:48, 0:64]
    images, targets = [], []
    for shift in (-6, 6):
        half_width = 4 + (rows - 16) * 0.4  # wider towards the bottom, as a path in perspective
        path = (rows >= 16) & (np.abs(cols - 32 - shift * (rows - 16) / 32) < half_width)
        image = rng.normal(0.0, 0.3, (3, 48, 64)) + 0.8 * path
        images.append(image.astype(np.float32))
        targets.append(path.astype(np.int64))
    return torch.from_numpy(np.stack(images)), torch.from_numpy(np.stack(targets))


@pytest.mark.parametrize("model", list(MODELS))
@pytest.mark.slow(seconds=4)
def test_each_network_overfits_one_batch(compose_config, model):
    m = compose_config(f"model={model}").model
    torch.manual_seed(0)
    # The configured network, loss and optimiser at a constant rate (a schedule needs a trainer's length)
    task = SegmentationTask(model=model, num_classes=2, width=0.125, lr=m.lr, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.0,
                            momentum=m.momentum, weight_decay=0.0, channels_last=False, optimizer=m.optimizer, lr_schedule="step",
                            dice_weight=m.dice_weight, batch_norm=m.batch_norm)  # fmt: skip
    optimiser = task.configure_optimizers()
    images, targets = one_batch()
    losses = []
    for _ in range(STEPS):
        loss = task.loss(task(images), targets)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / LOSS_FACTOR, f"{model}: loss {losses[0]:.3f} -> {losses[-1]:.3f} in {STEPS} steps"
    predicted = task(images).argmax(1)
    assert pooled(counts(predicted.numpy().astype(np.float32), targets.numpy())).iou > 0.8


@pytest.mark.slow(seconds=4)
def test_a_trained_unet_beats_the_mean_path_prior_on_the_held_out_frames(tiny_config, split_dir, tmp_path):
    from offroad_path.data.loading import load_labels, load_maps
    from offroad_path.train import train

    overrides = ("model=unet", "trainer.max_epochs=20", "callbacks.early_stopping.patience=20", "mlflow.enabled=false")
    metrics = train(tiny_config(tmp_path, *overrides))
    run = tmp_path / "run"
    assert json.loads((run / "metrics.json").read_text())["test/iou"] == metrics["test/iou"]
    predictions = read_predictions_manifest(run / "predictions" / "manifest.csv")
    truth = load_labels([sample for sample, _ in predictions])
    confidence = load_maps([path for _, path in predictions])
    prior = mean_path(load_labels(read_manifest(split_dir / "train.csv")))
    network = pooled(counts(confidence, truth)).iou
    baseline = pooled(counts(np.broadcast_to(prior, truth.shape), truth)).iou
    # Measured: 0.733 against 0.293 (seed 0, 2026-11-25).
    assert network > baseline + 0.05, f"U-Net {network:.3f} against the mean-path prior {baseline:.3f}"
