"""Training and pretraining on tiny inputs: every architecture runs, resume continues, MLflow
records runs (children of a sweep in a multirun), pretrained weights load or fail clearly."""

from __future__ import annotations

import itertools
import json
import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from helpers import command, hand_counted_iou

from offroad_path.models import MODELS, build_model
from offroad_path.pretrain import pretrain
from offroad_path.train import train
from offroad_path.training.pretrained import from_imagenet_vgg, from_path_network, from_segmentation


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


def test_pretrain_then_fine_tune_from_it(compose_config, split_dir, tmp_path, tiny_config):
    cfg = tiny_config(tmp_path, "model=unet", "trainer.max_epochs=1", "mlflow.enabled=false")
    assert pretrain(cfg)["best_val_iou"] is not None
    checkpoint = tmp_path / "pretrain" / "checkpoints" / "best.ckpt"
    saved = {k.removeprefix("model."): v for k, v in torch.load(checkpoint, weights_only=False)["state_dict"].items()}
    model = build_model("unet", 2, 0.125)
    loaded = from_segmentation(model, checkpoint, "unet", 0.125)
    assert len(loaded) == len(saved) - 2  # all but the 8-class classifier's weight and bias
    for name in loaded:
        assert torch.equal(model.state_dict()[name], saved[name])
    assert model.classifier.out_channels == 2
    fine = train(tiny_config(tmp_path, "model=unet", "pretraining=segmentation", f"pretraining.checkpoint={checkpoint}",
                      "trainer.fast_dev_run=true", "mlflow.enabled=false"))  # fmt: skip
    assert "test/iou" in fine
    with pytest.raises(ValueError, match=r"holds a unet of width 0\.125, not the segnet"):
        from_segmentation(build_model("segnet", 2, 0.125), checkpoint, "segnet", 0.125)


# Every layer of U-Net (models/unet.py), by module: pretraining=world loads each, the 2-class head too.
UNET_MODULES = {"down.0", "down.1", "down.2", "down.3", "bottom", "up.0", "up.1", "up.2", "up.3", "upconv", "classifier"}


def test_fine_tuning_from_the_world_loads_every_layer_of_the_path_network(compose_config, trained, tiny_config, tmp_path):
    """pretraining=world: a train-stage checkpoint of the same architecture gives every
    layer, the classifier's weight and bias included, and nothing is left at random."""
    checkpoint = trained[0]
    saved = {k.removeprefix("model."): v for k, v in torch.load(checkpoint, weights_only=True)["state_dict"].items()}
    model = build_model("unet", 2, 0.125)
    loaded = from_path_network(model, checkpoint, "unet", 0.125)
    assert loaded == list(model.state_dict())
    assert {name.rsplit(".", 2)[0] if name.count(".") > 1 else name.split(".")[0] for name in loaded} == UNET_MODULES
    assert {"classifier.weight", "classifier.bias", "down.0.0.weight", "bottom.0.weight"} <= set(loaded)
    for name, tensor in model.state_dict().items():
        assert torch.equal(tensor, saved[name]), name
    assert (
        compose_config("pretraining=world", "model=fcn", "seed=2").pretraining.checkpoint
        == "data/runs/fcn-none/seed2/checkpoints/best.ckpt"
    )
    fine = train(tiny_config(tmp_path, "model=unet", "pretraining=world", f"pretraining.checkpoint={checkpoint}",
                             "trainer.fast_dev_run=true", "mlflow.enabled=false"))  # fmt: skip
    assert "test/iou" in fine
    with pytest.raises(ValueError, match=r"holds a unet of width 0\.125, not the fcn"):
        from_path_network(build_model("fcn", 2, 0.125), checkpoint, "fcn", 0.125)
    with pytest.raises(ValueError, match=r"holds a 2-class network .*not a 8-class path network"):
        from_path_network(build_model("unet", 8, 0.125), checkpoint, "unet", 0.125)


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


