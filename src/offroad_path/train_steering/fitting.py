"""The train_steering stage's work: PilotNet fitted with the shared training loop
(training.run.fit), its test predictions, metrics and plots."""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path

import lightning as L
import numpy as np
import torch
from hydra.utils import instantiate
from lightning.pytorch.loggers import MLFlowLogger
from omegaconf import DictConfig, OmegaConf

from offroad_path.config import steering_folder, steering_stage
from offroad_path.data.labels import read_label_run
from offroad_path.sequence import meta
from offroad_path.steering.angle_dataset import SteeringDataModule
from offroad_path.steering.collapse import collapse_check, error_by_magnitude, scatter_plot, steering_metrics
from offroad_path.steering.frames import PARTS, steering_split, write_frames
from offroad_path.steering.pilotnet_task import SteeringTask
from offroad_path.training.run import MANIFEST_CONTEXTS, RunSpec, fit, run_identity, training_logger
from offroad_path.utils.atomic import write_text_atomic

log = logging.getLogger("offroad_path.train_steering")


def predict(task: SteeringTask, loader) -> tuple[np.ndarray, np.ndarray]:
    task.eval()
    true, predicted = [], []
    with torch.no_grad():
        for batch in loader:
            predicted.append(task.angle(batch["image"].to(task.device)).cpu())
            true.append(batch["steering"])
    return torch.cat(true).numpy(), torch.cat(predicted).numpy()


def main_test_frames(frames: list, labels_dir: Path) -> np.ndarray:
    """(N,) whether each test frame is of the main test set (not a stress world's): the label run's
    sequences whose meta.json names no other test set."""
    stress = {run.name for run in read_label_run(labels_dir) if meta.test_set(run.sequence.meta) != meta.MAIN}
    return np.array([frame.sequence not in stress for frame in frames], bool)


def slippery_steering(cfg: DictConfig) -> dict[str, np.ndarray]:
    """Each labelled synthetic sequence's steering had it been driven on world.slip's ground: the
    driver's input that made the same motion (offroad_path.world.record.steering_under_slip)."""
    from offroad_path.world.record import steering_under_slip  # the world and its renderer, only for this

    runs = read_label_run(Path(cfg.steering.labels_dir))
    folders = [run.sequence.root for run in runs if meta.rendered(run.sequence.meta)]
    if not folders:
        raise ValueError(f"steering.slip: {cfg.steering.labels_dir} labels no rendered sequence, whose world could be driven with slip")
    log.info("steering under slip (world.slip) for %d rendered sequences", len(folders))
    return steering_under_slip(cfg.world, folders)


