"""The train stage on tiny inputs: every architecture runs, resume continues, MLflow records runs
(children of a sweep in a multirun), searches and callbacks fail clearly, one seed gives one result."""

from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest
import yaml
from helpers import command, hand_counted_iou

from offroad_path.models import MODELS
from offroad_path.train import train


@pytest.mark.parametrize("model", list(MODELS))
def test_fast_dev_run_trains_tests_and_writes_confidence_maps(compose_config, split_dir, tmp_path, model, tiny_config):
    cfg = tiny_config(tmp_path, f"model={model}", "trainer.fast_dev_run=true", "mlflow.enabled=false")
    metrics = train(cfg)
    assert metrics["test/iou"] == pytest.approx(hand_counted_iou(cfg, tmp_path / "run" / "checkpoints" / "best.ckpt"), abs=1e-6)
    predictions = sorted((tmp_path / "run" / "predictions").rglob("*.npy"))
    test_rows = (split_dir / "test.csv").read_text().splitlines()[1:]
    assert len(predictions) == len(test_rows)
    confidence = np.load(predictions[0])
    assert confidence.dtype == np.float16 and confidence.shape == (288, 512)  # the label's size, not the input's
    assert confidence.min() >= 0.0 and confidence.max() <= 1.0


@pytest.mark.slow(seconds=7)
def test_resume_continues_the_step_count_and_mlflow_has_the_run(compose_config, split_dir, tmp_path, tiny_config):
    first = train(tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1"))
    second = train(tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=2"))
    assert first["global_step"] > 0 and second["global_step"] == 2 * first["global_step"]
    with sqlite3.connect(tmp_path / "mlflow.db") as db:
        runs = db.execute("select run_uuid, name from runs").fetchall()
        keys = {k for (k,) in db.execute("select distinct key from metrics")}
    assert len(runs) == 2 and all(name == "train fcn-none seed0" for _, name in runs)
    assert {"train/loss_epoch", "val/iou", "val/precision", "val/recall", "val/accuracy", "test/iou"} <= keys
    # Artifacts beside the database: validation samples each epoch, the best checkpoint, metrics.
    stored = {p.as_posix().split("/artifacts/", 1)[1] for p in (tmp_path / "mlartifacts").rglob("*") if p.is_file()}
    assert {"samples/epoch_000.png", "checkpoints/best.ckpt", "metrics.json"} <= stored


def test_a_run_that_stopped_early_stays_stopped_when_run_again(tiny_config, tmp_path):
    # min_delta 1: no epoch improves on the first, so early stopping ends the run after 1 + patience epochs.
    overrides = ("model=fcn", "trainer.max_epochs=6", "callbacks.early_stopping.patience=1", "+callbacks.early_stopping.min_delta=1.0",
                 "mlflow.enabled=false")  # fmt: skip
    first = train(tiny_config(tmp_path, *overrides))
    assert first["epochs"] == 2
    published = (tmp_path / "run" / "metrics.json").read_bytes(), (tmp_path / "run" / "checkpoints" / "best.ckpt").read_bytes()
    again = train(tiny_config(tmp_path, *overrides))  # resumes from the finished run's last.ckpt
    assert again == first  # no extra epoch: the same steps, epochs and test metrics
    assert ((tmp_path / "run" / "metrics.json").read_bytes(), (tmp_path / "run" / "checkpoints" / "best.ckpt").read_bytes()) == published


@pytest.mark.slow(seconds=20)
def test_multirun_jobs_are_children_of_one_sweep_run(split_dir, tmp_path, tiny_overrides):
    db = tmp_path / "mlflow.db"
    overrides = [*tiny_overrides, f"data.split_dir={split_dir}", f"train.out_dir={tmp_path}/runs/${{model.name}}",
                 "trainer.fast_dev_run=true", f"mlflow.tracking_uri=sqlite:///{db}", f"hydra.sweep.dir={tmp_path / 'sweep'}"]  # fmt: skip
    run = command("offroad_path.train", "-m", "model=unet,fcn", *overrides, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    with sqlite3.connect(db) as con:
        tags = con.execute("select run_uuid, key, value from tags").fetchall()
    sweeps = {r for r, k, v in tags if k == "sweep_dir" and v == str(tmp_path / "sweep")}
    children = {r for r, k, v in tags if k == "mlflow.parentRunId" and v in sweeps}
    assert len(sweeps) == 1 and len(children) == 2


@pytest.mark.slow(seconds=18)
def test_optuna_search_trains_each_trial_and_reports_the_best(split_dir, tmp_path, tiny_overrides):
    sweep = tmp_path / "sweep"
    tiny = [o for o in tiny_overrides if not o.startswith("model.width=")]  # the search sets the width
    overrides = [*tiny, f"data.split_dir={split_dir}", "trainer.max_epochs=1", "mlflow.enabled=false", f"hydra.sweep.dir={sweep}",
                 "hydra.sweeper.n_trials=2", "hydra.sweeper.sampler.n_startup_trials=1"]  # fmt: skip
    run = command("offroad_path.train", "-m", "hparams_search=path_optuna", *overrides, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    results = yaml.safe_load((sweep / "optimization_results.yaml").read_text())
    assert set(results["best_params"]) == {"model.lr", "model.width"} and 0.0 <= results["best_value"] <= 1.0
    trials = [json.loads((sweep / str(i) / "metrics.json").read_text()) for i in range(2)]
    assert results["best_value"] == pytest.approx(max(t["best_val_iou"] for t in trials))
    assert all((sweep / str(i) / "checkpoints" / "best.ckpt").is_file() for i in range(2))


@pytest.mark.slow(seconds=10)
def test_a_search_for_a_metric_the_stage_does_not_return_says_so(split_dir, tmp_path, tiny_overrides):
    overrides = [*tiny_overrides, f"data.split_dir={split_dir}", "trainer.fast_dev_run=true", "mlflow.enabled=false",
                 f"train.out_dir={tmp_path / 'run'}", "optimized_metric=val_accuracy"]  # fmt: skip
    run = command("offroad_path.train", *overrides, cwd=tmp_path)
    assert run.returncode == 2 and "optimized_metric=val_accuracy: this stage returned no such metric" in run.stderr


@pytest.mark.slow(seconds=8)
def test_a_callback_that_cannot_be_built_is_named(split_dir, tmp_path, tiny_overrides):
    overrides = [*tiny_overrides, f"data.split_dir={split_dir}", "trainer.fast_dev_run=true", "mlflow.enabled=false",
                 f"train.out_dir={tmp_path / 'run'}", "+callbacks.mine._target_=lightning.pytorch.callbacks.NoSuchCallback"]  # fmt: skip
    run = command("offroad_path.train", *overrides, cwd=tmp_path)
    assert run.returncode == 2 and "error: callbacks.mine: cannot be built" in run.stderr, run.stderr[-2000:]
    assert not (tmp_path / "run").exists()


def test_unknown_choices_list_the_valid_ones(compose_config, split_dir, tmp_path, tiny_config):
    from hydra.errors import ConfigCompositionException

    with pytest.raises(ConfigCompositionException, match="model"):
        compose_config("model=deeplab")
    with pytest.raises(ValueError, match="valid: none, segmentation, world, imagenet"):
        train(tiny_config(tmp_path, "pretraining.name=places365", "trainer.fast_dev_run=true", "mlflow.enabled=false"))


def test_same_seed_same_metrics(compose_config, split_dir, tmp_path, tiny_config):
    runs = [train(tiny_config(tmp_path / str(i), "model=segnet", "trainer.max_epochs=1", "mlflow.enabled=false")) for i in range(2)]
    assert runs[0] == runs[1]
