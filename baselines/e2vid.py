"""E2VID-style recurrent U-Net, trained here on the suite's own simulator (method ``e2vid``).

The architecture follows E2VID (Rebecq et al., TPAMI 2019), written from its published description
(REFERENCE.md §3.2)::

    head      5x5 conv 5 -> 32, ReLU                                   (H,   W)
    enc1      5x5 conv 32 -> 64, stride 2, ReLU, then ConvLSTM(64)      (H/2, W/2)
    enc2      5x5 conv 64 -> 128, stride 2, ReLU, then ConvLSTM(128)    (H/4, W/4)
    enc3      5x5 conv 128 -> 256, stride 2, ReLU, then ConvLSTM(256)   (H/8, W/8)
    res1,res2 residual blocks of 256 channels (3x3 conv, ReLU, 3x3 conv, + input, ReLU)
    dec1      (x + enc3) -> bilinear x2 -> 5x5 conv 256 -> 128, ReLU    (H/4, W/4)
    dec2      (x + enc2) -> bilinear x2 -> 5x5 conv 128 -> 64, ReLU     (H/2, W/2)
    dec3      (x + enc1) -> bilinear x2 -> 5x5 conv 64 -> 32, ReLU      (H,   W)
    pred      (x + head) -> 1x1 conv 32 -> 1, sigmoid

Skips are sums (E2VID's ``skip_type="sum"``); the ConvLSTM cells (:class:`neuspike.nn.ConvLSTM`, 3x3
gates) carry the recurrent state. The input is zero-padded at the bottom and right to a multiple of
8 (three halvings) and the output cropped back, so any size works. :data:`PARAMETERS` = 10,710,401
parameters (the paper quotes 10,700k for E2VID).

The method ``e2vid`` reads its input exactly as FireNet does (it is a :class:`~baselines.firenet.FireNet`
with another module): fixed-count windows of ``0.35 * H * W`` events counted back from the key
instant, at most 24, each a 5-bin voxel grid whose non-zero entries are normalised to mean 0 and
std 1 (E2VID's normalisation); the state is reset at the start of every reconstruction and warmed
up on the sample's event history. Output: the sigmoid's value (already in [0, 1]; label
``"clamp"``, which changes nothing here).

Weights: ``e2vid.safetensors`` (with its JSON card ``e2vid.json``), trained with
``python -m neuspike.train e2vid`` and shipped in ``neuspike/trained/``; found without any
flag and loaded strictly.
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from baselines.firenet import NUM_BINS, FireNet
from neuspike.nn import ConvLSTM, ResidualBlock

__all__ = ["BASE_CHANNELS", "PARAMETERS", "E2VIDModule", "E2VID", "register_methods"]

#: Channels of the head; each encoder doubles them.
BASE_CHANNELS = 32
#: Parameters of :class:`E2VIDModule` with the default sizes.
PARAMETERS = 10_710_401
#: Input sizes are padded to a multiple of this (three stride-2 encoders).
MULTIPLE = 8

State = tuple[tuple[torch.Tensor, torch.Tensor], ...]


class E2VIDModule(nn.Module):
    """The recurrent U-Net; one call advances the three ConvLSTM states by one voxel grid.

    Forward
    -------
    grid : Tensor (B, 5, H, W)
        Event voxel grid (any H, W; padded internally to a multiple of 8).
    state : tuple of three (h, c) pairs or None
        The ConvLSTM states at 1/2, 1/4 and 1/8 of the padded size, float32; ``None`` starts from zeros.

    Returns
    -------
    image : Tensor (B, 1, H, W) in [0, 1]
    state : the new states
    """

    def __init__(self, bins: int = NUM_BINS, base: int = BASE_CHANNELS, levels: int = 3) -> None:
        super().__init__()
        self.head = nn.Conv2d(bins, base, 5, padding=2)
        chans = [base * 2 ** i for i in range(levels + 1)]  # 32, 64, 128, 256
        self.encoders = nn.ModuleList(nn.Conv2d(chans[i], chans[i + 1], 5, stride=2, padding=2)
                                      for i in range(levels))
        self.cells = nn.ModuleList(ConvLSTM(chans[i + 1], chans[i + 1], 3) for i in range(levels))
        self.res = nn.Sequential(ResidualBlock(chans[-1]), ResidualBlock(chans[-1]))
        self.decoders = nn.ModuleList(nn.Conv2d(chans[i + 1], chans[i], 5, padding=2)
                                      for i in reversed(range(levels)))
        self.pred = nn.Conv2d(base, 1, 1)

    def forward(self, grid: torch.Tensor, state: State | None = None) -> tuple[torch.Tensor, State]:
        h, w = grid.shape[-2:]
        pad_h, pad_w = (-h) % MULTIPLE, (-w) % MULTIPLE
        x = F.pad(grid, (0, pad_w, 0, pad_h)) if pad_h or pad_w else grid
        head = F.relu(self.head(x))
        skips = []
        new_state = []
        x = head
        for i, (enc, cell) in enumerate(zip(self.encoders, self.cells)):
            x = F.relu(enc(x))
            x, s = cell(x, None if state is None else state[i])
            new_state.append(s)
            x = x.to(head.dtype)
            skips.append(x)
        x = self.res(x)
        for dec, skip in zip(self.decoders, reversed(skips)):
            x = F.interpolate(x + skip, scale_factor=2, mode="bilinear", align_corners=False)
            x = F.relu(dec(x))
        out = torch.sigmoid(self.pred(x + head))
        return out[..., :h, :w], tuple(new_state)


class E2VID(FireNet):
    """``e2vid``: :class:`E2VIDModule` on normalised 5-bin voxel grids, FireNet's windows (module docstring).

    Parameters are FireNet's (``normalize``, ``events_per_pixel``, ``max_windows``) and those of every
    :class:`~neuspike.methods.learned.LearnedMethod`; the weights are our own safetensors.
    """

    def build_module(self) -> nn.Module:
        return E2VIDModule()

    def _state_hw(self) -> tuple[int, int]:
        return self._state_input_hw

    def run_step(self, inputs: tuple[torch.Tensor, ...]) -> torch.Tensor:
        self._state_input_hw = tuple(inputs[0].shape[-2:])
        return super().run_step(inputs)


def register_methods(register: Any) -> None:
    """Add ``e2vid`` to the registry."""
    register("e2vid", E2VID, params={"normalize": True}, weights="e2vid.safetensors",
             description="E2VID-style recurrent U-Net trained here on the simulator (10.7M parameters), "
                         "normalised 5-bin voxel grids, 0.35 events/pixel windows")