def write_vgg(path: Path, batch_norm: bool, width: float = 1.0) -> None:
    """A file in torchvision's VGG16(-BN) state-dict layout, with random tensors."""
    state, index, cin = {}, 0, 3
    for stage in ((64, 64), (128, 128), (256, 256, 256), (512, 512, 512), (512, 512, 512)):
        for c in stage:
            c = round(c * width)
            state[f"features.{index}.weight"], state[f"features.{index}.bias"] = torch.randn(c, cin, 3, 3), torch.randn(c)
            if batch_norm:
                for attr in ("weight", "bias", "running_mean", "running_var"):
                    state[f"features.{index + 1}.{attr}"] = torch.rand(c)
            index += 3 if batch_norm else 2
            cin = c
        index += 1  # the max-pool
    fc = round(4096 * width)
    state |= {"classifier.0.weight": torch.randn(fc, cin * 49), "classifier.0.bias": torch.randn(fc),
              "classifier.3.weight": torch.randn(fc, fc), "classifier.3.bias": torch.randn(fc),
              "classifier.6.weight": torch.randn(1000, fc), "classifier.6.bias": torch.randn(1000)}  # fmt: skip
    torch.save(state, path)


def test_imagenet_weights_load_into_every_encoder_layer(tmp_path):
    write_vgg(tmp_path / "vgg16_bn.pth", batch_norm=True)
    segnet = build_model("segnet", 2, 1.0)
    loaded = from_imagenet_vgg(segnet, tmp_path / "vgg16_bn.pth")
    assert len(loaded) == 13 * 2 + 13 * 4  # every encoder convolution and batch norm
    source = torch.load(tmp_path / "vgg16_bn.pth")
    assert torch.equal(segnet.encoder[0][0].weight, source["features.0.weight"])
    assert torch.equal(segnet.encoder[4][-2].running_var, source["features.41.running_var"])


def test_imagenet_fc_layers_become_fcn_convolutions(tmp_path):
    write_vgg(tmp_path / "vgg16.pth", batch_norm=False, width=0.125)
    fcn = build_model("fcn", 2, 0.125)
    loaded = from_imagenet_vgg(fcn, tmp_path / "vgg16.pth")
    assert len(loaded) == 13 * 2 + 4
    source = torch.load(tmp_path / "vgg16.pth")
    assert torch.equal(fcn.fc6[0].weight.flatten(1), source["classifier.0.weight"])


def test_imagenet_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing is downloaded"):
        from_imagenet_vgg(build_model("segnet", 2, 1.0), tmp_path / "missing.pth")
    write_vgg(tmp_path / "vgg16.pth", batch_norm=False, width=0.125)
    with pytest.raises(ValueError, match=r"vgg16\.pth: has 13 convolutions and 0 batch norms; this encoder needs VGG16-BN"):
        from_imagenet_vgg(build_model("segnet", 2, 0.125), tmp_path / "vgg16.pth")
    (tmp_path / "junk.pth").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=r"junk\.pth: not a PyTorch state dict"):
        from_imagenet_vgg(build_model("fcn", 2, 0.125), tmp_path / "junk.pth")
    state = torch.load(tmp_path / "vgg16.pth")
    torch.save({k: v for k, v in state.items() if not k.startswith("features.28.")}, tmp_path / "vgg12.pth")
    with pytest.raises(ValueError, match=r"vgg12\.pth: has 12 convolutions and 0 batch norms; U-Net reads VGG16 or VGG16-BN"):
        from_imagenet_vgg(build_model("unet", 2, 0.125), tmp_path / "vgg12.pth")


@pytest.mark.parametrize("batch_norm", [True, False])
def test_imagenet_weights_fill_the_first_two_convolutions_of_each_unet_level(tmp_path, batch_norm):
    write_vgg(tmp_path / "vgg.pth", batch_norm=batch_norm, width=0.125)
    unet = build_model("unet", 2, 0.125)
    bottom = unet.bottom[0].weight.clone()
    loaded = from_imagenet_vgg(unet, tmp_path / "vgg.pth")
    assert len(loaded) == 4 * 2 * (2 + (4 if batch_norm else 0))
    source = torch.load(tmp_path / "vgg.pth")
    step = 3 if batch_norm else 2  # torchvision's index of the k-th convolution: conv, [bn,] relu, and a pool after each level
    first_of_level = [0, 2 * step + 1, 4 * step + 2, 7 * step + 3]  # VGG16's levels hold 2, 2, 3, 3 convolutions
    for level, index in enumerate(first_of_level):
        assert torch.equal(unet.down[level][0].weight, source[f"features.{index}.weight"])
        second = unet.down[level][3]  # conv, bn, relu, conv
        assert torch.equal(second.weight, source[f"features.{index + step}.weight"])
    if batch_norm:
        assert torch.equal(unet.down[3][1].running_var, source[f"features.{7 * step + 3 + 1}.running_var"])
    assert torch.equal(unet.bottom[0].weight, bottom)  # no VGG counterpart: left as initialised


