"""NeuSpike-Net: the spike + event fusion network and its spike-only variant.

A path written ``61a150f8:reports/neuspike-net/...`` below is a file of the training history, which left
the tree after that commit: ``git show 61a150f8:reports/neuspike-net/README.md`` prints it.

Architecture (REFERENCE §1.1; :mod:`neuspike.nets.network`): two 3-level strided encoders (64, 128,
256), the sum of the deepest features through two residual blocks, three transposed-conv decoders
(128, 64, 32) with concatenated skips, the fusion module F at the two inner skip levels, the
input-level skip ``x_t^0 + w x_m^0``, instance norm before ReLU, and a prediction head; any input
size (padded to multiples of 8, cropped back). The paper's head (a convolution and tanh mapped to
[0, 1], ``head="tanh"``) compressed contrast by about 8 % on bright scenes, since the instance-normalised
features carry no absolute scale; the shipped weights use ``head="support-count"``: a per-pixel
softmax over the spike representation's 32 radiance estimates (the temporal support the motion
allows) plus an additive correction counted in spikes per group and scaled by the data's own spike
quantum (:mod:`neuspike.nets.network`). The shipped fusion weights also have a motion gate (``motion_gate="stats"``): it scales the
motion path at each level by gains computed from the representations' un-normalised statistics, so
that noise-dominated events can be turned down (instance normalisation alone gives them full scale).
``transformer="learned"`` adds a learned full-resolution module on each representation (the paper's
learned T_spike and T_event, whose form is unknown here); against the fixed representations it did
not win on validation (``61a150f8:reports/neuspike-net/README.md``, stage 21), so the shipped weights keep
``"fixed"``.

Designs where the paper is unknown here (:mod:`neuspike.nets.representations`,
:mod:`neuspike.nets.fusion`), chosen by a short measured ablation: each candidate trained from the
same seed for 80 steps (batch 8, 48x48 crops, AdamW 1e-3, ``python -m neuspike.train neuspike-net
--steps 80 --crop 48 --param KEY=VALUE``) on windows simulated from the *training* photographs and
dead-leaves scenes, validated on 24 held-out windows (128x128) of the same distribution; one factor
changed at a time from A (``61a150f8:reports/neuspike-net/ablation.csv``):

====  =================  ==============  =========  ==================  ==================
run   T_spike            T_event         F          fusion PSNR / SSIM  spike-only PSNR
====  =================  ==============  =========  ==================  ==================
A     counts             voxel           gate       22.63 / 0.674       23.01
B     counts_interval    voxel           gate       23.35 / 0.721       23.95
C     counts             contrast        gate       23.24 / 0.693       23.13
D     counts             voxel           attention  21.98 / 0.650       22.53
====  =================  ==============  =========  ==================  ==================

Chosen (:data:`DEFAULT_DESIGN`): T_spike ``counts_interval`` (+0.7 dB over counts), T_event
``contrast`` (+0.6 dB over the normalised voxel grid: the per-bin log-contrast keeps a physical
scale that normalisation removes), F ``gate`` (+0.65 dB over channel attention). The runs are short
and single-seed, so differences below about 0.5 dB would not be decisive; these are not.

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
    "ARCHITECTURE_PARAMS", "DEFAULT_DESIGN", "DESPECKLE", "EVENT_REPRESENTATIONS", "FUSIONS", "PAPER_PARAMETERS",
    "SPIKE_REPRESENTATIONS", "AttentionFusion", "GateFusion", "NeuSpikeNet", "NeuSpikeNetMethod",
    "WIENER", "event_representation", "make_fusion", "pad_to_multiple", "register_methods", "spike_representation",
]

#: The design the ablation chose (T_spike, T_event, F).
DEFAULT_DESIGN: dict[str, Any] = {"spike_representation": "counts_interval", "event_representation": "contrast",
                                  "fusion": "gate", "head": "support-count"}

#: What the shipped weights add to it (from stage 25 on; both files are stage 43's,
#: ``61a150f8:reports/neuspike-net/README.md``): the interval sequence at the key instant, weighed by
#: :class:`~neuspike.nets.network.KeyRefine`.
SHIPPED_DESIGN: dict[str, Any] = {"key_estimates": "isi-sequence"}

#: The compact variants (``neuspike-net-lite`` and ``neuspike-net-spike-lite`` once trained): the shipped design
#: at 0.45 of every encoder and decoder width with a 1x1 prediction layer, the representations, head and
#: level unchanged. At 400x250: 6.6 of the fusion network's 30.6 GFLOP and 4.4 of the spike-only
#: network's 20.2 (torch's FLOP counter; ``tests/neuspike/nets/test_lite.py``).
LITE_DESIGN: dict[str, Any] = {"width": 0.45, "head_kernel": 1}


#: The registered networks' read-out margin for isolated outliers (:func:`neuspike.methods.readout.despeckle`):
#: a pixel beyond all eight neighbours' range by more than 0.1 of the range is replaced by its 3x3
#: median, pass after pass until none remains. Chosen on the 48 validation windows of the training
#: photographs (2-core AMD EPYC Genoa, shipped weights; mean PSNR / SSIM / specks per mille of the
#: fusion network, one pass): off 35.90 / 0.881 / 1.69, 0.2: 36.05 / 0.889 / 0.85, 0.1: 35.97 / 0.892 / 0.06,
#: 0.05: 35.72 / 0.893 / 0.11: the smallest margin whose PSNR stays above the read-out without it, and the
#: fewest specks; repeated passes: 35.96 / 0.892 / 0.00 (the spike-only network 34.19 / 0.862 / 1.88 off,
#: 34.32 / 0.874 / 0.00).
DESPECKLE = 0.1

#: The registered networks' smoothing of what noise they leave (:func:`neuspike.methods.readout.wiener`, after
#: despeckling): the local Wiener filter over 5x5 boxes with the noise variance twice the 10th percentile of the
#: image's local variance. Chosen on windows of the training photographs (page, cell, rocket, hubble_deep_field,
#: brick, coffee; still and pan, 400x250, L = 1/32, 1/8, 1/2 at every noise level, seed 0: 96 cells, 2-core AMD
#: EPYC with AVX-512 BF16, the shipped weights in bfloat16) among boxes 3-9, percentiles 10-50 and multiples 1-3:
#: the highest mean SSIM of the candidates that lower neither PSNR nor SSIM at any of the 12 points for either
#: network by any amount, by a margin of 0.1 dB (5x5 with the 10th percentile and 7x7 also gain, 3x3 gains less).
#: Mean PSNR / SSIM over the 96 cells, off -> on: fusion 35.96 / 0.879 -> 36.73 / 0.927, spike-only 35.56 / 0.874
#: -> 36.34 / 0.924; the gain is largest where the noise is (L = 1/32 under high noise +1.6 dB / +0.20 SSIM) and
#: smallest on clean bright windows (L = 1/8 without noise +0.14 dB / +0.0008). The network is trained for PSNR and
#: leaves grain of a few hundredths of the range on flat dim regions, which SSIM's structure term punishes.
WIENER = 2.0


def register_methods(register: Callable[..., Any]) -> None:
    """Register ``neuspike-net`` and ``neuspike-net-spike`` (the ``neuspike.methods`` entry point)."""
    register("neuspike-net", NeuSpikeNetMethod,
             params={**DEFAULT_DESIGN, **SHIPPED_DESIGN, "spike_only": False, "motion_gate": "stats",
                     "despeckle": DESPECKLE, "wiener": WIENER},
             inputs={"spikes", "events"}, weights="neuspike-net.safetensors",
             description="NeuSpike-Net: spike + event fusion U-Net (trained here on the simulator)")
    register("neuspike-net-spike", NeuSpikeNetMethod,
             params={**DEFAULT_DESIGN, **SHIPPED_DESIGN, "spike_only": True, "despeckle": DESPECKLE, "wiener": WIENER},
             inputs={"spikes"}, weights="neuspike-net-spike.safetensors",
             description="NeuSpike-Net, spike-only variant: texture path and decoders")
