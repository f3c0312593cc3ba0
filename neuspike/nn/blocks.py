"""Convolution blocks with instance normalisation before ReLU (the NeuSpike-Net encoder/decoder parts).

Shapes use the project's letters: B batch, C channels, H, W. Instance normalisation is affine
(a learned scale and shift per channel) and keeps no running statistics, so training and
inference compute the same thing.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ConvNormReLU", "UpConvNormReLU", "NormResidualBlock"]


def _norm(channels: int) -> nn.InstanceNorm2d:
    return nn.InstanceNorm2d(channels, affine=True, track_running_stats=False)


class ConvNormReLU(nn.Module):
    """3x3 convolution (stride 1 or 2, padding 1), instance norm, ReLU.

    (B, C_in, H, W) -> (B, C_out, ceil(H / stride), ceil(W / stride)).
    """

    def __init__(self, in_channels: int, out_channels: int, stride: int = 1) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, 3, stride=stride, padding=1)
        self.norm = _norm(out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.norm(self.conv(x)))


class UpConvNormReLU(nn.Module):
    """3x3 transposed convolution (stride 2, padding 1, output padding 1), instance norm, ReLU.

    (B, C_in, H, W) -> (B, C_out, 2H, 2W).
    """

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.conv = nn.ConvTranspose2d(in_channels, out_channels, 3, stride=2, padding=1, output_padding=1)
        self.norm = _norm(out_channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.norm(self.conv(x)))


class NormResidualBlock(nn.Module):
    """conv 3x3, instance norm, ReLU, conv 3x3, instance norm, + input, ReLU; (B, C, H, W) -> same."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv_a = nn.Conv2d(channels, channels, 3, padding=1)
        self.norm_a = _norm(channels)
        self.conv_b = nn.Conv2d(channels, channels, 3, padding=1)
        self.norm_b = _norm(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.norm_a(self.conv_a(x)))
        return F.relu(self.norm_b(self.conv_b(y)) + x)
