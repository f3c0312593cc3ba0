"""Plug-in: TFP, TFI and SNM with NeuSpike-Net's counted mean level, to see what that level gives them.

    python -m bench.noise --level all --full --methods snm-counted,tfi-counted,tfp-counted \
        --plugin reports/neuspike-net/counted_baselines.py --out runs/full/noise-counted --workers 1 --threads 1

Registers ``snm-counted``, ``tfi-counted`` and ``tfp-counted``: each baseline as published, then its
image shifted so that its mean equals :func:`neuspike.nets.method.count_level` (the frame's mean
radiance from the window's spike count, the sensor's gain and dark rate), exactly as
``neuspike-net`` does with ``level="counts"``. They are for a fairness check in the NeuSpike-Net
report, not registered by default.
"""

import numpy as np

from baselines.snm import SNM
from baselines.tfi import TFI
from baselines.tfp import TFP
from neuspike.nets.method import COUNTED, count_level


def _counted(base):
    class Counted(base):
        def _reconstruct(self, sample):
            image, label = super()._reconstruct(sample)
            level = count_level(sample)
            if level is None:
                return image, label
            return np.clip(image + np.float32(level - image.mean(dtype=np.float64)), 0.0, 1.0), f"{label}; {COUNTED}"

    Counted.__name__ = f"{base.__name__}Counted"
    return Counted


def register_methods(register):
    for name, base in (("snm", SNM), ("tfi", TFI), ("tfp", TFP)):
        register(f"{name}-counted", _counted(base), params={},
                 description=f"{name} with the mean level counted from the spikes (fairness check)")
