"""The train_steering stage: a split that follows the path split, balance reaching the training
loader alone, and the stage on a real rendered drive (PilotNet itself: tests/steering)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from offroad_path.data.manifest import read_manifest
from offroad_path.geometry.path import distance_along
from offroad_path.sequence.reader import open_sequence
from offroad_path.steering.angle_dataset import SteeringDataModule
from offroad_path.steering.frames import steering_split
from offroad_path.train_steering import train_steering


def test_split_follows_the_path_split(compose_config, labelled_drive, split_dir):
    cfg = compose_config("split.block_m=4", "split.guard_m=3")
    parts = steering_split(labelled_drive, split_dir, cfg.split.block_m, cfg.split.guard_m, mirror=True)
    seq = open_sequence(json.loads((labelled_drive / "summary.json").read_text())["sequences"][0]["root"])
    at = distance_along(np.loadtxt(labelled_drive / "drive" / "poses_vo.txt").reshape(-1, 3, 4))
    for part in ("val", "test"):
        # every held-out labelled frame of the path split is held out here too, in the same part
        held = {s.f0 for s in read_manifest(split_dir / f"{part}.csv")}
        assert held <= {f.frame for f in parts[part]}
    train_at = at[[f.frame for f in parts["train"]]]
    held_at = at[[f.frame for f in parts["val"] + parts["test"]]]
    assert np.abs(train_at[:, None] - held_at[None, :]).min() >= 3.0
    # mirrored copies sit beside their frame with the angle negated, and angles come from steering.txt
    for a, b in zip(parts["test"][::2], parts["test"][1::2], strict=True):
        assert (a.frame, a.mirrored, b.mirrored) == (b.frame, False, True) and b.steering == -a.steering
        assert a.steering == pytest.approx(seq.steering[a.frame])


@pytest.mark.parametrize("balance", ["oversample", "weighted"])
def test_balance_reaches_the_training_loader_only(compose_config, labelled_drive, split_dir, balance):
    cfg = compose_config("split.block_m=4", "split.guard_m=3", f"steering.balance={balance}")
    parts = steering_split(labelled_drive, split_dir, cfg.split.block_m, cfg.split.guard_m, mirror=True)
    data = SteeringDataModule(parts, cfg.steering, cfg.seed)
    train, val = data.train_dataloader(), data.val_dataloader()
    assert (train.sampler.weights is not None) == (balance == "oversample")
    assert ("weight" in train.dataset[0]) == (balance == "weighted") and "weight" not in val.dataset[0]


def test_stage_fast_dev_run_writes_its_outputs(compose_config, labelled_drive, split_dir, tmp_path):
    cfg = compose_config(f"steering.labels_dir={labelled_drive}", f"steering.split_dir={split_dir}", "split.block_m=4", "split.guard_m=3",
                         f"steering.out_dir={tmp_path / 'steering'}", f"steering.metrics_path={tmp_path / 'steering.json'}",
                         f"steering.plots_path={tmp_path / 'scatter.csv'}", "trainer.fast_dev_run=true",
                         "mlflow.enabled=false")  # fmt: skip
    metrics = train_steering(cfg)
    written = json.loads((tmp_path / "steering.json").read_text())
    assert written.keys() == metrics.keys() and written["straight_ahead_margin_interval"] == metrics["straight_ahead_margin_interval"]
    assert {k: v for k, v in written.items() if isinstance(v, float)} == pytest.approx(
        {k: v for k, v in metrics.items() if isinstance(v, float)}
    )
    assert written["collapsed"] is True  # one step of training: a constant
    rows = (tmp_path / "scatter.csv").read_text().splitlines()
    assert rows[0] == "truth,prediction" and len(rows) - 1 == metrics["test_frames"]
    for name in ("predictions.csv", "error_by_magnitude.csv", "metrics.json", "scatter.png"):
        assert (tmp_path / "steering" / name).is_file()
