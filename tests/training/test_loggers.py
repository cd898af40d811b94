"""The training stages with the other Lightning loggers of conf/logger: CSV files, and Weights &
Biases in offline mode (what a cluster node without internet does; `wandb sync` uploads it later)."""

from __future__ import annotations

import csv

import pytest
import yaml

from offroad_path.train import train


def test_csv_logger_writes_each_metric_and_the_config(tiny_config, tmp_path):
    cfg = tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1", "logger=csv", f"logger.save_dir={tmp_path / 'logs'}")
    metrics = train(cfg)
    (run,) = (tmp_path / "logs" / "train" / "fcn-none" / "seed0").iterdir()  # named after its stage, run and seed, like the MLflow run
    with open(run / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    logged = {key for row in rows for key, value in row.items() if value}
    assert {"train/loss_epoch", "val/iou", "test/iou"} <= logged
    (test_row,) = [row for row in rows if row["test/iou"]]
    assert float(test_row["test/iou"]) == metrics["test/iou"]
    params = yaml.safe_load((run / "hparams.yaml").read_text())
    assert params["model.name"] == "fcn" and params["seed"] == cfg.seed and params["logger._target_"].endswith("CSVLogger")
    assert not (tmp_path / "mlflow.db").exists()  # the training run's only logger


@pytest.mark.slow(seconds=5)  # a training run with W&B's offline writer: 4 s here, 8.8 s on a slower machine
def test_wandb_logger_offline_records_the_run(tiny_config, tmp_path, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path / "logs"))
    monkeypatch.setenv("WANDB_SILENT", "true")
    cfg = tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1", "logger=wandb", "logger.offline=true",
                      f"logger.save_dir={tmp_path / 'logs'}")  # fmt: skip
    metrics = train(cfg)
    import wandb

    run = wandb.run  # what the logger sent, read back before the run closes
    assert run.offline and run.name == "train fcn-none seed0" and "stage=train" in run.tags
    assert run.config["model.name"] == "fcn" and run.config["logger._target_"].endswith("WandbLogger")
    assert run.summary["test/iou"] == metrics["test/iou"] and run.summary.get("val/iou") is not None
    wandb.finish()
    (folder,) = (tmp_path / "logs" / "wandb").glob("offline-run-*")
    assert (folder / f"run-{run.id}.wandb").stat().st_size > 0  # the run's record, for `wandb sync`
    assert list((folder / "files" / "media" / "images").glob("samples_*.png"))  # the validation samples