def fit_steering(cfg: DictConfig) -> dict:
    """The train_steering stage's run (offroad_path.train_steering): PilotNet on the path split's
    training frames, tested, written to steering.out_dir, steering.metrics_path and steering.plots_path."""
    steering = cfg.steering
    L.seed_everything(cfg.seed, workers=True)
    # The frames follow the path split's blocks of driving, with its guard (conf/split).
    angles = slippery_steering(cfg) if steering.slip else None
    parts = steering_split(
        Path(steering.labels_dir), Path(steering.split_dir), cfg.split.block_m, cfg.split.guard_m, steering.mirror, steering=angles
    )
    data = SteeringDataModule(parts, steering, cfg.seed)
    task: SteeringTask = instantiate(steering, _convert_="all")
    outputs = ("out_dir", "metrics_path", "plots_path", "max_epochs", "cache_mb", "slip")
    settings = {
        "block_m": cfg.split.block_m,
        "guard_m": cfg.split.guard_m,
        "steering": {k: v for k, v in OmegaConf.to_container(steering, resolve=True).items() if k not in outputs},
    }
    if steering.slip:
        settings["slip"] = OmegaConf.to_container(cfg.world.slip)
    files = [Path(steering.split_dir) / f"{part}.csv" for part in PARTS] + [Path(steering.labels_dir) / "summary.json"]
    scored: dict[str, np.ndarray] = {}

    def write_predictions(task: SteeringTask, data: SteeringDataModule, tmp: Path) -> dict:
        true, predicted = predict(task, data.test_dataloader())
        scored.update(true=true, predicted=predicted)
        write_frames(tmp, parts)  # train.csv, val.csv, test.csv: what this PilotNet saw
        # The headline figures are the main test set's (every frame when the split has no held-out worlds);
        # the stress worlds' frames are scored apart, as the path networks' stress sets are.
        main = main_test_frames(parts["test"], Path(steering.labels_dir))
        bins = error_by_magnitude(true[main], predicted[main])
        with open(tmp / "predictions.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["sequence", "frame", "mirrored", "true", "predicted"])
            for frame, a, b in zip(parts["test"], true, predicted, strict=True):
                writer.writerow([frame.sequence, frame.frame, frame.mirrored, f"{a:.6f}", f"{b:.6f}"])
        with open(tmp / "error_by_magnitude.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(bins[0]))
            writer.writeheader()
            writer.writerows(bins)
        scatter_plot(true[main], predicted[main], tmp / "scatter.png")
        collapse = collapse_check(true[main], predicted[main], [f.sequence for f, m in zip(parts["test"], main, strict=True) if m])
        stress = {"stress_test_frames": int((~main).sum())}
        if (~main).any():
            stress["stress_mean_absolute_error"] = float(np.abs(predicted[~main] - true[~main]).mean())
        headline = steering_metrics(true[main], predicted[main], steering.lock_deg, steering.steering_ratio)
        return {**headline, **collapse, **stress, "by_true_magnitude": bins}

    stage = steering_stage(steering.slip, steering.target)
    spec = RunSpec(
        stage=stage,
        out_dir=Path(steering.out_dir),
        out_key="steering.out_dir",
        key=run_identity(cfg, stage, settings, files),
        max_epochs=steering.max_epochs,
        patience=steering.patience,
        write_more=write_predictions,
        input_size=(steering.height, steering.width),
        manifests={context: Path(steering.split_dir) / f"{name}.csv" for context, name in MANIFEST_CONTEXTS},
        register_as=steering_folder(steering.slip, steering.target).replace("steering", "pilotnet"),  # pilotnet, pilotnet_slip, ...
    )
    tags = {"stage": stage, "model": "pilotnet", "slip": str(steering.slip).lower(), "target": steering.target}
    logger = training_logger(cfg, f"{stage} pilotnet", tags, OmegaConf.to_container(cfg, resolve=True))
    results = fit(cfg, task, data, spec, logger)
    metrics = {k: v for k, v in results.items() if k not in ("by_true_magnitude", "global_step") and not k.startswith("test/")}
    true, predicted = scored["true"], scored["predicted"]
    write_text_atomic(steering.metrics_path, json.dumps(metrics, indent=2) + "\n", stage)
    pairs = "".join(f"{a:.6f},{b:.6f}\n" for a, b in zip(true, predicted, strict=True))
    write_text_atomic(steering.plots_path, "truth,prediction\n" + pairs, stage)
    if logger is not None:
        logger.log_metrics({f"test/{k}": v for k, v in metrics.items() if isinstance(v, float)})
    if isinstance(logger, MLFlowLogger):
        for name in ("scatter.png", "error_by_magnitude.csv"):
            logger.experiment.log_artifact(logger.run_id, str(Path(steering.out_dir) / name))
    if metrics["collapsed"]:
        log.warning("PilotNet collapsed to a near-constant output: %s", "; ".join(metrics["collapse_reasons"]))
    log.info(
        "PilotNet: test mean absolute error %.4f (%.1f degrees at the steering wheel; straight ahead would score %.4f), "
        "largest predicted magnitude %.3f of true %.3f",
        metrics["mean_absolute_error"],
        metrics["mean_absolute_error_steering_wheel_deg"],
        metrics["straight_ahead_mean_absolute_error"],
        metrics["largest_predicted_magnitude"],
        metrics["largest_true_magnitude"],
    )
    return metrics
