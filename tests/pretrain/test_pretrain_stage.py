"""The pretrain stage on tiny inputs: pretraining, then fine-tuning from it or from the world's path network."""

from __future__ import annotations

import pytest
import torch

from offroad_path.models import build_model
from offroad_path.pretrain import pretrain
from offroad_path.train import train
from offroad_path.training.pretrained import from_path_network, from_segmentation

UNET_MODULES = {"down.0", "down.1", "down.2", "down.3", "bottom", "up.0", "up.1", "up.2", "up.3", "upconv", "classifier"}


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
