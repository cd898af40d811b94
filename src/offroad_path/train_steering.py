"""Stage `train_steering`: the end-to-end baseline, PilotNet trained on every frame's steering angle
of the training sequences, tested on the path split's held-out stretches (see offroad_path.steering).

    python -m offroad_path.train_steering [steering.lr=2e-4] [steering.max_epochs=30]

Writes steering.out_dir (data/steering): checkpoints/best.ckpt, metrics.json, predictions.csv (true
and predicted angle per test frame), error_by_magnitude.csv, scatter.png (the thesis's Fig. 5.4);
steering.metrics_path for `dvc metrics show`; steering.plots_path for `dvc plots show`; an MLflow run.
"""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path

import lightning as L
import numpy as np
import torch
from lightning.pytorch.callbacks import EarlyStopping, ModelCheckpoint
from lightning.pytorch.loggers import MLFlowLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.steering.dataset import SteeringDataModule
from offroad_path.steering.evaluation import error_by_magnitude, scatter_plot, steering_metrics
from offroad_path.steering.frames import steering_split
from offroad_path.steering.task import SteeringTask
from offroad_path.training.checkpoints import load_weights, save_weights
from offroad_path.utils.atomic import atomic_directory, check_output_dir, write_text_atomic
from offroad_path.utils.cli import hydra_stage
from offroad_path.utils.tracking import experiment_id, flatten, multirun_parent, tracking_uri

log = logging.getLogger("offroad_path.train_steering")


def steering_logger(cfg: DictConfig) -> MLFlowLogger | None:
    if not cfg.mlflow.enabled:
        return None
    tags = {"stage": "train_steering", "experiment_name": cfg.experiment_name, "model": "pilotnet"}
    if parent := multirun_parent(cfg):
        tags["mlflow.parentRunId"] = parent
    experiment_id(cfg.mlflow)  # created with its artifact location
    logger = MLFlowLogger(experiment_name=cfg.mlflow.experiment, run_name="train_steering pilotnet", tracking_uri=tracking_uri(cfg.mlflow),
                          tags=tags)  # fmt: skip
    logger.log_hyperparams(flatten(OmegaConf.to_container(cfg.steering, resolve=True), "steering."))
    return logger


def predict(task: SteeringTask, loader) -> tuple[np.ndarray, np.ndarray]:
    task.eval()
    true, predicted = [], []
    with torch.no_grad():
        for batch in loader:
            predicted.append(task(batch["image"].to(task.device)).cpu())
            true.append(batch["steering"])
    return torch.cat(true).numpy(), torch.cat(predicted).numpy()


def train_steering(cfg: DictConfig) -> dict:
    s, t = cfg.steering, cfg.trainer
    check_output_dir(s.out_dir, "steering.out_dir", [s.labels_dir, s.split_dir])
    L.seed_everything(s.seed, workers=True)
    parts = steering_split(Path(s.labels_dir), Path(s.split_dir), cfg.split.block_m, cfg.split.guard_m, s.mirror)
    data = SteeringDataModule(parts, s.width, s.height, s.batch_size, s.jitter, s.seed)
    task = SteeringTask(s.width, s.height, s.lr, s.lr_step_epochs, s.lr_gamma, s.momentum, s.weight_decay)
    logger = steering_logger(cfg)
    out_dir = Path(s.out_dir)
    with atomic_directory(out_dir, "train_steering", [s.labels_dir, s.split_dir], key="steering.out_dir") as tmp:
        best = ModelCheckpoint(dirpath=tmp / "checkpoints", filename="best", monitor=task.monitor, mode=task.mode)
        trainer = L.Trainer(
            max_epochs=s.max_epochs, accelerator=t.accelerator, devices=t.devices, strategy=t.strategy, num_nodes=t.num_nodes,
            precision=t.precision, deterministic=t.deterministic, log_every_n_steps=t.log_every_n_steps, fast_dev_run=t.fast_dev_run,
            logger=logger if logger is not None else False, default_root_dir=tmp, enable_progress_bar=False,
            callbacks=[best, EarlyStopping(task.monitor, mode=task.mode, patience=s.patience)],
        )  # fmt: skip
        trainer.fit(task, data)
        if best.best_model_path:
            # Published as weights and hyper-parameters only: Lightning's checkpoint names the temporary folder.
            load_weights(task, best.best_model_path)
            save_weights(Path(best.best_model_path), task)
        true, predicted = predict(task, data.test_dataloader())
        best_val = None if best.best_model_score is None else float(best.best_model_score)
        metrics = {**steering_metrics(true, predicted), "best_val_mae": best_val, "epochs": trainer.current_epoch}
        bins = error_by_magnitude(true, predicted)
        frames = parts["test"]
        with open(tmp / "predictions.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["sequence", "frame", "mirrored", "true", "predicted"])
            for frame, a, b in zip(frames, true, predicted, strict=True):
                writer.writerow([frame.sequence, frame.frame, frame.mirrored, f"{a:.6f}", f"{b:.6f}"])
        with open(tmp / "error_by_magnitude.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(bins[0]))
            writer.writeheader()
            writer.writerows(bins)
        (tmp / "metrics.json").write_text(json.dumps({**metrics, "by_true_magnitude": bins}, indent=2) + "\n")
        scatter_plot(true, predicted, tmp / "scatter.png")
    write_text_atomic(s.metrics_path, json.dumps(metrics, indent=2) + "\n")
    write_text_atomic(s.plots_path, "truth,prediction\n" + "".join(f"{a:.6f},{b:.6f}\n" for a, b in zip(true, predicted, strict=True)))
    if logger is not None:
        logger.log_metrics({f"test/{k}": v for k, v in metrics.items() if isinstance(v, float)})
        for name in ("scatter.png", "error_by_magnitude.csv", "metrics.json"):
            logger.experiment.log_artifact(logger.run_id, str(out_dir / name))
    log.info("PilotNet: test mean absolute error %.4f (straight ahead would score %.4f), largest predicted magnitude %.3f of true %.3f",
             metrics["mean_absolute_error"], metrics["straight_ahead_mean_absolute_error"], metrics["largest_predicted_magnitude"],
             metrics["largest_true_magnitude"])  # fmt: skip
    return metrics


main = hydra_stage(train_steering)


if __name__ == "__main__":
    main()
