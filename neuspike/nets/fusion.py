"""Fusion modules F: merge a texture feature t and a motion feature m of the same shape (B, C, H, W).

Every candidate has the form ``F(t, m) = t + a(t, m) * m``, so ``F(t, 0) = t`` (the spike-only
network is the fusion network with a silent motion path):

* ``"gate"``: a per-pixel, per-channel gate ``a = sigmoid(conv3x3([t, m]))`` (2C -> C channels);
* ``"attention"``: channel attention ``a = sigmoid(W2 relu(W1 [mean(t), mean(m)]))`` with a
  bottleneck of C / 4, one weight per channel for the whole image (squeeze-and-excitation style),
  followed by a 3x3 convolution of the weighted motion feature (C -> C).
"""

from __future__ import annotations

import torch
from torch import nn

from neuspike.errors import InputError

__all__ = ["FUSIONS", "AttentionFusion", "GateFusion", "make_fusion"]

FUSIONS = ("gate", "attention")


class GateFusion(nn.Module):
    """``t + sigmoid(conv3x3([t, m])) * m``; (B, C, H, W) x2 -> (B, C, H, W)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.gate = nn.Conv2d(2 * channels, channels, 3, padding=1)

    def forward(self, t: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        return t + torch.sigmoid(self.gate(torch.cat([t, m], dim=1))) * m


class AttentionFusion(nn.Module):
    """``t + conv3x3(sigmoid(mlp([mean t, mean m])) * m)``; (B, C, H, W) x2 -> (B, C, H, W)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.squeeze = nn.Sequential(nn.Linear(2 * channels, channels // 4), nn.ReLU(),
                                     nn.Linear(channels // 4, channels))
        self.mix = nn.Conv2d(channels, channels, 3, padding=1, bias=False)

    def forward(self, t: torch.Tensor, m: torch.Tensor) -> torch.Tensor:
        pooled = torch.cat([t.mean(dim=(2, 3)), m.mean(dim=(2, 3))], dim=1)
        a = torch.sigmoid(self.squeeze(pooled))[:, :, None, None]
        return t + self.mix(a * m)


def make_fusion(name: str, channels: int) -> nn.Module:
    """The fusion module ``name`` for ``channels`` channels."""
    if name == "gate":
        return GateFusion(channels)
    if name == "attention":
        return AttentionFusion(channels)
    raise InputError(f"fusion: expected one of {FUSIONS}, got {name!r}")
