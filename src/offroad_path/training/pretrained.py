"""Initialising a network before training: from the pretrain stage (8-class semantic
segmentation, then a new 2-class head, as the thesis did), from a path network the train stage
made on the world (fine-tuning on your own driving: every layer), or from VGG16(-BN) ImageNet
weights in torchvision's state-dict layout, read from a local file (nothing is downloaded)."""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from offroad_path.models import FCN8s, SegmentationNet, SegNet, UNet
from offroad_path.training.checkpoints import CheckpointError, load_checkpoint
from offroad_path.training.task import BaseTask

CHOICES = ("none", "segmentation", "world", "imagenet")


def initialise(task: BaseTask, name: str, cfg) -> list[str]:
    """Apply pretraining `name` (its settings `cfg`) to the task's network, whose architecture and width
    the task's hyper-parameters hold; returns the names of the parameters it set."""
    model, arch, width = task.model, task.hparams.model, task.hparams.width
    if name == "none":
        return []
    if name == "segmentation":
        return from_segmentation(model, Path(cfg.checkpoint), arch, width)
    if name == "world":
        return from_path_network(model, Path(cfg.checkpoint), arch, width)
    if name == "imagenet":
        return from_imagenet_vgg(model, Path(cfg.weights_path) if cfg.weights_path else None)
    raise ValueError(f"unknown pretraining {name!r}; valid: {', '.join(CHOICES)}")


def _same_network(checkpoint: Path, arch: str, width: float, made_by: str) -> tuple[dict, dict]:
    """The hyper-parameters and the network's weights of a checkpoint of `arch` at `width`."""
    if not checkpoint.is_file():
        raise FileNotFoundError(f"{checkpoint}: no checkpoint there; run `{made_by}` first (or give pretraining.checkpoint)")
    saved = load_checkpoint(checkpoint)
    hp = saved["hyper_parameters"]
    if hp.get("model") != arch or hp.get("width") != width:
        raise ValueError(
            f"{checkpoint}: holds a {hp.get('model')} of width {hp.get('width')}, not the {arch} of width {width} being trained"
        )
    return hp, {k.removeprefix("model."): v for k, v in saved["state_dict"].items() if k.startswith("model.")}


def from_segmentation(model: SegmentationNet, checkpoint: Path, arch: str, width: float) -> list[str]:
    """Load a pretrain-stage checkpoint of the same architecture, then give it `model`'s head."""
    hp, state = _same_network(checkpoint, arch, width, f"python -m offroad_path.pretrain model={arch}")
    num_classes = model.num_classes
    model.replace_head(hp["num_classes"])
    try:
        model.load_state_dict(state)
    except RuntimeError as e:
        raise CheckpointError(f"{checkpoint}: its weights do not fit a {arch} ({str(e).strip().splitlines()[0]})") from e
    model.replace_head(num_classes)
    head = set(model.head_parameters())
    return [k for k in state if k not in head]


def from_path_network(model: SegmentationNet, checkpoint: Path, arch: str, width: float) -> list[str]:
    """Load every layer, the head too, of a train-stage path network of the same architecture."""
    hp, state = _same_network(checkpoint, arch, width, f"python -m offroad_path.train model={arch}")
    if hp.get("num_classes") != model.num_classes:
        raise ValueError(
            f"{checkpoint}: holds a {hp.get('num_classes')}-class network (a pretrain-stage checkpoint?), "
            f"not a {model.num_classes}-class path network from the train stage"
        )
    try:
        model.load_state_dict(state)
    except RuntimeError as e:
        raise CheckpointError(f"{checkpoint}: its weights do not fit a {arch} ({str(e).strip().splitlines()[0]})") from e
    return list(state)


def _vgg_state(path: Path | None) -> dict:
    """The state dict of a torchvision VGG16(-BN) file, read weights-only."""
    if path is None or not path.is_file():
        raise FileNotFoundError(f"{path}: no VGG16 ImageNet weights there (pretraining.weights_path); nothing is downloaded")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:
        raise ValueError(f"{path}: not a PyTorch state dict ({e})") from e
    if not isinstance(state, dict) or not any(k.startswith("features.") for k in state):
        raise ValueError(f"{path}: not in torchvision's VGG layout (no features.N.weight keys)")
    return state


VGG16_LEVELS = (2, 2, 3, 3, 3)  # 3x3 convolutions between VGG16's max-pools


