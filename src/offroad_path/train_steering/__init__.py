"""Stage `train_steering`: the end-to-end baseline, PilotNet trained on every frame's steering angle
of the training sequences, tested on the path split's held-out stretches (see offroad_path.steering).

    python -m offroad_path.train_steering [steering.lr=2e-4] [steering.max_epochs=30]
    python -m offroad_path.train_steering steering.slip=true  # slippery ground: data/steering_slip/seed0 (train_steering_slip)
    python -m offroad_path.train_steering steering.target=curvature  # data/steering_curvature/seed0 (train_steering_curvature)

Writes steering.out_dir (data/steering/seed<seed>; steering_slip/ with slip): checkpoints/best.ckpt,
metrics.json, predictions.csv (true and predicted angle per test frame), error_by_magnitude.csv, scatter.png (the thesis's Fig. 5.4);
steering.metrics_path for `dvc metrics show`; steering.plots_path for `dvc plots show`; an MLflow run.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig

from offroad_path.config import steering_stage
from offroad_path.data.labels import label_run_folders
from offroad_path.data.manifest import manifest_folders
from offroad_path.stage import hydra_stage, reads
from offroad_path.training.stage_outputs import logger_folder
from offroad_path.utils.outputs import Outputs


def outputs(cfg: DictConfig) -> Outputs:
    steering = cfg.steering
    inputs = [*label_run_folders(steering.labels_dir), steering.split_dir, *manifest_folders(Path(steering.split_dir) / "train.csv")]
    files = {"steering.metrics_path": steering.metrics_path, "steering.plots_path": steering.plots_path}
    # Three stages in dvc.yaml (train_steering, _slip, _curvature): none replaces another's outputs.
    return Outputs(
        steering_stage(steering.slip, steering.target),
        folders={"steering.out_dir": steering.out_dir},
        files=files,
        inputs=inputs,
        shared=logger_folder(cfg),
    )


@reads("steering", "split", "world", "trainer", "callbacks", "logger", "mlflow", writes=outputs)
def train_steering(cfg: DictConfig) -> dict:
    from offroad_path.train_steering.fitting import fit_steering  # torch and Lightning: after the config is checked

    return fit_steering(cfg)


main = hydra_stage(train_steering)
