"""Layers shared by the suite's networks."""

from neuspike.nn.blocks import ConvNormReLU, NormResidualBlock, UpConvNormReLU
from neuspike.nn.layers import ConvGRU, ConvLSTM, ResidualBlock

__all__ = ["ConvGRU", "ConvLSTM", "ConvNormReLU", "NormResidualBlock", "ResidualBlock", "UpConvNormReLU"]