def from_imagenet_vgg(model: SegmentationNet, path: Path | None) -> list[str]:
    """Copy VGG16 or VGG16-BN ImageNet weights into the encoder: every layer of SegNet's (VGG16-BN)
    and FCN's (VGG16, fc6 / fc7 as convolutions) by layer order; for U-Net the first two
    convolutions of each of VGG's first four levels into its four down levels, which have the same
    shapes (with their batch norms when both have them). U-Net's bottom (1024 channels) has no
    VGG counterpart and stays random."""
    if not isinstance(model, SegNet | FCN8s | UNet):
        raise ValueError(f"imagenet pretraining exists for segnet, fcn and unet, not {type(model).__name__}")
    state = _vgg_state(path)
    index = lambda key: int(key.split(".")[1])  # noqa: E731
    convs = sorted({index(k) for k, v in state.items() if k.startswith("features.") and k.endswith(".weight") and v.ndim == 4})
    norms = sorted({index(k) for k in state if k.startswith("features.") and k.endswith(".running_mean")})
    pairs = _unet_pairs(model, convs, norms, path) if isinstance(model, UNet) else _encoder_pairs(model, convs, norms, path)
    return _copy(model, state, pairs, path)


def _encoder_pairs(model: SegNet | FCN8s, convs: list[int], norms: list[int], path: Path) -> list[tuple[str, nn.Module, tuple]]:
    encoder = model.encoder if isinstance(model, SegNet) else model.features
    ours_conv = [m for m in encoder.modules() if isinstance(m, nn.Conv2d)]
    ours_bn = [m for m in encoder.modules() if isinstance(m, nn.BatchNorm2d)]
    if len(convs) != len(ours_conv) or len(norms) != len(ours_bn):
        kind = "VGG16-BN" if ours_bn else "VGG16 without batch norm"
        raise ValueError(f"{path}: has {len(convs)} convolutions and {len(norms)} batch norms; this encoder needs {kind}")
    pairs = [(f"features.{i}", m, ("weight", "bias")) for i, m in zip(convs, ours_conv, strict=True)]
    pairs += [(f"features.{i}", m, ("weight", "bias", "running_mean", "running_var")) for i, m in zip(norms, ours_bn, strict=True)]
    if isinstance(model, FCN8s):  # fc6 / fc7 as convolutions: the same numbers, reshaped
        pairs += [("classifier.0", model.fc6[0], ("weight", "bias")), ("classifier.3", model.fc7[0], ("weight", "bias"))]
    return pairs


def _unet_pairs(model: UNet, convs: list[int], norms: list[int], path: Path) -> list[tuple[str, nn.Module, tuple]]:
    if len(convs) != sum(VGG16_LEVELS) or len(norms) not in (0, len(convs)):
        raise ValueError(f"{path}: has {len(convs)} convolutions and {len(norms)} batch norms; U-Net reads VGG16 or VGG16-BN")
    pairs = []
    for level, block in enumerate(model.down):
        first = sum(VGG16_LEVELS[:level])
        ours_conv = [m for m in block if isinstance(m, nn.Conv2d)]
        ours_bn = [m for m in block if isinstance(m, nn.BatchNorm2d)]
        for k, conv in enumerate(ours_conv):
            pairs.append((f"features.{convs[first + k]}", conv, ("weight", "bias")))
            if norms and ours_bn:
                pairs.append((f"features.{norms[first + k]}", ours_bn[k], ("weight", "bias", "running_mean", "running_var")))
    return pairs


def _copy(model: SegmentationNet, state: dict, pairs: list[tuple[str, nn.Module, tuple]], path: Path) -> list[str]:
    loaded = []
    names = {id(m): n for n, m in model.named_modules()}
    for key, module, attrs in pairs:
        for attr in attrs:
            source = state.get(f"{key}.{attr}")
            if source is None:
                raise ValueError(f"{path}: lacks {key}.{attr}")
            target = getattr(module, attr)
            if source.numel() != target.numel():
                raise ValueError(
                    f"{path}: {key}.{attr} has shape {tuple(source.shape)}, the model {tuple(target.shape)} (ImageNet weights need width 1)"
                )
            with torch.no_grad():
                target.copy_(source.reshape(target.shape))
            loaded.append(f"{names[id(module)]}.{attr}")
    return loaded
