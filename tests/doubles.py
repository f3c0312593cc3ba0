"""Test doubles shared by the suite's tests: methods that work, fail, or are unavailable, behind the
common interface (each test registers them under its own names)."""

from __future__ import annotations

import numpy as np

from neuspike.methods import Method, MethodUnavailable


class MeanRate(Method):
    """A spike method: the window's mean rate over the gain, clipped to [0, 1]."""

    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        s = sample.spikes
        return np.clip(s.planes.mean(axis=0) / s.gain, 0, 1).astype(np.float32), "gain"


class Failing(Method):
    """A spike method whose every call raises."""

    inputs = frozenset({"spikes"})

    def _reconstruct(self, sample):
        raise RuntimeError("deliberate failure")


class Unavailable(Method):
    """An event method that cannot be created (as a network without its weights)."""

    inputs = frozenset({"events"})

    def __init__(self, name=None, **params):
        raise MethodUnavailable("weights not given (test)")

    def _reconstruct(self, sample):
        raise AssertionError("never called")


class WithWeights(Method):
    """Base of doubles whose registry entry declares weights: built with a ``device``, then handed the
    file :func:`neuspike.methods.create` resolved (recorded as a learned method records it)."""

    def __init__(self, name=None, *, device="cpu", **params):
        super().__init__(name, device=device, **params)
        self.weights_path = None

    def load_file(self, path):
        from pathlib import Path

        self.weights_path = Path(path)
        self.params["weights_file"] = self.weights_path.name
        return self
