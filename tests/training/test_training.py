"""The training library: pretrained weights load or fail clearly, the schedules and the Dice loss
against hand-computed values (the stages that train: tests/train, tests/pretrain)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from offroad_path.models import build_model
from offroad_path.training.pretrained import from_imagenet_vgg

# Every layer of U-Net (models/unet.py), by module: pretraining=world loads each, the 2-class head too.


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


@pytest.mark.slow(seconds=5)  # full-size VGG16 weights written and loaded: 4 to 5 s here, over the budget on slower machines
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
