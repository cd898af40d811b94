"""U-Net: Ronneberger, Fischer and Brox, "U-Net: Convolutional Networks for Biomedical Image
Segmentation", MICCAI 2015.

Four down steps (two 3x3 convolutions, then a 2x2 max-pool), a bottom of two convolutions, four
up steps (a 2x2 up-convolution halving the channels, concatenation with the encoder's features,
two convolutions): 18 3x3 convolutions, then a 1x1 classifier. Padded convolutions keep the
size, and batch normalisation follows each convolution. About 31 M parameters at width 1.
"""

from __future__ import annotations

import torch
from torch import nn

from offroad_path.models.base import SegmentationNet, conv_bn_relu, scaled

CHANNELS = (64, 128, 256, 512, 1024)


def double_conv(cin: int, cout: int, batch_norm: bool) -> nn.Sequential:
    return nn.Sequential(*conv_bn_relu(cin, cout, batch_norm), *conv_bn_relu(cout, cout, batch_norm))


class UNet(SegmentationNet):
    title = "U-Net"
    stride = 16

    def __init__(self, num_classes: int = 2, width: float = 1.0, in_channels: int = 3, batch_norm: bool = True):
        super().__init__(num_classes)
        ch = [scaled(c, width) for c in CHANNELS]
        self.down = nn.ModuleList()
        cin = in_channels
        for c in ch[:-1]:
            self.down.append(double_conv(cin, c, batch_norm))
            cin = c
        self.bottom = double_conv(ch[-2], ch[-1], batch_norm)
        self.upconv = nn.ModuleList()
        self.up = nn.ModuleList()
        for lower, upper in zip(ch[:0:-1], ch[-2::-1], strict=True):
            self.upconv.append(nn.ConvTranspose2d(lower, upper, 2, stride=2))
            self.up.append(double_conv(2 * upper, upper, batch_norm))
        self.classifier = nn.Conv2d(ch[0], num_classes, 1)
        self.pool = nn.MaxPool2d(2, 2)

    def forward_padded(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            x = self.pool(x)
        x = self.bottom(x)
        for upconv, block, skip in zip(self.upconv, self.up, reversed(skips), strict=True):
            x = block(torch.cat([skip, upconv(x)], dim=1))
        return self.classifier(x)

    def head_parameters(self) -> list[str]:
        return ["classifier.weight", "classifier.bias"]

    def replace_head(self, num_classes: int) -> None:
        self.classifier = nn.Conv2d(self.classifier.in_channels, num_classes, 1)
        self.num_classes = num_classes
