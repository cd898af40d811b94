"""SegNet: Badrinarayanan, Kendall and Cipolla, "SegNet: A Deep Convolutional Encoder-Decoder
Architecture for Image Segmentation", IEEE TPAMI 2017.

The encoder is VGG16-BN's 13 convolutions with 5 max-pools; the decoder mirrors it, upsampling
with the encoder's saved pooling indices (max-unpooling). About 29.4 M parameters at width 1.
"""

from __future__ import annotations

import torch
from torch import nn

from offroad_path.models.base import SegmentationNet, conv_stages, scaled

# VGG16 stages: output channels of each 3x3 convolution, a max-pool after each stage.
VGG16 = ((64, 64), (128, 128), (256, 256, 256), (512, 512, 512), (512, 512, 512))


class SegNet(SegmentationNet):
    title = "SegNet"

    def __init__(self, num_classes: int = 2, width: float = 1.0, in_channels: int = 3):
        super().__init__(num_classes)
        stages = [[scaled(c, width) for c in stage] for stage in VGG16]
        self.encoder = nn.ModuleList(nn.Sequential(*layers) for layers in conv_stages(stages, in_channels))
        # Decoder stage i mirrors encoder stage i: same convolutions in reverse, ending on the
        # channel count that entered the encoder stage (the first stage ends on the classifier).
        self.decoder = nn.ModuleList()
        for i in reversed(range(len(stages))):
            stage = stages[i]
            outs = [*stage[::-1][1:], stages[i - 1][-1] if i > 0 else stage[0]]
            (layers,) = conv_stages([outs], stage[-1])
            self.decoder.append(nn.Sequential(*layers))
        self.classifier = nn.Conv2d(stages[0][0], num_classes, 3, padding=1)
        self.pool = nn.MaxPool2d(2, 2, return_indices=True)
        self.unpool = nn.MaxUnpool2d(2, 2)

    def forward_padded(self, x: torch.Tensor) -> torch.Tensor:
        indices, sizes = [], []
        for stage in self.encoder:
            x = stage(x)
            sizes.append(x.shape)
            x, idx = self.pool(x)
            indices.append(idx)
        for stage, idx, size in zip(self.decoder, reversed(indices), reversed(sizes), strict=True):
            x = stage(self.unpool(x, idx, output_size=size))
        return self.classifier(x)

    def head_parameters(self) -> list[str]:
        return ["classifier.weight", "classifier.bias"]

    def replace_head(self, num_classes: int) -> None:
        self.classifier = nn.Conv2d(self.classifier.in_channels, num_classes, 3, padding=1)
        self.num_classes = num_classes