def test_unknown_choices_list_the_valid_ones(compose_config, split_dir, tmp_path, tiny_config):
    from hydra.errors import ConfigCompositionException

    with pytest.raises(ConfigCompositionException, match="model"):
        compose_config("model=deeplab")
    with pytest.raises(ValueError, match="valid: none, segmentation, world, imagenet"):
        train(tiny_config(tmp_path, "pretraining.name=places365", "trainer.fast_dev_run=true", "mlflow.enabled=false"))


def test_same_seed_same_metrics(compose_config, split_dir, tmp_path, tiny_config):
    runs = [train(tiny_config(tmp_path / str(i), "model=segnet", "trainer.max_epochs=1", "mlflow.enabled=false")) for i in range(2)]
    assert runs[0] == runs[1]


def test_the_schedule_warms_up_then_steps_at_fractions_of_the_run():
    import lightning as L

    from offroad_path.training.task import SegmentationTask

    task = SegmentationTask(model="unet", num_classes=2, width=0.125, lr=0.1, lr_milestones=[0.5, 0.75], lr_gamma=0.1,
                            lr_warmup=0.2, momentum=0.9, weight_decay=0.0, channels_last=False)  # fmt: skip
    task.trainer = L.Trainer(max_steps=20, accelerator="cpu", logger=False, enable_checkpointing=False)
    config = task.configure_optimizers()
    optimizer, scheduler = config["optimizer"], config["lr_scheduler"]["scheduler"]
    assert config["lr_scheduler"]["interval"] == "step"
    rates = []
    for _ in range(20):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    expected = [0.1 * (k + 1) / 4 for k in range(4)] + [0.1] * 6 + [0.01] * 5 + [0.001] * 5  # 4 warm-up steps, then /10 at 10 and 15
    np.testing.assert_allclose(rates, expected, rtol=1e-9)
    fixed = SegmentationTask(**dict(task.hparams) | {"lr_milestones": [], "lr_warmup": 0.0})
    assert isinstance(fixed.configure_optimizers(), torch.optim.SGD)


def test_soft_dice_loss_scores_the_path_overlap():
    from offroad_path.training.task import soft_dice_loss

    path = torch.zeros(1, 1, 4, 4, dtype=torch.long)
    path[..., :2] = 1  # 8 of 16 pixels are path
    sure = torch.zeros(1, 2, 4, 4)
    sure[:, 1] = torch.where(path[:, 0] == 1, 20.0, -20.0)  # scores that say exactly the path
    assert soft_dice_loss(sure, path[:, 0]).item() == pytest.approx(0.0, abs=1e-4)
    even = torch.zeros(1, 2, 4, 4)  # probability 1/2 everywhere: overlap 4, sums 8 + 8, Dice (8 + 1) / (16 + 1)
    assert soft_dice_loss(even, path[:, 0]).item() == pytest.approx(1 - 9 / 17, abs=1e-6)


def test_the_cosine_schedule_warms_up_then_anneals_to_zero():
    from offroad_path.training.task import SegmentationTask

    task = SegmentationTask(model="unet", num_classes=2, width=0.125, lr=0.1, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.1,
                            momentum=0.9, weight_decay=0.0, channels_last=False, optimizer="adamw", lr_schedule="cosine")  # fmt: skip
    task.trainer = type("T", (), {"estimated_stepping_batches": 100})()
    configured = task.configure_optimizers()
    optimizer, scheduler = configured["optimizer"], configured["lr_scheduler"]["scheduler"]
    assert isinstance(optimizer, torch.optim.AdamW)
    rates = []
    for _ in range(100):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        scheduler.step()
    assert rates[0] == pytest.approx(0.1 / 10) and rates[9] == pytest.approx(0.1 * 0.5 * (1 + math.cos(math.pi * 0.09)))
    assert max(rates) <= 0.1 and rates[-1] < 1e-4 and all(a >= b for a, b in itertools.pairwise(rates[10:]))
    with pytest.raises(ValueError, match="optimizer 'adam'"):
        SegmentationTask(model="unet", num_classes=2, width=0.125, lr=0.1, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.0,
                         momentum=0.9, weight_decay=0.0, channels_last=False, optimizer="adam")  # fmt: skip
