"""PilotNet: Bojarski et al., "End to End Learning for Self-Driving Cars", arXiv:1604.07316, 2016,
at the 256 x 136 input of Holder's reimplementation (PhD thesis, 2018, section 5.1.1).

Five convolutions (three 5x5 with stride 2, two 3x3), three fully connected layers and one
regression output, squashed into [-1, 1] by tanh: the normalised steering angle. About 1.74 M
parameters at 256 x 136, most of them in the first fully connected layer.
"""

from __future__ import annotations

import itertools

import torch
from torch import nn

CONVOLUTIONS = ((24, 5, 2), (36, 5, 2), (48, 5, 2), (64, 3, 1), (64, 3, 1))  # (channels, kernel, stride)
FULLY_CONNECTED = (100, 50, 10)


def feature_size(width: int, height: int) -> tuple[int, int]:
    """(height, width) of the last convolution's output (no padding)."""
    for _, k, s in CONVOLUTIONS:
        width, height = (width - k) // s + 1, (height - k) // s + 1
    if width < 1 or height < 1:
        raise ValueError(f"input {width} x {height} is too small for PilotNet's five convolutions")
    return height, width


class PilotNet(nn.Module):
    def __init__(self, width: int = 256, height: int = 136, in_channels: int = 3):
        super().__init__()
        layers: list[nn.Module] = []
        for channels, k, s in CONVOLUTIONS:
            layers += [nn.Conv2d(in_channels, channels, k, stride=s), nn.ReLU(inplace=True)]
            in_channels = channels
        self.features = nn.Sequential(*layers)
        h, w = feature_size(width, height)
        sizes = (in_channels * h * w, *FULLY_CONNECTED)
        head: list[nn.Module] = [nn.Flatten()]
        for a, b in itertools.pairwise(sizes):
            head += [nn.Linear(a, b), nn.ReLU(inplace=True)]
        head += [nn.Linear(sizes[-1], 1)]
        self.head = nn.Sequential(*head)
        # He initialisation: with PyTorch's default (a third of He's variance per layer) the signal
        # fades through the eight layers to an output that hardly depends on the image, and SGD
        # settles on a constant.
        for m in self.modules():
            if isinstance(m, nn.Conv2d | nn.Linear):
                nn.init.kaiming_normal_(m.weight, nonlinearity="relu")
                nn.init.zeros_(m.bias)
        # The output starts at 0, where tanh passes the gradient whole: He's variance there put the
        # first outputs near +-1, where tanh's gradient vanishes, and the network stayed at a constant.
        nn.init.zeros_(self.head[-1].weight)

    def forward(self, image: torch.Tensor) -> torch.Tensor:  # (N, 3, H, W) -> steering (N,) in [-1, 1]
        return torch.tanh(self.head(self.features(image))[:, 0])
