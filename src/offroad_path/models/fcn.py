"""FCN-8s: Long, Shelhamer and Darrell, "Fully Convolutional Networks for Semantic
Segmentation", CVPR 2015.

VGG16 (no batch norm) with fc6/fc7 recast as 7x7 and 1x1 convolutions with dropout; class scores
from fc7 are upsampled 2x and fused with scores from pool4, again with pool3, then upsampled 8x.
Upsampling layers start as bilinear interpolation, the class scoring layers at zero (Long et al.,
section 4.3). About 134 M parameters at width 1.

Initialisation: the 15 convolutions before the scores have no batch norm, and PyTorch's default
initialisation (variance 1 / (3 fan_in)) shrinks the signal at every layer, so from scratch the
network often learnt only the class biases (all background; 2 of 3 laptop seeds). The convolutions
start as He et al. (2015) and torchvision's VGG do: normal, variance 2 / fan_out, biases at zero.
batch_norm=True puts batch normalisation after each of the 13 VGG convolutions (as VGG16-BN; not in
Long et al.): the laptop recipe's (benchmarks/README.md, "Training recipe").
"""

from __future__ import annotations

import torch
from torch import nn

from offroad_path.models.base import SegmentationNet, conv_stages, scaled
from offroad_path.models.segnet import VGG16


def bilinear_kernel(channels: int, size: int) -> torch.Tensor:
    """ConvTranspose2d weights (channels, channels, size, size) that upsample bilinearly."""
    factor = (size + 1) // 2
    centre = factor - 1 if size % 2 == 1 else factor - 0.5
    og = torch.arange(size, dtype=torch.float32)
    filt = (1 - (og - centre).abs() / factor)[:, None] * (1 - (og - centre).abs() / factor)[None, :]
    weight = torch.zeros(channels, channels, size, size)
    weight[range(channels), range(channels)] = filt
    return weight


class FCN8s(SegmentationNet):
    title = "FCN"

    def __init__(self, num_classes: int = 2, width: float = 1.0, in_channels: int = 3, dropout: float = 0.5, batch_norm: bool = False):
        super().__init__(num_classes)
        stages = [[scaled(c, width) for c in stage] for stage in VGG16]
        self.features = nn.ModuleList(
            nn.Sequential(*layers, nn.MaxPool2d(2, 2)) for layers in conv_stages(stages, in_channels, batch_norm=batch_norm)
        )
        cin = stages[-1][-1]
        fc = scaled(4096, width)
        self.fc6 = nn.Sequential(nn.Conv2d(cin, fc, 7, padding=3), nn.ReLU(inplace=True), nn.Dropout2d(dropout))
        self.fc7 = nn.Sequential(nn.Conv2d(fc, fc, 1), nn.ReLU(inplace=True), nn.Dropout2d(dropout))
        self._channels = (stages[2][-1], stages[3][-1], fc)
        for conv in [m for m in self.modules() if isinstance(m, nn.Conv2d)]:
            nn.init.kaiming_normal_(conv.weight, mode="fan_out", nonlinearity="relu")
            nn.init.zeros_(conv.bias)
        self._build_head(num_classes)

    def _build_head(self, num_classes: int) -> None:
        pool3, pool4, fc = self._channels
        self.score_fr = nn.Conv2d(fc, num_classes, 1)
        self.score_pool4 = nn.Conv2d(pool4, num_classes, 1)
        self.score_pool3 = nn.Conv2d(pool3, num_classes, 1)
        self.upscore2 = nn.ConvTranspose2d(num_classes, num_classes, 4, stride=2, padding=1, bias=False)
        self.upscore_pool4 = nn.ConvTranspose2d(num_classes, num_classes, 4, stride=2, padding=1, bias=False)
        self.upscore8 = nn.ConvTranspose2d(num_classes, num_classes, 16, stride=8, padding=4, bias=False)
        for up in (self.upscore2, self.upscore_pool4, self.upscore8):
            up.weight.data.copy_(bilinear_kernel(num_classes, up.kernel_size[0]))
        for score in (self.score_fr, self.score_pool4, self.score_pool3):
            nn.init.zeros_(score.weight)
            nn.init.zeros_(score.bias)
        self.num_classes = num_classes

    def forward_padded(self, x: torch.Tensor) -> torch.Tensor:
        pools = []
        for stage in self.features:
            x = stage(x)
            pools.append(x)
        score = self.upscore2(self.score_fr(self.fc7(self.fc6(x))))  # 1/16
        score = self.upscore_pool4(score + self.score_pool4(pools[3]))  # 1/8
        return self.upscore8(score + self.score_pool3(pools[2]))  # full size

    def head_parameters(self) -> list[str]:
        names = ("score_fr", "score_pool4", "score_pool3", "upscore2", "upscore_pool4", "upscore8")
        return [n for n, _ in self.named_parameters() if n.split(".")[0] in names]

    def replace_head(self, num_classes: int) -> None:
        self._build_head(num_classes)
