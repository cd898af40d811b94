"""The callbacks of every training run: those the loop always adds (per-epoch seeding, staying
stopped, the config stamp in each checkpoint, validation samples to MLflow) and conf/callbacks,
instantiated."""

from __future__ import annotations

import random

import lightning as L
import numpy as np
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from lightning.pytorch.callbacks import EarlyStopping
from lightning.pytorch.loggers import MLFlowLogger, WandbLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.data.loading import load_sample
from offroad_path.training.checkpoints import CONFIG_HASH
from offroad_path.training.task import BaseTask, SegmentationTask
from offroad_path.viz import colour_semantic, overlay


class LogSamples(L.Callback):
    """After each validation epoch, validation predictions beside their targets, as one image in
    MLflow or W&B (other loggers have no images)."""

    def __init__(self, count: int):
        self.count = count

    def on_validation_epoch_end(self, trainer: L.Trainer, task: SegmentationTask) -> None:
        if trainer.sanity_checking or not isinstance(trainer.logger, MLFlowLogger | WandbLogger) or self.count <= 0:
            return
        dataset = trainer.val_dataloaders.dataset
        rows = []
        for i in range(min(self.count, len(dataset))):
            image, target = load_sample(dataset.samples[i], dataset.target)
            with torch.no_grad():
                scores = task(dataset[i]["image"][None].to(task.device))
            scores = F.interpolate(scores, size=target.shape, mode="bilinear", align_corners=False)[0]
            predicted = scores.argmax(0).cpu().numpy()
            if task.hparams.num_classes == 2:
                rows.append(np.hstack([overlay(image, target), overlay(image, predicted)]))
            else:
                rows.append(np.hstack([image, colour_semantic(target.astype(np.uint8)), colour_semantic(predicted.astype(np.uint8))]))
        if isinstance(trainer.logger, WandbLogger):
            trainer.logger.log_image("samples", [np.vstack(rows)], step=trainer.global_step)
            return
        trainer.logger.experiment.log_image(
            trainer.logger.run_id, np.vstack(rows), artifact_file=f"samples/epoch_{trainer.current_epoch:03d}.png"
        )


class SeedEachEpoch(L.Callback):
    """Seeds torch, NumPy and random from (seed, epoch) before each training epoch: dropout and
    anything else drawn from the global generators replays the same after a resume."""

    def __init__(self, seed: int):
        self.seed = seed

    def on_train_epoch_start(self, trainer: L.Trainer, task: L.LightningModule) -> None:
        seed_everything_quietly(self.seed * 1_000_003 + trainer.current_epoch)


def seed_everything_quietly(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)


class StayStopped(L.Callback):
    """A run that early stopping ended stays ended when it is run again: resuming from its last.ckpt
    would otherwise train one more epoch (Lightning restores the callback's counters, not its
    decision) and change epochs, steps and possibly the best weights."""

    def on_train_start(self, trainer: L.Trainer, task: L.LightningModule) -> None:
        if any(isinstance(c, EarlyStopping) and c.stopped_epoch > 0 for c in trainer.callbacks):
            trainer.should_stop = True


class StampConfig(L.Callback):
    """Writes the run's config hash into every checkpoint, so a resume can check it belongs to this run."""

    def __init__(self, key: str):
        self.key = key

    def on_save_checkpoint(self, trainer: L.Trainer, task: L.LightningModule, checkpoint: dict) -> None:
        checkpoint[CONFIG_HASH] = self.key


def configured_callbacks(callbacks: DictConfig, task: BaseTask, validate: bool, patience: int | None) -> list[L.Callback]:
    """conf/callbacks instantiated, early stopping following the task's validation metric (left
    out when the run has no validation set)."""
    made = []
    for name, node in callbacks.items():
        extra: dict = {}
        if OmegaConf.select(node, "_target_", default="").endswith("EarlyStopping"):
            if not validate:
                continue
            extra = {"monitor": task.monitor, "mode": task.mode} | ({"patience": patience} if patience else {})
        try:
            made.append(instantiate(node, **extra))
        except Exception as e:  # Hydra wraps the callback's own error
            raise ValueError(f"callbacks.{name}: cannot be built ({e})") from e
    return made
