"""What the three segmentation networks share: width scaling, any input size, a swappable head."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def scaled(channels: int, width: float) -> int:
    """Channel count under the width multiplier (width 1: the original network)."""
    return max(1, round(channels * width))


def conv_bn_relu(cin: int, cout: int, batch_norm: bool = True) -> list[nn.Module]:
    # Biases even before batch norm, as VGG16-BN has them: its ImageNet weights then load whole.
    layers: list[nn.Module] = [nn.Conv2d(cin, cout, 3, padding=1)]
    if batch_norm:
        layers.append(nn.BatchNorm2d(cout))
    layers.append(nn.ReLU(inplace=True))
    return layers


def conv_stages(stages: list[list[int]], in_channels: int, batch_norm: bool = True) -> list[list[nn.Module]]:
    """The layers of a stack of conv stages (VGG's, the encoder's): each conv's output channels."""
    out, cin = [], in_channels
    for stage in stages:
        layers: list[nn.Module] = []
        for cout in stage:
            layers += conv_bn_relu(cin, cout, batch_norm)
            cin = cout
        out.append(layers)
    return out


class SegmentationNet(nn.Module):
    """Per-pixel class scores (N, C, H, W) for images (N, 3, H, W) of any size.

    Inputs are padded to a multiple of `stride` (the network's total downsampling) and the scores
    cropped back, so every architecture sees whole pooling windows.
    """

    stride = 32
    title = ""  # the name the results table prints ("U-Net"); the registry key when empty

    def __init__(self, num_classes: int):
        super().__init__()
        self.num_classes = num_classes

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        ph, pw = -h % self.stride, -w % self.stride
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph))
        return self.forward_padded(x)[..., :h, :w]

    def forward_padded(self, x: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def head_parameters(self) -> list[str]:
        """Names of the parameters that depend on the number of classes."""
        raise NotImplementedError

    def replace_head(self, num_classes: int) -> None:
        """New class-dependent layers for `num_classes` (fine-tuning after pretraining)."""
        raise NotImplementedError
