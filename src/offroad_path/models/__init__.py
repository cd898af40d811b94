"""The path-prediction networks of Holder & Breckon 2018, selectable by name."""

from __future__ import annotations

from offroad_path.config.training_schema import check_batch_norm
from offroad_path.models.base import SegmentationNet
from offroad_path.models.fcn import FCN8s
from offroad_path.models.segnet import SegNet
from offroad_path.models.unet import UNet

MODELS: dict[str, type[SegmentationNet]] = {"segnet": SegNet, "fcn": FCN8s, "unet": UNet}


def build_model(name: str, num_classes: int = 2, width: float = 1.0, batch_norm: bool | None = None) -> SegmentationNet:
    """batch_norm: the choice of a network that has one (FCN-8s); None: the network's own."""
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; valid: {', '.join(sorted(MODELS))}")
    check_batch_norm(name, batch_norm)
    return MODELS[name](num_classes=num_classes, width=width, **({} if batch_norm is None else {"batch_norm": batch_norm}))


__all__ = ["MODELS", "FCN8s", "SegNet", "SegmentationNet", "UNet", "build_model"]
