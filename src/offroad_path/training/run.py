"""One training run, shared by the `pretrain` and `train` stages: data, task, pretrained
initialisation, Lightning trainer with early stopping and checkpoints, MLflow, test, and the
test-set confidence maps that post-processing reads."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import lightning as L
import numpy as np
import torch
import torch.nn.functional as F
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint
from lightning.pytorch.loggers import MLFlowLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.data.datamodule import OffroadDataModule
from offroad_path.data.dataset import load_sample, transforms
from offroad_path.data.manifest import prediction_name, write_predictions_manifest
from offroad_path.labelling.overlay import overlay
from offroad_path.training.pretrained import initialise
from offroad_path.training.task import SegmentationTask
from offroad_path.utils.atomic import atomic_directory, write_text_atomic
from offroad_path.utils.tracking import experiment_id, flatten, multirun_parent, tracking_uri
from offroad_path.world.preview import colour_semantic

log = logging.getLogger(__name__)


class LogSamples(L.Callback):
    """After each validation epoch, validation predictions beside their targets, as one MLflow image."""

    def __init__(self, count: int):
        self.count = count

    def on_validation_epoch_end(self, trainer: L.Trainer, task: SegmentationTask) -> None:
        if trainer.sanity_checking or not isinstance(trainer.logger, MLFlowLogger) or self.count <= 0:
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
        trainer.logger.experiment.log_image(
            trainer.logger.run_id, np.vstack(rows), artifact_file=f"samples/epoch_{trainer.current_epoch:03d}.png"
        )


def mlflow_logger(cfg: DictConfig, stage: str) -> MLFlowLogger | None:
    if not cfg.mlflow.enabled:
        return None
    tags = {"stage": stage, "experiment_name": cfg.experiment_name, "model": cfg.model.name, "pretraining": cfg.pretraining.name}
    parent = multirun_parent(cfg)
    if parent:
        tags["mlflow.parentRunId"] = parent
    # The tracking URI is always explicit: Lightning's logger would otherwise fall back to ./mlruns.
    experiment_id(cfg.mlflow)  # created with its artifact location, which the logger would not set
    logger = MLFlowLogger(experiment_name=cfg.mlflow.experiment, run_name=f"{stage} {cfg.model.name}-{cfg.pretraining.name}",
                          tracking_uri=tracking_uri(cfg.mlflow), tags=tags)  # fmt: skip
    logger.log_hyperparams(flatten(OmegaConf.to_container(cfg, resolve=True)))
    return logger


def fit(
    cfg: DictConfig, stage: str, target: str, num_classes: int, out_dir: Path, pretraining: str
) -> tuple[dict, SegmentationTask, OffroadDataModule]:
    """Train (resuming from out_dir/checkpoints/last.ckpt when cfg.train.resume) and test the best
    checkpoint. Returns the metrics (also in out_dir/metrics.json), the task holding the best
    weights, and the data module."""
    L.seed_everything(cfg.train.seed, workers=True)
    d, m, t = cfg.data, cfg.model, cfg.trainer
    data = OffroadDataModule(
        d.split_dir, target, d.width, d.height, d.batch_size, d.num_workers, d.pin_memory, d.augment, d.jitter, d.min_scale, cfg.train.seed
    )
    task = SegmentationTask(m.name, num_classes, m.width, m.lr, m.lr_step_epochs, m.lr_gamma, m.momentum, m.weight_decay, t.channels_last)
    loaded = initialise(task.model, pretraining, cfg.pretraining, m.name, m.width)
    if loaded:
        log.info("initialised %d parameter tensors from %s pretraining", len(loaded), pretraining)
    checkpoints = out_dir / "checkpoints"
    best = ModelCheckpoint(dirpath=checkpoints, filename="best", monitor="val/iou", mode="max", save_last=True)
    logger = mlflow_logger(cfg, stage)
    trainer = L.Trainer(
        max_epochs=t.max_epochs, accelerator=t.accelerator, devices=t.devices, strategy=t.strategy, num_nodes=t.num_nodes,
        precision=t.precision, deterministic=t.deterministic, log_every_n_steps=t.log_every_n_steps, fast_dev_run=t.fast_dev_run,
        callbacks=[best, EarlyStopping("val/iou", mode="max", patience=t.patience), LogSamples(cfg.train.sample_images)],
        logger=logger if logger is not None else False, default_root_dir=out_dir, enable_progress_bar=False,
    )  # fmt: skip
    resume = checkpoints / "last.ckpt"
    trainer.fit(task, data, ckpt_path=str(resume) if cfg.train.resume and resume.is_file() else None)
    best_path = best.best_model_path or None
    tested = trainer.test(task, data, ckpt_path=best_path, verbose=False)[0]
    metrics = {"best_val_iou": float(best.best_model_score) if best.best_model_score is not None else None, "epochs": trainer.current_epoch,
               "global_step": trainer.global_step, **{k: float(v) for k, v in tested.items()}}  # fmt: skip
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    if logger is not None:
        logger.experiment.log_dict(logger.run_id, metrics, "metrics.json")
        if best_path:
            logger.experiment.log_artifact(logger.run_id, best_path, "checkpoints")
    return metrics, task, data


def write_confidence_maps(task: SegmentationTask, data: OffroadDataModule, out_dir: Path) -> int:
    """Path confidence (softmax of the path class) for every test sample, at the label's size, as
    float16 .npy under out_dir/<sequence>/NNNNNN[_mirrored].npy, listed in out_dir/manifest.csv."""
    data.setup("test")
    samples = data.samples["test"]
    transform = transforms(data.hparams.width, data.hparams.height, augment=False)
    task.eval()
    rows = []
    with atomic_directory(out_dir) as tmp, torch.no_grad():
        for sample in samples:
            image, label = load_sample(sample, "path")
            scores = task(transform(image=image)["image"][None].to(task.device))
            confidence = F.interpolate(scores.softmax(1)[:, 1:2], size=label.shape, mode="bilinear", align_corners=False)[0, 0]
            name = prediction_name(sample)
            (tmp / sample.sequence).mkdir(exist_ok=True)
            np.save(tmp / name, confidence.cpu().numpy().astype(np.float16))
            rows.append((sample, str(out_dir / name)))
        write_predictions_manifest(tmp / "manifest.csv", rows)
    return len(rows)
