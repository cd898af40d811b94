"""Initialising a network before training: from the pretrain stage (8-class semantic
segmentation, then a new 2-class head, as the thesis did) or from VGG16(-BN) ImageNet weights
in torchvision's state-dict layout, read from a local file (nothing is downloaded)."""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from offroad_path.models import FCN8s, SegmentationNet, SegNet
from offroad_path.training.checkpoints import CheckpointError, load_checkpoint

CHOICES = ("none", "segmentation", "imagenet")


def initialise(model: SegmentationNet, name: str, cfg, arch: str, width: float) -> list[str]:
    """Apply pretraining `name` to `model`; returns the names of the parameters it set."""
    if name == "none":
        return []
    if name == "segmentation":
        return from_segmentation(model, Path(cfg.checkpoint), arch, width)
    if name == "imagenet":
        return from_imagenet_vgg(model, Path(cfg.weights_path) if cfg.weights_path else None)
    raise ValueError(f"unknown pretraining {name!r}; valid: {', '.join(CHOICES)}")


def from_segmentation(model: SegmentationNet, checkpoint: Path, arch: str, width: float) -> list[str]:
    """Load a pretrain-stage checkpoint of the same architecture, then give it `model`'s head."""
    if not checkpoint.is_file():
        raise FileNotFoundError(f"{checkpoint}: no pretraining checkpoint; run `python -m offroad_path.pretrain model={arch}` first")
    saved = load_checkpoint(checkpoint)
    hp = saved["hyper_parameters"]
    if hp.get("model") != arch or hp.get("width") != width:
        raise ValueError(
            f"{checkpoint}: holds a {hp.get('model')} of width {hp.get('width')}, not the {arch} of width {width} being trained"
        )
    state = {k.removeprefix("model."): v for k, v in saved["state_dict"].items() if k.startswith("model.")}
    num_classes = model.num_classes
    model.replace_head(hp["num_classes"])
    try:
        model.load_state_dict(state)
    except RuntimeError as e:
        raise CheckpointError(f"{checkpoint}: its weights do not fit a {arch} ({str(e).strip().splitlines()[0]})") from e
    model.replace_head(num_classes)
    head = set(model.head_parameters())
    return [k for k in state if k not in head]


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


def from_imagenet_vgg(model: SegmentationNet, path: Path | None) -> list[str]:
    """Copy VGG16 (FCN) or VGG16-BN (SegNet) ImageNet weights into the encoder, by layer order."""
    if not isinstance(model, SegNet | FCN8s):
        raise ValueError("imagenet pretraining exists for the VGG16 encoders of segnet and fcn, not this model")
    state = _vgg_state(path)
    index = lambda key: int(key.split(".")[1])  # noqa: E731
    convs = sorted({index(k) for k, v in state.items() if k.startswith("features.") and k.endswith(".weight") and v.ndim == 4})
    norms = sorted({index(k) for k in state if k.startswith("features.") and k.endswith(".running_mean")})
    encoder = model.encoder if isinstance(model, SegNet) else model.features
    ours_conv = [m for m in encoder.modules() if isinstance(m, nn.Conv2d)]
    ours_bn = [m for m in encoder.modules() if isinstance(m, nn.BatchNorm2d)]
    if len(convs) != len(ours_conv) or len(norms) != len(ours_bn):
        kind = "VGG16-BN" if ours_bn else "VGG16 without batch norm"
        raise ValueError(f"{path}: has {len(convs)} convolutions and {len(norms)} batch norms; this encoder needs {kind}")
    loaded = []
    pairs = [(f"features.{i}", m, ("weight", "bias")) for i, m in zip(convs, ours_conv, strict=True)]
    pairs += [(f"features.{i}", m, ("weight", "bias", "running_mean", "running_var")) for i, m in zip(norms, ours_bn, strict=True)]
    if isinstance(model, FCN8s):  # fc6 / fc7 as convolutions: the same numbers, reshaped
        pairs += [("classifier.0", model.fc6[0], ("weight", "bias")), ("classifier.3", model.fc7[0], ("weight", "bias"))]
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
