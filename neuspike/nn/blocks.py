"""Convolution blocks with instance normalisation before ReLU (the NeuSpike-Net encoder/decoder parts).

Shapes use the project's letters: B batch, C channels, H, W. Instance normalisation is affine
(a learned scale and shift per channel) and keeps no running statistics, so training and
inference compute the same thing.

Padded inputs: a network that pads its input to a multiple of its strides (NeuSpike-Net, 250 -> 256
rows) runs inside :func:`valid_extent`, and every norm then takes its statistics over the part of
its feature map that the unpadded image covers (``ceil(h * H_f / H_padded)`` rows at a feature
height ``H_f``, the same for columns; rounding up scored 0.07 dB above rounding down on the grid of
training photographs) and applies them to the whole map. Without it the padding
enters every channel's mean and variance, so the padded band changes the whole image; with it the
padding reaches the rest of the image only through the features near the border that the statistics
include (their receptive fields overlap it), and an image
whose sides are already multiples is normalised exactly as before (the training crops are).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ConvNormReLU", "UpConvNormReLU", "NormResidualBlock", "RegionInstanceNorm", "valid_extent"]

#: (h, w, H, W): the valid rows and columns of the padded input (H, W) being run, or None.
_EXTENT: contextvars.ContextVar[tuple[int, int, int, int] | None] = contextvars.ContextVar("valid_extent", default=None)


@contextlib.contextmanager
def valid_extent(h: int, w: int, padded_h: int, padded_w: int) -> Iterator[None]:
    """Within this block, :class:`RegionInstanceNorm` takes its statistics over the part of each
    feature map that an ``h x w`` image padded to ``padded_h x padded_w`` covers."""
    if not (0 < h <= padded_h and 0 < w <= padded_w):
        raise ValueError(f"valid_extent: {h}x{w} does not fit in {padded_h}x{padded_w}")
    token = _EXTENT.set((h, w, padded_h, padded_w))
    try:
        yield
    finally:
        _EXTENT.reset(token)


class RegionInstanceNorm(nn.InstanceNorm2d):
    """Affine instance normalisation whose statistics cover the valid region (module docstring)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        extent = _EXTENT.get()
        if extent is None:
            return super().forward(x)
        h, w, ph, pw = extent
        hf, wf = x.shape[-2:]
        hv, wv = -(-h * hf // ph), -(-w * wf // pw)  # ceil
        if (hv, wv) == (hf, wf):
            return super().forward(x)
        var, mean = torch.var_mean(x[..., :hv, :wv].float(), dim=(-2, -1), correction=0, keepdim=True)
        y = (x.float() - mean) * torch.rsqrt(var + self.eps)
        y = y * self.weight.float()[:, None, None] + self.bias.float()[:, None, None]
        return y.to(x.dtype)


def _norm(channels: int) -> RegionInstanceNorm:
    return RegionInstanceNorm(channels, affine=True, track_running_stats=False)


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
