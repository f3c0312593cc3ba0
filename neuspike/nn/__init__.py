"""Layers shared by the suite's networks."""

from neuspike.nn.layers import ConvGRU, ConvLSTM, ResidualBlock

__all__ = ["ConvGRU", "ConvLSTM", "ResidualBlock"]
