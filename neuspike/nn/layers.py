"""Recurrent cells and residual blocks shared by the suite's networks (FireNet, E2VID-style, NeuSpike-Net).

Every layer documents its tensor shapes with the project's letters: B batch, C channels, H, W.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ConvGRU", "ConvLSTM", "ResidualBlock"]


class ConvGRU(nn.Module):
    """Convolutional GRU cell with 3x3 gates.

    The update and reset gates read the same ``[x, s]``, so they run as one convolution with
    ``2C`` output channels (their weights concatenated along the output channels), which computes
    each output channel exactly as the two separate convolutions do. Without autograd the
    concatenated input is built once: after the gates, its state half is overwritten in place with
    ``s * r`` for the candidate convolution.

    Parameters
    ----------
    channels : int
        Channels of the input and of the hidden state (C).
    """

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.update = nn.Conv2d(2 * channels, channels, 3, padding=1)
        self.reset = nn.Conv2d(2 * channels, channels, 3, padding=1)
        self.candidate = nn.Conv2d(2 * channels, channels, 3, padding=1)

    def gate_weights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The update and reset gates as one convolution: weight (2C, 2C, 3, 3), bias (2C,)."""
        return (torch.cat([self.update.weight, self.reset.weight]), torch.cat([self.update.bias, self.reset.bias]))

    def forward(self, x: torch.Tensor, state: torch.Tensor,
                gates: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """x, state: (B, C, H, W) -> new state (B, C, H, W), of the state's dtype.

        ``gates`` may pass :meth:`gate_weights` computed once in advance.
        """
        c = x.shape[1]
        weight, bias = self.gate_weights() if gates is None else gates
        xs = torch.cat([x, state.to(x.dtype)], dim=1)
        zr = torch.sigmoid(F.conv2d(xs, weight.to(xs.dtype), bias.to(xs.dtype), padding=1))
        z, r = zr[:, :c], zr[:, c:]
        if torch.is_grad_enabled() and (xs.requires_grad or r.requires_grad):
            xs = torch.cat([x, state.to(x.dtype) * r], dim=1)  # autograd still needs the old xs
        else:
            torch.mul(xs[:, c:], r, out=xs[:, c:])  # [x, s * r] in place
        o = torch.tanh(self.candidate(xs))
        return torch.addcmul(state, o.to(state.dtype) - state, z.to(state.dtype))


class ResidualBlock(nn.Module):
    """3x3 conv, ReLU, 3x3 conv, + input, ReLU; channels unchanged."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv_a = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv_b = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x: (B, C, H, W) -> (B, C, H, W)."""
        y = self.conv_b(F.relu_(self.conv_a(x)))
        return F.relu_(y.add_(x))


class ConvLSTM(nn.Module):
    """Convolutional LSTM cell: the four gates from one convolution over ``[x, h]``.

    ``i, f, o = sigmoid(...)``, ``g = tanh(...)``, ``c' = f * c + i * g``, ``h' = o * tanh(c')``.

    Parameters
    ----------
    in_channels : int
        Channels of the input x.
    hidden_channels : int
        Channels of the hidden state h and the cell c.
    kernel_size : int
        Size of the gate convolution (odd).
    """

    def __init__(self, in_channels: int, hidden_channels: int, kernel_size: int = 3) -> None:
        super().__init__()
        self.hidden_channels = hidden_channels
        self.gates = nn.Conv2d(in_channels + hidden_channels, 4 * hidden_channels, kernel_size,
                               padding=kernel_size // 2)

    def forward(self, x: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None
                ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """x: (B, C_in, H, W); state (h, c) each (B, C_h, H, W) or None (zeros) -> (h', (h', c'))."""
        if state is None:
            zeros = x.new_zeros((x.shape[0], self.hidden_channels, *x.shape[2:]), dtype=torch.float32)
            state = (zeros, zeros)
        h, c = state
        i, f, o, g = self.gates(torch.cat([x, h.to(x.dtype)], dim=1)).chunk(4, dim=1)
        c = torch.sigmoid(f).to(c.dtype) * c + (torch.sigmoid(i) * torch.tanh(g)).to(c.dtype)
        h = torch.sigmoid(o).to(c.dtype) * torch.tanh(c)
        return h, (h, c)
